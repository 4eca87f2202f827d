"""Light mirrored by glossy patches (core/form_factors/glossy.py) against closed forms: a mirror
shows a patch its image, so what it sees in the mirror is what it would see of the image, at
twice the height (Siegel & Howell's parallel rectangles; Lambert's point-to-rectangle factor)."""
from dataclasses import replace

import numpy as np
import pytest

from hemicube_radiosity.core import builtin_scenes as scenes
from hemicube_radiosity.core.form_factors.glossy import specular_transport
from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core import pipeline
from hemicube_radiosity.core.pipeline import BakeSettings, bake
from tests.support.analytic import parallel_rectangles, point_under_rectangle_corner
from tests.support.markers import needs_embree


def _quad(corners, name, rho=0.0, emission=0.0, glossy=None):
    m = MeshInput.from_faces(corners, [[0, 1, 2, 3]], rho=(rho,) * 3, emission=(emission,) * 3, name=name)
    return m if glossy is None else replace(m, face_glossy=np.full((1, 3), float(glossy)))


@needs_embree
def test_a_square_sees_its_image_at_twice_the_height():
    """A unit square 0.5 over a mirror of its size sees its image 1 away: F^s = F(parallel
    squares 1 apart) = 0.1998, and the rest of what it sees of the mirror is sky in the mirror:
    together F(parallel squares 0.5 apart) = 0.4152."""
    h = 0.5
    sq = _quad([(0, 0, h), (0, 1, h), (1, 1, h), (1, 0, h)], "square", rho=0.5)
    floor = _quad([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], "mirror")
    p = build_patches([sq, floor], 0.25)
    glossy = np.flatnonzero(p.owner == 1)
    S = specular_transport(p, glossy, 4096, seed=1)
    g = np.zeros((len(p), 3))
    g[glossy] = 1.0
    F = S.matrix(g).to_dense()
    a, i = p.areas, p.owner == 0
    seen = (a[i, None] * F[np.ix_(i, i)]).sum() / a[i].sum()
    sky = (a[i] * S.sky(g)[i, 0]).sum() / a[i].sum()
    # 16 mirror patches x 4096 samples, a fifth of them on the square both ways: ~1% noise
    assert seen == pytest.approx(parallel_rectangles(1, 1, 2 * h), rel=0.02)
    assert seen + sky == pytest.approx(parallel_rectangles(1, 1, h), rel=0.01)
    # reciprocity (A_i F^s_ik = A_k F^s_ki) holds sample by sample
    R = a[:, None] * F
    np.testing.assert_allclose(R, R.T, atol=1e-12)
    # g scales the mirror's light band by band
    g2 = g * np.array([1.0, 0.5, 0.0])
    np.testing.assert_allclose(S.apply(g2, np.ones((len(p), 3)))[i].sum(0) / S.apply(g, np.ones((len(p), 3)))[i].sum(0),
                               [1.0, 0.5, 0.0], atol=1e-12)


