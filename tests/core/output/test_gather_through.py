"""Final gather rays through see-through faces (core/output/through.py), against closed forms:
a floor point under a down-facing plane of uniform transmittance and under a checker of alpha
cut-outs (form factors of rectangles), the plane's back read once, and a scene whose rays meet
no see-through face giving exactly the gather it gave without one."""
from __future__ import annotations

import numpy as np
import pytest

from hemicube_radiosity.core.light.transmit import AlphaImage, Transmit
from hemicube_radiosity.core.mesh.backs import offset
from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.output.gather import correct_hits, gather_matrix
from hemicube_radiosity.core.rays import embree_available, embree_scene
from tests.core.output.test_gather import _rectangle_above

pytestmark = pytest.mark.skipif(not embree_available(), reason="the gather needs embreex")

PIX = (np.indices((4, 4)).sum(axis=0) % 2).astype(np.float32)     # transmittance, row 0 at v = 0
CORNER_UV = np.array([[0, 0], [0, 1], [1, 1], [1, 0]], float)      # the down-facing quad's corners
RAYS = 4096


def _meshes(transmit, back=True):
    """A 4 x 4 m floor (0.1 m faces) and a 2 x 2 m plane 1 m over it facing down (rho 0.3),
    with its back (a hair above, as :mod:`..mesh.backs` puts it) when ``back``."""
    xs = np.linspace(-2, 2, 41)
    X, Y = np.meshgrid(xs, xs, indexing="xy")
    v = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], 1)
    i = np.arange(41 * 41).reshape(41, 41)
    f = np.stack([i[:-1, :-1], i[:-1, 1:], i[1:, 1:], i[1:, :-1]], -1).reshape(-1, 4)
    floor = MeshInput.from_faces(v, f, rho=(0.5,) * 3, name="floor")
    pv = np.array([[-1, -1, 1], [-1, 1, 1], [1, 1, 1], [1, -1, 1]], float)         # normal -z
    leaf = MeshInput.from_faces(pv, [[0, 1, 2, 3]], rho=(0.3,) * 3, name="leaf")
    leaf.transmit = transmit
    out = [floor, leaf]
    if back:
        h = offset(pv)
        out.append(MeshInput(pv + [0, 0, h], leaf.face_offsets, leaf.face_indices[::-1].copy(),
                             leaf.face_rho, leaf.face_emission, "leaf (back)", back_of=1,
                             back_faces=np.array([0])))
    return out


def _gather(meshes, pts):
    P = build_patches(meshes, None)
    up = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    G, sky, H = gather_matrix(P, pts, up, embree_scene(P), rays=RAYS, hits=True)
    sides = [np.isin(np.arange(len(P.verts)), P.polys[P.owner == k]).astype(float)[:, None] for k in (1, 2)]
    return P, G, sky, H, [G.matvec(s)[:, 0] for s in sides]


def _cells(x, y, solid):
    """Form factor of the cells of the checker ``solid`` (4, 4) bool from floor point (x, y)."""
    e = np.linspace(-1, 1, 5)
    return sum(_rectangle_above(e[j] - x, e[j + 1] - x, e[i] - y, e[i + 1] - y, 1.0)
               for i in range(4) for j in range(4) if solid[i, j])


PTS = np.array([[0.0, 0.0, 0.0], [0.25, 0.25, 0.0], [0.75, -0.25, 0.0], [1.6, 0.3, 0.0]])


@pytest.mark.parametrize("back", [True, False])
def test_a_uniform_plane_is_read_whole_and_passes_its_share_to_the_sky(back):
    """Transmittance 0.3: the plane's light (its reflectance carries its opacity 0.7, as the
    solve's does) is read at weight 1 over its form factor F, and 0.3 F more of the sky is seen.
    Its back, a hair above, is the same surface: crossed once (not 0.3 squared)."""
    P, G, sky, H, (front, rear) = _gather(_meshes(Transmit(np.array([0.3])), back), PTS)
    F = np.array([_rectangle_above(-1 - x, 1 - x, -1 - y, 1 - y, 1.0) for x, y, _ in PTS])
    sigma = np.sqrt(F * (1 - F) / RAYS)
    assert np.all(np.abs(front - F) < 4 * sigma + 1e-9)
    assert np.all(np.abs(sky - (1 - 0.7 * F)) < 4 * sigma + 1e-9)
    assert not rear.any()                                    # the back faces away: never read
    assert H.shape[1] == 6 and np.allclose(H[H[:, 1] == np.flatnonzero(P.owner == 1)[0], 5], 1.0)


