"""Baked copies at the user's vertices: where the bake did not cut an object's faces (a dense
mesh, faces finer than the detail size), its copy is the user's evaluated mesh (modifiers applied)
with the attribute per corner: same vertices, loops and faces, same UVs, custom normals, sharp
edges and attributes, colours equal to the bake's vertex radiosity there, and the original
untouched. A coarse mesh still gets the element mesh. The .glb keeps TEXCOORD_0 with COLOR_0."""
from __future__ import annotations

import hashlib

import numpy as np
import pytest

from tests.support.addon import sub
from tests.support.gltf import read_gltf
from tests.support.scene import corner_data

pytestmark = pytest.mark.blender

N = 16   # the grid's cells per side: faces of 2/16 = 0.125 m, finer than the 0.25 m detail size


def _attr_array(attr):
    """Any attribute's data as an (n, width) array."""
    n = len(attr.data)
    if n == 0:
        return np.empty((0, 1))
    prop = next(p for p in ("vector", "color", "value") if hasattr(attr.data[0], p))
    first = getattr(attr.data[0], prop)
    width = len(first) if hasattr(first, "__len__") else 1
    x = first[0] if width > 1 or hasattr(first, "__len__") else first
    dtype = bool if isinstance(x, bool) else np.int32 if isinstance(x, int) else np.float32
    a = np.empty(n * width, dtype)
    attr.data.foreach_get(prop, a)
    return a.reshape(n, width)


def mesh_arrays(me):
    """Everything a user keeps on a mesh: positions, topology, every attribute (UV maps, custom
    attributes, sharp edges...), custom normals, materials."""
    out = {}
    co = np.empty(len(me.vertices) * 3, np.float32)
    me.vertices.foreach_get("co", co)
    out["co"] = co.reshape(-1, 3)
    lv = np.empty(len(me.loops), np.int32)
    me.loops.foreach_get("vertex_index", lv)
    out["loops"] = lv
    ls = np.empty(len(me.polygons), np.int32)
    me.polygons.foreach_get("loop_start", ls)
    out["loop_start"] = ls
    for a in me.attributes:
        if a.name.startswith(".") or a.name == "position":
            continue
        out[f"attr:{a.name}:{a.domain}:{a.data_type}"] = _attr_array(a)
    for uv in me.uv_layers:
        d = np.empty(len(me.loops) * 2, np.float32)
        uv.data.foreach_get("uv", d)
        out[f"uv:{uv.name}"] = d.reshape(-1, 2)
    n = np.empty(len(me.loops) * 3, np.float32)
    me.corner_normals.foreach_get("vector", n)
    out["corner_normals"] = n.reshape(-1, 3)
    out["materials"] = np.array([m.name if m else "" for m in me.materials], dtype=str)
    return out


def mesh_hash(me):
    h = hashlib.sha256()
    for k, v in sorted(mesh_arrays(me).items()):
        h.update(k.encode())
        h.update(np.ascontiguousarray(v).tobytes())
    return h.hexdigest()


def originals_hash(bpy):
    """Every mesh and object that was in the file: data and modifiers, placement, materials."""
    meshes = {m.name: mesh_hash(m) for m in bpy.data.meshes}
    objects = {o.name: (tuple(map(tuple, o.matrix_world)), tuple((m.name, m.type) for m in o.modifiers),
                        o.data.name if o.data else None) for o in bpy.data.objects}
    return meshes, objects


def dense_grid(bpy, name="Dense", location=(0, 0, 0), scale=(1, 1, 1)):
    """A 16 x 16 grid with a UV map (rotated, so it is not just the positions), a custom point
    attribute and a custom corner attribute, custom normals, a few sharp edges, its own material
    and a triangulate modifier (the evaluated mesh has 512 triangles)."""
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=N, y_subdivisions=N, size=2, location=location)
    ob = bpy.context.active_object
    ob.name = name
    ob.scale = scale
    me = ob.data
    uv = np.empty(len(me.loops) * 2, np.float32)
    me.uv_layers[0].data.foreach_get("uv", uv)
    uv = uv.reshape(-1, 2)
    me.uv_layers[0].data.foreach_set("uv", np.stack([0.3 + 0.5 * uv[:, 1], 0.9 - 0.7 * uv[:, 0]], 1).ravel())
    me.uv_layers.new(name="Second")
    w = me.attributes.new("wetness", "FLOAT", "POINT")
    w.data.foreach_set("value", np.linspace(0, 1, len(me.vertices)).astype(np.float32))
    t = me.attributes.new("tint", "FLOAT_VECTOR", "CORNER")
    t.data.foreach_set("vector", np.random.default_rng(0).uniform(size=3 * len(me.loops)).astype(np.float32))
    sharp = me.attributes.new("sharp_edge", "BOOLEAN", "EDGE")
    sharp.data.foreach_set("value", (np.arange(len(me.edges)) % 7 == 0))
    normals = np.random.default_rng(1).normal(size=(len(me.loops), 3)) * 0.2 + (0, 0, 1)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    me.normals_split_custom_set([tuple(n) for n in normals])
    mat = bpy.data.materials.new(name + "Paint")
    me.materials.append(mat)
    ob.modifiers.new("Triangulate", "TRIANGULATE")
    return ob


