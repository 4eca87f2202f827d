# SPDX-License-Identifier: GPL-3.0-or-later
"""Reflectance and emission as Cycles evaluates them (``blender/read/shading.py``).

Each case is a floor whose colour comes from nodes Cycles evaluates (an image texture through
UVs, a procedural texture through a Mix node, a colour attribute, an emission texture) or from a
Principled BSDF whose specular layer, metallic or transmission darken its diffuse lobe. It is lit
so that Cycles' bake has no noise (a uniform world over an open plane, a sun of angle 0), baked by
Cycles and by us, and compared at Cycles' own corners with the harness of
tests/support/cycles_scenes.py. Limit: 2% mean relative error (deterministic light).

The reader asks Cycles for the diffuse albedo (DIFFUSE pass, COLOR only) and the emission (EMIT)
at every corner of a temporary copy; the solve uses one colour per face (the mean of its corners),
the output each corner's own colour times the light there (``BakeResult.corner_values``): a tiled
floor whose every corner shows another tile (:func:`case_tiled_texture`) is exact at its corners,
in the result and in the baked copy. ``test_user_file_is_unchanged`` proves the copies leave nothing
behind. Run ``python -m tests.blender.test_cycles_textures`` for the errors per case, the errors the
reader made before (unlinked values, Base Color as the albedo) and the cost of the Cycles bakes.
"""
from __future__ import annotations

import hashlib
import time
import warnings

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tools import cycles_reference as cr  # noqa: E402
from hemicube_radiosity.blender.read import scene as reader  # noqa: E402
from hemicube_radiosity.blender.read import shading  # noqa: E402
from tests.support.fingerprint import hash_mesh  # noqa: E402
from tests.support.cycles_scenes import Comparison  # noqa: E402

pytestmark = [pytest.mark.blender, pytest.mark.cycles]

TOL = 0.02
SAMPLES = 4          # one light, nothing bouncing: every Cycles sample gives the exact value
HALF = 1.0           # floors are 2 x 2 m
WORLD = (0.9, 0.8, 0.7)


def material(name, shader="ShaderNodeBsdfPrincipled", **inputs):
    """(material, nodes, shader node): ``shader`` wired to the output, ``inputs`` set on it."""
    m = bpy.data.materials.new(name)
    nt, out = cr.bare_node_tree(m)
    s = nt.nodes.new(shader)
    for k, v in inputs.items():
        s.inputs[k].default_value = v
    nt.links.new(s.outputs[0], out.inputs["Surface"])
    return m, nt, s


def floor(n, mat, name="floor"):
    """An n x n grid over [-1, 1]^2 with a UV map u = (x + 1) / 2, v = (y + 1) / 2."""
    v, f = cr.grid_arrays(n, n, -HALF, HALF, -HALF, HALF)
    ob = cr.mesh_object(v, f, mat, name)
    me = ob.data
    lv = np.empty(len(me.loops), np.int64)
    me.loops.foreach_get("vertex_index", lv)
    uv = me.uv_layers.new(name="UVMap")
    uv.data.foreach_set("uv", ((v[lv, :2] + HALF) / (2 * HALF)).astype(np.float32).ravel())
    return ob


def lit_by_world(objects):
    cr.set_world(WORLD, 1.0)
    return Comparison(objects, samples=SAMPLES)


def pattern_image(size=32):
    """An 8-bit sRGB image (Cycles converts it to linear): red along u, green along v squared,
    blue a bump, so a flipped or shifted UV lookup shows."""
    img = bpy.data.images.new("pattern", size, size)
    y, x = (np.mgrid[0:size, 0:size] + 0.5) / size
    px = np.stack([0.15 + 0.8 * x, 0.1 + 0.85 * y ** 2, 0.3 + 0.5 * np.exp(-8 * ((x - 0.4) ** 2 + (y - 0.6) ** 2)),
                   np.ones_like(x)], -1)
    img.pixels.foreach_set(px.astype(np.float32).ravel())
    img.pack()
    return img


# ----------------------------------------------------------------------------- cases
def case_image_texture():
    """Base Color of Blender's default Principled BSDF from an image through UVs."""
    cr.new_empty_scene()
    m, nt, p = material("Floor")
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = pattern_image()
    tex.extension = "EXTEND"
    nt.links.new(tex.outputs["Color"], p.inputs["Base Color"])
    return lit_by_world([floor(32, m)])


