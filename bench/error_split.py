"""Where a real scene's error lies: our bake's parts against Cycles' at Cycles' own corners.

    .venv/bin/python bench/error_split.py godot_living_room            # after bench/real_scenes.py
    .venv/bin/python bench/error_split.py godot_truck_town --spp 64 --glossy 0

``bench/real_scenes.py`` says how far our default bake lies from Cycles' reference (256 spp) at
Cycles' corners; this says which part of the light is off, and where. In one process:

1. **Ours**: the scene loaded and lit as ``real_scenes.py`` does, baked with the defaults (or
   ``--set``), and :meth:`BakeResult.corner_parts` (emission, reflectivity ``rho``, direct light
   ``D``, light reflected at least once ``I``) read at Cycles' corners as ``real_scenes.py``
   reads our values (:func:`real_scenes.values_at_corners`).
2. **Cycles' parts**, on the same objects (modifiers applied, as the reference's): a DIFFUSE bake
   of the direct light times the colour (pass filter DIRECT + COLOR) at ``--spp`` samples and
   one of the colour alone; cached in ``bench/cache`` (the reference's cache key with the mode).
   Cycles' reflected part is the reference less its direct part. With ``--glossy 0`` also a
   DIFFUSE bake without glossy bounces (the light Cycles carries off specular layers taken out):
   the error of ours against it says what is left once that light is set apart.
3. **The split** (:func:`split`) over the corners the bench compares (``real_scenes.compared_
   corners``): the RMS (over the reference's mean luminance, raw: no noise taken out) of ours,
   and what it would be with ours' direct part replaced by Cycles' (only the reflected part
   wrong) and the other way round; the same per object, with biases; the worst corners of each
   part. Cycles' direct bake carries its own noise (at 64 spp a few percent at a corner), which
   lands in the direct part's error and out of the reflected part's.

Needs ``bench/out/real/<scene>_cycles.npz`` from a ``real_scenes.py`` run (the reference and
Cycles' corners). Writes ``bench/out/real/<scene>_split.npz`` (ours' parts and Cycles' at every
corner) and prints the tables.
"""
from __future__ import annotations

import argparse
import json
import os
import sys

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
for p in (ROOT, HERE, os.path.join(ROOT, "tools")):
    if p not in sys.path:
        sys.path.insert(0, p)

import real_scenes as rs  # noqa: E402
import speed_vs_error as sve  # noqa: E402

#: Cycles' DIFFUSE bake's pass filters for the parts (``tools/cycles_reference.PASS_FILTERS``).
PARTS = {"DIRECT_COLOR": {"DIRECT", "COLOR"}, "COLOR_ONLY": {"COLOR"}}


def split(ref, direct, ours, rho, D, I, mask) -> dict:
    """The error split at corners ``mask`` (L,) bool: ``ref`` (L, 3) Cycles' reference (the
    colour times the light arriving, direct and reflected), ``direct`` (L, 3) Cycles' colour
    times its direct light, ``ours`` (L, 3) our value, ``rho``, ``D``, ``I`` (L, 3) our colour,
    direct light and light reflected at least once (radiance). Luminance throughout; RMS over
    the reference's mean luminance. Returns {"rms", "rms_if_direct_right", "rms_if_reflected_right",
    "bias_direct", "bias_reflected", "d", "dd", "di"}: ``d`` (L,) ours less the reference,
    ``dd`` our direct part less Cycles', ``di`` our reflected part less Cycles' (``d`` = ``dd`` +
    ``di`` where ours is emission-free and equals ``rho (D + I)``)."""
    Y = sve.LUMA
    d = (ours - ref) @ Y
    dd = (rho * D) @ Y - direct @ Y
    di = (rho * I) @ Y - (ref - direct) @ Y
    mean = float((ref[mask] @ Y).mean())

    def rms(x):
        return float(np.sqrt(np.mean(x[mask] ** 2)) / mean)
    return {"rms": rms(d), "rms_if_direct_right": rms(di), "rms_if_reflected_right": rms(dd),
            "bias_direct": float(dd[mask].mean() / mean), "bias_reflected": float(di[mask].mean() / mean),
            "d": d, "dd": dd, "di": di}


def _ours(name, settings_json):
    """Our bake of scene ``name`` with parts at Cycles' corners: {E, rho, D, I, ours, matched}."""
    import bpy
    from hemicube_radiosity.blender.bake import BakeJob
    from hemicube_radiosity.blender.read.scene import GEOMETRY_TYPES
    from hemicube_radiosity.blender.read.visibility import render_visible_objects
    from hemicube_radiosity.core.settings import BakeSettings

    objs = render_visible_objects(bpy.context.view_layer, GEOMETRY_TYPES)
    job = BakeJob.prepare(bpy.context, objs, BakeSettings.from_mapping(json.loads(settings_json)))
    job.run()
    r = job.result
    with np.load(os.path.join(rs.WORK_DIR, name + "_cycles.npz")) as z:
        z = {k: z[k] for k in z.files}
    index = {n: i for i, n in enumerate(r.elements.object_names)}
    owner = np.array([index.get(str(n), -1) for n in z["names"]])[z["owner"]]
    parts = r.corner_parts()
    if parts is None:
        raise SystemExit("this bake keeps no parts (the paper's 'hemicube' path): nothing to split")
    out = {}
    for key, values in zip(("E", "rho", "D", "I", "ours"), (*parts, r.corner_values())):
        out[key], out["matched"] = rs.values_at_corners(r.elements, values, z["pos"], z["centroid"], z["normal"],
                                                        owner, z["face"], point=z["point"])
    return out


