"""three.js in headless Chromium, and the Khronos glTF validator: what the viewer tests share
(``tests/blender/test_viewer.py``, ``tests/blender/test_lightmap_viewer.py``).

The page and the node scripts live in ``tests/support/viewer/`` (``index.html``, ``render.mjs``,
``validate.mjs``), their npm packages in its git-ignored ``node_modules`` (``make viewer-deps``).
Nothing here installs anything: :func:`viewer_tools` skips (in CI: fails) naming that target.

Conventions: a camera is ``(M, fov)``, its 4x4 world matrix in Blender's Z-up world and its field
of view in radians (square pictures, sensor fit AUTO: the angle holds both ways). Pictures are
``size`` x ``size`` pixels, 8-bit levels as float64 (H, W, 3), top row first.
"""
from __future__ import annotations

import contextlib
import functools
import http.server
import json
import math
import os
import shutil
import subprocess
import threading
import urllib.parse

import numpy as np
import pytest

from . import ROOT

VIEWER = os.path.join(ROOT, "tests", "support", "viewer")
NODE_MODULES = os.path.join(VIEWER, "node_modules")
IN_CI = os.environ.get("CI", "").lower() in ("true", "1", "yes")


def unavailable(reason):
    """Skip the test (fail it in CI) for ``reason``, naming ``make viewer-deps``."""
    reason += ": run `make viewer-deps`"
    if IN_CI:
        pytest.fail(f"viewer test cannot run in CI: {reason}")
    pytest.skip(reason)


def run(cmd, timeout, **kw):
    """``subprocess.run`` with its output captured as text."""
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, **kw)


def npm_packages_current():
    """node_modules holds exactly what package-lock.json pins (npm's own record of it)."""
    try:
        with open(os.path.join(VIEWER, "package-lock.json")) as f:
            want = json.load(f)["packages"]
        with open(os.path.join(NODE_MODULES, ".package-lock.json")) as f:
            have = json.load(f)["packages"]
    except (OSError, ValueError, KeyError):
        return False
    return {k: v.get("version") for k, v in want.items() if k} == {k: v.get("version") for k, v in have.items()}


def viewer_tools():
    """(node, chromium) paths, both on PATH, with the npm packages the lock file pins installed;
    otherwise :func:`unavailable`."""
    node = shutil.which("node")
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if not node:
        unavailable("no node on PATH")
    if not npm_packages_current():
        unavailable("the npm packages of tests/support/viewer are missing or not those its lock file pins")
    if not chromium:
        unavailable("no chromium on PATH")
    return node, chromium


def validate(node, path):
    """The Khronos validator's report (dict, its ``issues`` with numErrors, numWarnings and
    messages) of the .glb/.gltf at ``path``."""
    r = run([node, "validate.mjs", str(path)], 120, cwd=VIEWER)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout)


def to_gltf(p):
    """Blender Z-up to glTF Y-up: (x, y, z) -> (x, z, -y), as the exporter writes it."""
    return np.array([p[0], p[2], -p[1]])


def project(camera, points, size):
    """(N, 2) pixel (column, row) of Blender world ``points`` (N, 3) in a ``size`` x ``size``
    picture from ``camera``."""
    M, fov = camera
    q = (np.linalg.inv(M) @ np.c_[points, np.ones(len(points))].T).T
    f = 0.5 / math.tan(fov / 2)
    return np.c_[(0.5 + f * q[:, 0] / -q[:, 2]) * size, (0.5 - f * q[:, 1] / -q[:, 2]) * size]


def load_png(path):
    """8-bit RGB levels (H, W, 3) float64, top row first, through Blender's image loader (no
    colour conversion: byte images are read as stored)."""
    import bpy

    im = bpy.data.images.load(str(path))
    w, h = im.size
    px = np.empty(w * h * 4, np.float32)
    im.pixels.foreach_get(px)
    bpy.data.images.remove(im)
    return np.round(px.reshape(h, w, 4)[::-1, :, :3] * 255.0)


class _Handler(http.server.SimpleHTTPRequestHandler):
    """tests/support/viewer at /, ``model_dir`` at /model/."""

    model_dir = None

    def translate_path(self, path):
        p = urllib.parse.unquote(urllib.parse.urlsplit(path).path)
        if p.startswith("/model/"):
            return os.path.join(self.model_dir, os.path.basename(p))
        return super().translate_path(path)

    def log_message(self, *args):
        pass


@contextlib.contextmanager
def serve(model_dir):
    """An HTTP server on 127.0.0.1 (a free port) serving the viewer page at / and the files of
    ``model_dir`` at /model/ (a .glb's textures are inside it); yields its base URL."""
    handler = type("Handler", (_Handler,), {"model_dir": str(model_dir)})
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(handler, directory=VIEWER))
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    try:
        yield f"http://127.0.0.1:{httpd.server_address[1]}"
    finally:
        httpd.shutdown()
        httpd.server_close()


def render_three(tools, server, camera, out, size, model):
    """three.js's picture of /model/``model`` from ``camera`` (``size`` x ``size``), written to
    ``out``; returns what the page reports (three's revision, each mesh's material, whether it
    uses vertex colours, its attributes, its texture maps)."""
    node, chromium = tools
    M, fov = camera
    pos, target = to_gltf(M[:3, 3]), to_gltf(M[:3, 3] - M[:3, 2])
    q = urllib.parse.urlencode({"model": f"/model/{model}", "size": size, "fov": math.degrees(fov),
                                "pos": ",".join(f"{v:.6f}" for v in pos),
                                "target": ",".join(f"{v:.6f}" for v in target)})
    r = run([node, "render.mjs", chromium, f"{server}/index.html?{q}", str(out)], 120, cwd=VIEWER)
    assert r.returncode == 0, r.stderr[-3000:]
    return json.loads(r.stdout.strip().splitlines()[-1])
