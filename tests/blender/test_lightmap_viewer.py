"""The lightmap target's .glb in the tools a pipeline uses: the Khronos glTF validator reports
nothing (no error, no warning), and three.js in headless Chromium (SwiftShader WebGL) draws from
the scene camera what Cycles draws of the baked copies (Standard view, 16 samples, no bounces:
each copy's material shows its lightmap .exr through the lightmap UV map), pixel by pixel.

Two scenes, the two ways the lightmap reaches the .glb:

* **The demo Cornell box** (``python -m hemicube_radiosity demo --target lightmap``): its meshes
  have no UV map, so the lightmap UV map is made on each copy (Lightmap Pack) and is TEXCOORD_0.
  Measured at 384 x 384 over the box's interior (the open front 3 pixels in): 0.50 levels mean
  difference, 99th percentile 6, 0.19% of the pixels more than 20 levels apart (at 512: 0.43, 4,
  0.12%). Those lie on the rim of the light and of the ceiling around it (up to 130 levels):
  Cycles filters the .exr's radiance (12 on the light, up to 8.4 on the ceiling that the light's
  back lights) before clamping to 1, the viewer the .png's, clamped before filtering, so a blend
  of 12 and 0.1 is white in one and grey in the other; and on silhouettes, anti-aliased by
  Cycles' pixel filter and by WebGL's multisampling. Below 1 the two agree.
* **The lightmap test's room** (``tests/support/lightmap_scenes.py``: walls and block with a
  texture-style UV map, an emitting panel), seen from inside: the lightmap UV map is made on the
  copy beside the user's and is TEXCOORD_1, three.js reads the map through its ``uv1`` (the
  lamp, with no UV map of its own, has its lightmap on TEXCOORD_0). Measured at 384 x 384 over
  the whole picture but a 3-pixel border: 0.53 levels mean, 99th percentile 4, 0.42% above 20
  (the lamp's rim, as above).

Both need what ``tests/blender/test_viewer.py`` needs (``make viewer-deps``); skipped without it,
failed in CI.
"""
from __future__ import annotations

import json
import math
import os
import sys

import numpy as np
import pytest

from tests.support import ROOT, three_viewer as tv

bpy = pytest.importorskip("bpy")

pytestmark = [pytest.mark.blender, pytest.mark.cycles, pytest.mark.slow]

SIZE = 384           # pixels of both pictures


@pytest.fixture(scope="module")
def viewer_tools():
    return tv.viewer_tools()


def three_version():
    with open(os.path.join(tv.NODE_MODULES, "three", "package.json")) as f:
        return json.load(f)["version"].split(".")[1]


def assert_valid(node, path):
    """The Khronos validator: no error, no warning (infos such as non-power-of-two images may
    remain: glTF 2.0 allows them)."""
    issues = tv.validate(node, path)["issues"]
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"]


def compare(three, cycles, rows, cols):
    """(mean, 99th percentile, share above 20 levels) of the absolute difference in 8-bit levels
    over the picture's ``rows`` x ``cols`` (slices)."""
    d = np.abs(three[rows, cols] - cycles[rows, cols])
    return float(d.mean()), float(np.percentile(d, 99)), float(np.mean(d.max(-1) > 20))