def _cycles_parts(spp, glossy):
    """Cycles' parts at its corners of the scene as loaded: {direct, color[, no_glossy]} (L, 3)."""
    import bpy
    import cycles_reference as cr
    from hemicube_radiosity.blender.read.scene import GEOMETRY_TYPES
    from hemicube_radiosity.blender.read.visibility import render_visible_objects

    objs = rs.own_evaluated_meshes(render_visible_objects(bpy.context.view_layer, GEOMETRY_TYPES))
    for mode, passes in PARTS.items():
        cr.PASS_FILTERS.setdefault(mode, passes)
        cr.BAKE_TYPES.setdefault(mode, "DIFFUSE")
    runs = {"direct": ("DIRECT_COLOR", spp, rs.GLOSSY), "color": ("COLOR_ONLY", 1, rs.GLOSSY)}
    if glossy is not None:
        runs["no_glossy"] = ("DIFFUSE", spp, glossy)
    out = {}
    for key, (mode, samples, gl) in runs.items():
        b = cr.cached_bake(objs, rs.CACHE_DIR, samples=samples, seed=sve.CAND_SEED + 1, mode=mode,
                           bounces=sve.BOUNCES, threads=2, glossy=int(gl), filter_glossy=rs.FILTER_GLOSSY)
        out[key] = np.concatenate([b.corner[o.name] for o in objs])
        rs.log(f"cycles {key}: {samples} spp {'cached' if b.cached else 'baked'} in {b.seconds:.1f} s")
    return out


def report(name, z, mask, ours, cyc, worst=12):
    """Print the split of scene ``name`` (``z``: the reference's arrays) overall and per object."""
    s = split(z["ref"], cyc["direct"], ours["ours"], ours["rho"], ours["D"], ours["I"], mask)
    rs.log(f"{name}: {int(mask.sum()):,} corners; RMS ours {s['rms']:.2%}; with Cycles' direct part "
           f"{s['rms_if_direct_right']:.2%}; with Cycles' reflected part {s['rms_if_reflected_right']:.2%}; "
           f"bias direct {s['bias_direct']:+.2%}, reflected {s['bias_reflected']:+.2%} (raw, of the mean)")
    if "no_glossy" in cyc:
        g = split(cyc["no_glossy"], cyc["direct"], ours["ours"], ours["rho"], ours["D"], ours["I"], mask)
        rs.log(f"  against Cycles without glossy bounces: RMS ours {g['rms']:.2%}")
    d, dd, di = s["d"], s["dd"], s["di"]
    tot = float((d[mask] ** 2).sum())
    rs.log("| object | corners | share of ours' squared error | of the direct part's | of the reflected part's "
           "| bias direct | bias reflected |\n|---|---|---|---|---|---|---|")
    rows = []
    for k, nm in enumerate(z["names"]):
        m = mask & (z["owner"] == k)
        if m.any():
            rows.append((float((d[m] ** 2).sum()) / tot, str(nm), int(m.sum()), float((dd[m] ** 2).sum()) / tot,
                         float((di[m] ** 2).sum()) / tot, float(dd[m].mean()), float(di[m].mean())))
    for share, nm, n, sd, si, bd, bi in sorted(rows, reverse=True)[:15]:
        rs.log(f"| {nm} | {n:,} | {share:.1%} | {sd:.1%} | {si:.1%} | {bd:+.4f} | {bi:+.4f} |")
    Y = sve.LUMA
    for label, x in (("direct", dd), ("reflected", di)):
        rs.log(f"worst corners by the {label} part (index, object, position, normal, reference, ours, part's error):")
        for i in np.argsort(-np.where(mask, x * x, 0.0))[:worst]:
            rs.log(f"  {i} {z['names'][z['owner'][i]]} {np.round(z['pos'][i], 3).tolist()} "
                   f"{np.round(z['normal'][i], 2).tolist()} {z['ref'][i] @ Y:.4f} {ours['ours'][i] @ Y:.4f} {x[i]:+.4f}")
    return s


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene", help="a folder name of ../shared/scenes (as bench/real_scenes.py)")
    ap.add_argument("--spp", type=int, default=256, help="samples of Cycles' direct-only bake")
    ap.add_argument("--glossy", type=int, default=None,
                    help="also bake Cycles without glossy bounces (give 0) and measure ours against it")
    ap.add_argument("--set", default="{}", help="settings of ours as JSON (default: the defaults)")
    ap.add_argument("--worst", type=int, default=12, help="worst corners listed per part")
    args = ap.parse_args(argv)
    cyc_npz = os.path.join(rs.WORK_DIR, args.scene + "_cycles.npz")
    if not os.path.exists(cyc_npz):
        raise SystemExit(f"no {cyc_npz}: run bench/real_scenes.py --scenes {args.scene} first")
    rs.prepare(rs.SPEC[args.scene])
    ours = _ours(args.scene, args.set)
    cyc = _cycles_parts(args.spp, args.glossy)
    with np.load(cyc_npz) as z:
        z = {k: z[k] for k in z.files}
    mask = rs.compared_corners(cyc_npz)[0] & ours["matched"] & np.all(np.isfinite(ours["ours"]), 1)
    report(args.scene, z, mask, ours, cyc, args.worst)
    np.savez(os.path.join(rs.WORK_DIR, args.scene + "_split.npz"), **ours, **{"cycles_" + k: v for k, v in cyc.items()})


if __name__ == "__main__":
    main()
