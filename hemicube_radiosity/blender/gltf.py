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
Options missing from an older exporter are skipped.
"""
from __future__ import annotations

import os

import bpy

from ..core.formats.gltf import tone_map_gltf

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


def _shows_bake(ob):
    """True when every material of ``ob`` is the bake material for its render colour attribute."""
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
    me.materials.clear()
    me.materials.append(baked_material(ca[ca.render_color_index].name))
    tmp = bpy.data.objects.new(ob.name + ".gltf", me)
    tmp.matrix_world = ob.matrix_world.copy()
    bpy.context.scene.collection.objects.link(tmp)
    return tmp


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
        for o, tmp, name in swaps:
            me = tmp.data
            bpy.data.objects.remove(tmp, do_unlink=True)
            bpy.data.meshes.remove(me)
            o.name = name
        for o in view_layer.objects:
            o.select_set(o in before)
        view_layer.objects.active = active
    tone_map_gltf(filepath, view_transform)
    return filepath
