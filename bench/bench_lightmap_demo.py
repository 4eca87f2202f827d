"""The lightmap target on the demo Cornell box as modelled (walls as single quads, two blocks):
texel RMS against a high-sample Cycles bake through the same UV maps, beside Cycles' own bake
at 64 samples, and the time of each (issue 34's acceptance).

    PYTHONPATH=. .venv/bin/python bench/bench_lightmap_demo.py [--density 16] [--reference 1024] [--quality draft]

Each object gets a second UV map by Lightmap Pack (as a user makes one); we bake every object
at once (``target='lightmap'``, the default settings otherwise), Cycles bakes each object alone
into an image of the same size through that map (DIFFUSE: direct + indirect + colour) at 64
samples and at ``--reference`` samples. Texels compared: those all three hold (> 0). Prints one
line per object and the totals; a measurement, not a test (nothing asserted). Not part of
``make bench``. Cycles' time is the sum of its per-object bakes (each syncs the scene again).
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import bpy  # noqa: E402

from hemicube_radiosity.blender import bake, demo, write  # noqa: E402
from tools import cycles_reference as cr  # noqa: E402


def image_rgb(name):
    return cr.image_rgb(bpy.data.images[name])


def pack(ob, name="LightmapUV"):
    layer = ob.data.uv_layers.new(name=name)
    ob.data.uv_layers.active = layer
    with bpy.context.temp_override(active_object=ob, object=ob, selected_objects=[ob],
                                   selected_editable_objects=[ob]):
        bpy.ops.uv.lightmap_pack(PREF_CONTEXT="ALL_FACES", PREF_PACK_IN_ONE=True, PREF_MARGIN_DIV=1.0)


def errors(a, ref, mask):
    r = ref.mean(-1)[mask]
    e = (a.mean(-1)[mask] - r) / r
    return np.mean(np.abs(e)), np.sqrt(np.mean(e ** 2))


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--density", type=float, default=16.0)
    ap.add_argument("--reference", type=int, default=1024)
    ap.add_argument("--quality", default="production")
    args = ap.parse_args(argv)
    cr.new_empty_scene()
    cr.set_world((0.0, 0.0, 0.0), 0.0)
    objs = demo.build_cornell_box(bpy.context)
    baked = [o for o in objs if o.name != "Light"]
    for o in baked:
        pack(o)
    settings = bake.BakeSettings(target="lightmap", lightmap_density=args.density, lightmap_uv="LightmapUV",
                                 lightmap_dir=tempfile.mkdtemp(), quality=args.quality)
    t = time.perf_counter()
    job = bake.BakeJob.prepare(bpy.context, baked, settings)
    job.run()
    job.write(bpy.context)
    ours_s = time.perf_counter() - t
    ours = {rec["object"]: (image_rgb(f"{rec['object']}.lightmap.exr"), rec["size"][0]) for rec in job.lightmaps}
    write.remove_bakes([o.name for o in baked], unhide=True)
    rows, low_s, sq = [], 0.0, {"ours": [], "c64": []}
    for o in baked:
        img, size = ours[o.name]
        ref, _ = cr.bake_image(o, size, samples=args.reference, uv_layer="LightmapUV")
        low, s = cr.bake_image(o, size, samples=64, uv_layer="LightmapUV")
        low_s += s
        mask = (ref.mean(-1) > 0) & (low.mean(-1) > 0) & (img.mean(-1) > 0)
        r = ref.mean(-1)[mask]
        for k, a in (("ours", img), ("c64", low)):
            sq[k].append((a.mean(-1)[mask] - r) / r)
        rows.append((o.name, size, int(mask.sum()), errors(img, ref, mask), errors(low, ref, mask)))
    print(f"\nlightmaps of the demo box, density {args.density:g}, quality {args.quality}, against Cycles "
          f"{args.reference} spp; our stages: " + ", ".join(f"{k} {v:.2f} s" for k, v in job.timings.items()))
    for name, size, n, (om, orms), (lm, lrms) in rows:
        print(f"  {name:11s} {size:3d}^2 {n:5d} texels: ours {100 * om:5.1f}% mean {100 * orms:5.1f}% RMS; "
              f"Cycles 64 spp {100 * lm:5.1f}% {100 * lrms:5.1f}%")
    e = {k: np.concatenate(v) for k, v in sq.items()}
    print(f"  all {e['ours'].size} texels: ours {100 * np.mean(np.abs(e['ours'])):.1f}% mean, "
          f"{100 * np.sqrt(np.mean(e['ours'] ** 2)):.1f}% RMS in {ours_s:.1f} s (bake and write); "
          f"Cycles 64 spp {100 * np.mean(np.abs(e['c64'])):.1f}%, {100 * np.sqrt(np.mean(e['c64'] ** 2)):.1f}% "
          f"in {low_s:.1f} s ({len(baked)} bakes)")


if __name__ == "__main__":
    main()
