"""What the output stage's forecast counts, against what each part of the stage took (issue 32).

    .venv/bin/python bench/forecast_parts.py godot_truck_town         # one real scene: a JSON line
    .venv/bin/python bench/forecast_parts.py --fit bench/out/parts/*.json   # the rates, leave-one-out

A scene (``bench/real_scenes.py``'s loading and light) baked as the CLI bakes it, ``BakeSettings()``
as shipped, printing the forecast (``core/runtime/forecast.py``: its counts ``hit``, ``edges``,
``leaning``, ``vertices``) and the CPU seconds (this process's and its forked workers',
``getrusage``: on a busy 2-core machine CPU time moves far less than wall time) of the output
stage and of two of its parts: the abrupt elements' corrections (``indirect._corrections``, what
:data:`PER_EDGE` counts) and the corners lit on their own (``crease.corner_light``,
:data:`PER_LEANING`); the rest is the vertices' own (:data:`PER_VERTEX_LAMPS`,
:data:`PER_VERTEX_HIT`). Writes ``bench/out/parts/<scene>.json``.

``--fit`` takes those files (lamps, suns and the world only: no emitting face) and each scene's
idle times in ``bench/out/real/<scene>_defaults.json`` (``--idle`` another folder), fits each rate
to its part (the vertices' two rates by least squares relative to the part, the other two as
geometric means of part / count), scales all four by one factor to the idle output stages (times
1 + PER_EXTRA_WORKER: one worker's), and prints them with each scene's output stage measured
against its forecast, fitted with every scene and with that scene left out, and whether the
forecast's range then holds the form factors and output's time as ``real_scenes.py`` checks it.
"""
from __future__ import annotations

import glob
import json
import os
import resource
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path[:0] = [ROOT, os.path.join(ROOT, "bench")]


def _cpu() -> float:
    a, b = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime


def measure(scene: str) -> dict:
    import bpy
    import real_scenes as rs
    from hemicube_radiosity.blender.bake import BakeJob
    from hemicube_radiosity.blender.read.scene import GEOMETRY_TYPES
    from hemicube_radiosity.blender.read.visibility import render_visible_objects
    from hemicube_radiosity.core import pipeline
    from hemicube_radiosity.core.output import crease, indirect, stage as output_stage
    from hemicube_radiosity.core.settings import BakeSettings

    parts = {}

    def timed(fn, name):
        def wrapped(*a, **k):
            t = time.process_time()          # in this process (the parts run on its threads)
            try:
                return fn(*a, **k)
            finally:
                parts[name] = parts.get(name, 0.0) + time.process_time() - t
        return wrapped
    indirect._corrections = timed(indirect._corrections, "corrections")
    output_stage.corner_light = timed(crease.corner_light, "corner_light")

    def whole(fn):
        def wrapped(ctx):
            t = _cpu()                      # with the forked workers' (the gather's rays)
            try:
                return fn(ctx)
            finally:
                parts["vertices"] = _cpu() - t
        return wrapped
    pipeline.STAGES = tuple((n, whole(f) if n == "vertices" else f) for n, f in pipeline.STAGES)
    spec = rs.SPEC[scene]
    rs.prepare(spec)
    objs = render_visible_objects(bpy.context.view_layer, GEOMETRY_TYPES)
    job = BakeJob.prepare(bpy.context, objs, BakeSettings())
    job.run()
    r = job.result
    return dict(scene=scene, forecast=r.forecast.as_dict(), cpu=parts, timings=dict(job.timings),
                out_vertices=len(r.elements.verts), emitting=bool(r.patches.emitting().any()),
                load=os.getloadavg())


