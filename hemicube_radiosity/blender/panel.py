# SPDX-License-Identifier: GPL-3.0-or-later
"""Panels: Render properties (next to Cycles' Bake panel) and the 3D view sidebar."""
from __future__ import annotations

import bpy

__all__ = ["RENDER_PT_radiosity_bake", "VIEW3D_PT_radiosity_bake", "classes"]


def draw_settings(layout, context):
    s = context.scene.hemicube_radiosity
    layout.use_property_split = True
    layout.use_property_decorate = False
    col = layout.column()
    col.prop(s, "auto_size")
    sizes = col.column()
    sizes.enabled = not s.auto_size
    sizes.prop(s, "patch_size")
    sizes.prop(s, "element_size")
    col.prop(s, "method")
    if s.method == "EMBREE_STOCHASTIC":
        col.prop(s, "rays_per_patch")
    else:
        col.prop(s, "resolution")
    col.prop(s, "gather_rays")
    col.prop(s, "direct")
    if s.direct == "EXACT":
        col.prop(s, "direct_samples")
    col.separator()
    col.prop(s, "solver")
    col.prop(s, "tolerance")
    col.prop(s, "max_iterations")
    col.separator()
    col.prop(s, "output_mode")
    col.prop(s, "attribute_name")
    col.prop(s, "exposure")
    col.prop(s, "use_lights")
    col.prop(s, "include_others")
    col.prop(s, "cache_dir")
    layout.separator()
    row = layout.row(align=True)
    row.scale_y = 1.4
    row.operator("object.radiosity_bake", icon="LIGHT_AREA")
    row = layout.row(align=True)
    row.operator("object.radiosity_clear", icon="TRASH")


class RENDER_PT_radiosity_bake(bpy.types.Panel):
    bl_label = "Radiosity Bake"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        draw_settings(self.layout, context)


class VIEW3D_PT_radiosity_bake(bpy.types.Panel):
    bl_label = "Radiosity Bake"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Radiosity"

    def draw(self, context):
        draw_settings(self.layout, context)


classes = (RENDER_PT_radiosity_bake, VIEW3D_PT_radiosity_bake)
