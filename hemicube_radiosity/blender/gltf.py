# SPDX-License-Identifier: GPL-3.0-or-later
"""Baked glTF export through Blender's own exporter, with the options that keep the bake.

* COLOR_0 comes from the active colour attribute (the bake sets its attribute active), as float
  VEC3. ``export_vertex_color='ACTIVE'`` is used because the default 'MATERIAL' mode writes
  COLOR_0 only when the material reads the attribute and ``export_all_vertex_colors`` (on by
  default) would add a white COLOR_0 for materials that don't.
* Blender writes the attribute's HDR values (a lamp's 12.0), which glTF forbids in COLOR_0. The
  written file is then rewritten by ``core/formats/gltf.py`` ``tone_map_gltf``: COLOR_0 becomes the
  values through the view transform (linear, 0..1; 'standard' = clamp, so a viewer shows what
  Blender's Standard view shows) and the HDR values stay as the custom attribute ``_RADIANCE``.
  The colour attribute in Blender is not changed. See docs/gltf.md.
* The baked-copy material (colour attribute wired into the output) exports as
  ``KHR_materials_unlit`` with a white base colour, so viewers show the baked lighting as is.
* Objects baked in place keep their own materials, which do not read the attribute: the exporter
  would then write COLOR_0 as clamped 16-bit RGBA, and a lit material would be multiplied by
  the baked light a second time. Such objects are exported through a temporary stand-in (a copy
  of the mesh with the bake material, under the object's name), removed again afterwards.
* UVs: ``export_texcoords`` is None ('auto') by default: TEXCOORD_n are written when an exported
  mesh has UV maps (a baked copy that keeps the user's topology keeps their UVs, so a pipeline can
  multiply a texture by the baked light at run time), and left out otherwise.
* Lightmapped copies (``blender/lightmap.py``): their material (UV Map -> Image Texture ->
  output) exports as ``KHR_materials_unlit`` with the image as baseColorTexture through the
  TEXCOORD_n of the lightmap's UV map. The material shows the HDR .exr in Blender; while the
  exporter runs, its image is the tone-mapped .png instead (glTF holds PNG or JPEG only), so the
  file carries exactly that PNG. Such a copy keeps the user's colour attributes; it is exported
  through a stand-in without them, as a COLOR_0 would multiply the lightmap. The lighting-only
  pass (its PNG) is added to the file after the exporter ran (``core/formats/gltf.py``
  ``add_light_maps``): one more image and texture, named in the material's
  ``extras.hemicube_radiosity.lightMap`` with the same TEXCOORD_n, for engines that multiply a
  light map by the surface's base colour at run time (docs/gltf.md: three.js).
Options missing from an older exporter are skipped.
"""
from __future__ import annotations

import os

import bpy

from ..core.formats.gltf import LIGHTING_NOTE, add_light_maps, tone_map_gltf

__all__ = ["export_gltf", "EXPORT_OPTIONS"]

EXPORT_OPTIONS = dict(
    use_selection=True,
    export_apply=False,
    export_materials="EXPORT",
    export_vertex_color="ACTIVE",
    export_all_vertex_colors=False,
    export_active_vertex_color_when_no_material=True,
    export_texcoords=None,     # auto: on when an exported mesh has UV maps
    export_normals=True,
    export_yup=True,
    export_extras=False,
    export_animations=False,
    export_cameras=False,
    export_lights=False,
)


LIGHTMAP_KEY = "radiosity_lightmap_png"    # blender/lightmap.py MATERIAL_KEY
LIGHTING_KEY = "radiosity_lighting_png"    # blender/lightmap.py LIGHTING_KEY


def _lightmapped(ob):
    """True when every material of ``ob`` is a lightmap material (``blender/lightmap.py``)."""
    mats = [s.material for s in ob.material_slots]
    return bool(mats) and all(m is not None and LIGHTMAP_KEY in m for m in mats)


def _shows_bake(ob):
    """True when every material of ``ob`` is the bake material for its render colour attribute,
    or a lightmap material on a mesh without colour attributes."""
    if _lightmapped(ob):
        return len(ob.data.color_attributes) == 0
    ca = ob.data.color_attributes
    if ca.render_color_index < 0:
        return True  # nothing baked here; exported as it is
    name = ca[ca.render_color_index].name
    mats = [s.material for s in ob.material_slots]
    return bool(mats) and all(m is not None and m.get("radiosity_attribute") == name for m in mats)