def fit(paths, idle_dir):
    import numpy as np
    from hemicube_radiosity.core.runtime.forecast import OTHER, PER_EXTRA_WORKER, PER_JOINED, SPREAD

    rows = []
    for p in paths:
        m = json.load(open(p))
        if m["emitting"] or not m["forecast"].get("hit"):
            continue
        idle = json.load(open(os.path.join(idle_dir, f"{m['scene']}_defaults.json")))
        fc, c = m["forecast"], m["cpu"]
        speed = 1 + PER_EXTRA_WORKER * (fc["workers"] - 1)
        casting = fc["vertices"] - (1 - PER_JOINED) * fc.get("joined", 0)
        rows.append(dict(scene=m["scene"], casting=casting, hit=fc["hit"], edges=fc["edges"],
                         leaning=fc["leaning"], corr=c.get("corrections", 0.0), corner=c.get("corner_light", 0.0),
                         rest=c["vertices"] - c.get("corrections", 0.0) - c.get("corner_light", 0.0),
                         idle=idle["stages"]["vertices"] * speed, speed=speed,
                         took=idle["stages"]["form_factors"] + idle["stages"]["vertices"],
                         ff=fc["form_factors"]))

    def rates(R):
        n = np.array([r["casting"] for r in R])
        h = np.array([r["hit"] for r in R])
        rest = np.array([r["rest"] for r in R])
        X = np.column_stack([n, n * h]) / rest[:, None]
        ab = np.maximum(np.linalg.lstsq(X, np.ones(len(R)), rcond=None)[0], 0.0)
        edge = np.exp(np.mean([np.log(r["corr"] / r["edges"]) for r in R if r["edges"] > 0 and r["corr"] > 0]))
        L = [np.log(r["corner"] / r["leaning"]) for r in R if r["leaning"] > 0 and r["corner"] > 0]
        lean = np.exp(np.mean(L)) if L else 0.0

        def cpu(r):
            return r["casting"] * (ab[0] + ab[1] * r["hit"]) + edge * r["edges"] + lean * r["leaning"]
        k = np.exp(np.mean([np.log(r["idle"] / cpu(r)) for r in R]))
        return dict(PER_VERTEX_LAMPS=k * ab[0], PER_VERTEX_HIT=k * ab[1], PER_EDGE=k * edge, PER_LEANING=k * lean,
                    scale=k)

    def output(q, r):
        return (r["casting"] * (q["PER_VERTEX_LAMPS"] + q["PER_VERTEX_HIT"] * r["hit"])
                + q["PER_EDGE"] * r["edges"] + q["PER_LEANING"] * r["leaning"]) / r["speed"]
    q = rates(rows)
    print("rates (one worker, idle seconds):", {k: float(f"{v:.3g}") for k, v in q.items()})
    print("scene: output stage measured / forecast, all scenes fitted | that scene left out; "
          "the form factors and output's time in the range?")
    for i, r in enumerate(rows):
        out = []
        for qq in (q, rates(rows[:i] + rows[i + 1:])):
            o = output(qq, r)
            sec = (1 + OTHER) * (r["ff"] + o)
            out.append(f"{r['idle'] / r['speed'] / o:.2f} ({SPREAD[0] * sec:.1f}-{SPREAD[1] * sec:.1f} s: "
                       f"{'yes' if SPREAD[0] * sec <= r['took'] <= SPREAD[1] * sec else 'no'})")
        print(f"  {r['scene']}: took {r['took']:.1f} s; {out[0]} | {out[1]}")


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "--fit":
        idle = os.path.join(ROOT, "bench", "out", "real")
        if "--idle" in argv:
            i = argv.index("--idle")
            idle = argv[i + 1]
            del argv[i:i + 2]
        fit(argv[1:] or sorted(glob.glob(os.path.join(ROOT, "bench", "out", "parts", "*.json"))), idle)
        return
    m = measure(argv[0])
    os.makedirs(os.path.join(ROOT, "bench", "out", "parts"), exist_ok=True)
    with open(os.path.join(ROOT, "bench", "out", "parts", f"{argv[0]}.json"), "w") as f:
        json.dump(m, f, indent=1)
    print(json.dumps(m))


if __name__ == "__main__":
    main()
