# SPDX-License-Identifier: GPL-3.0-or-later
"""Panels: Render properties (next to Cycles' Bake panel) and the 3D view sidebar.

Laid out as Cycles' Bake panel: the few settings an artist needs first at the top (the 'main'
group of the schema: automatic sizes, where the result goes, lights, other meshes) with the Bake
button, the rest in collapsed sub-panels, one per schema group. Both places are generated from
the same drawing functions and the same schema (``core/settings.py``); a new setting shows up in
its group's sub-panel without touching this file.
"""
from __future__ import annotations

import bpy

from ...core.settings import AUTO_SWITCH
from .props import panel_settings

__all__ = ["RENDER_PT_radiosity_bake", "VIEW3D_PT_radiosity_bake", "SUBPANELS", "classes"]

# (group, sub-panel label) in the order they are drawn
SUBPANELS = (("patches", "Patches"), ("form_factors", "Form Factors"), ("light", "Light"),
             ("solver", "Solver"), ("output", "Output"))

# settings that only mean something with another setting's value
_SHOWN = {
    "resolution": lambda s: s.method != "EMBREE_STOCHASTIC",
    "rays_per_patch": lambda s: s.method == "EMBREE_STOCHASTIC",
    "direct_samples": lambda s: s.direct == "EXACT",
}


def _settings(context):
    return context.scene.hemicube_radiosity


def _column(layout):
    layout.use_property_split = True
    layout.use_property_decorate = False
    return layout.column()


def draw_group(layout, s, group):
    """Every setting of schema group ``group``, in schema order."""
    col = _column(layout)
    for entry in panel_settings():
        if entry.group != group or not _SHOWN.get(entry.name, lambda _: True)(s):
            continue
        row = col.row()
        row.enabled = not (entry.meta.get("size") and getattr(s, AUTO_SWITCH))
        row.prop(s, entry.name)


def draw_main(layout, context):
    s = _settings(context)
    col = _column(layout)
    col.prop(s, AUTO_SWITCH)
    draw_group(layout, s, "main")
    row = layout.row(align=True)
    row.scale_y = 1.4
    row.operator("object.radiosity_bake", icon="LIGHT_AREA")
    layout.row(align=True).operator("object.radiosity_clear", icon="TRASH")


def _draw_main(self, context):
    draw_main(self.layout, context)


def _draw_sub(self, context):
    draw_group(self.layout, _settings(context), self.radiosity_group)


def _family(prefix, space, region, extra, main_options=()):
    """The main panel and its sub-panels (one per schema group) for one place in the UI."""
    base = dict(bl_space_type=space, bl_region_type=region, **extra)
    main_name = f"{prefix}_PT_radiosity_bake"
    main = type(main_name, (bpy.types.Panel,), dict(base, bl_label="Radiosity Bake", draw=_draw_main,
                                                    bl_options=set(main_options)))
    subs = tuple(type(f"{prefix}_PT_radiosity_{group}", (bpy.types.Panel,),
                      dict(base, bl_label=label, bl_parent_id=main_name, bl_options={"DEFAULT_CLOSED"},
                           radiosity_group=group, draw=_draw_sub))
                 for group, label in SUBPANELS)
    return (main,) + subs


_RENDER = _family("RENDER", "PROPERTIES", "WINDOW", {"bl_context": "render"}, {"DEFAULT_CLOSED"})
_VIEW3D = _family("VIEW3D", "VIEW_3D", "UI", {"bl_category": "Radiosity"})
RENDER_PT_radiosity_bake, VIEW3D_PT_radiosity_bake = _RENDER[0], _VIEW3D[0]

classes = _RENDER + _VIEW3D
