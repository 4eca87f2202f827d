# SPDX-License-Identifier: GPL-3.0-or-later
"""Baked glTF export through Blender's own exporter, with the options that keep the bake.

* COLOR_0 comes from the active colour attribute (the bake sets its attribute active), as float
  VEC3, HDR values as written (not clamped). ``export_vertex_color='ACTIVE'`` is used because the
  default 'MATERIAL' mode writes COLOR_0 only when the material reads the attribute and
  ``export_all_vertex_colors`` (on by default) would add a white COLOR_0 for materials that don't.
* The baked-copy material (colour attribute wired into the output) exports as
  ``KHR_materials_unlit`` with a white base colour, so viewers show the baked lighting as is.
Options missing from an older exporter are skipped.
"""
from __future__ import annotations

import os

import bpy

__all__ = ["export_gltf", "EXPORT_OPTIONS"]

EXPORT_OPTIONS = dict(
    use_selection=True,
    export_apply=False,
    export_materials="EXPORT",
    export_vertex_color="ACTIVE",
    export_all_vertex_colors=False,
    export_active_vertex_color_when_no_material=True,
    export_texcoords=False,
    export_normals=True,
    export_yup=True,
    export_extras=False,
    export_animations=False,
    export_cameras=False,
    export_lights=False,
)


def export_gltf(filepath, objects, **overrides):
    """Write ``objects`` (and nothing else) to ``filepath`` (.glb binary, .gltf separate)."""
    filepath = os.path.abspath(os.fspath(filepath))
    fmt = "GLB" if filepath.lower().endswith(".glb") else "GLTF_SEPARATE"
    os.makedirs(os.path.dirname(filepath), exist_ok=True)
    names = set(bpy.ops.export_scene.gltf.get_rna_type().properties.keys())
    opts = {k: v for k, v in {**EXPORT_OPTIONS, **overrides}.items() if k in names}
    view_layer = bpy.context.view_layer
    before = [o for o in view_layer.objects if o.select_get()]
    active = view_layer.objects.active
    try:
        for o in before:
            o.select_set(False)
        for o in objects:
            o.select_set(True)
        bpy.ops.export_scene.gltf(filepath=filepath, export_format=fmt, **opts)
    finally:
        for o in view_layer.objects:
            o.select_set(o in before)
        view_layer.objects.active = active
    return filepath
