# SPDX-License-Identifier: GPL-3.0-or-later
"""The Blender add-on: reader, writer, operators, panel, glTF export and the CLI command.

Glue only; every numerical step is in :mod:`..core`. ``register()`` / ``unregister()`` are
symmetric: enable, disable and enable again leaves no classes, scene properties or CLI commands
behind.
"""
from __future__ import annotations

import bpy

from .ui import operators, panel, props

__all__ = ["register", "unregister", "cli_command"]

_classes = (*operators.classes, *panel.classes)
_cli_handle = None


def cli_command(argv):
    """``blender -b -c hemicube_radiosity bake ...``: returns the exit code, never exits."""
    from .cli.main import main

    return main(list(argv), in_blender=True)


def _menu_bake(self, context):
    self.layout.operator("object.radiosity_bake", icon="LIGHT_AREA")


def register():
    global _cli_handle
    props.register()
    for cls in _classes:
        bpy.utils.register_class(cls)
    bpy.types.VIEW3D_MT_object.append(_menu_bake)
    _cli_handle = bpy.utils.register_cli_command("hemicube_radiosity", cli_command)


def unregister():
    global _cli_handle
    if _cli_handle is not None:
        bpy.utils.unregister_cli_command(_cli_handle)
        _cli_handle = None
    bpy.types.VIEW3D_MT_object.remove(_menu_bake)
    for cls in reversed(_classes):
        bpy.utils.unregister_class(cls)
    props.unregister()
    from .bake import clear_session_cache

    clear_session_cache()  # cached form factors go with the add-on