def test_demo_lightmap_glb_in_three_js_as_in_cycles(viewer_tools, tmp_path):
    out = tmp_path / "demo"
    r = tv.run([sys.executable, "-m", "hemicube_radiosity", "demo", "--output-dir", str(out), "-q",
                "--target", "lightmap", "--render-size", str(SIZE)], 600, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-2000:]
    assert_valid(viewer_tools[0], out / "cornell.glb")
    with open(out / "cornell_report.json") as f:
        lightmaps = json.load(f)["lightmaps"]
    assert len(lightmaps) == 8 and all(lm["unset"] == 0 and lm["made_uvs"] for lm in lightmaps)

    from hemicube_radiosity.blender import demo

    bpy.ops.wm.read_homefile(use_empty=True)
    cam = demo.add_preview_camera(bpy.context)
    bpy.context.view_layer.update()
    camera = (np.array(cam.matrix_world), cam.data.angle)
    with tv.serve(out) as url:
        info = tv.render_three(viewer_tools, url, camera, tmp_path / "three.png", SIZE, "cornell.glb")
    assert info["three"] == three_version()
    # unlit, no vertex colours, the lightmap as an sRGB map on the only UV set (TEXCOORD_0)
    assert len(info["materials"]) == 8
    for kind, vertex_colours, attrs, tex in info["materials"]:
        assert kind == "MeshBasicMaterial" and not vertex_colours and "color" not in attrs.split()
        assert tex == [0, "srgb"]
    three, cycles = tv.load_png(tmp_path / "three.png"), tv.load_png(out / "cornell.png")
    front = tv.project(camera, np.array([[0, 0, 0], [2, 0, 0], [2, 0, 2], [0, 0, 2]], float), SIZE)
    c0, r0 = np.ceil(front.min(axis=0)).astype(int) + 3
    c1, r1 = np.floor(front.max(axis=0)).astype(int) - 3
    assert (c1 - c0) > 0.8 * SIZE and (r1 - r0) > 0.8 * SIZE
    mean, p99, over = compare(three, cycles, slice(r0, r1), slice(c0, c1))
    print(f"\ndemo lightmap: {mean:.2f} levels mean, 99th percentile {p99:.0f}, {100 * over:.2f}% above 20")
    # the pictures are not flat: light, shadow, coloured walls
    assert np.percentile(cycles[r0:r1, c0:c1], 95) - np.percentile(cycles[r0:r1, c0:c1], 5) > 100
    assert mean < 2.0 and p99 <= 8 and over < 0.005, (mean, p99, over)


def room_camera():
    """A camera inside the room, in a corner by the door side at eye height, looking at the
    block and the far corner: (object, (M, fov))."""
    from mathutils import Vector

    data = bpy.data.cameras.new("RoomView")
    data.lens_unit = "FOV"
    data.angle = math.radians(75.0)
    ob = bpy.data.objects.new("RoomView", data)
    ob.location = (0.35, 0.3, 1.6)
    ob.rotation_euler = (Vector((3.6, 2.4, 0.7)) - ob.location).to_track_quat("-Z", "Y").to_euler()
    bpy.context.scene.collection.objects.link(ob)
    bpy.context.scene.camera = ob
    bpy.context.view_layer.update()
    return ob, (np.array(ob.matrix_world), data.angle)


def test_room_lightmap_through_texcoord_1(viewer_tools, tmp_path):
    from hemicube_radiosity.blender import bake, demo, gltf
    from tests.support.gltf import read_gltf
    from tests.support.lightmap_scenes import room

    r, b, lamp = room()
    settings = bake.BakeSettings(target="lightmap", lightmap_density=16.0, resolution=32, gather_rays=64,
                                 lightmap_dir=str(tmp_path))
    job = bake.BakeJob.prepare(bpy.context, [r, b, lamp], settings)
    job.run()
    copies = job.write(bpy.context)
    assert [lm["uv_map"] for lm in job.lightmaps] == ["Lightmap"] * 3
    assert [lm["unset"] for lm in job.lightmaps] == [0, 0, 0]
    path = tmp_path / "room.glb"
    gltf.export_gltf(path, copies)
    assert_valid(viewer_tools[0], path)
    doc, _ = read_gltf(path)
    texcoord = sorted(m["pbrMetallicRoughness"]["baseColorTexture"].get("texCoord", 0) for m in doc["materials"])
    assert texcoord == [0, 1, 1]         # the lamp has no UV map of its own: its lightmap's is its first

    _, camera = room_camera()
    demo.render_preview(bpy.context, str(tmp_path / "room.png"), resolution=SIZE, samples=16)
    with tv.serve(tmp_path) as url:
        info = tv.render_three(viewer_tools, url, camera, tmp_path / "room_three.png", SIZE, "room.glb")
    assert sorted(m[3][0] for m in info["materials"]) == [0, 1, 1]
    assert all(m[0] == "MeshBasicMaterial" and m[3][1] == "srgb" for m in info["materials"])
    three, cycles = tv.load_png(tmp_path / "room_three.png"), tv.load_png(tmp_path / "room.png")
    inner = slice(3, SIZE - 3)
    mean, p99, over = compare(three, cycles, inner, inner)
    print(f"\nroom lightmap: {mean:.2f} levels mean, 99th percentile {p99:.0f}, {100 * over:.2f}% above 20")
    assert np.percentile(cycles, 95) - np.percentile(cycles, 5) > 60
    assert mean < 2.0 and p99 <= 8 and over < 0.005, (mean, p99, over)