def case_procedural():
    """A Noise texture mixing two colours (Mix node) into a Diffuse BSDF."""
    cr.new_empty_scene()
    m, nt, d = material("Noise", "ShaderNodeBsdfDiffuse")
    noise = nt.nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value = 1.5
    noise.inputs["Detail"].default_value = 0.0
    coords = nt.nodes.new("ShaderNodeTexCoord")        # (Generated is degenerate on a flat floor)
    nt.links.new(coords.outputs["Object"], noise.inputs["Vector"])
    mix = nt.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    rgba = {s.name: s for s in mix.inputs if s.type == "RGBA"}       # (A, B exist per data type)
    rgba["A"].default_value = (0.9, 0.6, 0.3, 1.0)
    rgba["B"].default_value = (0.05, 0.1, 0.3, 1.0)
    nt.links.new(noise.outputs["Fac"], mix.inputs["Factor"])
    nt.links.new(next(s for s in mix.outputs if s.type == "RGBA"), d.inputs["Color"])
    return lit_by_world([floor(32, m)])


def case_vertex_colours():
    """A colour attribute on the points read by a Color Attribute node, under a sun of angle 0."""
    cr.new_empty_scene()
    m, nt, d = material("Painted", "ShaderNodeBsdfDiffuse")
    vc = nt.nodes.new("ShaderNodeVertexColor")
    vc.layer_name = "paint"
    nt.links.new(vc.outputs["Color"], d.inputs["Color"])
    ob = floor(24, m)
    me = ob.data
    co = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", co)
    x, y = co.reshape(-1, 3)[:, 0], co.reshape(-1, 3)[:, 1]
    col = np.stack([0.5 + 0.4 * np.sin(1.5 * x), 0.5 + 0.3 * y, np.full_like(x, 0.2), np.ones_like(x)], 1)
    me.color_attributes.new("paint", "FLOAT_COLOR", "POINT").data.foreach_set("color", col.astype(np.float32).ravel())
    cr.add_light("SUN", (0, 0, 3), (0.3, 0.1, 0.0), energy=2.0, angle=0.0)
    return Comparison([ob], samples=SAMPLES)


def case_principled_parts():
    """Blender's default Principled BSDF (roughness 0.5, IOR 1.5), a metallic and a transmissive
    part, and a red Principled of roughness 1, IOR 1.45 with a coat, side by side (faces by x)."""
    cr.new_empty_scene()
    mats = [bpy.data.materials.new("Default")]            # Blender's own default node tree
    if mats[0].node_tree is None:
        mats[0].use_nodes = True                          # Blender < 5
    mats.append(material("Metal", Metallic=1.0)[0])
    mats.append(material("Glass", **{"Transmission Weight": 1.0})[0])
    mats.append(material("Coated", **{"Base Color": (0.8, 0.2, 0.1, 1.0), "Roughness": 1.0, "IOR": 1.45,
                                      "Coat Weight": 0.5})[0])
    ob = floor(16, None)
    for m in mats:
        ob.data.materials.append(m)
    cx = np.empty(len(ob.data.polygons) * 3)
    ob.data.polygons.foreach_get("center", cx)
    part = np.clip(((cx.reshape(-1, 3)[:, 0] + HALF) / (2 * HALF) * 4).astype(np.int32), 0, 3)
    ob.data.polygons.foreach_set("material_index", part)
    ob.data.update()
    return lit_by_world([ob])


def case_emission_texture():
    """An emissive floor (no light at all): Emission Color from a Gradient texture, strength 2
    times a colour attribute; Cycles' COMBINED bake is exactly the emission."""
    cr.new_empty_scene()
    m, nt, p = material("Glow", **{"Base Color": (0.0, 0.0, 0.0, 1.0), "Emission Strength": 2.0})
    grad = nt.nodes.new("ShaderNodeTexGradient")
    ramp = nt.nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.elements[0].color = (1.0, 0.3, 0.1, 1.0)
    ramp.color_ramp.elements[1].color = (0.2, 0.5, 1.0, 1.0)
    nt.links.new(grad.outputs["Fac"], ramp.inputs["Fac"])
    nt.links.new(ramp.outputs["Color"], p.inputs["Emission Color"])
    return Comparison([floor(24, m)], samples=1)


