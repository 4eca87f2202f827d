# SPDX-License-Identifier: GPL-3.0-or-later
"""Light off metal reaches the walls (core/mesh/specular.py), compared with Cycles rendering as
a user's render does (glossy bounces and reflective caustics on, Blender's defaults) at its own
face corners: a closed 4 x 4 x 2.5 m room lit by a ceiling panel, its floor a metal of roughness
0.3. Cycles' DIFFUSE view of the floor is black; the light the floor mirrors lights the walls.

The spread keeps the glossy light's energy, not its direction, and overshoots on smooth
surfaces (mean wall radiance against Cycles; `docs/lighting.md` has the table):

    metal floor, roughness 0.3         +29% (without the bounce -45%)
    metal floor, roughness 0.6         +11%
    default Principled everywhere      +9.4% (without -8.5%)
    glossy plastic (0.2) everywhere    +22% (without +0.6%)

Run ``python -m tests.blender.test_specular_bounce`` to print them."""
from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tools import cycles_reference as cr  # noqa: E402
from tests.support.cycles_scenes import RHO, Comparison, box_arrays  # noqa: E402

pytestmark = [pytest.mark.blender, pytest.mark.cycles]

GLOSSY_BOUNCES = 4          # Blender's default


def principled(base=0.8, roughness=0.5, metallic=0.0, name="principled"):
    m = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        m.use_nodes = True
    p = m.node_tree.nodes.get("Principled BSDF")
    p.inputs["Base Color"].default_value = (base, base, base, 1.0)
    p.inputs["Metallic"].default_value = metallic
    p.inputs["Roughness"].default_value = roughness
    return m


def room(floor=None, walls=None, settings=None, samples=256):
    """A 4 x 4 x 2.5 m closed room lit by a 1 m emissive panel (strength 10) 5 cm under the
    ceiling; ``floor`` and ``walls`` make the materials (None: a metal floor of Base Color 0.8 and
    roughness 0.3; diffuse 0.8 walls and ceiling). A ``Comparison`` with Cycles at 4 glossy bounces."""
    cr.new_empty_scene()
    v, f = box_arrays((-2, -2, 0), (2, 2, 2.5), 8, inward=True, top=True, bottom=False)
    wall_ob = cr.mesh_object(v, f, walls() if walls else cr.diffuse_material((RHO,) * 3), "walls")
    v, f = cr.grid_arrays(8, 8, -2, 2, -2, 2, 0.0)
    floor_ob = cr.mesh_object(v, f, floor() if floor else principled(roughness=0.3, metallic=1.0), "floor")
    v, f = cr.grid_arrays(2, 2, -0.5, 0.5, -0.5, 0.5, 2.45)
    lamp = cr.mesh_object(v, f[:, ::-1], cr.diffuse_material((RHO,) * 3, emission=10.0), "lamp")
    return Comparison([wall_ob, floor_ob, lamp], samples=samples, glossy=GLOSSY_BOUNCES, settings=settings)


def walls_mean(c):
    """(ours, Cycles') mean radiance (band mean) over the room's vertical wall faces."""
    wall = (c.owner == 0) & (np.abs(c.normal[:, 2]) < 0.5)
    return c.ours[wall].mean(), c.cycles[wall].mean()


@pytest.fixture(scope="module")
def metal_room():
    return room()


def test_a_metal_floor_lights_the_walls(metal_room):
    """With the bounce the walls are +29% of Cycles' (the issue asks 5%: the spread loses the
    mirror's direction); without it -45%. Both figures held to within a few points, so a change
    that moves either shows."""
    ours, theirs = walls_mean(metal_room)
    assert 1.20 < ours / theirs < 1.36
    off, theirs_again = walls_mean(room(settings=dict(specular_bounce=False)))
    assert theirs_again == pytest.approx(theirs, rel=0.03)        # Cycles' noise between two runs
    assert 0.50 < off / theirs < 0.60
    assert abs(ours / theirs - 1) < abs(off / theirs - 1)


def test_the_metal_floor_itself_shows_its_diffuse_part(metal_room):
    """Cycles' DIFFUSE view of a metal is black: so is the baked floor, although it bounces 0.8."""
    floor = metal_room.owner == 1
    assert metal_room.cycles[floor].max() < 1e-3
    assert metal_room.ours[floor].max() < 1e-6


def test_the_default_material_room_is_within_ten_percent():
    """Every surface Blender's default Principled BSDF: +9.4% with the bounce, -8.5% without."""
    c = room(floor=principled, walls=principled, samples=128)
    ours, theirs = walls_mean(c)
    assert 1.04 < ours / theirs < 1.14


CASES = {
    "metal floor r0.3": dict(),
    "metal floor r0.6": dict(floor=lambda: principled(roughness=0.6, metallic=1.0)),
    "default Principled": dict(floor=principled, walls=principled),
    "glossy plastic r0.2": dict(floor=lambda: principled(roughness=0.2), walls=lambda: principled(roughness=0.2)),
}

if __name__ == "__main__":
    for name, kw in CASES.items():
        for bounce in (True, False):
            o, t = walls_mean(room(**kw, settings=dict(specular_bounce=bounce)))
            print(f"{name:>20} bounce {'on ' if bounce else 'off'}: walls ours {o:.4f} Cycles {t:.4f} "
                  f"({100 * (o / t - 1):+.1f}%)", flush=True)
