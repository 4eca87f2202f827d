"""Batch speed-up: four demo-size bakes with ``batch -j 2`` against ``-j 1``.

Four copies of the Cornell box (the demo scene, default settings: automatic sizes, resolution 32,
64 gather rays, each about 2 s of bake plus Blender's start-up) are baked by ``python -m
hemicube_radiosity batch --force``, alternately with one and two workers; the best wall time of
each is kept. The target is the one the batch exists for: near-linear in the cores (about 1.8x with
-j 2 on 2 cores: the workers share nothing but the disk). Results go to bench/out/bench_batch.json.

    .venv/bin/python bench/bench_batch.py [--quick] [--files 4] [--repeat 2]

The ratio only means something with the cores free. On a machine where other sessions keep the
CPUs busy, Linux's autogroup scheduler gives each session an equal share however many workers it
starts (``nice`` does not change that), so the script warns when the load average is high. As
root, giving the run's own session group the CPU measures what an idle machine would show:

    setsid sh -c 'echo -19 > /proc/self/autogroup; exec .venv/bin/python bench/bench_batch.py'
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)

TARGET = 1.8


def make_scenes(d, n):
    """n .blend copies of the demo's Cornell box (built once, saved n times)."""
    import bpy

    from hemicube_radiosity.blender import demo

    bpy.ops.wm.read_homefile(use_empty=True)
    demo.build_cornell_box(bpy.context)
    paths = []
    for i in range(n):
        p = os.path.join(d, f"cornell_{i}.blend")
        bpy.ops.wm.save_as_mainfile(filepath=p, copy=True)
        paths.append(p)
    return paths


def run_batch(files, out_dir, jobs):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [ROOT, os.environ.get("PYTHONPATH")])))
    cmd = [sys.executable, "-m", "hemicube_radiosity", "batch", *files, "--out-dir", out_dir,
           "-j", str(jobs), "--force", "-q"]
    t = time.perf_counter()
    p = subprocess.run(cmd, env=env, capture_output=True, text=True)
    dt = time.perf_counter() - t
    if p.returncode != 0:
        raise SystemExit(f"batch -j {jobs} failed ({p.returncode}):\n{p.stderr}")
    bakes = []
    for f in files:
        rep = json.load(open(os.path.join(out_dir, os.path.splitext(os.path.basename(f))[0] + ".json")))
        bakes.append(rep["timings"]["total"])
    return dt, bakes


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--files", type=int, default=4)
    ap.add_argument("--repeat", type=int, default=2, help="runs of each -j (best kept)")
    ap.add_argument("--quick", action="store_true", help="one run of each")
    args = ap.parse_args(argv)
    repeat = 1 if args.quick else args.repeat
    d = os.path.join(HERE, "out", "batch")
    os.makedirs(os.path.join(d, "in"), exist_ok=True)
    files = make_scenes(os.path.join(d, "in"), args.files)
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else 0.0
    if load > 0.5 * cores:
        print(f"warning: load average {load:.1f} on {cores} cores: other work shares the CPUs and the "
              f"ratio will be low (see this script's docstring)", flush=True)
    best = {}
    for r in range(repeat):
        for jobs in (1, 2):
            dt, bakes = run_batch(files, os.path.join(d, f"out_j{jobs}"), jobs)
            print(f"run {r + 1}: -j {jobs}: {dt:6.2f} s wall for {len(files)} files "
                  f"(bakes {min(bakes):.2f}-{max(bakes):.2f} s each, in-process)", flush=True)
            best[jobs] = min(best.get(jobs, dt), dt)
    ratio = best[1] / best[2]
    ok = ratio >= TARGET * 0.95
    print(f"\n{len(files)} demo-size files on {cores} cores: -j 1 {best[1]:.2f} s, -j 2 {best[2]:.2f} s, "
          f"speed-up {ratio:.2f}x (target ~{TARGET}x: {'met' if ok else 'NOT met'})")
    with open(os.path.join(HERE, "out", "bench_batch.json"), "w") as f:
        json.dump({"quick": args.quick, "repeat": repeat, "files": len(files), "cores": cores, "j1_s": best[1], "j2_s": best[2], "speedup": ratio,
                   "target": TARGET}, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