def framed_image(size=64, frame=3):
    """A float image, white but for a black frame ``frame`` pixels wide (a TV's screen)."""
    px = np.ones((size, size, 4), np.float32)
    px[:frame, :, :3] = px[-frame:, :, :3] = px[:, :frame, :3] = px[:, -frame:, :3] = 0.0
    img = bpy.data.images.new("screen", size, size, float_buffer=True)
    img.pixels.foreach_set(px.ravel())
    img.pack()
    return img, float(px[..., 0].mean())


def case_framed_emitter():
    """A TV: one quad 1 m over a floor, facing it, whose Emission Color is an image with a black
    frame (its four corners are black) at strength 5; nothing else lights the room."""
    cr.new_empty_scene()
    m, nt, p = material("Screen", **{"Base Color": (0.0, 0.0, 0.0, 1.0), "Emission Strength": 5.0})
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image, mean = framed_image()
    nt.links.new(tex.outputs["Color"], p.inputs["Emission Color"])
    v, f = cr.grid_arrays(1, 1, -0.5, 0.5, -0.5, 0.5, 1.0)
    tv = cr.mesh_object(v, f[:, ::-1], m, "tv")
    uv = tv.data.uv_layers.get("UVMap") or tv.data.uv_layers.new(name="UVMap")
    lv = np.empty(len(tv.data.loops), np.int64)
    tv.data.loops.foreach_get("vertex_index", lv)
    uv.data.foreach_set("uv", (v[lv, :2] + 0.5).astype(np.float32).ravel())
    fl = cr.mesh_object(*cr.grid_arrays(16, 16, -2.0, 2.0, -2.0, 2.0), cr.diffuse_material((0.8,) * 3), "floor")
    return Comparison([fl, tv], samples=1024), 5.0 * mean


def case_tiled_texture(n=4, tiles=6):
    """A coarse n x n floor under a Closest-filtered image of ``tiles`` x ``tiles`` colours, each
    face corner's UV on a tile of its own (seeded): the corners that meet at a vertex show
    different colours, as at a UV seam or where a tiled texture repeats across faces."""
    cr.new_empty_scene()
    rng = np.random.default_rng(7)
    img = bpy.data.images.new("tiles", tiles, tiles, float_buffer=True)
    px = np.concatenate([rng.uniform(0.05, 0.95, (tiles, tiles, 3)), np.ones((tiles, tiles, 1))], -1)
    img.pixels.foreach_set(px.astype(np.float32).ravel())
    img.pack()
    m, nt, p = material("Tiles")
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation = img, "Closest"
    nt.links.new(tex.outputs["Color"], p.inputs["Base Color"])
    ob = floor(n, m)
    uv = ob.data.uv_layers["UVMap"]
    cells = (rng.integers(0, tiles, (len(ob.data.loops), 2)) + 0.5) / tiles
    uv.data.foreach_set("uv", cells.astype(np.float32).ravel())
    return lit_by_world([ob])


CASES = {"image texture": case_image_texture, "tiled texture (a tile per corner)": case_tiled_texture, "procedural (noise, mix)": case_procedural,
         "vertex colours": case_vertex_colours, "Principled parts": case_principled_parts,
         "emission texture": case_emission_texture}


# ----------------------------------------------------------------------------- tests
def test_image_texture_through_uvs():
    c = case_image_texture()
    assert c.error() < TOL
    src = reader.read_object(bpy.data.objects["floor"], bpy.context.evaluated_depsgraph_get())
    assert any("'Floor'" in n and "image texture 'pattern'" in n and "by Cycles at each output corner" in n
               for n in src.notes), src.notes
    assert not any("unlinked" in n for n in src.notes), src.notes
    # per corner: Cycles' own albedo at the corner (the reference bake divided by the world)
    L = src.corner_rho.shape[0]
    assert src.corner_rho.shape == src.corner_emission.shape == (L, 3) == (src.mesh.face_indices.size, 3)
    ref = cr.bake_vertex_radiance([bpy.data.objects["floor"]], samples=1).corner["floor"]
    np.testing.assert_allclose(src.corner_rho * WORLD, ref[src.corner_loop], rtol=1e-4, atol=1e-6)
    # the faces carry the mean of their corners
    off = src.mesh.face_offsets
    np.testing.assert_allclose(src.mesh.face_rho[5], src.corner_rho[off[5]:off[6]].mean(axis=0))


