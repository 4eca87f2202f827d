"""What is written for a single plane whose back takes part in the light (core/mesh/backs.py): the
baked copy holds both sides, each face and its back, with a material that culls back faces (so
each side shows its own light in the viewport, and glTF's material is single-sided); the user's
mesh is untouched; In Place writes the front and says where the back's light went."""
from __future__ import annotations

import hashlib

import numpy as np
import pytest

from tests.support.addon import sub
from tests.support.gltf import read_gltf
from tests.support.scene import corner_data

pytestmark = pytest.mark.blender


def _grid(bpy, name, verts, faces):
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(map(float, v)) for v in verts], [], [list(map(int, f)) for f in faces])
    me.update()
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _scene(bpy):
    """A 3 m floor; on it a single-plane wall at y = 0 facing -y; a point lamp behind the wall."""
    bpy.ops.wm.read_homefile(use_empty=True)
    n = 6
    u = np.linspace(-1.5, 1.5, n + 1)
    X, Y = np.meshgrid(u, u, indexing="xy")
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    quads = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], -1).reshape(-1, 4)
    floor = _grid(bpy, "Floor", np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], 1), quads)
    Z = (Y + 1.5) / 2                                        # 0 .. 1.5 m
    wall = _grid(bpy, "Wall", np.stack([X.ravel(), np.zeros(X.size), Z.ravel()], 1), quads)
    bpy.ops.object.light_add(type="POINT", location=(0.0, 0.8, 1.0))
    bpy.context.active_object.data.energy = 300.0
    return floor, wall


def _hash(me):
    co = np.empty(len(me.vertices) * 3, np.float32)
    me.vertices.foreach_get("co", co)
    lv = np.empty(len(me.loops), np.int32)
    me.loops.foreach_get("vertex_index", lv)
    return hashlib.sha256(co.tobytes() + lv.tobytes() + str(sorted(a.name for a in me.attributes)).encode()).hexdigest()


def _bake(addon, bpy, objects, **kw):
    settings = sub(addon, "core.settings").BakeSettings(patch_size=0.5, element_size=0.25, resolution=16,
                                                        gather_rays=16, **kw)
    job = sub(addon, "blender.bake").BakeJob.prepare(bpy.context, objects, settings,
                                                     cache=sub(addon, "core.runtime.cache").FormFactorCache(None))
    job.run()
    job.write(bpy.context)
    return job


@pytest.fixture(scope="module")
def copies(addon):
    import bpy

    floor, wall = _scene(bpy)
    before = _hash(wall.data)
    job = _bake(addon, bpy, [floor, wall])
    return dict(bpy=bpy, job=job, before=before)


def _face_normals_and_colours(ob):
    me = ob.data
    n = np.empty(len(me.polygons) * 3)
    me.polygons.foreach_get("normal", n)
    starts = np.empty(len(me.polygons), np.int64)
    me.polygons.foreach_get("loop_start", starts)
    _, col = corner_data(ob)
    return n.reshape(-1, 3), col[starts]


def test_the_copy_of_a_single_plane_wall_holds_both_sides(addon, copies):
    bpy, job = copies["bpy"], copies["job"]
    r = job.result
    names = r.patches.object_names
    assert "Wall (back)" in names and "Floor (back)" not in names    # the floor's underside faces nothing
    (ob,) = sub(addon, "blender.write").copies_of(["Wall"])
    assert ob["radiosity_mesh"] == "elements"
    normals, colours = _face_normals_and_colours(ob)
    front, back = normals[:, 1] < -0.99, normals[:, 1] > 0.99
    assert front.sum() == back.sum() > 0 and np.all(front | back)
    # the lamp is behind the wall: its back is lit, its front (facing away) dark
    assert colours[back].mean() > 0.05 and colours[front].max() < 1e-3 * colours[back].mean()
    # the back's written light is the bake's on the back's elements
    el = r.elements
    on_back = np.isin(el.owner, r.owners_of(names.index("Wall"))[1:])
    v = np.unique(el.polys[on_back][el.polys[on_back] >= 0])
    assert colours[back].mean() == pytest.approx(r.vertex_radiosity[v].mean(), rel=0.25)
    mat = ob.data.materials[0]
    assert mat.use_backface_culling and mat.get("radiosity_attribute") == job.settings.attribute_name
    (plain,) = sub(addon, "blender.write").copies_of(["Floor"])
    assert not plain.data.materials[0].use_backface_culling
    assert _hash(bpy.data.objects["Wall"].data) == copies["before"]


def test_the_glb_of_a_two_sided_copy_is_single_sided(addon, copies, tmp_path):
    obs = sub(addon, "blender.write").copies_of(["Wall", "Floor"])
    path = sub(addon, "blender.gltf").export_gltf(tmp_path / "wall.glb", obs)
    doc, _ = read_gltf(path)
    by_name = {n["name"]: n for n in doc["nodes"]}
    sided = {}
    for ob in obs:
        for prim in doc["meshes"][by_name[ob.name]["mesh"]]["primitives"]:
            sided[ob[sub(addon, "blender.write").SOURCE_KEY]] = doc["materials"][prim["material"]].get("doubleSided", False)
    assert sided == {"Wall": False, "Floor": True}


def test_in_place_writes_the_front_and_says_where_the_back_went(addon):
    import bpy

    floor, wall = _scene(bpy)
    job = _bake(addon, bpy, [floor, wall], output_mode="in_place")
    lines = [str(n) for n in job.notes]
    assert any(line.startswith("Wall: in place keeps the light on the front") for line in lines)
    assert not any(line.startswith("Floor: in place keeps the light on the front") for line in lines)
    _, col = corner_data(bpy.data.objects["Wall"])
    assert col.max() < 1e-3                                   # the front faces away from the lamp
