# SPDX-License-Identifier: GPL-3.0-or-later
"""Cycles' material bakes in batches (``blender/read/shading.py``): the copies of many objects are
joined into one mesh per batch and baked in one Cycles run, instead of one run per object (each
run syncs the whole temporary scene: 6 minutes for the 349 textured objects of
bitterli_wooden_staircase). The values must be exactly those of each object baked on its own:
moved, rotated, mirrored and scaled objects, a modifier, two materials on one object, render UV
maps of different names, a colour attribute; objects whose material depends on the object
(Object coordinates) are baked as themselves."""
from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tools import cycles_reference as cr  # noqa: E402
from hemicube_radiosity.blender.read import scene as reader  # noqa: E402
from hemicube_radiosity.blender.read import shading  # noqa: E402

pytestmark = [pytest.mark.blender, pytest.mark.cycles]


def _material(name, base=(0.8, 0.8, 0.8)):
    m = bpy.data.materials.new(name)
    nt, out = cr.bare_node_tree(m)
    p = nt.nodes.new("ShaderNodeBsdfPrincipled")
    p.inputs["Base Color"].default_value = (*base, 1.0)
    nt.links.new(p.outputs[0], out.inputs["Surface"])
    return m, nt, p


def _image(name, size=16, seed=0):
    rng = np.random.default_rng(seed)
    img = bpy.data.images.new(name, size, size)
    px = np.concatenate([rng.uniform(0.05, 0.95, (size, size, 3)), np.ones((size, size, 1))], -1)
    img.pixels.foreach_set(px.astype(np.float32).ravel())
    img.pack()
    return img


def _textured(name, img, coords=None):
    m, nt, p = _material(name)
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = img
    if coords is not None:
        c = nt.nodes.new("ShaderNodeTexCoord")
        nt.links.new(c.outputs[coords], tex.inputs["Vector"])
    nt.links.new(tex.outputs["Color"], p.inputs["Base Color"])
    return m


def _painted(name, layer=""):
    m, nt, p = _material(name)
    vc = nt.nodes.new("ShaderNodeVertexColor")
    vc.layer_name = layer
    nt.links.new(vc.outputs["Color"], p.inputs["Base Color"])
    return m


def _grid(name, n, mats, uv_names=("UVMap",), render_uv=0, seed=0):
    """An n x n grid over [0, 1]^2 with random UVs in every layer, faces alternating over
    ``mats``."""
    v, f = cr.grid_arrays(n, n, 0.0, 1.0, 0.0, 1.0)
    ob = cr.mesh_object(v, f, None, name)
    me = ob.data
    for m in mats:
        me.materials.append(m)
    me.polygons.foreach_set("material_index", (np.arange(len(f)) % len(mats)).astype(np.int32))
    rng = np.random.default_rng(seed)
    for k, uvn in enumerate(uv_names):
        uv = me.uv_layers.new(name=uvn)
        uv.data.foreach_set("uv", rng.uniform(0, 1, 2 * len(me.loops)).astype(np.float32))
    if uv_names:
        me.uv_layers[render_uv].active_render = True
    me.update()
    return ob


def _scene():
    cr.new_empty_scene()
    wood, tiles = _image("wood", seed=1), _image("tiles", seed=2)
    m_wood, m_tiles = _textured("Wood", wood), _textured("Tiles", tiles)
    obs = [_grid("second_uv", 4, [m_tiles], uv_names=("other", "UVMap"), render_uv=1, seed=4),
           _grid("plain", 4, [m_wood]),
           _grid("two_mats", 5, [m_wood, m_tiles], seed=3),
           _grid("renamed_uv", 3, [m_tiles], uv_names=("other",), seed=8),
           _grid("object_coords", 4, [_textured("Projected", wood, coords="Object")], seed=5),
           _grid("painted", 3, [_painted("Paint", "paint"), m_wood], seed=6)]
    col = np.random.default_rng(7).uniform(0.1, 0.9, (len(obs[5].data.loops), 4)).astype(np.float32)
    obs[5].data.color_attributes.new("paint", "FLOAT_COLOR", "CORNER").data.foreach_set("color", col.ravel())
    obs[2].location, obs[2].rotation_euler = (3, 1, 2), (0.4, 1.1, -0.3)
    obs[0].scale = (-2, 1, 0.5)                                     # mirrored
    obs[4].location, obs[4].scale = (-2, 4, 0), (3, 3, 3)
    obs[1].modifiers.new("sub", "SUBSURF").levels = 1
    bpy.context.view_layer.update()
    return obs