def test_each_corner_shows_its_own_tile():
    """Per corner, not per vertex: the corners that meet at a vertex keep their own tiles in the
    result and in the baked copy, as Cycles bakes them (a vertex's mean would be far off)."""
    from hemicube_radiosity.blender.write import write_copies

    c = case_tiled_texture()
    assert c.error() < 0.005
    P, res = c.result.patches, c.result
    mine = np.flatnonzero(P.owner == 0)
    by_vertex = res.vertex_radiosity[P.polys[mine]].reshape(-1, 3)       # the mean of a vertex's corners
    assert float(np.mean(np.abs(by_vertex.mean(1) - c.cycles.mean(1)) / c.cycles.mean(1))) > 0.1
    ob = bpy.data.objects["floor"]
    s = reader.read_scene(bpy.context.evaluated_depsgraph_get(), [ob])
    copy, = write_copies(bpy.context, s, res)
    assert copy["radiosity_mesh"] == "source"                               # the user's own topology
    rgba = np.empty(len(copy.data.loops) * 4, np.float32)
    copy.data.color_attributes["Radiosity"].data.foreach_get("color", rgba)
    written = rgba.reshape(-1, 4)[c.loop, :3]
    np.testing.assert_allclose(written, c.cycles, rtol=0.01, atol=1e-4)


def test_procedural_texture_and_mix():
    c = case_procedural()
    assert c.error() < TOL
    lum = c.cycles.mean(axis=1)
    assert lum.max() > 1.5 * lum.min()              # the noise really varies over the floor
    assert np.all(np.abs(c.ours - c.cycles) < 0.05 * c.cycles + 1e-3)   # each band, each corner


def test_vertex_colours():
    c = case_vertex_colours()
    assert c.error() < TOL


def test_principled_specular_layer_metallic_and_transmission():
    c = case_principled_parts()
    me = bpy.data.objects["floor"].data
    loop_face = np.repeat(np.arange(len(me.polygons)), 4)
    mi = np.empty(len(me.polygons), np.int64)
    me.polygons.foreach_get("material_index", mi)
    part = mi[loop_face[c.loop]]                 # the material of each compared corner's face
    default, metal, glass, coated = (part == k for k in range(4))
    # default Principled: 0.770 of Base Color 0.8 in Cycles' diffuse pass (3.7% below)
    np.testing.assert_allclose(c.cycles[default].mean(axis=0), 0.7700921 * np.array(WORLD), rtol=1e-4)
    assert c.error(default) < 0.01
    assert c.error(coated) < TOL
    # metallic and transmissive parts reflect no diffuse light, in Cycles and here
    for p in (metal, glass):
        assert np.all(np.abs(c.cycles[p]) < 1e-6) and np.all(np.abs(c.ours[p]) < 1e-6)
    src = reader.read_object(bpy.data.objects["floor"], bpy.context.evaluated_depsgraph_get())
    # Blender's default Principled BSDF keeps 96% of its colour: nothing to say; glass passes no
    # shadow ray (as in Cycles with refractive caustics off, as here: nothing to say either);
    # metal mirrors its light (core/form_factors/glossy.py), its roughness not read: one note
    assert not any("'Default'" in n for n in src.notes), src.notes
    assert not any("leaves out" in n for n in src.notes), src.notes
    spread = [n for n in src.notes if "sharp mirror" in n]
    assert {n.subject for n in spread} == {"material 'Metal'"}, src.notes
    assert not any("ignored" in n for n in src.notes), src.notes


def test_emission_from_nodes():
    c = case_emission_texture()
    assert c.cycles.max() > 1.5 and c.error() < TOL
    src = reader.read_object(bpy.data.objects["floor"], bpy.context.evaluated_depsgraph_get())
    assert np.all(src.corner_rho == 0)
    assert np.ptp(src.corner_emission[:, 0]) > 1.0


