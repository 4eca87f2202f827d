# SPDX-License-Identifier: GPL-3.0-or-later
"""Extension entry point: Blender loads this folder as ``bl_ext.<repo>.hemicube_radiosity``.

Thin on purpose; the add-on lives in the ``hemicube_radiosity`` package next to this file.
"""


def register():
    from .hemicube_radiosity import register as _register

    _register()


def unregister():
    from .hemicube_radiosity import unregister as _unregister

    _unregister()
