"""Random scenes through the whole bake (issue 29), so that a crash cannot hide in a corner of the
input space the hand-made scenes miss: meshes welded, split per face (flat shading) or along a
seam, grids of 1..120 faces a side, textured or plain, thin boards and closed boxes, blocks
standing on or sunk into the floor, coplanar rugs, tiny and huge faces, n-gons, emitters, lamps
and the world (``tests/support/random_scenes.py`` builds them from a seed).

Every bake must end in a result or a :class:`RadiosityError` (a one-line refusal); any other
exception is a bug. A result must hold what holds for any scene: finite, non-negative radiosity
at every output vertex, no brighter than the brightest source can make it (E_max / (1 - rho_max)
when only emitting faces and the world light it); in a closed room where every surface emits E
and reflects rho, every vertex is E / (1 - rho) (the furnace); and the same grid welded or split
per face gives the same light.

A sweep over more seeds (hundreds, to hunt crashes) is the same tests with a range:

    HR_RANDOM_SCENES=0:500 .venv/bin/python -m pytest -q tests/core/test_random_scenes.py -k "sweep and not dense"
"""
from __future__ import annotations

import os

import numpy as np
import pytest

from hemicube_radiosity.core.builtin_scenes import box, quad, tessellate
from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.pipeline import BakeSettings, bake
from hemicube_radiosity.core.runtime.errors import RadiosityError
from tests.support.random_scenes import (box_sides, furnace_scene, grid, random_settings, scene,
                                         split_per_face)

LUMA = np.array([0.2126, 0.7152, 0.0722])


def _seeds(default):
    """``HR_RANDOM_SCENES`` 'a:b' (a sweep), else ``default``."""
    span = os.environ.get("HR_RANDOM_SCENES")
    if not span:
        return list(default)
    a, b = (int(x) for x in span.split(":"))
    return list(range(a, b))


def _bake(sc, settings):
    """The bake of scene ``sc``, or None when it was refused with a one-line RadiosityError."""
    try:
        return bake(sc.meshes, settings, lights=sc.lights, world=sc.world)
    except RadiosityError as e:
        msg = str(e)
        assert msg and "\n" not in msg, f"a refusal is one line: {msg!r}"
        return None


def check(r, sc):
    """What holds for the result ``r`` of any scene ``sc``."""
    if r is None:
        return
    v = r.vertex_radiosity
    assert v.shape == (len(r.elements.verts), 3), sc
    assert np.isfinite(v).all(), f"not finite at {np.flatnonzero(~np.isfinite(v).all(1))[:5]}: {sc}"
    B = r.solution.B
    assert np.isfinite(B).all() and B.min() >= 0, sc
    # non-negative; round-off of a vertex's corrections below 0 is 1e-12 of the brightest
    assert v.min() >= -1e-9 * max(float(v.max()), 1e-300), f"negative: {v.min()}: {sc}"
    # every element vertex is used by an element (the output mesh is whole)
    polys = r.elements.polys
    assert polys.max() < len(r.elements.verts) and (polys[:, :3] >= 0).all(), sc
    bound = sc.bound
    if bound is not None:
        # B = E + rho F B with rows of F summing to at most 1: nothing exceeds E_max / (1 - rho_max)
        # (the gather and the interpolation may overshoot a little: 10%)
        assert v.max() <= 1.1 * bound and B.max() <= 1.1 * bound, (float(v.max()), bound, str(sc))


# --------------------------------------------------------------------------------------------
# random scenes, small: every other seed with the default settings, the rest with random ones

QUICK = _seeds(range(30))


@pytest.mark.parametrize("seed", QUICK)
def test_sweep_random_scene_bakes_to_a_sound_result(seed):
    sc = scene(seed, budget=300)
    settings = BakeSettings() if seed % 2 == 0 else random_settings(seed, sc.meshes)
    check(_bake(sc, settings), sc)


