# SPDX-License-Identifier: GPL-3.0-or-later
"""Hemi-cube radiosity: bake diffuse global illumination into colour attributes.

``core`` is pure NumPy (no bpy); ``blender`` holds the add-on (operators, panel, reader/writer,
glTF export, CLI command). Importing this package does not import bpy, so the core can be used
in plain Python; ``register()`` / ``unregister()`` are called by the extension's root
``__init__.py`` and hand over to :mod:`.blender`.
"""

from .version import __version__  # noqa: F401  (the package's version, read by the CLI and tests)


def register():
    from . import blender

    blender.register()


def unregister():
    from . import blender

    blender.unregister()
