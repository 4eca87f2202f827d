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
from tests.support.cycles_scenes import RHO, Comparison, floor_object  # noqa: E402

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
