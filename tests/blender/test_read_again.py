# SPDX-License-Identifier: GPL-3.0-or-later
"""Reading a scene again (a relight) finds what it made of each unchanged mesh (welded arrays,
corner normals as Cycles shades them, in world space: the same read-only arrays, so whatever the
bake keys on them is found too), and never serves a mesh edited since: a vertex moved, the
object moved, its shading changed; each then reads as a fresh read with nothing kept does."""
from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tools import cycles_reference as cr  # noqa: E402
from hemicube_radiosity.blender.read import scene as reader  # noqa: E402
from hemicube_radiosity.blender.read import split_normals  # noqa: E402

pytestmark = pytest.mark.blender


def _read(ob):
    return reader.read_object(ob, bpy.context.evaluated_depsgraph_get())


def _fresh(ob):
    for memo in (reader._WELDED, reader._IN_WORLD, split_normals._SHADED):
        memo.clear()
    return _read(ob)


def _same(a, b):
    for x, y in ((a.mesh.verts, b.mesh.verts), (a.mesh.face_indices, b.mesh.face_indices),
                 (a.mesh.corner_normal, b.mesh.corner_normal)):
        np.testing.assert_array_equal(x, y)


def test_an_edited_mesh_is_read_again():
    cr.new_empty_scene()
    v, f = cr.grid_arrays(6, 6, -1.0, 1.0, -1.0, 1.0)
    v[:, 2] = 0.3 * np.sin(2 * v[:, 0]) * np.cos(3 * v[:, 1])          # curved: the normals vary
    ob = cr.mesh_object(v, f, cr.diffuse_material((0.5,) * 3), "Wavy")
    ob.data.shade_smooth()
    ob.location, ob.rotation_euler = (0.5, 0.2, 1.0), (0.3, 0.0, 0.7)
    bpy.context.view_layer.update()
    first = _fresh(ob)
    assert first.mesh.corner_normal is not None
    again = _read(ob)
    assert again.mesh.corner_normal is first.mesh.corner_normal        # found, not made again
    assert again.mesh.verts is first.mesh.verts
    edits = {
        "vertex moved": lambda: ob.data.vertices[10].co.__setitem__(2, 0.5),
        "object moved": lambda: setattr(ob, "rotation_euler", (0.3, 0.2, 0.7)),
        "flat shaded": lambda: ob.data.shade_flat(),
    }
    before = again
    for what, edit in edits.items():
        edit()
        ob.data.update()
        bpy.context.view_layer.update()
        warm = _read(ob)
        assert warm.mesh.corner_normal is not before.mesh.corner_normal, what
        assert not np.array_equal(warm.mesh.corner_normal, before.mesh.corner_normal), what
        _same(warm, _fresh(ob))
        before = _read(ob)


def test_instances_are_placed_again_from_the_same_arrays_until_they_move():
    from tests.blender.test_instances import sun_scene

    floor, inst = sun_scene("collection")

    def placed():
        s = reader.read_scene(bpy.context.evaluated_depsgraph_get(), [floor], instancers=None)
        return [o for o in s.objects if "[instance" in o.name]

    def fresh():
        for memo in (reader._WELDED, reader._IN_WORLD, reader._PLACED, split_normals._SHADED):
            memo.clear()
        return placed()
    first = fresh()
    assert len(first) == 1
    again = placed()
    assert again[0].mesh.verts is first[0].mesh.verts and not again[0].mesh.verts.flags.writeable
    assert again[0].mesh.face_indices is first[0].mesh.face_indices
    inst.location.x += 0.25                                    # the instancer moved
    bpy.context.view_layer.update()
    moved = placed()
    assert moved[0].mesh.verts is not first[0].mesh.verts
    np.testing.assert_allclose(moved[0].mesh.verts, first[0].mesh.verts + [0.25, 0, 0], atol=1e-12)
    ref = fresh()
    np.testing.assert_array_equal(moved[0].mesh.verts, ref[0].mesh.verts)
    np.testing.assert_array_equal(moved[0].mesh.face_indices, ref[0].mesh.face_indices)