@pytest.mark.slow
@pytest.mark.parametrize("seed", _seeds(range(1000, 1004)))
def test_sweep_dense_random_scene_bakes_to_a_sound_result(seed):
    """Grids up to 120 a side (up to 15,000 faces a scene), default settings."""
    sc = scene(seed, budget=15000)
    check(_bake(sc, BakeSettings()), sc)


# --------------------------------------------------------------------------------------------
# the furnace: a closed room and boxes in it, every surface emitting E and reflecting rho


@pytest.mark.parametrize("seed", _seeds(range(8)))
def test_sweep_random_furnace_is_e_over_one_minus_rho_everywhere(seed):
    """The paper's path (emission through F), random grids, splits, seams, textures, thin and
    closed boxes: every patch and vertex is E / (1 - rho) (measured: 1e-7, but 1.4e-4 on one
    patch of seed 4: its hemi-cube sees 2.8e-4 of sky through a crack between the outlines
    drawn.py draws beside faces whose sides were snapped (subdivide.py); drawn piece by piece,
    or with every count equalised, it sees none. Left open, issue 29's closing note)."""
    sc = furnace_scene(seed)
    E, rho = sc.furnace
    r = bake(sc.meshes, BakeSettings(direct="hemicube", element_size=None, tolerance=1e-8,
                                     max_iterations=2000))
    check(r, sc)
    np.testing.assert_allclose(r.solution.B, E / (1 - rho), rtol=5e-4, err_msg=str(sc))
    np.testing.assert_allclose(r.vertex_radiosity, E / (1 - rho), rtol=5e-4, err_msg=str(sc))
    assert np.median(np.abs(r.vertex_radiosity / (E / (1 - rho)) - 1)) < 1e-6


@pytest.mark.slow
def test_random_furnace_with_exact_direct_light():
    """The same with the default (exact) direct light and finer output elements, a smaller
    scene: every face is an emitter, so the direct light is the costly part (measured 3e-4
    off; seeds 2, 3 and 4: 1.3e-3, 2.5e-3, 3.9e-3)."""
    sc = furnace_scene(1, budget=80)
    E, rho = sc.furnace
    r = bake(sc.meshes, BakeSettings(tolerance=1e-7, max_iterations=2000))
    check(r, sc)
    np.testing.assert_allclose(r.vertex_radiosity, E / (1 - rho), rtol=5e-3, err_msg=str(sc))


# --------------------------------------------------------------------------------------------
# split or welded: the same light


def _room(floor):
    walls = box_sides((0, 0, 0), (2, 2, 1.5), inward=True, bottom=False, rho=(0.5,) * 3, name="walls")
    block = box_sides((0.6, 0.7, 0), (1.1, 1.2, 0.5), bottom=False, rho=(0.7,) * 3, rotate=0.3, name="block")
    lamp = grid((0.8, 0.8, 1.49), (0, 0.4, 0), (0.4, 0, 0), 1, 1, rho=(0,) * 3, emission=(10,) * 3, name="lamp")
    return [floor, walls, block, lamp]


def _floor_light(r):
    """{position: luminance} at the floor's output vertices (the mean of a split vertex's copies)."""
    el = r.elements
    p = el.polys[el.owner == el.object_names.index("floor")]
    v = np.unique(p[p >= 0])
    pos, inv = np.unique(el.verts[v].round(7), axis=0, return_inverse=True)
    y = np.bincount(inv.ravel(), weights=r.vertex_radiosity[v] @ LUMA) / np.bincount(inv.ravel())
    return {tuple(x): val for x, val in zip(pos, y)}


