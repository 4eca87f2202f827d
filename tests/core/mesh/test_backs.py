"""Backs of open surfaces (core/mesh/backs.py) on faces that cover nothing."""
import numpy as np
import pytest

from hemicube_radiosity.core.builtin_scenes import box, quad
from hemicube_radiosity.core.mesh.backs import with_backs
from hemicube_radiosity.core.mesh.patches import MeshInput, covering_faces
from hemicube_radiosity.core.pipeline import bake
from hemicube_radiosity.core.runtime.cache import FormFactorCache
from hemicube_radiosity.core.settings import BakeSettings

SKY = np.array([0.4, 0.5, 0.6])


def _with_slivers(mesh, slivers):
    """``mesh`` plus faces of no area: each sliver (3, 3) three corners on one line, or (3, 3)
    with two corners at one point."""
    v = np.asarray(mesh.verts, float)
    off, idx = np.asarray(mesh.face_offsets), np.asarray(mesh.face_indices)
    polys = [list(idx[off[f]:off[f + 1]]) for f in range(len(off) - 1)]
    for s in slivers:
        polys.append(list(range(len(v), len(v) + 3)))
        v = np.vstack([v, s])
    F = len(polys)
    rho = np.vstack([mesh.face_rho, np.repeat(np.asarray(mesh.face_rho)[:1], F - len(off) + 1, 0)])
    return MeshInput.from_faces(v, polys, rho, np.zeros((F, 3)), mesh.name)


def _scene(slivers=()):
    floor = quad([(-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)], rho=(0.6, 0.6, 0.6), name="floor")
    block = box((-0.5, -0.5, 0.0), (0.5, 0.5, 1.0), rho=(0.7, 0.5, 0.3), name="block")
    return [floor, _with_slivers(block, slivers) if len(slivers) else block]


SLIVERS = [[(0.6, 0.0, 0.2), (0.6, 0.0, 0.5), (0.6, 0.0, 0.8)],          # three corners on a line
           [(0.7, 0.1, 0.3), (0.7, 0.1, 0.3), (0.7, 0.3, 0.3)]]          # two corners at one point


def test_faces_of_no_area_cover_nothing_and_get_no_back():
    m = _scene(SLIVERS)[1]
    cover = covering_faces(m.verts, m.face_offsets, m.face_indices)
    assert cover.tolist() == [True] * 6 + [False, False]
    out = with_backs(_scene(SLIVERS), world=SKY)
    for back in out[2:]:
        assert back.back_of == 0 or covering_faces(back.verts, back.face_offsets, back.face_indices).all()
        assert back.back_of != 1           # the block is closed but for its slivers: no back at all


@pytest.mark.parametrize("method", ["hemicube", "embree"])
def test_a_mesh_whose_only_open_faces_are_slivers_bakes_as_without_them(method):
    """The grey-white room's Mesh035 (6 faces of no area, the rest closed) was refused: 'Mesh035
    (back)': every face has zero area. Its slivers now change nothing."""
    s = BakeSettings(patch_size=0.5, resolution=32, gather_rays=0, method=method)
    plain = bake(_scene(), s, world=SKY)
    slivered = bake(_scene(SLIVERS), s, world=SKY)
    assert len(slivered.patches.object_names) == len(plain.patches.object_names)
    for r in (plain, slivered):
        assert np.all(np.isfinite(r.vertex_radiosity))
    np.testing.assert_allclose(slivered.patch_radiosity, plain.patch_radiosity, rtol=1e-9, atol=1e-12)
    # the floor beside the block: lit by the sky (0.6 x sky on open ground, less in the block's shade)
    floor = slivered.patch_radiosity[slivered.patches.owner == 0]
    assert 0.3 * 0.6 * SKY[2] < floor[:, 2].mean() < 0.6 * SKY[2]


def test_a_relight_of_hundreds_of_open_meshes_keeps_its_form_factors():
    """300 open cards over a floor under a sky: each card's back matters. Their backs are one
    cache item, so a relight finds the form factors the first bake left (a staircase hall of 775
    objects evicted them: the backs filled the cache's count of items) and equals a cold bake."""
    cards = [quad([(x, y, 0.5), (x + 0.2, y, 0.5), (x + 0.2, y, 0.7), (x, y, 0.7)], name=f"card{x}_{y}")
             for x in np.linspace(-1.8, 1.6, 20) for y in np.linspace(-1.8, 1.6, 15)]
    floor = quad([(-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)], rho=(0.6, 0.6, 0.6), name="floor")
    s = BakeSettings(patch_size=0.5, resolution=16, method="hemicube")
    cache = FormFactorCache()
    first = bake([floor, *cards], s, world=SKY, cache=cache)
    assert len(first.patches.areas) > 600                      # both sides of every card
    warm = bake([floor, *cards], s, world=2 * SKY, cache=cache)
    assert warm.form_factor_source == "cached" and warm.form_factors is first.form_factors
    assert len(cache._mem) < 64
    np.testing.assert_allclose(warm.solution.B, 2 * first.solution.B, rtol=1e-6, atol=1e-12)


def test_a_back_s_corner_normals_are_kept_per_front_array_and_follow_an_edit():
    """A card's back shades with its front's corner normals reversed. With read-only fronts a
    relight's back has the same (read-only) array, so what is keyed on it (the output's shading
    normals) is found again; new front normals (an edit) give the new ones reversed; a writable
    front (which may change in place) is read anew every time."""
    from dataclasses import replace

    card = quad([(0, 0, 0.5), (1, 0, 0.5), (1, 0, 0.7), (0, 0, 0.7)], name="card")
    floor = quad([(-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)], rho=(0.6, 0.6, 0.6), name="floor")
    tilt = np.tile([[0.0, -0.8, 0.6]], (len(card.face_indices), 1))
    tilt /= np.linalg.norm(tilt, axis=1, keepdims=True)
    tilt.flags.writeable = False
    card = replace(card, corner_normal=tilt)
    cache = FormFactorCache()

    def back(c):
        out = with_backs([floor, c], world=SKY, cache=cache)
        backs = [m for m in out if getattr(m, "back_of", -1) == 1]
        assert len(backs) == 1                                   # the card's back matters
        return backs[0].corner_normal
    a = back(card)
    np.testing.assert_array_equal(a, -tilt)                      # every corner the same: reversed
    assert back(card) is a and not a.flags.writeable             # a relight: the same array
    other = np.tile([[0.0, -0.6, 0.8]], (len(card.face_indices), 1))
    other.flags.writeable = False
    np.testing.assert_array_equal(back(replace(card, corner_normal=other)), -other)   # an edit
    loose = tilt.copy()                                          # writable: never kept
    b1 = back(replace(card, corner_normal=loose))
    loose[:] = other
    np.testing.assert_array_equal(back(replace(card, corner_normal=loose)), -other)
    np.testing.assert_array_equal(b1, -tilt)
