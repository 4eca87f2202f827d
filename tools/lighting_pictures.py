# SPDX-License-Identifier: GPL-3.0-or-later
"""Pictures for docs/lighting.md: the same scene rendered by Cycles and shown from our bake.

For each case of tests/support/cycles_scenes.py (same scenes, same bakes) three renders from one
camera, side by side in ``docs/img/lighting_<case>.png``:

1. Cycles path-traced render of the scene (its lamps, world and materials);
2. Cycles' own vertex bake (the reference the tests compare with), shown as emission;
3. our bake (read_lights + core.pipeline, one patch per face), shown as emission.

Panels 2 and 3 render a FLOAT_COLOR corner attribute through an Emission shader with the lamps
and world switched off, so a pixel shows exactly the interpolated vertex radiance; panel 1 is
what an artist's F12 render shows. All panels use the AgX view transform and the same exposure.

Usage: ``.venv/bin/python tools/lighting_pictures.py [case ...] [--size 256] [--samples 128]``
(cases: point spot sun area world emitter; default all).
"""
from __future__ import annotations

import argparse
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import bpy  # noqa: E402
from mathutils import Vector  # noqa: E402

from tests.support import cycles_scenes as cases  # noqa: E402
from tools import cycles_reference as cr  # noqa: E402

CAMERAS = {   # eye, target
    "point": ((0.0, -4.6, 3.2), (0.0, 0.2, 0.0)),
    "spot": ((0.0, -2.6, 2.2), (0.0, 0.1, 0.0)),
    "area": ((0.0, -4.6, 3.2), (0.0, 0.2, 0.3)),
    "sun": ((-4.2, -5.2, 3.6), (0.0, 0.0, 0.4)),
    "world": ((0.0, -3.0, 3.4), (0.0, 0.1, 0.2)),
    "emitter": ((0.0, -4.6, 2.6), (0.0, 0.2, 0.4)),
}
RUN = {
    "point": lambda: cases.case_point()[0],
    "spot": lambda: cases.case_spot()[0],
    "sun": lambda: cases.case_sun()[0],
    "area": lambda: cases.case_area()[0],
    "world": cases.case_world,
    "emitter": cases.case_emitter,
}


def add_camera(eye, target):
    cam = bpy.data.cameras.new("cam")
    cam.lens = 30
    ob = bpy.data.objects.new("cam", cam)
    bpy.context.scene.collection.objects.link(ob)
    ob.location = eye
    ob.rotation_euler = (Vector(target) - Vector(eye)).to_track_quat("-Z", "Y").to_euler()
    bpy.context.scene.camera = ob
    return ob


def render(path, size, samples):
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = samples
    sc.cycles.use_adaptive_sampling = False
    sc.cycles.use_denoising = False
    sc.render.resolution_x = sc.render.resolution_y = size
    sc.render.resolution_percentage = 100
    sc.render.film_transparent = False
    sc.view_settings.view_transform = "AgX"
    sc.view_settings.look = "None"
    sc.view_settings.exposure = 0.0
    sc.render.image_settings.file_format = "PNG"
    sc.render.filepath = path
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path)
    px = np.empty(size * size * 4, np.float32)
    img.pixels.foreach_get(px)
    bpy.data.images.remove(img)
    os.remove(path)
    return px.reshape(size, size, 4)


def show_values(objects, c, values):
    """Corner attribute = ``values`` (per compared corner) on each object, emission material,
    lamps and world off."""
    mat = bpy.data.materials.get("_show") or bpy.data.materials.new("_show")
    nt, out = cr.bare_node_tree(mat)
    attr = nt.nodes.new("ShaderNodeAttribute")
    attr.attribute_name = "_shown"
    em = nt.nodes.new("ShaderNodeEmission")
    nt.links.new(attr.outputs["Color"], em.inputs["Color"])
    nt.links.new(em.outputs[0], out.inputs["Surface"])
    for k, ob in enumerate(objects):
        me = ob.data
        if "_shown" in me.color_attributes:
            me.color_attributes.remove(me.color_attributes["_shown"])
        a = me.color_attributes.new("_shown", "FLOAT_COLOR", "CORNER")
        col = np.ones((len(me.loops), 4), np.float32)
        sel = c.owner == k
        col[c.loop[sel], :3] = values[sel]
        a.data.foreach_set("color", col.ravel())
        me.materials.clear()
        me.materials.append(mat)
    for ob in bpy.context.scene.objects:
        if ob.type == "LIGHT":
            ob.hide_render = True
    bpy.context.scene.world = None


def make(case, size, samples, outdir):
    c = RUN[case]()
    objects = c.objects
    add_camera(*CAMERAS[case])
    tmp = os.path.join(outdir, f"_tmp_{case}.png")
    panels = [render(tmp, size, samples)]
    show_values(objects, c, c.cycles)
    panels.append(render(tmp, size, 16))
    show_values(objects, c, c.ours)
    panels.append(render(tmp, size, 16))
    gap = np.ones((size, 4, 4), np.float32)
    row = np.concatenate([panels[0], gap, panels[1], gap, panels[2]], axis=1)
    h, w = row.shape[:2]
    img = bpy.data.images.new(f"lighting_{case}", w, h, alpha=False)
    img.pixels.foreach_set(row.ravel())
    path = os.path.join(outdir, f"lighting_{case}.png")
    img.filepath_raw = path
    img.file_format = "PNG"
    img.save()
    print(f"{case}: {path}  (mean rel err over every lit corner, shadow edges included: {100 * c.error(c.cycles.mean(axis=1) > 1e-6):.2f}%)")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("cases", nargs="*", default=list(RUN))
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--samples", type=int, default=128)
    ap.add_argument("--outdir", default=os.path.join(ROOT, "docs", "img"))
    a = ap.parse_args(argv)
    os.makedirs(a.outdir, exist_ok=True)
    for case in a.cases:
        make(case, a.size, a.samples, a.outdir)


if __name__ == "__main__":
    main()
