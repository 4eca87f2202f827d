"""Shared fixtures.

Blender reads its user configuration when bpy is first imported, so BLENDER_USER_RESOURCES is
pointed at a fresh temp dir here, at conftest import, before any test module can import bpy:
tests never see (or write) the developer's own preferences and extensions.

* ``bpy_module``: the bpy module (session).
* ``addon``: the extension installed the way Blender does it: a local extension repository
  whose directory holds a ``hemicube_radiosity`` link to the repository root (the extension's
  source folder), enabled with ``addon_utils.enable(..., handle_error=<raise>)``. Returns the
  add-on's package module (``bl_ext.<repo>.hemicube_radiosity.hemicube_radiosity``).
* ``empty_scene``: ``bpy.ops.wm.read_homefile(use_empty=True)`` before the test; returns bpy.
* ``extension_wheels``: the embreex wheels ``blender_manifest.toml`` lists, downloaded into
  ``wheels/`` by ``make wheels`` when missing (session); returns their paths.
* ``node_tree(material_or_world)``: its node tree on every Blender (4.x makes new materials and
  worlds without one).
* ``scene_hash(bpy)``: sha256 of every mesh (vertices, faces, attributes) and object
  (visibility, matrix), for "a failed or cancelled bake leaves the scene unchanged";
  ``file_sha256(path)``: for "the input file is byte-identical".

Blender 4.2's bpy module crashes at interpreter exit once the glTF exporter has run (the same
workaround as ``python -m hemicube_radiosity``): :func:`pytest_unconfigure` leaves with pytest's
own exit status there, after everything is printed.
"""
from __future__ import annotations

import hashlib
import importlib
import os
import subprocess
import sys
import tempfile
import tomllib

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
_USER_RESOURCES = tempfile.mkdtemp(prefix="hr_blender_user_")
os.environ["BLENDER_USER_RESOURCES"] = _USER_RESOURCES

REPO_MODULE = "hr_test_repo"
ADDON_MODULE = f"bl_ext.{REPO_MODULE}.hemicube_radiosity"


@pytest.fixture(scope="session")
def bpy_module():
    import bpy

    return bpy


def _raise(ex):
    raise ex


def install_extension_repo(bpy):
    """A USER extension repository whose only extension is this source folder."""
    prefs = bpy.context.preferences.extensions
    if prefs.repos.get(REPO_MODULE) is None and all(r.module != REPO_MODULE for r in prefs.repos):
        repo_dir = os.path.join(_USER_RESOURCES, "dev_repo")
        os.makedirs(repo_dir, exist_ok=True)
        link = os.path.join(repo_dir, "hemicube_radiosity")
        if not os.path.exists(link):
            os.symlink(ROOT, link, target_is_directory=True)
        prefs.repos.new(name=REPO_MODULE, module=REPO_MODULE, custom_directory=repo_dir, source="USER")


def enable_addon():
    import addon_utils

    return addon_utils.enable(ADDON_MODULE, default_set=True, handle_error=_raise)


def disable_addon():
    import addon_utils

    addon_utils.disable(ADDON_MODULE, default_set=True, handle_error=_raise)


@pytest.fixture(scope="session")
def addon(bpy_module):
    install_extension_repo(bpy_module)
    enable_addon()
    yield importlib.import_module(ADDON_MODULE + ".hemicube_radiosity")


@pytest.fixture
def empty_scene(bpy_module):
    bpy_module.ops.wm.read_homefile(use_empty=True)
    return bpy_module


def node_tree(idblock):
    """The node tree of a material or world: Blender 4.x makes new ones with ``use_nodes`` off and
    no tree; 5.0 always has one (and deprecates ``use_nodes``, so it is not touched there)."""
    if idblock.node_tree is None:
        idblock.use_nodes = True
    return idblock.node_tree


def manifest_wheels():
    with open(os.path.join(ROOT, "blender_manifest.toml"), "rb") as f:
        return [os.path.join(ROOT, w) for w in tomllib.load(f).get("wheels", [])]


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


