# SPDX-License-Identifier: GPL-3.0-or-later
"""Light off metal reaches the walls (core/form_factors/glossy.py: mirrored with its direction),
compared with Cycles at its own face corners: a closed 4 x 4 x 2.5 m room lit by a ceiling
panel, its floor a metal of roughness 0.3. Cycles' DIFFUSE view of the floor is black; the light
the floor mirrors lights the walls.

Cycles renders with 4 glossy bounces and reflective caustics (Blender's defaults) and Filter
Glossy off (0): Blender's default Filter Glossy (1.0) blurs a glossy surface met after a diffuse
bounce and loses light doing so, a quarter of the walls' light here (an independent path tracer
of the room with a perfect 0.8 mirror floor gives the walls 0.680 +- 0.003; Cycles 0.679 with
the filter off, 0.518 with it on). Mean wall radiance against Cycles (`docs/lighting.md` has the
table):

    room                               Filter Glossy 0    default (1.0)   without the bounce
    metal floor, roughness 0.3         +0.9%              +29.9%          -57.0%
    metal floor, roughness 0.6         +3.5%              +11.6%          -54.2%
    default Principled everywhere      +0.5%              +9.5%           -17.2%
    glossy plastic (0.2) everywhere    -2.5%              +24.4%          -20.7%

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


def room(floor=None, walls=None, settings=None, samples=256, filter_glossy=0.0):
    """A 4 x 4 x 2.5 m closed room lit by a 1 m emissive panel (strength 10) 5 cm under the
    ceiling; ``floor`` and ``walls`` make the materials (None: a metal floor of Base Color 0.8 and
    roughness 0.3; diffuse 0.8 walls and ceiling). A ``Comparison`` with Cycles at 4 glossy bounces
    and Filter Glossy ``filter_glossy`` (None: Blender's default, 1.0)."""
    cr.new_empty_scene()
    v, f = box_arrays((-2, -2, 0), (2, 2, 2.5), 8, inward=True, top=True, bottom=False)
    wall_ob = cr.mesh_object(v, f, walls() if walls else cr.diffuse_material((RHO,) * 3), "walls")
    v, f = cr.grid_arrays(8, 8, -2, 2, -2, 2, 0.0)
    floor_ob = cr.mesh_object(v, f, floor() if floor else principled(roughness=0.3, metallic=1.0), "floor")
    v, f = cr.grid_arrays(2, 2, -0.5, 0.5, -0.5, 0.5, 2.45)
    lamp = cr.mesh_object(v, f[:, ::-1], cr.diffuse_material((RHO,) * 3, emission=10.0), "lamp")
    return Comparison([wall_ob, floor_ob, lamp], samples=samples, glossy=GLOSSY_BOUNCES, settings=settings,
                      filter_glossy=filter_glossy)


def walls_mean(c):
    """(ours, Cycles') mean radiance (band mean) over the room's vertical wall faces."""
    wall = (c.owner == 0) & (np.abs(c.normal[:, 2]) < 0.5)
    return c.ours[wall].mean(), c.cycles[wall].mean()


@pytest.fixture(scope="module")
def metal_room():
    return room()


def test_a_metal_floor_lights_the_walls(metal_room):
    """The issue's bar: within 5% of Cycles (+0.9%); without the bounce -57%."""
    ours, theirs = walls_mean(metal_room)
    assert abs(ours / theirs - 1) < 0.05
    off, theirs_again = walls_mean(room(settings=dict(specular_bounce=False)))
    assert theirs_again == pytest.approx(theirs, rel=0.03)        # Cycles' noise between two runs
    assert 0.38 < off / theirs < 0.48


def test_cycles_filter_glossy_darkens_its_render():
    """Blender's default Filter Glossy loses a quarter of the walls' light in Cycles: the bake is
    +30% of that render (the gap is the filter's, not the bake's: see the module docstring)."""
    ours, theirs = walls_mean(room(filter_glossy=None, samples=128))
    assert 1.22 < ours / theirs < 1.38


def test_the_metal_floor_itself_shows_its_diffuse_part(metal_room):
    """Cycles' DIFFUSE view of a metal is black: so is the baked floor, although it mirrors 0.8."""
    floor = metal_room.owner == 1
    assert metal_room.cycles[floor].max() < 1e-3
    assert metal_room.ours[floor].max() < 1e-6


def test_a_rougher_metal_floor():
    """Roughness 0.6: +3.5% (the mirror is sharp here; Cycles' rougher metal loses a little
    more light at grazing angles than its albedo at normal incidence says)."""
    ours, theirs = walls_mean(room(floor=lambda: principled(roughness=0.6, metallic=1.0), samples=128))
    assert 0.99 < ours / theirs < 1.07


def test_the_default_material_room():
    """Every surface Blender's default Principled BSDF (glossy albedo 0.037: spread as diffuse
    light): +0.5%."""
    ours, theirs = walls_mean(room(floor=principled, walls=principled, samples=128))
    assert abs(ours / theirs - 1) < 0.04


CASES = {
    "metal floor r0.3": dict(),
    "metal floor r0.6": dict(floor=lambda: principled(roughness=0.6, metallic=1.0)),
    "default Principled": dict(floor=principled, walls=principled),
    "glossy plastic r0.2": dict(floor=lambda: principled(roughness=0.2), walls=lambda: principled(roughness=0.2)),
}

if __name__ == "__main__":
    for name, kw in CASES.items():
        for fg, bounce in ((0.0, True), (None, True), (0.0, False)):
            o, t = walls_mean(room(**kw, settings=dict(specular_bounce=bounce), filter_glossy=fg))
            print(f"{name:>20} Filter Glossy {'default' if fg is None else fg} bounce {'on ' if bounce else 'off'}: "
                  f"walls ours {o:.4f} Cycles {t:.4f} ({100 * (o / t - 1):+.1f}%)", flush=True)
