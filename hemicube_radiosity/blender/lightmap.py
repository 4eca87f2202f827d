# SPDX-License-Identifier: GPL-3.0-or-later
"""The lightmap target: the bake read into an image through a UV map of the baked copy.

For each baked object (``settings.target == 'lightmap'``, baked copies only):

* **The copy** is the user's evaluated mesh (:func:`.write.source_mesh_copy`: modifiers applied,
  topology, UV maps and attributes as they are), never the element mesh: the topology stays the
  artist's. The user's own mesh is never touched.
* **UVs**: the UV map named by ``lightmap_uv`` if the mesh has it; with no name, the mesh's second
  UV map. Otherwise one is made on the copy (named ``lightmap_uv``, or ``Lightmap``) by Blender's
  *Lightmap Pack* (``bpy.ops.uv.lightmap_pack``, a Python operator that runs headless under
  ``temp_override``: every face its own box, all packed in one square, a margin of two texels
  of the image size around each, but at most 1% of the square: the operator's limit, so below
  about 100 texels islands lie closer than 4 texels apart and filtering may blend neighbours).
  The copy's active UV map stays the user's.
* **Size**: ``lightmap_density`` x sqrt(the object's world-space area), clamped to
  ``lightmap_max_size`` (square; a power of two is not required). Packing wastes some of it,
  so the density reached on the surface is lower than asked.
* **Texels** (:mod:`..core.output.lightmap`): the bake's output read at every texel centre of
  the copy's triangles in that UV map (Blender's loop triangles, as Cycles and glTF interpolate
  UVs), from the same solution and output elements as the vertex colours: the direct light
  exact at the texel (the bake's :class:`..core.light.direct.DirectLight`, lit with the mesh's
  corner normals; averaged over the texel's square where it varies), the rest interpolated from
  the elements' corners; then dilated 8 texels. Values are radiance times ``2**exposure``.
* **Files** in ``lightmap_dir`` (empty: ``lightmaps/`` beside the saved .blend; unsaved: Blender's
  temporary folder, said in a note): ``<object>.lightmap.exr`` (RGBA 32-bit float, the HDR
  radiance) and ``<object>.lightmap.png`` (8-bit sRGB, Blender's Standard view: clamped to 0..1,
  sRGB-encoded). Both are loaded as images ``<object>.lightmap.exr`` / ``.png``. Beside them the
  lighting-only pass, ``<object>.lighting.exr`` / ``.png``: the light arriving times each slot's
  albedo scale (:func:`albedo_scale_of`), what an engine multiplies the base colour by (not
  written with the paper's direct light, which keeps no direct light apart: a note says so).
* **Material** ``Radiosity Lightmap (<object>)`` on every slot: a UV Map node (the lightmap UV
  map) -> Image Texture (the EXR) -> Material Output, so Cycles and EEVEE show it as emission
  and the viewport shows it. glTF export (:mod:`.gltf`) swaps the EXR for the PNG while it
  writes: an unlit material whose baseColorTexture is the PNG through the TEXCOORD_n of that UV
  map, and the lighting pass's PNG (:data:`LIGHTING_KEY`) as the light map its ``extras`` name.

A relight (the same cache) re-solves and rewrites both images: the form factors and the texels'
emitter transport (keyed on the same points: Lightmap Pack makes the same UVs again) come from
the cache. Not done: one atlas for the selection (one image per object). Objects that are not
meshes (text, curves) and objects whose evaluated mesh changed since it was read are left out
with a note.
"""
from __future__ import annotations

import contextlib
import io
import os
import tempfile
import time

import bpy
import numpy as np

from ..core.formats.gltf import LIGHTING_NOTE, srgb_encode
from ..core.output import lightmap as core_lightmap
from ..core.output import texel_cover
from . import textures, write
from .read.scene import mesh_corner_normals

__all__ = ["write_lightmaps", "LIGHTMAP_UV", "MATERIAL_KEY", "LIGHTING_KEY", "lightmap_folder",
           "albedo_scale_of"]

