"""Both cores (issue 9): every bake stage with ``workers=1`` against ``workers=2``, in one run.

Scenes: the dense Cornell box (``scenes.tessellate(scenes.cornell_box(), 40)``: 51,200 triangles,
grouped into ~555 patches by the default settings) and the coarse ``cornell_box()`` cut into 0.1 m
patches; each baked by the NumPy hemi-cube and by Embree, alternately with 1 and 2 workers,
``--repeat`` times (best wall time kept). Per stage it prints wall and CPU seconds (CPU of this
process: with 2 busy threads CPU ~ 2 x wall) and the speed-up, checks that the two worker counts
gave identical F and vertex colours, and says how loaded the machine was: the CPU the rest of the
machine used during the run, from /proc/stat (a shared machine's other sessions take their share
whatever this run asks for; see bench_batch.py).

    .venv/bin/python bench/bench_parallel.py [--quick] [--repeat 2] [--only dense|coarse]

Results go to bench/out/bench_parallel.json.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)

from hemicube_radiosity.core import pipeline, scenes  # noqa: E402
from hemicube_radiosity.core.parallel import cpu_count  # noqa: E402
from hemicube_radiosity.core.rays import clear_ray_cache, embree_available  # noqa: E402
from hemicube_radiosity.core.settings import BakeSettings  # noqa: E402

TARGET = 1.8
STAGES = [name for name, _ in pipeline.STAGES]


def machine_cpu():
    """(busy, total) jiffies of the whole machine since boot, or None off Linux."""
    try:
        with open("/proc/stat") as f:
            v = [int(x) for x in f.readline().split()[1:]]
    except OSError:
        return None
    idle = v[3] + (v[4] if len(v) > 4 else 0)
    return sum(v) - idle, sum(v)


def timed_bake(meshes, settings):
    """bake() with wall and CPU seconds of every stage."""
    cpu = {}
    orig = pipeline.BakeContext.run

    def run(self, name, stage):
        c = time.process_time()
        try:
            return orig(self, name, stage)
        finally:
            cpu[name] = time.process_time() - c

    pipeline.BakeContext.run = run
    try:
        clear_ray_cache()
        c0 = time.process_time()
        res = pipeline.bake(meshes, settings)
        cpu["total"] = time.process_time() - c0
    finally:
        pipeline.BakeContext.run = orig
    return res, dict(res.timings), cpu


def cases(only):
    dense = scenes.tessellate(scenes.cornell_box(), 40)
    coarse = scenes.cornell_box()
    methods = ["hemicube"] + (["embree"] if embree_available() else [])
    out = []
    for name, meshes, kw in (("dense", dense, {}), ("coarse", coarse, {"patch_size": 0.1})):
        if only and name != only:
            continue
        for m in methods:
            out.append((f"{name} / {m}", meshes, dict(kw, method=m)))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=2, help="runs of each worker count (best kept)")
    ap.add_argument("--quick", action="store_true", help="one run of each, the coarse box only")
    ap.add_argument("--only", choices=("dense", "coarse"))
    args = ap.parse_args(argv)
    repeat = 1 if args.quick else args.repeat
    print(f"{cpu_count()} CPUs; load average before: {os.getloadavg()[0]:.2f}", flush=True)
    m0, w0 = machine_cpu() or (0, 0), time.perf_counter()
    own0 = time.process_time()
    report = {"cpus": cpu_count(), "cases": {}}
    all_ok = True
    for label, meshes, kw in cases("coarse" if args.quick else args.only):
        best = {}
        results = {}
        for r in range(repeat):
            for w in (1, 2):
                res, wall, cpu = timed_bake(meshes, BakeSettings(workers=w, **kw))
                results[w] = res
                b = best.setdefault(w, {"wall": dict(wall), "cpu": dict(cpu)})
                if wall["total"] < b["wall"]["total"]:
                    best[w] = {"wall": dict(wall), "cpu": dict(cpu)}
        same = (np.array_equal(results[1].form_factors.data, results[2].form_factors.data)
                and np.array_equal(results[1].form_factors.indices, results[2].form_factors.indices)
                and np.array_equal(results[1].vertex_radiosity, results[2].vertex_radiosity))
        all_ok &= same
        print(f"\n{label}: {results[1].unknowns} unknowns, {len(results[1].patches)} patches, "
              f"{len(results[1].elements)} output elements; workers 1 and 2 identical: {same}")
        print(f"  {'stage':14s} {'wall 1':>8s} {'wall 2':>8s} {'speed-up':>8s} {'cpu 1':>8s} {'cpu 2':>8s}")
        rows = {}
        for st in STAGES + ["total"]:
            w1, w2 = best[1]["wall"].get(st, 0.0), best[2]["wall"].get(st, 0.0)
            c1, c2 = best[1]["cpu"].get(st, 0.0), best[2]["cpu"].get(st, 0.0)
            sp = w1 / w2 if w2 > 0 else float("nan")
            rows[st] = {"wall_1": w1, "wall_2": w2, "speedup": sp, "cpu_1": c1, "cpu_2": c2}
            print(f"  {st:14s} {w1:8.2f} {w2:8.2f} {sp:7.2f}x {c1:8.2f} {c2:8.2f}"
                  f"   cores used {c1 / max(w1, 1e-9):.2f} / {c2 / max(w2, 1e-9):.2f}")
        report["cases"][label] = {"identical": bool(same), "stages": rows}
    m1, w1 = machine_cpu() or (0, 0), time.perf_counter()
    own = time.process_time() - own0
    elapsed = w1 - w0
    hz = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
    others = max(0.0, (m1[0] - m0[0]) / hz - own) / elapsed if elapsed > 0 else 0.0
    print(f"\nload average after: {os.getloadavg()[0]:.2f}; during the run other processes used "
          f"{others:.2f} of {cpu_count()} CPUs on average")
    if others > 0.3:
        print("  (a loaded machine: a 2-worker stage gets less than two cores and the speed-ups "
              "above understate what an idle machine shows; compare the CPU columns)")
    report["other_cpus"] = others
    os.makedirs(os.path.join(HERE, "out"), exist_ok=True)
    with open(os.path.join(HERE, "out", "bench_parallel.json"), "w") as f:
        json.dump(report, f, indent=1)
    ff = [c["stages"]["form_factors"]["speedup"] for c in report["cases"].values()]
    if ff and max(ff) < TARGET:
        print(f"target not met: best form-factor speed-up {max(ff):.2f}x < {TARGET}x")
    return 0 if all_ok else 1


if __name__ == "__main__":
    sys.exit(main())
