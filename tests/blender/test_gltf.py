"""Baked glTF: _RADIANCE parsed back from the file (struct + json) equals the baked attribute,
COLOR_0 is it through the view transform, and each view transform gives the 8-bit pixels that
Blender's own view of that name gives."""
from __future__ import annotations


import numpy as np
import pytest

from tests.support.addon import sub
from tests.support.gltf import read_gltf
from tests.support.scene import corner_data
from hemicube_radiosity.core.formats.gltf import (
    VIEW_TRANSFORMS, display_linear, srgb_encode, tone_map_gltf
)

pytestmark = pytest.mark.blender


def corners(ob, attr="Radiosity"):
    """World positions (glTF is Y-up: x, z, -y) and RGB of every corner."""
    p, col = corner_data(ob, attr)
    return np.stack([p[:, 0], p[:, 2], -p[:, 1]], 1), col


def gltf_vertices(doc, accessor, object_name, attribute="_RADIANCE"):
    """World positions and ``attribute`` (RGB) of every vertex of node ``object_name``."""
    node = next(n for n in doc["nodes"] if n.get("name") == object_name)
    mesh_index = node["mesh"]
    pos, col = [], []
    for prim in doc["meshes"][mesh_index]["primitives"]:
        acc = doc["accessors"][prim["attributes"][attribute]]
        assert acc["componentType"] == 5126 and not acc.get("normalized", False)   # float
        assert acc["type"] == "VEC3"
        pos.append(accessor(prim["attributes"]["POSITION"]))
        col.append(accessor(prim["attributes"][attribute]))
    pos = np.concatenate(pos)
    # node transform (translation/rotation/scale) to world
    if "matrix" in node:
        M = np.array(node["matrix"]).reshape(4, 4).T
    else:
        t = np.array(node.get("translation", [0, 0, 0]))
        x, y, z, w = node.get("rotation", [0, 0, 0, 1])
        R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                      [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                      [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
        S = np.diag(node.get("scale", [1, 1, 1]))
        M = np.eye(4)
        M[:3, :3] = R @ S
        M[:3, 3] = t
    return pos @ M[:3, :3].T + M[:3, 3], np.concatenate(col)


def assert_colors_match(gpos, gcol, bpos, bcol, tol=1e-5):
    """Every glTF vertex carries the colour of a Blender corner at its position, and every Blender
    corner's colour is found on a glTF vertex there (hard edges: several colours per position)."""
    d = np.linalg.norm(gpos[:, None, :] - bpos[None, :, :], axis=2) < 1e-4      # (G, B) same place
    assert d.any(axis=1).all() and d.any(axis=0).all()
    cd = np.abs(gcol[:, None, :] - bcol[None, :, :]).max(axis=2)
    scale = np.maximum(1.0, np.abs(bcol).max(axis=1))[None, :]
    match = d & (cd <= tol * scale)
    assert match.any(axis=1).all(), "a glTF colour matches no Blender corner at its position"
    assert match.any(axis=0).all(), "a Blender corner colour is missing from the glTF"


@pytest.fixture(scope="module")
def baked_cornell(addon):
    import bpy

    bpy.ops.wm.read_homefile(use_empty=True)
    objs = sub(addon, "blender.demo").build_cornell_box(bpy.context)
    for o in objs:
        o.select_set(True)
    assert bpy.ops.object.radiosity_bake(patch_size=0.5, resolution=16) == {"FINISHED"}
    return sub(addon, "blender.write").copies_of([o.name for o in objs])


@pytest.mark.parametrize("ext", [".glb", ".gltf"])
def test_radiance_equals_baked_attribute_and_color0_is_it_clamped(addon, baked_cornell, tmp_path, ext):
    path = sub(addon, "blender.gltf").export_gltf(tmp_path / f"cornell{ext}", baked_cornell)
    doc, accessor = read_gltf(path)
    assert doc["asset"]["extras"]["hemicube_radiosity"]["view_transform"] == "standard"
    assert "KHR_materials_unlit" in doc.get("extensionsUsed", [])
    for mat in doc["materials"]:
        assert "KHR_materials_unlit" in mat.get("extensions", {})
        assert mat.get("pbrMetallicRoughness", {}).get("baseColorFactor", [1, 1, 1, 1]) == [1, 1, 1, 1]
    assert sorted(n["name"] for n in doc["nodes"]) == sorted(o.name for o in baked_cornell)
    for ob in baked_cornell:
        gpos, gcol = gltf_vertices(doc, accessor, ob.name)
        bpos, bcol = corners(ob)
        assert_colors_match(gpos, gcol, bpos, bcol)
        # standard view transform: COLOR_0 is the same vertices' radiance clamped to 0..1
        cpos, ccol = gltf_vertices(doc, accessor, ob.name, "COLOR_0")
        np.testing.assert_array_equal(cpos, gpos)
        np.testing.assert_allclose(ccol, np.clip(gcol, 0.0, 1.0), rtol=1e-6, atol=1e-7)
    # HDR: the light's radiance 12 is kept in _RADIANCE; COLOR_0 is 1
    light = next(o for o in baked_cornell if o.name.startswith("Light"))
    _, lcol = gltf_vertices(doc, accessor, light.name)
    np.testing.assert_allclose(lcol, 12.0, rtol=1e-6)
    _, lc0 = gltf_vertices(doc, accessor, light.name, "COLOR_0")
    np.testing.assert_array_equal(lc0, 1.0)
    # rewriting again changes nothing (a file already done is left alone)
    before = open(path, "rb").read()
    assert tone_map_gltf(path, "agx")["primitives"] == 0
    assert open(path, "rb").read() == before


def test_agx_export_keeps_radiance_and_maps_color0_below_white(addon, baked_cornell, tmp_path):
    path = sub(addon, "blender.gltf").export_gltf(tmp_path / "agx.glb", baked_cornell, view_transform="agx")
    doc, accessor = read_gltf(path)
    assert doc["asset"]["extras"]["hemicube_radiosity"]["view_transform"] == "agx"
    for ob in baked_cornell:
        _, rad = gltf_vertices(doc, accessor, ob.name)
        _, col = gltf_vertices(doc, accessor, ob.name, "COLOR_0")
        np.testing.assert_allclose(col, display_linear(rad, "agx"), atol=1e-6)
    light = next(o for o in baked_cornell if o.name.startswith("Light"))
    _, lc0 = gltf_vertices(doc, accessor, light.name, "COLOR_0")
    assert 0.8 < lc0.min() and lc0.max() < 1.0          # 12 is bright but not clipped in AgX


def test_element_copies_have_no_texcoords(addon, baked_cornell, tmp_path):
    """Element-mesh copies (the Cornell box's walls, cut finer) have no UV maps: none is written."""
    assert all(len(o.data.uv_layers) == 0 for o in baked_cornell)
    path = sub(addon, "blender.gltf").export_gltf(tmp_path / "cornell_uv.glb", baked_cornell)
    doc, _ = read_gltf(path)
    for mesh in doc["meshes"]:
        for prim in mesh["primitives"]:
            assert "COLOR_0" in prim["attributes"] and "TEXCOORD_0" not in prim["attributes"]


# view transform -> (Blender's view, max mean |difference| and max |difference| in 8-bit levels)
BLENDER_VIEWS = {"standard": ("Standard", 0.01, 1), "khronos_neutral": ("Khronos PBR Neutral", 0.6, 8),
                 "agx": ("AgX", 4.5, 50)}


@pytest.mark.parametrize("view_transform", VIEW_TRANSFORMS)
def test_view_transform_gives_blenders_pixels(empty_scene, tmp_path, view_transform):
    """Blender's colour management (OCIO) turns HDR linear pixels into 8-bit sRGB with the view
    transform; a viewer shows COLOR_0 = display_linear(x) as srgb_encode(display_linear(x)).
    Standard is exact (Blender's Standard view is clip + the sRGB OETF); Khronos PBR Neutral is a
    LUT of the same formula in Blender; our AgX is a fit of Blender's AgX LUT."""
    bpy = empty_scene
    scene = bpy.context.scene
    rng = np.random.default_rng(1)
    x = np.concatenate([np.exp2(rng.uniform(-8, 4, (3000, 1))) * rng.uniform(0, 1, (3000, 3)),
                        np.exp2(np.linspace(-10, 4, 400))[:, None] * np.ones(3)])
    im = bpy.data.images.new("hdr", 100, len(x) // 100, float_buffer=True, alpha=True)
    im.pixels.foreach_set(np.concatenate([x, np.ones((len(x), 1))], 1).astype(np.float32).ravel())
    blender_view, mean_tol, max_tol = BLENDER_VIEWS[view_transform]
    scene.view_settings.view_transform = blender_view
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_depth = "8"
    im.save_render(str(tmp_path / "view.png"), scene=scene)
    png = bpy.data.images.load(str(tmp_path / "view.png"))
    px = np.empty(len(x) * 4, np.float32)
    png.pixels.foreach_get(px)
    got = np.round(px.reshape(-1, 4)[:, :3] * 255)
    want = np.round(srgb_encode(display_linear(x, view_transform)) * 255)
    d = np.abs(got - want)
    assert d.mean() <= mean_tol and d.max() <= max_tol, (d.mean(), d.max())


def test_in_place_bake_exports_its_attribute_not_white(addon, empty_scene, tmp_path):
    """The original's material does not read the attribute: COLOR_0 must still be the bake."""
    bpy = empty_scene
    bpy.ops.mesh.primitive_plane_add(size=2)
    floor = bpy.context.active_object
    bpy.ops.mesh.primitive_plane_add(size=1, location=(0.8, 0, 1), rotation=(np.pi, 0, 0))
    lamp = bpy.context.active_object
    m = bpy.data.materials.new("Glow")
    if bpy.app.version < (5, 0, 0):
        m.use_nodes = True
    b = m.node_tree.nodes["Principled BSDF"]
    b.inputs["Emission Color"].default_value = (1, 1, 1, 1)
    b.inputs["Emission Strength"].default_value = 3.0
    b.inputs["Base Color"].default_value = (0, 0, 0, 1)
    lamp.data.materials.append(m)
    floor.data.materials.append(bpy.data.materials.new("Plain"))
    for o in bpy.context.view_layer.objects:
        o.select_set(o == floor)
    assert bpy.ops.object.radiosity_bake(patch_size=0, resolution=16, output_mode="IN_PLACE") == {"FINISHED"}
    path = sub(addon, "blender.gltf").export_gltf(tmp_path / "floor.glb", [floor])
    doc, accessor = read_gltf(path)
    assert [n["name"] for n in doc["nodes"]] == [floor.name]
    assert all("KHR_materials_unlit" in m.get("extensions", {}) for m in doc["materials"])
    gpos, gcol = gltf_vertices(doc, accessor, floor.name)
    bpos, bcol = corners(floor)
    # the stand-in is gone, the original keeps its name and material
    assert [o.name for o in bpy.data.objects] == ["Plane", "Plane.001"]
    assert floor.data.materials[0].name == "Plain" and len(bpy.data.meshes) == 2
    assert bcol.max() > 0.05 and np.ptp(bcol) > 0.01
    assert_colors_match(gpos, gcol, bpos, bcol)
    # the plane's UV map is exported (texcoords are on when a mesh has UVs), unless turned off
    assert all("TEXCOORD_0" in p["attributes"] for m in doc["meshes"] for p in m["primitives"])
    path = sub(addon, "blender.gltf").export_gltf(tmp_path / "floor_no_uv.glb", [floor], export_texcoords=False)
    doc, _ = read_gltf(path)
    assert not any("TEXCOORD_0" in p["attributes"] for m in doc["meshes"] for p in m["primitives"])
