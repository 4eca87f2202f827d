# SPDX-License-Identifier: GPL-3.0-or-later
"""Corners Cycles turns around (core/output/crease.py: a shading normal N facing away from the
face's own normal Ng, both negated) take the light reflected more than once that their lune
sees, behind the face (core/output/lune.py), not a share of what their vertex gathered in front
of it; against Cycles' bake at its own corners.

A closed box, 2 cm over a sunlit floor, every edge sharp (Cycles stores each corner's own
normal, core/mesh/cycles_normals.py); the corners of its +x side have custom normals tilted
past that side's plane (N . Ng = -0.3), as a game level's faces along a partition edge are shaded
with a neighbour's normal (godot_zdm2: 2,854 corners whose Cycles normal faces away from their
face, which it never lights). Their lune lies inside the box: Cycles bakes them black. Our
corners kept (1 + N . Ng) / 2 of their vertex's light from the floor in front (0.35 of it)."""
from __future__ import annotations

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tools import cycles_reference as cr  # noqa: E402
from tests.support.cycles_scenes import RHO, Comparison, box_arrays, floor_object  # noqa: E402

pytestmark = [pytest.mark.blender, pytest.mark.cycles]

ZEN = math.radians(40.0)          # the sun's zenith angle, from +x
IRRADIANCE = 3.0                  # W/m^2
SKY = (0.3, 0.35, 0.4)
FACING = -0.3                     # N . Ng at the turned side's corners


def _box():
    """The closed box [-0.5, 0.5]^2 x [0.02, 1.02], 3 x 3 quads a side, smooth, every edge
    sharp; the +x side's corners shaded with N = (-0.3, 0, 0.954), the others with their face's
    normal."""
    v, f = box_arrays((-0.5, -0.5, 0.02), (0.5, 0.5, 1.02), 3, top=True, bottom=True)
    ob = cr.mesh_object(v, f, cr.diffuse_material((RHO,) * 3), "box")
    me = ob.data
    me.shade_smooth()
    for e in me.edges:
        e.use_edge_sharp = True
    turned = (FACING, 0.0, math.sqrt(1 - FACING ** 2))
    normals = []
    for poly in me.polygons:
        n = turned if poly.normal.x > 0.99 else tuple(poly.normal)
        normals += [n] * poly.loop_total
    me.normals_split_custom_set(normals)
    return ob


def test_a_box_side_whose_normals_face_away_bakes_black_as_in_cycles():
    """Under a sun from the +x side and a sky: Cycles bakes the turned side's 36 corners black
    (its lune looks into the closed box; measured 0); ours within 0.004 of it (before:
    0.35 of the light the floor in front of the side reflects, about 0.08). The box's top,
    shaded with its own normal, as Cycles has it (within 3%)."""
    cr.new_empty_scene()
    fl = floor_object(6, 3.0)
    box = _box()
    cr.add_light("SUN", (0, 0, 5), (ZEN, 0.0, math.pi / 2), energy=IRRADIANCE, angle=0.0)
    cr.set_world(SKY, 1.0)
    c = Comparison([fl, box], samples=64, settings={"light_samples": 16})
    on = c.owner == 1
    side = on & (c.normal[:, 0] > 0.99)
    top = on & (c.normal[:, 2] > 0.99)
    assert side.sum() == 36 and top.sum() == 36
    sun = RHO * IRRADIANCE * math.cos(ZEN) / math.pi
    assert c.cycles[top].mean() > sun                           # lit: the sun and the sky
    np.testing.assert_allclose(c.ours[top].mean(axis=1), c.cycles[top].mean(axis=1), rtol=0.03)
    assert c.cycles[side].max() < 1e-3                          # black, in Cycles
    front = (c.owner == 0) & (c.pos[:, 0] > 0.5)
    assert c.cycles[front].mean() > 0.5 * sun                   # the floor the side faces is lit
    print("side: ours max", c.ours[side].max(), "Cycles max", c.cycles[side].max(),
          "top: ours", c.ours[top].mean(), "Cycles", c.cycles[top].mean())
    np.testing.assert_allclose(c.ours[side], c.cycles[side], atol=0.004)


def _wall():
    """An open wall x = 0 facing +x over [-1, 1] x [0.02, 1.02] (y, z), 2 x 2 quads, smooth,
    every edge sharp, each corner shaded with N = (-0.3, 0, 0.954): turned around, Cycles
    shades its back (-x), whose lune looks down at the floor behind the wall."""
    v = [(0.0, y, z) for z in (0.02, 0.52, 1.02) for y in (-1.0, 0.0, 1.0)]
    f = [(0, 1, 4, 3), (1, 2, 5, 4), (3, 4, 7, 6), (4, 5, 8, 7)]
    ob = cr.mesh_object(v, f, cr.diffuse_material((RHO,) * 3), "wall")
    me = ob.data
    me.shade_smooth()
    for e in me.edges:
        e.use_edge_sharp = True
    assert all(p.normal.x > 0.99 for p in me.polygons)
    me.normals_split_custom_set([(FACING, 0.0, math.sqrt(1 - FACING ** 2))] * len(me.loops))
    return ob


def test_an_open_wall_turned_around_takes_what_its_lune_sees_behind_it():
    """The wall alone over the floor, the sun on the floor behind it (from -x) and no sky:
    Cycles shades the wall's turned corners from behind, lit by the sun in the lune and by the
    floor there. Ours read the floor behind from its back (an open surface's, core/mesh/backs.py):
    within 12% of Cycles' mean over the wall (measured 5%), each corner within 0.05."""
    cr.new_empty_scene()
    fl = floor_object(6, 3.0)
    wall = _wall()
    cr.add_light("SUN", (0, 0, 5), (ZEN, 0.0, -math.pi / 2), energy=IRRADIANCE, angle=0.0)
    c = Comparison([fl, wall], samples=256, settings={"light_samples": 16})
    on = c.owner == 1
    assert on.sum() == 16
    print("wall: ours", c.ours[on].mean(), "Cycles", c.cycles[on].mean(), "max diff",
          np.abs(c.ours[on] - c.cycles[on]).max())
    assert c.cycles[on].mean() > 0.05
    np.testing.assert_allclose(c.ours[on].mean(), c.cycles[on].mean(), rtol=0.12)
    np.testing.assert_allclose(c.ours[on], c.cycles[on], atol=0.05)