LIGHTMAP_UV = "Lightmap"
MATERIAL_KEY = "radiosity_lightmap_png"   # on a lightmap material: the PNG image glTF exports
LIGHTING_KEY = "radiosity_lighting_png"   # on a lightmap material: the lighting pass's PNG image
MARGIN_TEXELS = 2.0                       # Lightmap Pack's margin around each face, in texels


def lightmap_folder(settings):
    """(absolute folder, note or None): ``settings.lightmap_dir``, else ``lightmaps`` beside the
    saved .blend, else a folder in Blender's temporary directory (with a note saying so)."""
    if settings.lightmap_dir:
        return os.path.abspath(bpy.path.abspath(settings.lightmap_dir)), None
    if bpy.data.filepath:
        return os.path.join(os.path.dirname(bpy.data.filepath), "lightmaps"), None
    folder = os.path.join(bpy.app.tempdir or tempfile.gettempdir(), "lightmaps")
    return folder, (f"lightmaps were written to the temporary folder {folder}: save the .blend or "
                    "set a Lightmap Folder to keep them")


def _uv_layer(me, wanted):
    """(name, made): the UV map of copy mesh ``me`` the lightmap uses, or the name of one to make."""
    if wanted:
        return wanted, wanted not in me.uv_layers
    if len(me.uv_layers) >= 2:
        return me.uv_layers[1].name, False
    name = LIGHTMAP_UV
    while name in me.uv_layers:
        name += "_"
    return name, True


def _world_triangles(me, matrix):
    """(T, 3, 3) mesh ``me``'s loop triangles in world space (``matrix`` 4x4)."""
    me.calc_loop_triangles()
    tl = np.empty(len(me.loop_triangles) * 3, np.int64)
    me.loop_triangles.foreach_get("loops", tl)
    lv = np.empty(len(me.loops), np.int64)
    me.loops.foreach_get("vertex_index", lv)
    co = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", co)
    M = np.asarray(matrix, dtype=np.float64)
    world = co.reshape(-1, 3) @ M[:3, :3].T + M[:3, 3]
    return world[lv[tl]].reshape(-1, 3, 3)


def _triangle_faces(me):
    """(T,) int64 the face of each of mesh ``me``'s loop triangles (as :func:`_world_triangles`
    made them): the bake's ``source_face`` of the copy's own topology."""
    f = np.empty(len(me.loop_triangles), np.int64)
    me.loop_triangles.foreach_get("polygon_index", f)
    return f


def _corner_normals(me, matrix):
    """(T, 3, 3) the shading normals at the corners of mesh ``me``'s loop triangles (as
    :func:`_world_triangles` made them) in world space (``matrix`` 4x4), unit length: what
    Cycles shades with (smooth faces, custom normals; :mod:`.read.split_normals`)."""
    tl = np.empty(len(me.loop_triangles) * 3, np.int64)
    me.loop_triangles.foreach_get("loops", tl)
    N = np.linalg.inv(np.asarray(matrix, dtype=np.float64)[:3, :3]).T
    n = mesh_corner_normals(me)[tl] @ N.T
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    return n.reshape(-1, 3, 3)


def _triangle_uvs(me, uv_name):
    """(T, 3, 2) mesh ``me``'s loop triangles (as :func:`_world_triangles` made them) in UV map
    ``uv_name``."""
    tl = np.empty(len(me.loop_triangles) * 3, np.int64)
    me.loop_triangles.foreach_get("loops", tl)
    uv = np.empty(len(me.loops) * 2)
    me.uv_layers[uv_name].data.foreach_get("uv", uv)
    return uv.reshape(-1, 2)[tl].reshape(-1, 3, 2)


def _triangle_slots(me, slots):
    """(T,) int64 the material slot of each of mesh ``me``'s loop triangles, clipped to the
    ``slots`` there are."""
    slot = np.empty(len(me.loop_triangles), np.int64)
    me.loop_triangles.foreach_get("material_index", slot)
    return np.clip(slot, 0, max(int(slots) - 1, 0))