@needs_embree
def test_a_mirror_cut_fine_casts_its_unknowns_samples_not_its_faces(monkeypatch):
    """The same square over a mirror of 24 x 24 faces grouped as one unknown (a cluster): the
    samples are the cluster's (spread over its faces by area), so the rays follow the unknowns,
    not how finely the mirror was modelled, and the image is the closed form's all the same."""
    from hemicube_radiosity.core.form_factors import glossy as glossy_mod
    from hemicube_radiosity.core.mesh.clusters import make_clusters

    h = 0.5
    sq = _quad([(0, 0, h), (0, 1, h), (1, 1, h), (1, 0, h)], "square", rho=0.5)
    floor = scenes.tessellate([_quad([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], "mirror")], 24, triangles=False)[0]
    p = build_patches([sq, floor], 0.25)
    glossy = np.flatnonzero(p.owner == 1)
    assert glossy.size == 576
    # the square's 16 patches each their own unknown, the mirror's 576 faces one
    of = np.where(p.owner == 1, 16, np.cumsum(p.owner == 0) - 1)
    clusters = make_clusters(p, of)
    cast = []
    intersect = glossy_mod.embree_scene(p).intersect

    def counting(o, d):
        cast.append(len(o))
        return intersect(o, d)
    monkeypatch.setattr(glossy_mod.embree_scene(p), "intersect", counting)
    S = specular_transport(p, glossy, 16384, seed=1, clusters=clusters)
    assert sum(cast) - 1 == 2 * 16384                 # (the first ray commits the scene)
    g = np.zeros((len(p), 3))
    g[glossy] = 1.0
    F = S.matrix(g).to_dense()[:16, :16]              # the square's unknowns
    a = clusters.areas[:16]
    seen = (a[:, None] * F).sum() / a.sum()
    sky = (a * S.sky(g)[:16, 0]).sum() / a.sum()
    assert seen == pytest.approx(parallel_rectangles(1, 1, 2 * h), rel=0.02)
    assert seen + sky == pytest.approx(parallel_rectangles(1, 1, h), rel=0.01)


def _offset_factor(h, n=60):
    """Area mean over the unit square [0,1]^2 at z = h facing down of the form factor to the
    parallel square [1,2] x [0,1] at z = -h facing up (by superposition of Lambert's
    point-under-a-corner factor), on an n x n grid of points."""
    c = 2 * h
    f = (lambda dx, dy: np.sign(dx) * np.sign(dy) * point_under_rectangle_corner(np.abs(dx), np.abs(dy), c))
    t = (np.arange(n) + 0.5) / n
    x, y = np.meshgrid(t, t, indexing="ij")
    F = f(2 - x, 1 - y) - f(1 - x, 1 - y) - f(2 - x, 0 - y) + f(1 - x, 0 - y)
    return float(F.mean())


@needs_embree
def test_an_emitter_seen_in_a_mirror_lights_as_its_image(monkeypatch):
    """A lamp panel beside a square, both facing down 0.5 over a mirror floor of albedo 0.9 (no
    diffuse part): the square receives nothing directly, and through the mirror what the lamp's
    image 1 below would give it: 0.9 x E x F(square -> image) = 0.0774, the closed form; 0.0776
    here. The floor's light spread as diffuse light (without Embree) gives 0.0683, 12% low."""
    h, g, E = 0.5, 0.9, 1.0
    sq = _quad([(0, 0, h), (0, 1, h), (1, 1, h), (1, 0, h)], "square", rho=0.01)
    lamp = _quad([(1, 0, h), (1, 1, h), (2, 1, h), (2, 0, h)], "lamp", emission=E)
    floor = _quad([(0, 0, 0), (2, 0, 0), (2, 1, 0), (0, 1, 0)], "mirror", glossy=g)
    s = BakeSettings(patch_size=0.125, element_size=None, method="embree", resolution=32,
                     specular_rays=4096, two_sided_emission=False)
    res = bake([sq, lamp, floor], s)
    p = res.patches
    i = p.owner == 0
    arriving = (res.solution.B[i] - p.emission[i]) / p.rho[i]
    mean = (p.areas[i, None] * arriving).sum(0) / p.areas[i].sum()
    exact = g * E * _offset_factor(h)
    # the square sees its own image too (rho 0.01 x 0.9 x 0.2: +0.2%), the rays' noise ~1%
    np.testing.assert_allclose(mean, exact, rtol=0.03)
    # the mirror shows only its diffuse part: black
    assert np.abs(res.solution.B[p.owner == 2]).max() == 0.0
    monkeypatch.setattr(pipeline, "embree_available", lambda: False)      # the diffuse spread
    res = bake([sq, lamp, floor], s)
    p = res.patches
    i = p.owner == 0
    spread = (res.solution.B[i, 0] - p.emission[i, 0]) / p.rho[i, 0]
    assert (p.areas[i] * spread).sum() / p.areas[i].sum() < 0.9 * exact