def build_scene(bpy):
    dense = dense_grid(bpy)
    mirrored = dense_grid(bpy, "Mirrored", location=(0, 2.5, 0), scale=(-1, 1, 1))
    bpy.ops.mesh.primitive_plane_add(size=2, location=(3, 0, 0))
    coarse = bpy.context.active_object
    coarse.name = "Coarse"
    bpy.ops.object.light_add(type="POINT", location=(0.6, 0.4, 1.2))
    bpy.context.active_object.data.energy = 300.0
    bpy.ops.object.light_add(type="POINT", location=(0.3, 2.8, 1.0))
    bpy.context.active_object.data.energy = 300.0
    return dense, mirrored, coarse


def bake(addon, bpy, objects):
    bake_mod = sub(addon, "blender.bake")
    settings = sub(addon, "core.settings").BakeSettings(patch_size=0.5, element_size=0.25, resolution=16,
                                                        gather_rays=0)
    cache = sub(addon, "core.runtime.cache").FormFactorCache(None)
    job = bake_mod.BakeJob.prepare(bpy.context, objects, settings, cache=cache)
    job.run()
    job.write(bpy.context)
    return job


@pytest.fixture(scope="module")
def baked(addon):
    import bpy

    bpy.ops.wm.read_homefile(use_empty=True)
    dense, mirrored, coarse = build_scene(bpy)
    before = originals_hash(bpy)
    dg = bpy.context.evaluated_depsgraph_get()
    evaluated = {}
    for ob in (dense, mirrored):
        me = ob.evaluated_get(dg).to_mesh()
        evaluated[ob.name] = mesh_arrays(me)
        ob.evaluated_get(dg).to_mesh_clear()
    job = bake(addon, bpy, [dense, mirrored, coarse])
    return dict(bpy=bpy, job=job, before=before, evaluated=evaluated,
                names=(dense.name, mirrored.name, coarse.name))


def copy_of(addon, name):
    (ob,) = sub(addon, "blender.write").copies_of([name])
    return ob


@pytest.mark.parametrize("name", ["Dense", "Mirrored"])
def test_dense_copy_keeps_the_evaluated_mesh(addon, baked, name):
    bpy = baked["bpy"]
    ob, src = copy_of(addon, name), bpy.data.objects[name]
    assert ob["radiosity_mesh"] == "source"
    np.testing.assert_array_equal(np.array(ob.matrix_world), np.array(src.matrix_world))
    assert len(ob.modifiers) == 0
    got, want = mesh_arrays(ob.data), baked["evaluated"][name]
    assert len(got["co"]) == len(want["co"]) == (N + 1) ** 2
    assert len(got["loop_start"]) == len(want["loop_start"]) == 2 * N * N   # the triangulate modifier
    assert len(got["loops"]) == len(want["loops"])
    for key in want:
        if key == "materials":
            continue
        assert key in got, f"the copy lost {key}"
        np.testing.assert_array_equal(got[key], want[key], err_msg=key)
    # the extra keys are the bake's colour attribute only
    assert {k for k in got if k not in want} == {"attr:Radiosity:CORNER:FLOAT_COLOR"}
    assert {"uv:UVMap", "uv:Second", "attr:wetness:POINT:FLOAT", "attr:tint:CORNER:FLOAT_VECTOR",
            "attr:sharp_edge:EDGE:BOOLEAN"} <= set(want)
    # the custom normals are there (not the flat grid's +z)
    assert np.abs(got["corner_normals"] - (0, 0, 1)).max() > 0.05
    # the material shows the bake
    mats = list(ob.data.materials)
    assert mats and all(m.get("radiosity_attribute") == "Radiosity" for m in mats)
    assert ob.data.color_attributes.active_color.name == "Radiosity"
    ca = ob.data.color_attributes
    assert ca[ca.render_color_index].name == "Radiosity"


