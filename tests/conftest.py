"""Shared fixtures (the helpers they use live in ``tests/support/``).

Blender reads its user configuration when bpy is first imported, so BLENDER_USER_RESOURCES is
pointed at a fresh temp dir here, at conftest import, before any test module can import bpy:
tests never see (or write) the developer's own preferences and extensions.

* ``bpy_module``: the bpy module (session).
* ``addon``: the extension installed the way Blender does it (``support.addon``), enabled with
  errors raised. Returns the add-on's package module
  (``bl_ext.<repo>.hemicube_radiosity.hemicube_radiosity``).
* ``empty_scene``: ``bpy.ops.wm.read_homefile(use_empty=True)`` before the test; returns bpy.
* ``extension_wheels``: the embreex wheels ``blender_manifest.toml`` lists, downloaded into
  ``wheels/`` by ``make wheels`` when missing (session); returns their paths.

Blender 4.2's bpy module crashes at interpreter exit once the glTF exporter has run (the same
workaround as ``python -m hemicube_radiosity``): :func:`pytest_unconfigure` leaves with pytest's
own exit status there, after everything is printed.
"""
from __future__ import annotations

import importlib
import os
import subprocess
import sys
import tempfile

import pytest

from tests.support import ROOT
from tests.support.addon import ADDON_MODULE, enable_addon, install_extension_repo
from tests.support.extension import manifest_wheels

os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp(prefix="hr_blender_user_")


@pytest.fixture(scope="session")
def bpy_module():
    import bpy

    return bpy


@pytest.fixture(scope="session")
def addon(bpy_module):
    install_extension_repo(bpy_module)
    enable_addon()
    yield importlib.import_module(ADDON_MODULE + ".hemicube_radiosity")


@pytest.fixture
def empty_scene(bpy_module):
    bpy_module.ops.wm.read_homefile(use_empty=True)
    return bpy_module


@pytest.fixture(scope="session")
def extension_wheels():
    wheels = manifest_wheels()
    if not all(os.path.isfile(w) for w in wheels):
        p = subprocess.run(["make", "-s", "wheels", f"WHEEL_PY={sys.executable}"], cwd=ROOT,
                           capture_output=True, text=True, timeout=600)
        assert p.returncode == 0, "make wheels failed:\n" + p.stdout + p.stderr
    return wheels


_exit_status = None


def pytest_sessionfinish(session, exitstatus):
    global _exit_status
    _exit_status = int(exitstatus)


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    bpy = sys.modules.get("bpy")
    if _exit_status is None or bpy is None or "io_scene_gltf2" not in sys.modules:
        return
    if bpy.app.version < (4, 5, 0):
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(_exit_status)
