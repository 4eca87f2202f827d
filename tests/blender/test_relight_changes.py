"""A relight in the session equals a fresh bake after any change: what it keeps (the cached
geometry-only products, the refined patches, the open faces and backs, the copies' element
meshes) must follow a lamp moved, a colour changed and a vertex moved."""
from __future__ import annotations

import importlib

import numpy as np
import pytest

from tests.support.addon import lit_cornell_box, select
from tests.support.scene import corner_data

pytestmark = pytest.mark.blender

BAKE = dict(patch_size=0.25, resolution=32)


@pytest.mark.slow
def test_relight_equals_a_fresh_bake_after_each_change(addon, empty_scene):
    bpy = empty_scene
    bake_mod = importlib.import_module(f"{addon.__name__}.blender.bake")
    write = importlib.import_module(f"{addon.__name__}.blender.write")
    objs, lamp, names = lit_cornell_box(addon, bpy)

    def bake():
        copies = write.copies_of(names)
        select(bpy, copies if copies else [bpy.data.objects[n] for n in names])
        assert bpy.ops.object.radiosity_bake(**BAKE) == {"FINISHED"}
        return {n: corner_data(write.copies_of([n])[0]) for n in names}

    def same(a, b):
        for n in names:
            np.testing.assert_array_equal(a[n][0], b[n][0], err_msg=n)
            np.testing.assert_allclose(a[n][1], b[n][1], rtol=1e-6, atol=1e-9, err_msg=n)

    first = bake()
    elements = [n for n in names if write.copies_of([n])[0].get(write.MESH_KIND_KEY) == "elements"]
    assert elements, "the test needs copies made of the output elements"
    for n in elements:
        write.copies_of([n])[0].data["kept"] = True
    # brighter: the same geometry, the copies' meshes written again (colours only)
    lamp.data.energy *= 1.5
    brighter = bake()
    for n in names:
        np.testing.assert_array_equal(brighter[n][0], first[n][0])
    for n in elements:
        assert "kept" in write.copies_of([n])[0].data, f"{n}: the relight rebuilt the copy's mesh"
    # each change, relit in the session, against the same scene baked with nothing cached
    changes = {
        "lamp moved": lambda: setattr(lamp, "location", (0.6, 1.3, 1.0)),
        "colour changed": lambda: bpy.data.objects["RedWall"].active_material.node_tree.nodes[
            "Principled BSDF"].inputs["Base Color"].default_value.__setitem__(slice(0, 3), (0.1, 0.6, 0.1)),
        "vertex moved": lambda: _move_top(bpy.data.objects["TallBlock"].data, 0.15),
    }
    before = brighter
    for what, change in changes.items():
        change()
        warm = bake()
        bake_mod.clear_session_cache()
        cold = bake()
        same(warm, cold)
        changed = any(not np.allclose(warm[n][1], before[n][1], rtol=1e-3) for n in names)
        assert changed, f"{what}: the relight changed nothing"
        before = warm
    block = write.copies_of(["TallBlock"])[0]
    assert corner_data(block)[0][:, 2].max() > first["TallBlock"][0][:, 2].max() + 0.1


def _move_top(me, dz):
    """Raise the highest vertices of mesh ``me`` by ``dz`` (a taller block)."""
    z = np.array([v.co.z for v in me.vertices])
    for v in me.vertices:
        if v.co.z >= z.max() - 1e-6:
            v.co.z += dz
    me.update()
