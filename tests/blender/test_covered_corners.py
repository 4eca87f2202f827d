# SPDX-License-Identifier: GPL-3.0-or-later
"""Corners under a surface that passes closer over them than our rays start
(core/output/covered.py), against Cycles' bake at its own corners: a sunlit floor with a board
a hair above part of it. Cycles' rays start on the floor and meet the board, so the floor's
corners under it are dark; ours started above the board (the floor's ray offset) and read the
full sun and sky."""
from __future__ import annotations

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tools import cycles_reference as cr  # noqa: E402
from hemicube_radiosity.core.rays import mesh_offsets  # noqa: E402
from tests.support.cycles_scenes import RHO, Comparison, box_arrays, floor_object  # noqa: E402

pytestmark = [pytest.mark.blender, pytest.mark.cycles]

GAP = 2e-5                      # metres between the floor and the board over it
ZEN = math.radians(40.0)        # the sun's zenith angle
IRRADIANCE = 3.0                # W/m^2
SKY = (0.3, 0.35, 0.4)


def _scene():
    """An 8 x 8 floor of 0.5 m quads over [-2, 2]^2 and a single-plane board over
    [-0.6, 0.6]^2 at ``GAP`` above it (facing up), under a sun of angle 0 and a uniform sky."""
    cr.new_empty_scene()
    floor = floor_object(8, 2.0)
    v, f = cr.grid_arrays(2, 2, -0.6, 0.6, -0.6, 0.6, GAP)
    board = cr.mesh_object(v, f, cr.diffuse_material((RHO,) * 3), "board")
    cr.add_light("SUN", (0, 0, 5), (ZEN, 0.0, 0.3), energy=IRRADIANCE, angle=0.0)
    cr.set_world(SKY, 1.0)
    return floor, board


def test_floor_corners_under_a_board_a_hair_above_are_dark_as_in_cycles():
    floor, board = _scene()
    c = Comparison([floor, board], samples=64, settings={"light_samples": 16})
    res = c.result
    eps = mesh_offsets(res.patches)[0]
    assert GAP < 0.5 * eps, "the board lies within the floor's ray offset (the case tested)"
    on_floor = c.owner == 0
    under = on_floor & np.all(np.abs(c.pos[:, :2]) < 0.6, axis=1)
    # corners of faces that run from under the board into the open: their open corners are lit
    far = on_floor & np.any(np.abs(c.pos[:, :2]) > 0.7, axis=1)
    lit = c.cycles[far].mean()
    assert under.sum() == 36 and lit > 0.5        # 9 vertices under the board, 4 faces each
    # Cycles: the board shades the floor under it (only grazing sky through the gap)
    assert c.cycles[under].mean(axis=1).max() < 0.02 * lit
    # ours now: the same corners as dark, the open floor as before
    assert c.ours[under].mean(axis=1).max() < 0.02 * lit
    np.testing.assert_allclose(c.ours[far].mean(axis=1), c.cycles[far].mean(axis=1), rtol=0.03)
    # and the board itself, lit from above, as Cycles has it
    on_board = c.owner == 1
    np.testing.assert_allclose(c.ours[on_board].mean(axis=1), c.cycles[on_board].mean(axis=1), rtol=0.03)


def _chamfered_block_on_a_slab(h=0.04, c=0.1, top=0.5):
    """A closed 4 x 4 x 0.2 m slab (its top at z = 0, 1 m quads) and on it a closed block whose
    bottom face covers [0, 1] x [-1, 1] of the slab's top, its two long bottom edges chamfered
    ``c`` out and ``h`` up: each chamfer rises from the slab at 22 deg, facing down and out (a
    bevelled box on a shelf, as in the living room). Sun and sky as above."""
    cr.new_empty_scene()
    v, f = box_arrays((-2.0, -2.0, -0.2), (2.0, 2.0, 0.0), 4, bottom=True)
    sec = [(0.0, 0.0), (1.0, 0.0), (1.0 + c, h), (1.0 + c, top), (-c, top), (-c, h)]
    n = len(sec)
    verts = [(x, -1.0, z) for x, z in sec] + [(x, 1.0, z) for x, z in sec]
    faces = [(n + i, n + (i + 1) % n, (i + 1) % n, i) for i in range(n)]
    faces += [(0, 1, 2, 5), (5, 2, 3, 4), (n + 5, n + 2, n + 1, n), (n + 4, n + 3, n + 2, n + 5)]
    cr.add_light("SUN", (0, 0, 5), (ZEN, 0.0, 0.3), energy=IRRADIANCE, angle=0.0)
    cr.set_world(SKY, 1.0)
    grey = cr.diffuse_material((RHO,) * 3)
    return cr.mesh_object(v, f, grey, "slab"), cr.mesh_object(verts, faces, grey, "block")