def albedo_scale_of(objects) -> dict:
    """{material name_full: k (3,)} for every material of ``objects`` (bpy objects): Cycles'
    diffuse albedo of the material with its colour input white (:func:`.textures.albedo_scales`,
    one Cycles evaluation for all), what the lighting pass is multiplied by so that a base colour
    times it is what the surface reflects; 1 for a material with no Principled or Diffuse BSDF
    colour to multiply (and for an empty slot)."""
    mats = {s.material.name_full: s.material for ob in objects for s in ob.material_slots if s.material}
    k = textures.albedo_scales([m for m in mats.values() if textures.colour_input(m) is not None])
    return {name: np.asarray(k.get(name, np.ones(3)), dtype=np.float64) for name in mats}


def _lighting_scale(ob, me, scales):
    """(T, 3) per loop triangle of the copy mesh ``me`` of object ``ob`` its slot's albedo scale."""
    slots = ob.material_slots
    k = np.array([scales.get(s.material.name_full, np.ones(3)) if s.material else np.ones(3)
                  for s in slots] or [np.ones(3)], dtype=np.float64)
    return k[_triangle_slots(me, len(k))]


def _triangle_area(world):
    return float(0.5 * np.linalg.norm(np.cross(world[:, 1] - world[:, 0], world[:, 2] - world[:, 0]),
                                      axis=1).sum())


def _pack(ob, uv_name, size):
    """Make UV map ``uv_name`` on copy ``ob`` with Lightmap Pack (one box per face, a margin of
    :data:`MARGIN_TEXELS` at ``size`` texels, at most 1% of the square: the operator's limit);
    the active UV map stays as it was."""
    me = ob.data
    before = me.uv_layers.active.name if me.uv_layers.active is not None else None
    layer = me.uv_layers.new(name=uv_name)
    me.uv_layers.active = layer
    margin = float(np.clip(100.0 * MARGIN_TEXELS / size, 0.001, 1.0))   # percent of the UV square
    with bpy.context.temp_override(active_object=ob, object=ob, selected_objects=[ob],
                                   selected_editable_objects=[ob], edit_object=None), \
            contextlib.redirect_stdout(io.StringIO()):              # its progress lines
        bpy.ops.uv.lightmap_pack(PREF_CONTEXT="ALL_FACES", PREF_PACK_IN_ONE=True,
                                 PREF_NEW_UVLAYER=False, PREF_MARGIN_DIV=margin)
    if before is not None:
        me.uv_layers.active = me.uv_layers[before]


def _save_image(name, path, pixels, file_format):
    """Write ``pixels`` (H, W, 3) to ``path`` (``file_format``: 'OPEN_EXR' float, or 'PNG' 8-bit
    of values already in 0..1) and load it back as image ``name`` (an older one of that name is
    replaced)."""
    old = bpy.data.images.get(name)
    if old is not None:
        bpy.data.images.remove(old)
    h, w = pixels.shape[:2]
    img = bpy.data.images.new(name + ".tmp", w, h, alpha=False, float_buffer=file_format == "OPEN_EXR")
    rgba = np.ones((h, w, 4), np.float32)
    rgba[..., :3] = pixels
    img.pixels.foreach_set(rgba.ravel())
    img.filepath_raw = path
    img.file_format = file_format
    if file_format == "OPEN_EXR":
        # radiance as it is: Blender 4.2 / 4.5 write a generated float image's EXR through the
        # sRGB curve unless its colours are data (7.0 came back as 2.318); 5.0 writes it as it
        # is, and zeros when told the colours are data (both measured)
        if bpy.app.version < (5, 0, 0):
            img.colorspace_settings.is_data = True
        if hasattr(img, "use_half_precision"):
            img.use_half_precision = False
    try:
        img.save()
    except RuntimeError as ex:
        raise write.WriteError(f"could not write the lightmap {path}: {ex}") from None
    finally:
        bpy.data.images.remove(img)
    loaded = bpy.data.images.load(path, check_existing=False)
    loaded.name = name
    return loaded