def test_a_checker_of_cut_outs_is_read_where_solid_and_seen_through_its_holes():
    """A 4 x 4 checker of alpha cut-outs (opacity 1/2): a ray reads the plane where it lands
    on a solid cell, twice its mean light (its reflectance carries the half), and sees the sky
    through a hole: 2 F_solid and 1 - F_solid, F_solid the solid cells' form factor."""
    tr = Transmit(np.zeros(1), np.zeros(1, np.int64), CORNER_UV, [AlphaImage(PIX, closest=True)])
    P, G, sky, H, (front, _) = _gather(_meshes(tr), PTS)
    Fs = np.array([_cells(x, y, PIX < 0.5) for x, y, _ in PTS])
    sigma = np.sqrt(Fs * (1 - Fs) / RAYS)
    assert np.all(np.abs(front - 2 * Fs) < 8 * sigma + 1e-9)
    assert np.all(np.abs(sky - (1 - Fs)) < 4 * sigma + 1e-9)
    assert Fs[1] > 0.25 and Fs[3] < 0.1       # a point under a solid cell, one outside the plane
    # the hits carry their weights: a correction that reads 1 on the plane adds what G reads
    # of 1 there less what it reads of the values interpolated
    vals = np.random.default_rng(1).random((len(P.verts), 1))
    on = np.isin(np.arange(len(P.verts)), P.polys[P.owner == 1])
    got = correct_hits(G, H, P, vals, lambda y, pid: np.ones((len(pid), 1)), P.owner == 1)[:, 0]
    np.testing.assert_allclose(got, front - G.matvec(np.where(on, vals[:, 0], 0.0)[:, None])[:, 0], atol=1e-6)


def test_rays_that_meet_no_see_through_face_give_the_opaque_gather_bit_for_bit():
    """A see-through plane where no ray reaches it (below the floor) changes nothing: the same
    G, sky fraction and hits as the scene without see-through faces."""
    tr = Transmit(np.array([0.5]))
    floor, leaf = _meshes(tr, back=False)
    wall = MeshInput.from_faces(np.array([[2, -2, 0], [2, 2, 0], [2, 2, 1], [2, -2, 1]], float),
                                [[0, 1, 2, 3]], rho=(0.5,) * 3, name="wall")
    leaf.verts = leaf.verts - [0, 0, 3]
    pts = np.array([[0.0, 0.0, 0.0], [1.5, 1.0, 0.0], [-1.9, 0.4, 0.0]])
    a = _gather([floor, wall, leaf], pts)
    leaf.transmit = None
    b = _gather([floor, wall, leaf], pts)
    assert a[0].see_through is not None and b[0].see_through is None
    for x, y in ((a[1].indptr, b[1].indptr), (a[1].indices, b[1].indices), (a[1].data, b[1].data), (a[2], b[2])):
        assert np.array_equal(x, y)
    assert np.array_equal(a[3][:, :5], b[3]) and np.all(a[3][:, 5] == 1)


def _lid_scene(t):
    """The 4 x 4 m floor, a 2 x 2 m roof of transmittance ``t`` 1 m over it and an opaque lid
    facing down 1 m over the roof, a point lamp between the two: the floor under the roof sees
    the lit lid through it."""
    floor, roof = _meshes(Transmit(np.array([t])), back=False)
    lid = MeshInput.from_faces(np.array([[-2, -2, 2], [-2, 2, 2], [2, 2, 2], [2, -2, 2]], float),
                               [[0, 1, 2, 3]], rho=(0.8,) * 3, name="lid")
    return [floor, roof, lid]


def test_a_relight_with_a_new_transmittance_gathers_again():
    """The gather's matrix is cached by geometry and by what passes: a roof made more
    transparent on a relight (same geometry, cache shared) gathers the new share of the lid's
    light, as a bake without the cache does (the first bake's matrix, passing 0.2 of it, would
    not)."""
    from hemicube_radiosity.core.light.lamps import PointLight
    from hemicube_radiosity.core.pipeline import BakeSettings, bake
    from hemicube_radiosity.core.runtime.cache import FormFactorCache

    s = BakeSettings(patch_size=1.0, element_size=0.5, method="hemicube", resolution=16, gather_rays=64,
                     group_faces=False)
    lamp = [PointLight(position=(0.0, 0.0, 1.5), power_w=200.0)]
    cache = FormFactorCache()
    first = bake(_lid_scene(0.2), s, lights=lamp, cache=cache)
    second = bake(_lid_scene(0.8), s, lights=lamp, cache=cache)
    fresh = bake(_lid_scene(0.8), s, lights=lamp)
    assert first.elements.see_through is not None
    np.testing.assert_allclose(second.corner_values(), fresh.corner_values(), rtol=1e-6, atol=1e-9)