def test_framed_emitter_emits_its_mean_over_the_face():
    """Emission is integrated over the face, not read at its corners (which are black here: the
    floor was black, the report said emitted 0). Cycles lights the floor from the image's texels;
    we take the face's mean (the image's mean: 0.821 of white) as its one emitted radiance."""
    c, mean = case_framed_emitter()
    tv = c.meshes[1]
    np.testing.assert_allclose(tv.face_emission, mean, rtol=1e-4)
    assert np.all(tv.corner_emission == 0)             # the corners show the frame they lie on
    floor = c.owner == 0
    assert c.cycles[floor].mean() > 0.1
    assert c.error(floor) < 0.025      # measured 1.7% (2.6% at 64 spp: Cycles noise; the rest the
    #                                    uniform stand-in for the framed image, 1 m away)
    assert not [m for m in bpy.data.meshes if m.name.startswith("_hr")]   # no sample copy left
    # two screens of one material are baked joined: each face still gets its own mean
    tv = bpy.data.objects["tv"]
    half = cr.mesh_object(*cr.grid_arrays(2, 1, 0.0, 1.0, 0.0, 0.5, 1.0), tv.data.materials[0], "half")
    uv = half.data.uv_layers.get("UVMap") or half.data.uv_layers.new(name="UVMap")
    uv.data.foreach_set("uv", np.tile([[0, 0], [1, 0], [1, 1], [0, 1]], (2, 1)).astype(np.float32).ravel() * 0.5)
    dg = bpy.context.evaluated_depsgraph_get()
    s = reader.read_scene(dg, [tv, half])
    np.testing.assert_allclose(s.objects[0].mesh.face_emission, mean, rtol=1e-4)
    # half's faces cover u, v in [0, 0.5]: the frame's corner quarter (a 32 x 32 block, 3 black rows
    # and columns on two sides); two samples a texel, so Cycles' linear filter blends a little
    np.testing.assert_allclose(s.objects[1].mesh.face_emission, 5.0 * (29 / 32) ** 2, rtol=1e-3)


def _fingerprint():
    """Every mesh's vertices, faces and attributes, every material's nodes, the datablocks and
    the scene's state, as one hash."""
    h = hashlib.sha256()
    for me in sorted(bpy.data.meshes, key=lambda m: m.name):
        hash_mesh(h, me)
        for at in sorted(me.attributes, key=lambda a: a.name):
            h.update(f"{at.name} {at.domain} {at.data_type}".encode())
            key = "color" if at.data_type in ("FLOAT_COLOR", "BYTE_COLOR") else (
                "vector" if at.data_type in ("FLOAT_VECTOR", "FLOAT2") else "value")
            try:
                n = {"FLOAT_COLOR": 4, "BYTE_COLOR": 4, "FLOAT_VECTOR": 3, "FLOAT2": 2}.get(at.data_type, 1)
                a = np.empty(len(at.data) * n, np.float64)
                at.data.foreach_get(key, a)
                h.update(a.tobytes())
            except (AttributeError, TypeError, RuntimeError):
                pass
        h.update(repr([m.name if m else None for m in me.materials]).encode())
        h.update(repr((me.color_attributes.active_color_name, me.color_attributes.default_color_name,
                       me.uv_layers.active.name if me.uv_layers.active else None)).encode())
    for m in sorted(bpy.data.materials, key=lambda m: m.name):
        h.update(repr(cr._tree(m.node_tree)).encode())
    for coll in ("objects", "meshes", "materials", "scenes", "images", "worlds", "node_groups"):
        h.update(repr(sorted(x.name for x in getattr(bpy.data, coll))).encode())
    sc, vl = bpy.context.scene, bpy.context.view_layer
    h.update(repr((sc.name, sc.render.engine, sorted(o.name for o in sc.objects if o.select_get()),
                   vl.objects.active.name if vl.objects.active else None)).encode())
    return h.hexdigest()


def test_user_file_is_unchanged():
    cr.new_empty_scene()
    m, nt, p = material("Floor")
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = pattern_image(8)
    nt.links.new(tex.outputs["Color"], p.inputs["Base Color"])
    ob = floor(6, m)
    ob.data.color_attributes.new("Col", "BYTE_COLOR", "CORNER")
    ob.modifiers.new("sub", "SUBSURF").levels = 1
    plain = floor(2, material("Plain")[0], "plain")
    ob.select_set(True)
    bpy.context.view_layer.objects.active = plain
    before = _fingerprint()
    dg = bpy.context.evaluated_depsgraph_get()
    s = reader.read_scene(dg, [ob], [plain])
    assert _fingerprint() == before
    # the modified mesh was evaluated: one corner per evaluated loop, all from Cycles
    assert s.objects[0].corner_rho.shape[0] == s.objects[0].eval_counts[1] == 4 * 4 * 36
    assert np.ptp(s.objects[0].corner_rho[:, 0]) > 0.3