def _stand_in(ob):
    from .write import baked_material

    ca = ob.data.color_attributes
    me = ob.data.copy()
    if _lightmapped(ob):                      # the lightmap's material, no colour attribute
        for attr in list(me.color_attributes):
            me.color_attributes.remove(attr)
    else:
        me.materials.clear()
        me.materials.append(baked_material(ca[ca.render_color_index].name))
    tmp = bpy.data.objects.new(ob.name + ".gltf", me)
    tmp.matrix_world = ob.matrix_world.copy()
    bpy.context.scene.collection.objects.link(tmp)
    return tmp


def _png_for_exr(objects):
    """Set every lightmap material's image node of ``objects`` to its PNG; returns [(node, the
    image it had)] to put back."""
    swapped = []
    for o in objects:
        for slot in getattr(o, "material_slots", ()):
            m = slot.material
            png = bpy.data.images.get(m[LIGHTMAP_KEY]) if m is not None and LIGHTMAP_KEY in m else None
            if png is None:
                continue
            for node in m.node_tree.nodes:
                if node.type == "TEX_IMAGE" and node.image is not None and node.image != png:
                    swapped.append((node, node.image))
                    node.image = png
    return swapped


def _light_maps(objects) -> dict:
    """{material name: (the lighting pass's PNG file, what it holds)} of the lightmap materials
    of ``objects`` that carry a lighting pass."""
    out = {}
    for o in objects:
        for slot in getattr(o, "material_slots", ()):
            m = slot.material
            img = bpy.data.images.get(m[LIGHTING_KEY]) if m is not None and LIGHTING_KEY in m else None
            if img is not None:
                out[m.name] = (bpy.path.abspath(img.filepath), LIGHTING_NOTE)
    return out


def export_gltf(filepath, objects, view_transform="standard", **overrides):
    """Write ``objects`` (and nothing else) to ``filepath`` (.glb binary, .gltf separate), with
    COLOR_0 through ``view_transform`` (a choice of the ``view_transform`` setting) and the HDR
    bake as ``_RADIANCE``; ``overrides``: options of Blender's glTF exporter."""
    filepath = os.path.abspath(os.fspath(filepath))
    fmt = "GLB" if filepath.lower().endswith(".glb") else "GLTF_SEPARATE"
    os.makedirs(os.path.dirname(filepath), exist_ok=True)
    names = set(bpy.ops.export_scene.gltf.get_rna_type().properties.keys())
    opts = {**EXPORT_OPTIONS, **overrides}
    if opts.get("export_texcoords") is None:
        opts["export_texcoords"] = any(o.type == "MESH" and len(o.data.uv_layers) > 0 for o in objects)
    opts = {k: v for k, v in opts.items() if k in names}
    view_layer = bpy.context.view_layer
    before = [o for o in view_layer.objects if o.select_get()]
    active = view_layer.objects.active
    swaps = []   # (original, stand-in, original name)
    images = _png_for_exr(objects)   # [(image node, its own image)]: the lightmaps' PNG while exporting
    try:
        export = []
        for o in objects:
            if o.type == "MESH" and not _shows_bake(o):
                tmp = _stand_in(o)
                name = o.name
                o.name = name + ".exporting"
                tmp.name = name
                swaps.append((o, tmp, name))
                export.append(tmp)
            else:
                export.append(o)
        for o in before:
            o.select_set(False)
        for o in export:
            o.select_set(True)
        bpy.ops.export_scene.gltf(filepath=filepath, export_format=fmt, **opts)
    finally:
        for node, image in images:
            node.image = image
        for o, tmp, name in swaps:
            me = tmp.data
            bpy.data.objects.remove(tmp, do_unlink=True)
            bpy.data.meshes.remove(me)
            o.name = name
        for o in view_layer.objects:
            o.select_set(o in before)
        view_layer.objects.active = active
    tone_map_gltf(filepath, view_transform)
    maps = _light_maps(objects)
    if maps:
        add_light_maps(filepath, maps)
    return filepath