@needs_embree
@pytest.mark.parametrize("direct", ["exact", "hemicube"])
def test_the_furnace_with_a_coloured_mirror_floor(direct):
    """A closed 2 x 2 x 1 room where every surface emits E = 1 and reflects rho = (0.9, 0.7, 0.5)
    in all: walls and ceiling diffusely, the floor 0.3 diffusely and (0.6, 0.4, 0.2) as a mirror.
    The radiance is E / (1 - rho) everywhere, whatever goes where (the furnace): the walls show
    (10, 3.33, 2), the floor its diffuse part E + 0.3 E / (1 - rho). Checks that the mirror hands
    on what it receives, no more and no less, band by band (a coloured metal's own bands), with
    a diffuse part that makes rho F + F^s count its floor twice (walls at 0.9 x (1 + 0.6 x 0.4))."""
    rho = np.array([0.9, 0.7, 0.5])
    g = np.array([0.6, 0.4, 0.2])
    room = scenes.box((0, 0, 0), (2, 2, 1), tuple(rho), (1.0, 1.0, 1.0), inward=True, bottom=False, name="room")
    floor = replace(_quad([(0, 0, 0), (2, 0, 0), (2, 2, 0), (0, 2, 0)], "floor", rho=0.3, emission=1.0),
                    face_glossy=g[None, :])
    s = BakeSettings(patch_size=0.25, element_size=None, method="embree", resolution=64, direct=direct)
    res = bake([room, floor], s)
    p, B = res.patches, res.solution.B
    walls, fl = p.owner == 0, p.owner == 1
    furnace = 1.0 / (1.0 - rho)
    mean = lambda m: (p.areas[m, None] * B[m]).sum(0) / p.areas[m].sum()    # noqa: E731
    np.testing.assert_allclose(mean(walls), furnace, rtol=0.02)
    np.testing.assert_allclose(mean(fl), 1.0 + 0.3 * furnace, rtol=0.02)


def test_a_receiver_sees_no_more_in_the_mirrors_than_it_sees_of_them():
    """bounded_by_view caps a receiver's row of F^s (with its sky part) at its own hemi-cube's
    view of the glossy patches: a 2 cm chip over a 4 m mirror is met by a few of the mirror's
    rays, each weighted A_j / A_i = 40,000 (here receiver 0: 2.0 + 0.4 through mirror 2 against
    a view of 0.9), while a receiver within its view (1: 0.5 against 0.6) keeps its entries
    and one that sees no mirror in F (3) loses them."""
    from hemicube_radiosity.core.form_factors.glossy import Specular, bounded_by_view
    from hemicube_radiosity.core.util.sparse import CSR

    i64 = lambda *v: np.array(v, np.int64)
    S = Specular(rows=i64(0, 0, 1, 3), cols=i64(1, 3, 0, 1), via=i64(2, 2, 2, 2),
                 weight=np.array([1.5, 0.5, 0.5, 0.2]), sky_rows=i64(0), sky_via=i64(2),
                 sky_weight=np.array([0.4]), n=4, rays=64, glossy=i64(2))
    F = CSR.from_coo(i64(0, 0, 1, 1, 3), i64(2, 1, 2, 3, 1), np.array([0.9, 0.1, 0.6, 0.4, 1.0]), (4, 4))
    B = bounded_by_view(S, F)
    g = np.zeros((4, 3))
    g[2] = 1.0
    row = lambda X: X.matrix(g).to_dense().sum(axis=1) + X.sky(g)[:, 0]
    np.testing.assert_allclose(row(S), [2.4, 0.5, 0.0, 0.2])
    np.testing.assert_allclose(row(B), [0.9, 0.5, 0.0, 0.0], rtol=1e-6)
    # the direction is kept: the chip's entries keep their proportions
    np.testing.assert_allclose(B.weight[:2] / B.weight[:2].sum(), [0.75, 0.25])