def _material(name, uv_name, exr, png, lighting_png=None):
    """A material showing image ``exr`` through UV map ``uv_name`` as emitted light (unlit);
    glTF exports ``png`` in its place (:data:`MATERIAL_KEY`) and ``lighting_png``, the lighting
    pass, as its light map (:data:`LIGHTING_KEY`, :func:`..core.formats.gltf.add_light_maps`)."""
    mat = bpy.data.materials.get(name)
    if mat is None:
        mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0) or mat.node_tree is None:
        mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    out.location = (300, 0)
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation, tex.extension = exr, "Linear", "EXTEND"
    tex.location = (0, 0)
    uv = nt.nodes.new("ShaderNodeUVMap")
    uv.uv_map = uv_name
    uv.location = (-250, 0)
    nt.links.new(uv.outputs["UV"], tex.inputs["Vector"])
    nt.links.new(tex.outputs["Color"], out.inputs["Surface"])
    nt.nodes.active = tex
    mat.diffuse_color = (1.0, 1.0, 1.0, 1.0)
    mat[MATERIAL_KEY] = png.name
    if lighting_png is not None:
        mat[LIGHTING_KEY] = lighting_png.name
    elif LIGHTING_KEY in mat:
        del mat[LIGHTING_KEY]
    return mat


def _texel_light(result, scale):
    """(parts, split, probed) for :func:`..core.output.lightmap.bake_lightmap`: the bake's
    corner parts and its exact direct light at any points, each source apart
    (:meth:`..core.light.direct.DirectLight.split_at`), both times ``scale`` (the exposure), and
    which sources a one-ray probe stands for (:meth:`..core.light.direct.DirectLight.probed`); (None,
    None, None) without the exact direct light (every texel then interpolated)."""
    parts = result.corner_parts()
    if parts is None or result.direct is None:
        return None, None, None
    E, rho, D, I = parts
    light = result.direct

    def split(points, normals, samples=None, which=None, facing=None, low=None, **shared):
        return light.split_at(points, normals, "texels", samples, which, facing, low, **shared) * scale
    return (E * scale, rho, D * scale, I * scale), split, light.probed()


def write_lightmaps(context, scene_input, result, settings):
    """Baked copies with lightmaps (see the module docstring). Returns (copies, records, notes):
    records one dict per lightmap (object, uv_map, made_uvs, size, exr, png, lighting_exr,
    lighting_png (None without the exact direct light), covered, filled, unset texels, passes:
    which file holds which pass, texel_seconds: the time its texels took,
    :func:`..core.output.lightmap.bake_lightmap`), notes plain lines."""
    baked = [s for s in scene_input.objects if s.bake]
    write.remove_bakes([s.name for s in baked])
    coll = write.copies_collection(context.scene)
    depsgraph = context.evaluated_depsgraph_get()
    folder, note = lightmap_folder(settings)
    notes = [note] if note else []
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as ex:
        raise write.WriteError(f"could not make the lightmap folder {folder}: {ex.strerror}") from None
    scale = 2.0 ** float(settings.exposure)
    light = (result.corner_values() * scale,) + _texel_light(result, scale)
    users = [bpy.data.objects.get(s.name) for s in baked]
    scales = albedo_scale_of([o for o in users if o is not None]) if light[1] is not None else None
    out, records = [], []
    for oi, src in enumerate(scene_input.objects):
        if not src.bake:
            continue
        me = write.source_mesh_copy(depsgraph, src)
        if me is None:
            notes.append(f"'{src.name}': no lightmap (not a mesh, or changed since it was read): "
                         "bake it with the vertex-colour target")
            continue
        if result.owners_of(oi).size > 1:
            notes.append(f"'{src.name}': its lightmap shows the front of its open faces only")
        if scales is None:
            notes.append(f"'{src.name}': no lighting-only lightmap: the paper's direct light "
                         "('hemicube') keeps no direct light apart; choose 'exact'")
        ob = write.place_copy(coll, src, me, "source")
        rec = _write_one(ob, me, src, oi, result, light, scales, settings, folder)
        if rec["unset"]:
            notes.append(f"'{src.name}': {rec['unset']} texels of its lightmap's islands hold no value")
        out.append(ob)
        records.append(rec)
    write.select_copies(context, out)
    return out, records, notes


