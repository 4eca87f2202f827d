"""The extension as Blender packages it: the wheels ``blender_manifest.toml`` lists, and Blender's
own ``blender_ext.py`` (validate, build) found inside the installed bpy module."""
from __future__ import annotations

import os
import subprocess
import sys
import tomllib

from . import ROOT


def manifest_wheels():
    """Absolute paths of the wheels the manifest lists (present or not)."""
    with open(os.path.join(ROOT, "blender_manifest.toml"), "rb") as f:
        return [os.path.join(ROOT, w) for w in tomllib.load(f).get("wheels", [])]


def bpy_scripts():
    """The ``scripts`` folder of the bpy module's Blender version."""
    import importlib.util

    spec = importlib.util.find_spec("bpy")
    base = os.path.dirname(spec.origin)
    version = next(d for d in os.listdir(base) if d[:1].isdigit() and os.path.isdir(os.path.join(base, d, "scripts")))
    return os.path.join(base, version, "scripts")


def blender_ext(*args):
    """Run Blender's ``blender_ext.py`` with ``args`` from the repository root."""
    tool = os.path.join(bpy_scripts(), "addons_core", "bl_pkg", "cli", "blender_ext.py")
    return subprocess.run([sys.executable, tool, *args], cwd=ROOT, capture_output=True, text=True, timeout=120)