def test_joined_bake_equals_each_object_alone(monkeypatch):
    obs = _scene()
    dg = bpy.context.evaluated_depsgraph_get()
    runs = []
    real = shading._bake

    def counting(scene, objects, kind, pass_filter):
        runs.append(len(objects))
        return real(scene, objects, kind, pass_filter)

    monkeypatch.setattr(shading, "_bake", counting)
    together = shading.shade(obs, dg)
    assert together.failed is None
    # one Cycles run a pass, DIFFUSE and GLOSSY (no material emits: no EMIT run), of 4 objects:
    # the join of the three objects
    # that read the render UV map 'UVMap' and nothing else (its first layer in 'second_uv'),
    # 'renamed_uv' (render UV map 'other'), 'painted' (reads the colour attribute 'paint' too)
    # and 'object_coords' as itself
    assert runs == [4, 4], runs
    for ob in obs:
        alone = shading.shade([ob], bpy.context.evaluated_depsgraph_get())
        r, e, g = together.corners[ob.name]
        assert r.shape == alone.corners[ob.name][0].shape == (ob.evaluated_get(dg).data.loops.__len__(), 3)
        np.testing.assert_allclose(r, alone.corners[ob.name][0], atol=1e-6, err_msg=ob.name)
        np.testing.assert_allclose(e, alone.corners[ob.name][1], atol=1e-6, err_msg=ob.name)
        np.testing.assert_allclose(g, alone.corners[ob.name][2], atol=1e-6, err_msg=ob.name)
        assert np.ptp(r[:, 0]) > 0.2, ob.name                 # really textured, not a fallback
    # nothing of the temporary scene is left
    assert not [o for o in bpy.data.objects if o.name.startswith(shading.SCENE)]
    assert not [m for m in bpy.data.meshes if m.name.startswith(shading.SCENE)]
    assert [s.name for s in bpy.data.scenes] == [bpy.context.scene.name]


def test_object_space_inputs_are_not_joined():
    cr.new_empty_scene()
    img = _image("i")
    assert shading.object_independent(_textured("uv", img))
    assert shading.object_independent(_textured("uv node", img, coords="UV"))
    for coords in ("Object", "Generated", "Normal"):
        assert not shading.object_independent(_textured(coords, img, coords=coords)), coords
    m, nt, p = _material("noise")
    nt.links.new(nt.nodes.new("ShaderNodeTexNoise").outputs[0], p.inputs["Base Color"])
    assert not shading.object_independent(m)                # default coordinates: Generated
    m = _textured("box", img)
    next(n for n in m.node_tree.nodes if n.type == "TEX_IMAGE").projection = "BOX"
    assert not shading.object_independent(m)


def test_reader_uses_the_batch_values():
    """read_scene over the batch gives each object the corner values of its own bake, mapped to
    its (mirrored, reordered) corners."""
    obs = _scene()
    dg = bpy.context.evaluated_depsgraph_get()
    s = reader.read_scene(dg, obs)
    for src, ob in zip(s.objects, obs):
        alone = reader.read_object(ob, bpy.context.evaluated_depsgraph_get())
        np.testing.assert_allclose(src.corner_rho, alone.corner_rho, atol=1e-6, err_msg=ob.name)
        np.testing.assert_allclose(src.mesh.face_rho, alone.mesh.face_rho, atol=1e-6)


def test_missing_image_uses_the_sockets_own_value(tmp_path):
    """An image whose file is missing renders magenta in Cycles; baked, every such surface would
    reflect 0.999 of red and blue (sauer_pandora ships without its textures). It is read as the
    socket's own value instead, the same as the material without the texture, with a note."""
    cr.new_empty_scene()
    img = bpy.data.images.new("gone.png", 4, 4)
    img.source, img.filepath = "FILE", str(tmp_path / "gone.png")
    lost = _textured("Lost", img)
    base = (0.6, 0.5, 0.4)
    next(n for n in lost.node_tree.nodes if n.type == "BSDF_PRINCIPLED").inputs["Base Color"].default_value = (*base, 1)
    plain = _material("Plain", base)[0]
    obs = [_grid("lost", 2, [lost]), _grid("plain", 2, [plain])]
    links = len(lost.node_tree.links)
    dg = bpy.context.evaluated_depsgraph_get()
    assert [n.name for n in shading.missing_images(lost)] == ["Image Texture"]
    s = reader.read_scene(dg, obs)
    a, b = s.objects
    np.testing.assert_allclose(a.corner_rho, b.corner_rho, atol=1e-6)
    # Cycles' diffuse albedo of the default Principled BSDF: 0.770 / 0.8 of Base Color
    np.testing.assert_allclose(a.corner_rho[0], 0.9626151 * np.array(base), rtol=1e-4)
    # a warning of the image (said once, whatever uses it), with the path to fix
    said = [n for n in a.notes if "cannot be read" in n]
    assert len(said) == 1 and said[0].warning and said[0].subject == "image 'gone.png'", a.notes
    assert "magenta" in said[0] and str(tmp_path / "gone.png") in said[0]
    assert len(lost.node_tree.links) == links
    assert sorted(m.name for m in bpy.data.materials) == ["Lost", "Plain"]
