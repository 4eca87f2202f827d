"""The extension manifest passes Blender's own validator; the built zip holds the add-on and its
wheels only; the manifest's minimum Blender, wheels and platforms agree with what is tested."""
from __future__ import annotations

import glob
import os
import re
import tomllib
import zipfile

import pytest

from tests.support import ROOT
from tests.support.extension import blender_ext, bpy_scripts, manifest_wheels

pytestmark = pytest.mark.blender


def test_manifest_fields():
    with open(os.path.join(ROOT, "blender_manifest.toml"), "rb") as f:
        m = tomllib.load(f)
    assert m["schema_version"] == "1.0.0" and m["id"] == "hemicube_radiosity" and m["type"] == "add-on"
    assert m["blender_version_min"] == "4.2.0"
    assert m["license"] == ["SPDX:GPL-3.0-or-later"]
    major, minor, patch = (int(x) for x in m["version"].split("."))
    import hemicube_radiosity

    assert hemicube_radiosity.__version__ == m["version"]
    assert set(m["tags"]) <= {"Lighting", "Render", "Bake"} and m["tags"]


def test_minimum_blender_is_the_oldest_tested_and_wheels_follow_the_pins():
    with open(os.path.join(ROOT, "blender_manifest.toml"), "rb") as f:
        m = tomllib.load(f)
    tested = []
    for req in glob.glob(os.path.join(ROOT, "requirements-*.txt")):
        found = re.search(r"^bpy==(\d+)\.(\d+)\.", open(req).read(), re.M)
        if found:
            tested.append((int(found[1]), int(found[2])))
    assert min(tested) == tuple(int(x) for x in m["blender_version_min"].split(".")[:2]), tested
    assert sorted(m["platforms"]) == ["linux-x64", "macos-arm64", "macos-x64", "windows-x64"]
    pin = re.search(r"^embreex==(\S+)", open(os.path.join(ROOT, "requirements-dev.txt")).read(), re.M)[1]
    assert len(m["wheels"]) == 4 and all(os.path.basename(w).startswith(f"embreex-{pin}-cp311-") for w in m["wheels"])


def test_blender_validator_accepts_manifest():
    tags = os.path.join(bpy_scripts(), "modules", "_bpy_internal", "extensions", "tags.py")
    p = blender_ext("validate", "--valid-tags", tags, ".")
    assert p.returncode == 0, p.stdout + p.stderr
    assert "Success" in p.stdout


def test_build_zip_contains_the_addon_only(tmp_path, extension_wheels):
    p = blender_ext("build", "--source-dir", ".", "--output-dir", str(tmp_path))
    assert p.returncode == 0, p.stdout + p.stderr
    (zpath,) = [os.path.join(tmp_path, f) for f in os.listdir(tmp_path) if f.endswith(".zip")]
    names = zipfile.ZipFile(zpath).namelist()
    allowed_top = {"blender_manifest.toml", "__init__.py", "LICENSE",
                   *(os.path.relpath(w, ROOT) for w in manifest_wheels())}
    stray = [n for n in names if n not in allowed_top and not n.startswith("hemicube_radiosity/")]
    assert stray == [], stray
    assert not any("__pycache__" in n or n.endswith(".pyc") for n in names)
    for needed in ("blender_manifest.toml", "__init__.py", "hemicube_radiosity/__init__.py",
                   "hemicube_radiosity/blender/ui/operators.py", "hemicube_radiosity/core/pipeline.py",
                   "hemicube_radiosity/blender/cli/main.py"):
        assert needed in names, needed