def read_gltf(path):
    """(json dict, accessor reader) of a .glb or .gltf (+ .bin) file, with struct + json only.

    ``accessor(i)`` returns accessor ``i`` as a float64/int64 array of shape (count, components).
    """
    import json
    import struct

    import numpy as np

    with open(path, "rb") as f:
        data = f.read()
    if data[:4] == b"glTF":
        _, _, length = struct.unpack_from("<III", data, 0)
        jlen, jtype = struct.unpack_from("<II", data, 12)
        assert jtype == 0x4E4F534A  # JSON
        doc = json.loads(data[20:20 + jlen])
        blen, btype = struct.unpack_from("<II", data, 20 + jlen)
        assert btype == 0x004E4942  # BIN
        buffers = [data[28 + jlen:28 + jlen + blen]]
    else:
        doc = json.loads(data)
        base = os.path.dirname(path)
        buffers = []
        for b in doc["buffers"]:
            with open(os.path.join(base, b["uri"]), "rb") as f:
                buffers.append(f.read())
    ncomp = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}
    dtypes = {5126: np.float32, 5125: np.uint32, 5123: np.uint16, 5121: np.uint8}

    def accessor(i):
        acc = doc["accessors"][i]
        bv = doc["bufferViews"][acc["bufferView"]]
        k = ncomp[acc["type"]]
        dt = np.dtype(dtypes[acc["componentType"]])
        off = bv.get("byteOffset", 0) + acc.get("byteOffset", 0)
        stride = bv.get("byteStride", k * dt.itemsize)
        buf = buffers[bv["buffer"]]
        raw = np.frombuffer(buf, np.uint8, count=stride * (acc["count"] - 1) + k * dt.itemsize, offset=off)
        rows = np.lib.stride_tricks.as_strided(raw, (acc["count"], k * dt.itemsize), (stride, 1))
        out = np.ascontiguousarray(rows).view(dt).reshape(acc["count"], k)
        return out.astype(np.float64 if dt.kind == "f" else np.int64)

    return doc, accessor


def corner_data(ob, attr="Radiosity"):
    """World positions and RGB of every face corner of a baked object."""
    me = ob.data
    co = np.empty(len(me.vertices) * 3, np.float32)
    me.vertices.foreach_get("co", co)
    lv = np.empty(len(me.loops), np.int32)
    me.loops.foreach_get("vertex_index", lv)
    col = np.empty(len(me.loops) * 4, np.float32)
    me.color_attributes[attr].data.foreach_get("color", col)
    M = np.array(ob.matrix_world)
    pos = co.reshape(-1, 3)[lv] @ M[:3, :3].T + M[:3, 3]
    return pos, col.reshape(-1, 4)[:, :3].astype(np.float64)


# ----------------------------------------------------------------------------- scene fingerprint
_ATTRIBUTE_PROPS = {"FLOAT_VECTOR": ("vector", 3), "FLOAT2": ("vector", 2), "FLOAT_COLOR": ("color", 4),
                    "BYTE_COLOR": ("color", 4), "INT32_2D": ("value", 2), "INT16_2D": ("value", 2),
                    "INT8_2D": ("value", 2), "QUATERNION": ("value", 4), "FLOAT4X4": ("value", 16)}


def _attribute_bytes(attr):
    n = len(attr.data)
    if attr.data_type == "STRING":
        return "\0".join(d.value for d in attr.data).encode("utf-8", "surrogateescape")
    prop, k = _ATTRIBUTE_PROPS.get(attr.data_type, ("value", 1))
    a = np.empty(n * k, np.float64)
    attr.data.foreach_get(prop, a)
    return a.tobytes()


def scene_hash(bpy):
    """sha256 hex of everything a bake must not change when it fails or is cancelled: every mesh
    datablock (vertex positions, edges, face corners and sizes, every attribute with its name,
    domain, type and values, materials, users) and every object (name, type, data, matrix,
    hide_render/hide_viewport/view-layer visibility, library), plus the collection names."""
    h = hashlib.sha256()
    for me in sorted(bpy.data.meshes, key=lambda m: m.name_full):
        h.update(f"mesh {me.name_full} {me.users} {len(me.vertices)} {len(me.edges)} "
                 f"{len(me.loops)} {len(me.polygons)}".encode())
        for coll, prop, k in ((me.vertices, "co", 3), (me.edges, "vertices", 2),
                              (me.loops, "vertex_index", 1), (me.polygons, "loop_start", 1),
                              (me.polygons, "loop_total", 1)):
            a = np.empty(len(coll) * k, np.float64)
            coll.foreach_get(prop, a)
            h.update(a.tobytes())
        for attr in sorted(me.attributes, key=lambda a: a.name):
            h.update(f"attr {attr.name} {attr.domain} {attr.data_type}".encode())
            h.update(_attribute_bytes(attr))
        h.update(repr([m.name_full if m else None for m in me.materials]).encode())
    vl = bpy.context.view_layer
    vl.update()   # objects linked by a script join the view layer at its next sync: not a change
    for ob in sorted(bpy.data.objects, key=lambda o: o.name_full):
        shown = vl.objects.get(ob.name) is not None and not ob.hide_get(view_layer=vl)
        h.update(f"object {ob.name_full} {ob.type} {ob.data.name_full if ob.data else None} "
                 f"{ob.hide_render} {ob.hide_viewport} {shown} {ob.library is not None}".encode())
        h.update(np.array(ob.matrix_world, np.float64).tobytes())
    h.update(repr(sorted(c.name_full for c in bpy.data.collections)).encode())
    return h.hexdigest()


def file_sha256(path):
    """sha256 hex of a file's bytes."""
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()