def _write_one(ob, me, src, oi, result, light, scales, settings, folder):
    """Bake, write and show the lightmap of one copy ``ob`` (mesh ``me``) of ``src`` (owner
    ``oi``); ``light`` (corner values, parts, split, probed; :func:`_texel_light`); ``scales`` the
    materials' albedo scales (None: no lighting pass). Returns its record."""
    uv_name, make = _uv_layer(me, settings.lightmap_uv)
    M = np.asarray(src.matrix_world, dtype=np.float64)
    world = _world_triangles(me, M)
    size = core_lightmap.image_size(_triangle_area(world), settings.lightmap_density, settings.lightmap_max_size)
    if make:
        _pack(ob, uv_name, size)
    uv = _triangle_uvs(me, uv_name)
    user = bpy.data.objects.get(src.name)
    k = None if scales is None or user is None else _lighting_scale(user, me, scales)
    corners, parts, split, probed = light
    t = time.perf_counter()
    lm = core_lightmap.bake_lightmap(result.elements, corners, oi, uv, world, size,
                                     flip=bool(np.linalg.det(M[:3, :3]) < 0), parts=parts, split=split,
                                     normals=_corner_normals(me, M), lighting_scale=k, probed=probed,
                                     faces=_triangle_faces(me), workers=settings.workers,
                                     cover=None if parts is None else texel_cover.Cover.of(result, oi))
    texel_seconds = time.perf_counter() - t
    stem = bpy.path.clean_name(src.name)
    exr, png = _save_pass(src.name, folder, stem, "lightmap", lm.image)
    lit = (None, None) if lm.lighting is None else _save_pass(src.name, folder, stem, "lighting", lm.lighting)
    mat = _material(f"Radiosity Lightmap ({src.name})", uv_name, exr, png, lit[1])
    write.set_materials(me, [mat] * max(1, len(me.materials)))
    ob["radiosity_lightmap_uv"] = uv_name
    files = [None if i is None else bpy.path.abspath(i.filepath) for i in (exr, png) + lit]
    return {"object": src.name, "uv_map": uv_name, "made_uvs": bool(make), "size": list(lm.size),
            "exr": files[0], "png": files[1], "lighting_exr": files[2], "lighting_png": files[3],
            "passes": {"radiosity": "exr, png: what the surface shows (radiance x 2^exposure); the copy's "
                                    "material and glTF's unlit baseColorTexture",
                       "lighting": None if lit[0] is None else
                       "lighting_exr, lighting_png: " + LIGHTING_NOTE + "; glTF: the material's "
                       "extras.hemicube_radiosity.lightMap"},
            "covered": int(lm.covered.sum()), "filled": int(lm.filled.sum()), "unset": int(lm.unset),
            "texel_seconds": texel_seconds}


def _save_pass(name, folder, stem, kind, pixels):
    """(EXR image, PNG image) of one pass ``kind`` ('lightmap': the radiosity, 'lighting'):
    ``<stem>.<kind>.exr`` (32-bit float) and ``.png`` (Standard view: clamped, sRGB) in
    ``folder``, loaded as images ``<name>.<kind>.exr`` / ``.png``."""
    exr = _save_image(f"{name}.{kind}.exr", os.path.join(folder, f"{stem}.{kind}.exr"), pixels, "OPEN_EXR")
    png = _save_image(f"{name}.{kind}.png", os.path.join(folder, f"{stem}.{kind}.png"), srgb_encode(pixels), "PNG")
    return exr, png