@pytest.mark.parametrize("group_faces, triangles", [(True, False), (True, True), (False, True)])
def test_a_grid_split_per_face_is_lit_as_the_same_grid_welded(group_faces, triangles):
    """A 16 x 16 floor in a lit room with a block standing on it, welded (smooth shading) and
    split per face (flat shading): the same faces, so the same light at every floor vertex
    (split copies averaged), within the gather's noise: 2% at the 95th percentile, 5% at most,
    of the floor's median. Measured without grouping: 0.7% / 2.4% (quads), 1.0% / 2.6%
    (triangles); with grouping, which connects faces through welded corner positions (when it
    followed vertex ids a split grid was not grouped at all: 682 unknowns against 290, and
    3.8% / 10% and 5.1% / 10% off)."""
    floor = grid((0, 0, 0), (2, 0, 0), (0, 2, 0), 16, 16, triangles=triangles, rho=(0.6, 0.5, 0.4), name="floor")
    s = BakeSettings(patch_size=0.5, element_size=0.25, group_faces=group_faces)
    welded = bake(_room(floor), s)
    split = bake(_room(split_per_face(floor)), s)
    assert split.unknowns == welded.unknowns
    a, b = _floor_light(welded), _floor_light(split)
    assert a.keys() == b.keys()
    ya = np.array([a[k] for k in a])
    yb = np.array([b[k] for k in a])
    d = np.abs(ya - yb) / np.median(ya)
    assert np.quantile(d, 0.95) < 0.02 and d.max() < 0.05, (np.quantile(d, 0.95), d.max())


# --------------------------------------------------------------------------------------------
# crashes found, kept


@pytest.mark.parametrize("seed", [1016])
def test_seeds_that_crashed_bake(seed):
    """Dense-sweep seeds that crashed: 1016 (a room whose 6 x 6 floor has a 12 x 12 textured rug
    lying on it) hit the contact cut's empty grid expansion, as the 100 x 100 floor below did."""
    sc = scene(seed, budget=15000)
    check(_bake(sc, BakeSettings()), sc)


Q = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]


def _lamp():
    return quad([(0.3, 0.3, 1), (0.3, 0.7, 1), (0.7, 0.7, 1), (0.7, 0.3, 1)], (0, 0, 0), (5, 5, 5), name="lamp")


def _with_corners(rho, name="textured"):
    m = quad(Q, name=name)
    return MeshInput(m.verts, m.face_offsets, m.face_indices, m.face_rho, m.face_emission, name, np.asarray(rho))


ABSURD = {
    "a zero-area face": lambda: [MeshInput.from_faces([(0, 0, 0), (1, 0, 0), (2, 0, 0)], [[0, 1, 2]], name="line"),
                                 quad(Q, name="floor"), _lamp()],
    "a vertex twice in a face": lambda: [MeshInput.from_faces(Q, [[0, 1, 1, 2, 3]], name="rep"), _lamp()],
    "one point": lambda: [MeshInput.from_faces([(0, 0, 0)] * 4, [[0, 1, 2, 3]], name="point")],
    "a mesh of no faces": lambda: [MeshInput.from_faces(Q, [], name="none"), _lamp()],
    "a bow tie": lambda: [MeshInput.from_faces([(0, 0, 0), (1, 1, 0), (1, 0, 0), (0, 1, 0)], [[0, 1, 2, 3]],
                                               name="bowtie"), _lamp()],
    "a warped quad": lambda: [MeshInput.from_faces([(0, 0, 0), (1, 0, 0.8), (1, 1, 0), (0, 1, 0.8)], [[0, 1, 2, 3]],
                                                   name="warp"), _lamp()],
    "a face doubled": lambda: [MeshInput.from_faces(Q, [[0, 1, 2, 3], [0, 1, 2, 3]], name="doubled"), _lamp()],
    "a face doubled and reversed": lambda: [MeshInput.from_faces(Q, [[0, 1, 2, 3], [0, 1, 2, 3], [3, 2, 1, 0]],
                                                                 name="doubled"), _lamp()],
    "a nanometre emitter alone": lambda: [MeshInput.from_faces([(0, 0, 0), (1e-9, 0, 0), (0, 1e-9, 0)], [[0, 1, 2]],
                                                               emission=(1, 1, 1), name="tiny")],
    "a face 1e8 away": lambda: [MeshInput.from_faces(np.array(Q) * 1e7 + 1e8, [[0, 1, 2, 3]], name="far"), _lamp()],
    "an n-gon with a spike": lambda: [MeshInput.from_faces([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0.5, 0.5, 0), (1, 1, 0),
                                                            (0, 1, 0)], [list(range(6))], name="spike"), _lamp()],
    "corner_rho of the wrong shape": lambda: [_with_corners(np.full((3, 3), 0.5)), _lamp()],
    "corner_rho of 2": lambda: [_with_corners(np.full((4, 3), 2.0)), _lamp()],
    "corner_rho NaN": lambda: [_with_corners(np.full((4, 3), np.nan)), _lamp()],
    "a mesh of no vertices": lambda: [MeshInput.from_faces(np.zeros((0, 3)), [], name="empty"), _lamp()],
}
@pytest.mark.parametrize("name, patch_size", [
    pytest.param(k, size, id=f"{k}-{'auto' if size else 'face'}") for k in ABSURD for size in ("auto", 0.0)])
