"""bench/real_scenes.py: its scene list and the light it adds (needs ../shared/scenes; skipped without)."""
from __future__ import annotations

import os
import sys

import numpy as np
import pytest

from tests.support import ROOT

for _p in (os.path.join(ROOT, "bench"), os.path.join(ROOT, "tools")):
    if _p not in sys.path:
        sys.path.insert(0, _p)

import real_scenes  # noqa: E402

pytestmark = [pytest.mark.blender,
              pytest.mark.skipif(not os.path.isdir(real_scenes.SCENES_DIR),
                                 reason=f"{real_scenes.SCENES_DIR} is absent (real scenes are not in the repository)")]


def test_scene_list_names_files_that_exist():
    specs = real_scenes.scene_list()
    assert specs, "no scene of ../shared/scenes has an entry in SPECS"
    assert [s.triangles for s in specs] == sorted(s.triangles for s in specs)
    for s in specs:
        if s.file == real_scenes.GENERATED:               # made by bench/terrain.py, not read
            continue
        assert os.path.isfile(os.path.join(real_scenes.SCENES_DIR, s.folder, s.file)), s
    assert "generated_terrain" in [s.folder for s in specs]
    assert [s.folder for s in real_scenes.scene_list(quick=True)] == sorted(
        real_scenes.QUICK, key=lambda n: real_scenes.SPEC[n].triangles)
    with pytest.raises(ValueError, match="no such scene"):
        real_scenes.scene_list(names=["no_such_scene"])


def test_a_scene_without_light_gets_the_sun_and_the_sky(bpy_module):
    """What both Cycles and our reader see after the set-up of a file with no light."""
    from hemicube_radiosity.blender.read.lights import read_lights
    from hemicube_radiosity.core.light.lamps import SunLight

    bpy = bpy_module
    real_scenes.prepare(real_scenes.SPEC["godot_living_room"])
    assert [o.data.type for o in bpy.context.scene.objects if o.type == "LIGHT"] == ["SUN"]
    lights, world, _ = read_lights(bpy.context.evaluated_depsgraph_get())
    assert len(lights) == 1 and isinstance(lights[0], SunLight)
    np.testing.assert_allclose(world, real_scenes.SKY, rtol=1e-6)


def test_the_generated_terrain_is_128_by_128_quads_and_five_buildings_every_time(bpy_module):
    import terrain

    bpy = bpy_module

    def made():
        terrain.build()
        ground = bpy.data.objects["Ground"].data
        pos = np.empty(len(ground.vertices) * 3)
        ground.vertices.foreach_get("co", pos)
        return ground, pos
    ground, first = made()
    assert len(ground.polygons) == 128 * 128 and {len(p.vertices) for p in ground.polygons} == {4}
    z = first.reshape(-1, 3)[:, 2]
    assert 15.0 < z.max() - z.min() < 40.0                       # rolling ground, not flat
    assert np.ptp(first.reshape(-1, 3)[:, 0]) == pytest.approx(1000.0)
    buildings = [o for o in bpy.data.objects if o.name.startswith("Building")]
    assert len(buildings) == 5 and all(len(o.data.polygons) == 6 for o in buildings)
    for o in buildings:                                        # closed boxes, normals outward
        c = np.mean([v.co for v in o.data.vertices], axis=0)
        assert all(np.dot(np.array(p.center) - c, p.normal) > 0 for p in o.data.polygons)
    assert np.array_equal(made()[1], first)                    # the same file every time