def test_a_chamfer_s_foot_on_a_shelf_is_dark_as_in_cycles():
    """The chamfers' corners on the slab: Cycles bakes them a hair up the chamfer, whose rays meet
    the slab's top within micrometres: 0.04-0.06 (the block's lit top 0.87). Our vertex there
    starts its rays inside the slab: the light they gathered (0.85 of the slab's top) was kept
    whole at the corner's own point (core/output/covered.py: the vertex's few open rays against
    the corner's few): 0.68-0.69. Now 0.05-0.07."""
    slab, block = _chamfered_block_on_a_slab()
    c = Comparison([slab, block], samples=64, settings={"light_samples": 16})
    on_block = c.owner == 1
    foot = on_block & (np.abs(c.pos[:, 2]) < 1e-9) & (np.abs(c.normal[:, 0]) > 0.3)
    top = on_block & (c.normal[:, 2] > 0.9)
    lit = c.cycles[top].mean()
    assert foot.sum() == 4 and lit > 0.5                    # 2 chamfers, their 2 corners on the slab
    ours, theirs = c.ours[foot].mean(axis=1), c.cycles[foot].mean(axis=1)
    assert theirs.max() < 0.1 * lit
    np.testing.assert_allclose(ours, theirs, atol=0.05 * lit)


def test_a_shadow_s_edge_through_a_vertex_parts_its_corners_as_in_cycles():
    """zdm2's floors at a wall's end: a 2 m wall (a box 1 m thick, so that its feet stand on the
    floor's edges, and 1 m high, its end on the floor's vertex (0, 0)) under a sun from -y, 40 deg
    off the zenith: its shadow lies on the floor
    for x < 0 from y = 0 to 0.84, its edge along x = 0 through that vertex. Cycles bakes each
    face corner on its own face: at (0, 0) the corner of the face behind the wall is in the
    shadow, the one beside it in the sun. We lit the vertex once, both corners alike (the
    shadowed one in the sun: 0.94 where Cycles has 0.31 on zdm2); now each corner its own
    (core/output/covered.py)."""
    cr.new_empty_scene()
    floor = floor_object(4, 2.0)
    v, f = box_arrays((-2.0, -1.0, 0.0), (0.0, 0.0, 1.0), 1)
    wall = cr.mesh_object(v, f, cr.diffuse_material((RHO,) * 3), "wall")
    cr.add_light("SUN", (0, 0, 5), (ZEN, 0.0, 0.0), energy=IRRADIANCE, angle=0.0)
    cr.set_world(SKY, 1.0)
    c = Comparison([floor, wall], samples=64, settings={"light_samples": 16})
    P = c.result.patches
    centre = np.concatenate([np.repeat(P.centers[P.owner == k], 4, axis=0) for k in range(2)])   # each corner's face
    at = (c.owner == 0) & np.all(np.abs(c.pos) < 1e-9, axis=1)
    behind = at & (np.abs(centre[:, 0] + 0.5) < 1e-9) & (np.abs(centre[:, 1] - 0.5) < 1e-9)
    beside = at & (np.abs(centre[:, 0] - 0.5) < 1e-9) & (np.abs(centre[:, 1] - 0.5) < 1e-9)
    assert behind.sum() == 1 and beside.sum() == 1
    ours_b, theirs_b = c.ours[behind].mean(), c.cycles[behind].mean()
    ours_s, theirs_s = c.ours[beside].mean(), c.cycles[beside].mean()
    assert theirs_b < 0.5 * theirs_s                        # Cycles: one corner shadowed, one lit
    # the lit corner keeps its vertex's light (0.84 against 0.89); the shadowed one had it too
    # (0.84 against 0.27), now its own: 0.21 (its sky and bounced light a little under Cycles')
    np.testing.assert_allclose(ours_s, theirs_s, rtol=0.06)
    np.testing.assert_allclose(ours_b, theirs_b, rtol=0.25)