def test_absurd_input_bakes_or_is_refused_in_one_line(name, patch_size):
    """Degenerate, doubled, far, tiny or malformed input: a sound result or a RadiosityError,
    never a raw exception. Found here: a doubled face (form_factors/drawn.py, IndexError) and
    corner values of the wrong shape (output/corners.py, IndexError; now refused with the faces')."""
    from tests.support.random_scenes import Scene

    sc = Scene(ABSURD[name](), parts=[name])
    check(_bake(sc, BakeSettings(patch_size=patch_size, element_size="auto" if patch_size else None)), sc)


def test_a_textured_100_by_100_floor_under_a_block_bakes():
    """The crash that started issue 29: a room whose floor is a 100 x 100 grid with an image
    texture, a block standing on it, default settings. The output elements' contact cut matched
    the block's sides (each over more than 64 cells of a grid sized by the floor's tiny faces)
    against the floor with no small box on one side, and ``np.repeat`` raised 'operands could
    not be broadcast together with shape (1,) (0,)' (core/mesh/contact.py ``_overlapping``)."""
    plane = tessellate([quad([(0, 0, 0), (4, 0, 0), (4, 4, 0), (0, 4, 0)])], 100, triangles=False)[0]
    pos = plane.verts[plane.face_indices]
    checker = (np.floor(pos[:, 0] * 3) + np.floor(pos[:, 1] * 3)) % 2
    corner_rho = 0.2 + 0.6 * checker[:, None] * np.array([1.0, 0.5, 0.25])
    face = np.repeat(np.arange(len(plane.face_offsets) - 1), 4)
    rho = np.stack([np.bincount(face, weights=corner_rho[:, k]) / 4 for k in range(3)], 1)
    floor = MeshInput(plane.verts, plane.face_offsets, plane.face_indices, rho, plane.face_emission, "Floor",
                      corner_rho)
    block = box((1.3, 1.2, 0), (2.1, 2.3, 1.0), (0.6,) * 3, bottom=False, name="Block")
    lamp = quad([(1, 1, 2.5), (1, 3, 2.5), (3, 3, 2.5), (3, 1, 2.5)], (0, 0, 0), (5, 5, 5), name="Lamp")
    r = bake([floor, block, lamp], BakeSettings())
    el = r.elements
    assert (el.owner == 0).sum() >= 10000                  # the floor's own faces, cut at the block
    v = r.vertex_radiosity
    assert np.isfinite(v).all() and v.min() >= 0
    # the floor's vertices in the open, away from the block's foot, are lit
    on = np.unique(el.polys[el.owner == 0])
    on = on[on >= 0]
    x = el.verts[on]
    open_ = (np.abs(x[:, 0] - 1.7) > 0.5) | (np.abs(x[:, 1] - 1.75) > 0.6)
    assert (v[on[open_]] @ LUMA).min() > 0
