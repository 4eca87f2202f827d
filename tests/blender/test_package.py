"""The per-platform zip installs the way a user installs it and bakes with the embreex it bundles.

Two fresh processes share one temporary Blender user folder (BLENDER_USER_RESOURCES):
1. installs the linux-x64 zip (built here as ``make package`` does: ``blender_ext.py build
   --split-platforms``) with ``bpy.ops.extensions.package_install_files`` into the user
   repository; Blender extracts the bundled wheel into ``extensions/.local/lib/python3.11/
   site-packages``;
2. starts again (Blender puts that folder before Python's own site-packages at start-up, so the
   bundled embreex wins over the one in this venv; in the installing session it is appended
   after them), enables the extension, bakes the Cornell box with ``--method embree`` through the
   installed copy's CLI and reports where embreex and the add-on were imported from.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import zipfile

import pytest

from tests.support import ROOT
from tests.support.extension import blender_ext

pytestmark = pytest.mark.blender

INSTALL = textwrap.dedent("""
    import sys
    import bpy
    r = bpy.ops.extensions.package_install_files(filepath=sys.argv[1], repo="user_default",
                                                 enable_on_install=True)
    assert r == {"FINISHED"}, r
""")

BAKE = textwrap.dedent("""
    import importlib, json, os, sys
    import bpy
    import addon_utils
    module = "bl_ext.user_default.hemicube_radiosity"
    def fail(ex):
        raise ex
    addon_utils.enable(module, default_set=True, handle_error=fail)
    cli = importlib.import_module(module + ".hemicube_radiosity.blender.cli.main")
    rc = cli.main(["demo", "--output-dir", sys.argv[1], "--no-render", "--method", "embree",
                   "--patch-size", "0.5", "--resolution", "16", "--element-size", "0", "-q"])
    import embreex
    print(json.dumps({"rc": rc, "enabled": addon_utils.check(module)[1], "cli": cli.__file__, "embreex": embreex.__file__,
                      "site": os.path.join(bpy.utils.user_resource("EXTENSIONS", path=".local"), "lib",
                                           "python3.11", "site-packages"),
                      "repo": bpy.utils.user_resource("EXTENSIONS", path="user_default")}), flush=True)
    if bpy.app.version < (4, 5, 0):   # 4.2's bpy crashes at exit after a glTF export (docs/pipeline.md)
        os._exit(0)
""")


@pytest.fixture(scope="module")
def linux_zip(extension_wheels, tmp_path_factory):
    out = tmp_path_factory.mktemp("dist")
    p = blender_ext("build", "--source-dir", ".", "--output-dir", str(out), "--split-platforms")
    assert p.returncode == 0, p.stdout + p.stderr
    zips = sorted(f for f in os.listdir(out) if f.endswith(".zip"))
    assert zips == [f"hemicube_radiosity-{v}.zip" for v in
                    ("0.1.0-linux_x64", "0.1.0-macos_arm64", "0.1.0-macos_x64", "0.1.0-windows_x64")]
    for z in zips:   # each zip holds its own platform's wheel only
        wheels = [n for n in zipfile.ZipFile(out / z).namelist() if n.endswith(".whl")]
        tag = {"linux": "manylinux", "windows": "win_amd64", "macos_arm64": "arm64", "macos_x64": "macosx_13_0_x86_64"}
        key = next(k for k in tag if k in z)
        assert len(wheels) == 1 and tag[key] in wheels[0], (z, wheels)
    return str(out / zips[0])


def test_installed_zip_bakes_with_its_bundled_embreex(linux_zip, tmp_path):
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    env.pop("PYTHONPATH", None)   # nothing from the repository: only what the zip installed

    def py(code, *args):
        p = subprocess.run([sys.executable, "-c", code, *args], cwd=str(tmp_path), env=env,
                           capture_output=True, text=True, timeout=300)
        assert p.returncode == 0, p.stdout + p.stderr
        return p.stdout

    py(INSTALL, linux_zip)
    got = json.loads(py(BAKE, str(tmp_path / "out")).strip().splitlines()[-1])
    assert got["rc"] == 0 and got["enabled"]
    assert got["cli"].startswith(got["repo"] + os.sep), got      # the installed copy, not the source
    assert os.path.realpath(got["cli"]) != os.path.join(ROOT, "hemicube_radiosity", "blender", "cli.py")
    assert got["embreex"].startswith(got["site"] + os.sep), got  # the bundled wheel
    rep = json.loads((tmp_path / "out" / "cornell_report.json").read_text())
    assert rep["settings"]["method"] == "embree" and rep["form_factor_source"] == "computed"
    assert rep["patches"] > 50 and rep["residual"] < rep["settings"]["tolerance"]