def test_a_buried_vertex_s_corner_takes_the_light_at_cycles_point():
    """Truck town's slivers of a house's ledge in a nook of its walls: their vertices see less
    than a quarter of the open scene (:func:`core.output.sides.buried_side`) and took the light
    where their edges from the open side meet what buries them, a hair off a wall and in its
    shadow (0.02), where Cycles' corners have the sun (0.21). Here a 2 x 1 m wall (facing -y,
    2 x 2 quads) under a black plate that leans over its top: from a hair off the wall at
    z = 0.95 out to 6.25 cm off it at z = 1.2. A sun 11.5 deg off the zenith toward -y passes
    between the two; the two corners at the top of the wall's middle (a buried vertex: the
    plate closes its hemisphere, open only up the slit and past the plate's ends) see it and
    almost no sky: Cycles reads the sun's rho E cos / pi (0.153) and 0.004 more. Their edges
    from the open wall below meet the plate's foot, in its shadow and open to the sky below it:
    ours read that, 0.275 (75% over). Now each such corner (of its source face) is lit at its
    own bake point (core/output/covered.py): 0.158. (The top corners at the wall's ends, not
    buried, read 0.24 against Cycles' 0.30, before and after.)"""
    cr.new_empty_scene()
    v = [(x, 0.0, z) for z in (0.0, 0.5, 1.0) for x in (-1.0, 0.0, 1.0)]
    f = [(a, a + 1, a + 4, a + 3) for a in (0, 1, 3, 4)]
    wall = cr.mesh_object(v, f, cr.diffuse_material((RHO,) * 3), "wall")
    gap, foot, top, lean = 1e-5, 0.95, 1.2, 0.25
    pv = [(-1.0, -gap, foot), (1.0, -gap, foot), (1.0, -gap - (top - foot) * lean, top),
          (-1.0, -gap - (top - foot) * lean, top)]
    plate = cr.mesh_object(pv, [(0, 1, 2, 3)], cr.diffuse_material((0.0,) * 3), "plate")
    sun = 0.2                                   # the sun's cosine to the wall's normal
    cr.add_light("SUN", (0, 0, 5), (math.asin(sun), 0.0, 0.0), energy=IRRADIANCE, angle=0.0)
    cr.set_world(SKY, 1.0)
    c = Comparison([wall, plate], samples=64, settings={"light_samples": 16})
    middle = (c.owner == 0) & (np.abs(c.pos[:, 2] - 1.0) < 1e-9) & (np.abs(c.pos[:, 0]) < 1e-9)
    low = (c.owner == 0) & (c.pos[:, 2] < 0.6)
    assert middle.sum() == 2 and low.sum() == 12
    direct = RHO * IRRADIANCE * sun / math.pi
    theirs, ours = c.cycles[middle].mean(axis=1), c.ours[middle].mean(axis=1)
    assert np.all((theirs > direct) & (theirs < 1.1 * direct))        # the sun, and little sky
    np.testing.assert_allclose(ours, theirs, rtol=0.05)
    # the open wall below as before
    np.testing.assert_allclose(c.ours[low].mean(axis=1), c.cycles[low].mean(axis=1), rtol=0.03)


def test_a_covered_corner_s_sun_ray_starts_as_low_as_cycles_one():
    """Truck town's road corner beside the grass: its sun ray from Cycles' bake point meets the
    grass 0.3 mm on, a few hundredths of a millimetre up; started 16 float32 steps off the road
    (5.7e-5 m there) it passed over the grass's edge: 0.35 where Cycles has 0.12. Here a floor
    at x = 28..32 m (a float32 step is 3.6e-6 m at its vertex (30, 0, 0)) and a board 6e-5 m
    over it, its edge 4 mm short of that vertex toward a sun 0.23 deg high (tan 0.004): Cycles'
    rays from the vertex's corners (each 3 mm in toward its triangle, 1-6 mm from the edge)
    rise 4-24 um by the edge and meet the board. A start 8 steps up (2.9e-5 m) still meets it
    out to 7.9 mm from the edge, one 16 steps up (5.7e-5 m) only within 0.7 mm: the corners
    read the full sun (0.80 against Cycles' 0.04), now 0.04. (From 7.9 to 15 mm, Cycles' dark
    corners would still read the sun.)"""
    h, edge, tan_e = 6e-5, -0.004, 0.004
    cr.new_empty_scene()
    grey = cr.diffuse_material((RHO,) * 3)
    v, f = cr.grid_arrays(4, 4, 28.0, 32.0, -2.0, 2.0, 0.0)
    floor = cr.mesh_object(v, f, grey, "floor")
    v, f = cr.grid_arrays(1, 1, 29.0, 31.0, -1.0, edge, h)
    board = cr.mesh_object(v, f, grey, "board")
    zen = math.atan2(1.0, tan_e)
    cr.add_light("SUN", (30, 0, 5), (zen, 0.0, 0.0), energy=IRRADIANCE / math.cos(zen), angle=0.0)
    cr.set_world((0.05, 0.05, 0.05), 1.0)
    c = Comparison([floor, board], samples=64, settings={"light_samples": 16})
    at = (c.owner == 0) & (np.linalg.norm(c.pos - [30.0, 0.0, 0.0], axis=1) < 1e-6)
    lit = (c.owner == 0) & (np.linalg.norm(c.pos - [30.0, 1.0, 0.0], axis=1) < 1e-6)
    assert at.sum() == 4 and lit.sum() == 4
    sun = RHO * IRRADIANCE / math.pi                    # the floor in the open: the sun, and sky
    assert np.all(c.cycles[lit].mean(axis=1) > sun)
    assert np.all(c.cycles[at].mean(axis=1) < 0.1 * sun)        # Cycles: the board shades them
    np.testing.assert_allclose(c.ours[at].mean(axis=1), c.cycles[at].mean(axis=1), rtol=0.05)
    np.testing.assert_allclose(c.ours[lit].mean(axis=1), c.cycles[lit].mean(axis=1), rtol=0.03)
