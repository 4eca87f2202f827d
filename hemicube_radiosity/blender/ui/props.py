# SPDX-License-Identifier: GPL-3.0-or-later
"""Bake settings as Blender properties, generated from the core schema (``core/settings.py``).

This module owns every Blender property and enum item of the add-on, as Cycles' ``properties.py``
does; nothing here restates a default, a limit or a help text: each comes from the core's
:class:`BakeSettings` field. The scene's property group (the panel) and the bake operator get the
same definitions. Settings without a panel group (e.g. the rotation seed) are CLI-only.
"""
from __future__ import annotations

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

from ...core.settings import AUTO_SWITCH, BakeSettings, schema

__all__ = ["setting_annotations", "SETTING_NAMES", "enum_items", "panel_settings", "to_settings",
           "RadiositySettings", "register", "unregister"]

_AUTO_LABEL = "Automatic Sizes"
_AUTO_HELP = ("Patch size = the scene's diagonal / 14 and detail size = a third of it (the "
              "benchmark's best trade-off at any scale; an object far larger than the rest, such "
              "as a ground plane, gets a size of its own); off: use the sizes below")
_LIMITS = ("min", "max", "soft_min", "soft_max", "step", "precision", "unit", "subtype", "maxlen")


def panel_settings():
    """The schema entries the panel and the operator show (those with a panel group)."""
    return tuple(s for s in schema() if s.group is not None)


def enum_items(setting):
    """Blender enum items for a setting with choices: identifiers are the values in upper case."""
    return tuple((value.upper(), label, help) for value, label, help in setting.choices)


def _property(s):
    kw = dict(name=s.label, description=s.help)
    kw.update({k: s.meta[k] for k in _LIMITS if k in s.meta})
    if s.choices is not None:
        return EnumProperty(items=enum_items(s), default=s.default.upper(), **kw)
    if s.meta.get("size"):
        return FloatProperty(default=s.meta["manual"], **kw)
    make = {bool: BoolProperty, int: IntProperty, float: FloatProperty, str: StringProperty}[s.type]
    return make(default=s.default, **kw)


def setting_annotations():
    """Fresh property definitions (Blender needs one set per class)."""
    out = {}
    for s in panel_settings():
        if s.meta.get("size") and AUTO_SWITCH not in out:
            out[AUTO_SWITCH] = BoolProperty(name=_AUTO_LABEL, description=_AUTO_HELP,
                                            default=s.default == "auto")
        out[s.name] = _property(s)
    return out


SETTING_NAMES = tuple(setting_annotations())


def _typed(value):
    """Blender keeps floats in single precision: 1e-4 reads back as 9.9999997e-05. The shortest
    decimal that rounds to the same float32 is what the artist typed, and what the CLI gets."""
    return float(str(np.float32(value))) if isinstance(value, float) else value


def to_settings(props) -> BakeSettings:
    """Core settings from the property group or the operator (same property names)."""
    s = BakeSettings.from_mapping({name: _typed(getattr(props, name)) for name in SETTING_NAMES})
    if s.cache_dir:
        s.cache_dir = bpy.path.abspath(s.cache_dir)
    return s


class RadiositySettings(bpy.types.PropertyGroup):
    __annotations__ = setting_annotations()


def register():
    bpy.utils.register_class(RadiositySettings)
    bpy.types.Scene.hemicube_radiosity = PointerProperty(type=RadiositySettings)


def unregister():
    del bpy.types.Scene.hemicube_radiosity
    bpy.utils.unregister_class(RadiositySettings)