@pytest.mark.parametrize("name", ["Dense", "Mirrored"])
def test_dense_copy_colours_are_the_bake_s_corner_values(addon, baked, name):
    """Each face corner of the copy (the user's own triangles) holds the bake's value at that
    corner of the same triangle (``BakeResult.corner_values``): the random custom normals lean
    many corners more than 15 degrees off their triangle, and those are lit on their own
    (core/output/crease.py), so corners at one vertex differ."""
    job = baked["job"]
    ob = copy_of(addon, name)
    oi = [o.name for o in job.scene_input.objects].index(name)
    E = job.result.elements
    mine = np.flatnonzero(E.owner == oi)
    values = job.result.corner_values()[mine]                        # (n, 4, 3)
    corners = E.corners()[mine]                                      # (n, 4, 3)
    pos, col = corner_data(ob)
    me = ob.data
    start = np.empty(len(me.polygons), np.int64)
    me.polygons.foreach_get("loop_start", start)
    total = np.empty(len(me.polygons), np.int64)
    me.polygons.foreach_get("loop_total", total)
    face = np.repeat(np.arange(len(start)), total)
    centre = np.stack([np.bincount(face, pos[:, k]) for k in range(3)], 1) / total[:, None]
    element = np.linalg.norm(centre[:, None, :] - E.centers[mine][None, :, :], axis=2).argmin(axis=1)[face]
    d = np.linalg.norm(corners[element] - pos[:, None, :], axis=2)  # (L, 4)
    assert d.min(axis=1).max() < 1e-5, "a corner of the copy is not a corner of its element"
    want = values[element, d.argmin(axis=1)]
    np.testing.assert_allclose(col, want, rtol=1e-5, atol=1e-7)
    assert col.max() > 0.05 and np.ptp(col[:, 0]) > 0.2 * col.max()   # lit, and not uniformly
    # corners that share a vertex differ where they are lit on their own
    ids = np.unique(np.round(pos, 5), axis=0, return_inverse=True)[1].reshape(-1)
    spread = np.zeros(ids.max() + 1)
    np.maximum.at(spread, ids, col[:, 0])
    low = np.full(ids.max() + 1, np.inf)
    np.minimum.at(low, ids, col[:, 0])
    assert np.any(spread - low > 0.05 * col.max())


def test_originals_untouched(addon, baked):
    bpy = baked["bpy"]
    meshes, objects = originals_hash(bpy)
    b_meshes, b_objects = baked["before"]
    assert {k: meshes[k] for k in b_meshes} == b_meshes
    assert {k: objects[k] for k in b_objects} == b_objects
    assert all(bpy.data.objects[n].hide_render for n in baked["names"])


def test_coarse_mesh_keeps_the_element_copy(addon, baked):
    ob = copy_of(addon, "Coarse")
    assert ob["radiosity_mesh"] == "elements"
    assert len(ob.data.polygons) == 64                      # 2 m cut at 0.25 m
    # the plane's own UV map, at every element corner: u = (x + 1) / 2, v = (y + 1) / 2
    assert [u.name for u in ob.data.uv_layers] == ["UVMap"]
    me = ob.data
    uv = np.empty(len(me.loops) * 2, np.float32)
    me.uv_layers["UVMap"].data.foreach_get("uv", uv)
    co = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", co)
    lv = np.empty(len(me.loops), np.int64)
    me.loops.foreach_get("vertex_index", lv)
    np.testing.assert_allclose(uv.reshape(-1, 2), (co.reshape(-1, 3)[lv, :2] + 1.0) / 2.0, atol=1e-6)


def test_glb_has_texcoords_and_color(addon, baked, tmp_path):
    copies = [copy_of(addon, n) for n in baked["names"]]
    path = sub(addon, "blender.gltf").export_gltf(tmp_path / "dense.glb", copies)
    doc, accessor = read_gltf(path)
    by_name = {n["name"]: n for n in doc["nodes"]}
    for ob in copies:
        prims = doc["meshes"][by_name[ob.name]["mesh"]]["primitives"]
        has_uv = ob["radiosity_mesh"] == "source"
        maps = len(ob.data.uv_layers)               # an element copy has the user's UVs as well
        assert maps == (2 if ob.name != "Coarse.radiosity" else 1)
        for prim in prims:
            assert {"POSITION", "COLOR_0", "_RADIANCE"} <= set(prim["attributes"])
            assert "TEXCOORD_0" in prim["attributes"]
            assert ("TEXCOORD_1" in prim["attributes"]) == (maps == 2)
        if has_uv:
            # the UVs written are the copy's (glTF flips v)
            uv = np.concatenate([accessor(p["attributes"]["TEXCOORD_0"]) for p in prims])
            me_uv = mesh_arrays(ob.data)["uv:UVMap"]
            got = np.unique(np.round(np.stack([uv[:, 0], 1 - uv[:, 1]], 1), 5), axis=0)
            want = np.unique(np.round(me_uv.astype(np.float64), 5), axis=0)
            np.testing.assert_allclose(got, want, atol=2e-5)
            rad = np.concatenate([accessor(p["attributes"]["_RADIANCE"]) for p in prims])
            col = np.concatenate([accessor(p["attributes"]["COLOR_0"]) for p in prims])
            np.testing.assert_allclose(col[:, :3], np.clip(rad, 0, 1), rtol=1e-6, atol=1e-7)
            _, bcol = corner_data(ob)
            np.testing.assert_allclose(np.sort(np.unique(np.round(rad[:, 0], 5))),
                                       np.sort(np.unique(np.round(bcol[:, 0], 5))), atol=2e-5)


def test_rebake_of_the_copy_still_keeps_the_topology(addon, baked):
    """A re-bake (the sources are hidden by the first one; the copies are selected) writes the
    user's topology again and still leaves the originals alone."""
    bpy = baked["bpy"]
    copies = [copy_of(addon, n) for n in baked["names"]]
    bake(addon, bpy, copies)
    assert [copy_of(addon, n)["radiosity_mesh"] for n in baked["names"]] == ["source", "source", "elements"]
    meshes, _ = originals_hash(bpy)
    assert {k: meshes[k] for k in baked["before"][0]} == baked["before"][0]