def test_plain_materials_need_no_cycles():
    cr.new_empty_scene()
    d = cr.diffuse_material((0.3, 0.4, 0.5), emission=2.0)
    assert shading.classify(d)[0] == "plain"
    assert shading.classify(material("P")[0])[0] == "constant"
    m, nt, p = material("N")
    bump = nt.nodes.new("ShaderNodeBump")                     # a normal map changes no colour
    nt.links.new(bump.outputs[0], p.inputs["Normal"])
    assert shading.classify(m)[0] == "constant"
    nt.links.new(nt.nodes.new("ShaderNodeTexChecker").outputs[0], p.inputs["Roughness"])
    kind, notes = shading.classify(m)
    assert kind == "corners" and any("'Roughness' from a Checker Texture" in n for n in notes), notes
    ob = floor(2, d)
    s = shading.shade([ob], bpy.context.evaluated_depsgraph_get())
    assert not s.corners and not s.materials and s.seconds == 0.0
    # a constant from an RGB node: one Cycles value for the material, not per corner
    m, nt, g = material("G", "ShaderNodeBsdfGlossy")
    rgb = nt.nodes.new("ShaderNodeRGB")
    nt.links.new(rgb.outputs[0], g.inputs["Color"])
    kind, notes = shading.classify(m)
    assert kind == "constant" and any("Glossy BSDF" in n and "diffuse pass" in n for n in notes), notes


def test_cycles_failure_falls_back_with_a_note(monkeypatch):
    """Without a Cycles bake (an add-on build without Cycles, a refused bake) the reader keeps
    its own values and says so, naming the material."""
    cr.new_empty_scene()
    m, nt, p = material("Floor", **{"Base Color": (0.6, 0.5, 0.4, 1.0)})
    nt.links.new(nt.nodes.new("ShaderNodeTexChecker").outputs[0], p.inputs["Base Color"])
    ob = floor(2, m)

    def refuse(*a, **k):
        raise RuntimeError("Cycles is not available\nmore")

    monkeypatch.setattr(shading, "evaluate", refuse)
    src = reader.read_object(ob, bpy.context.evaluated_depsgraph_get())
    np.testing.assert_allclose(src.corner_rho, np.tile([0.6, 0.5, 0.4], (16, 1)))
    assert any("'Floor'" in n and "Cycles could not evaluate" in n and "not available" in n
               for n in src.notes), src.notes


if __name__ == "__main__":
    warnings.simplefilter("ignore")
    real = shading.shade

    def line(name, c, old, mask=None):
        n = len(c.pos) if mask is None else int(mask.sum())
        print(f"{name:>24}: mean rel err {100 * c.error(mask):6.3f}% over {n} corners "
              f"(before: {100 * old.error(mask):6.2f}%)")

    for name, make in CASES.items():
        c = make()
        shading.shade = lambda objects, dg: shading.Shaded()      # the reader before Cycles' shading was baked
        try:
            old = Comparison(c.objects, samples=SAMPLES)
        finally:
            shading.shade = real
        if name != "Principled parts":
            line(name, c, old)
            continue
        me = bpy.data.objects["floor"].data
        mi = np.empty(len(me.polygons), np.int64)
        me.polygons.foreach_get("material_index", mi)
        part = mi[np.repeat(np.arange(len(me.polygons)), 4)[c.loop]]
        line("default Principled", c, old, part == 0)
        line("red, rough 1, coat 0.5", c, old, part == 3)
        for k, what in ((1, "metallic 1"), (2, "transmission 1")):
            print(f"{what:>24}: Cycles {np.abs(c.cycles[part == k]).max():.2g}, ours "
                  f"{np.abs(c.ours[part == k]).max():.2g} (before: {old.ours[part == k].mean():.3f})")
    cr.new_empty_scene()
    m, nt, p = material("Floor")
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = pattern_image()
    nt.links.new(tex.outputs["Color"], p.inputs["Base Color"])
    for n in (50, 158, 500):
        ob = floor(n, m, f"floor{n}")
        dg = bpy.context.evaluated_depsgraph_get()
        t = time.perf_counter()
        s = shading.shade([ob], dg)
        total = time.perf_counter() - t
        L = 4 * n * n
        print(f"{L:>8} corners: Cycles bakes {s.seconds:.3f} s, with the copies {total:.3f} s "
              f"({1e4 * total / L * 1000:.1f} ms per 10k corners)")
