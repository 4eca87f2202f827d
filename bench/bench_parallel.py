"""Both cores (issue 9): every bake stage with ``workers=1`` against ``workers=2``, in one run.

Scenes: the dense Cornell box (``scenes.tessellate(scenes.cornell_box(), 40)``: 51,200 triangles,
grouped into ~555 patches by the default settings), the coarse ``cornell_box()`` cut into 0.1 m
patches, each baked by the NumPy hemi-cube and by Embree, and Suzanne at subdivision level 3 in
the box (bench_curved.py's scene, the hemi-cube only), in turn with 1 worker, 2 workers (the
hemi-cube's form factors on two forked processes, :mod:`core.runtime.parallel`) and, unless
``--no-threads``, 2 workers with processes switched off (``forked.PROCESSES = False``:
everything on threads, as before), ``--repeat`` times (each stage's best wall time kept, with
its CPU time: on a shared machine the best run is the one least disturbed). Per stage it prints
wall and CPU seconds (CPU of this process and of its worker processes: with two busy workers CPU
~ 2 x wall) and the speed-ups, checks that every worker count gave identical F and vertex
colours, and says how loaded the machine was: the load average before and after, and the CPU
the rest of the machine used during each case and the whole run, from /proc/stat (a shared
machine's other sessions take their share whatever this run asks for; see bench_batch.py), and
what two cores give this machine at best: for plain Python arithmetic (:func:`two_process_ceiling`)
and, after each case, for that case's own one-worker bake (:func:`bake_ceiling`; not with ``--quick``).

    .venv/bin/python bench/bench_parallel.py [--quick] [--repeat 2] [--only dense|coarse|curved]
                                             [--method hemicube|embree]
                                             [--no-threads] [--gather-threads]
    .venv/bin/python bench/bench_parallel.py --gather ROUNDS     (the final gather alone)

Results go to bench/out/bench_parallel.json.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)

from hemicube_radiosity.core.runtime import forked  # noqa: E402
from hemicube_radiosity.core import pipeline, builtin_scenes as scenes  # noqa: E402
from hemicube_radiosity.core.runtime.parallel import cpu_count  # noqa: E402
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


def others_cpu(m0, m1, own, elapsed):
    """CPUs the rest of the machine used on average between two :func:`machine_cpu` readings,
    ``own`` CPU seconds of this run taken out."""
    hz = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
    return max(0.0, (m1[0] - m0[0]) / hz - own) / elapsed if elapsed > 0 else 0.0


def cpu_time():
    """CPU seconds of this process and of its children that have ended (the worker processes of
    a stage are joined before it returns, so a stage's difference counts them)."""
    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + ch.ru_utime + ch.ru_stime


def timed_bake(meshes, settings):
    """bake() with wall and CPU seconds of every stage."""
    cpu = {}
    orig = pipeline.BakeContext.run

    def run(self, name, stage):
        c = cpu_time()
        try:
            return orig(self, name, stage)
        finally:
            cpu[name] = cpu_time() - c

    pipeline.BakeContext.run = run
    try:
        clear_ray_cache()
        c0 = cpu_time()
        res = pipeline.bake(meshes, settings)
        cpu["total"] = cpu_time() - c0
    finally:
        pipeline.BakeContext.run = orig
    return res, dict(res.timings), cpu


def cases(only, method=None):
    methods = ["hemicube"] + (["embree"] if embree_available() else [])
    methods = [m for m in methods if method in (None, m)]
    out = []
    for name in ("dense", "coarse", "curved"):
        if only and name != only:
            continue
        if name == "curved":                 # the NumPy rasteriser's heaviest case (bench_curved.py)
            if "hemicube" in methods:
                out.append(("curved / hemicube", curved_scene(), {"method": "hemicube"}))
            continue
        meshes = scenes.tessellate(scenes.cornell_box(), 40) if name == "dense" else scenes.cornell_box()
        for m in methods:
            out.append((f"{name} / {m}", meshes, dict({"patch_size": 0.1} if name == "coarse" else {}, method=m)))
    return out


def curved_scene():
    """Suzanne with a level-3 Subdivision Surface on the Cornell box's floor, as bench_curved.py
    bakes her (31,488 faces; bpy makes her)."""
    sys.path.insert(0, HERE)
    import bpy  # noqa: F401  (bmesh comes with it)
    from bench_curved import suzanne
    return scenes.cornell_box() + [suzanne(3)[0]]


def _spin(n):
    x = 0
    for i in range(n):
        x += i * i % 7
    return x


def two_process_ceiling(rounds=5, n=15_000_000):
    """What two cores give this machine at best: one process runs a loop of plain Python
    arithmetic (no memory traffic, no GIL between processes) alone, then two forked processes
    run it at once; ``2 x alone / together`` is the work two cores do in the time one does
    one's (2.0 on two free cores; less where the two virtual CPUs share a physical core, or
    run slower together). The rounds alternate; the median is kept. A bake's speed-up on two
    workers is bounded by this number, not by 2."""
    import multiprocessing
    ctx = multiprocessing.get_context("fork")
    ratios = []
    for _ in range(rounds):
        t = time.perf_counter()
        _spin(n)
        alone = time.perf_counter() - t
        procs = [ctx.Process(target=_spin, args=(n,)) for _ in range(2)]
        t = time.perf_counter()
        for p in procs:
            p.start()
        for p in procs:
            p.join()
        ratios.append(2 * alone / (time.perf_counter() - t))
    return float(np.median(ratios)), ratios


def _bake_alone(meshes, kw):
    t = time.perf_counter()
    timed_bake(meshes, BakeSettings(workers=1, **kw))
    return time.perf_counter() - t


def bake_ceiling(meshes, kw, rounds=2):
    """What two cores give this machine on this very bake: the one-worker bake in a forked
    process alone, then in two forked processes at once (nothing shared between them but the
    machine: its cores, caches and memory bandwidth); ``2 x alone / together`` per round, the
    rounds alternating, the median kept. Unlike :func:`two_process_ceiling` this counts what the
    bake's own work (Embree, NumPy over arrays larger than the caches) loses when two run side
    by side: a two-worker bake does its one bake's work, so it can reach this at best."""
    import multiprocessing
    ctx = multiprocessing.get_context("fork")

    def together(k):
        procs = [ctx.Process(target=_bake_alone, args=(meshes, kw)) for _ in range(k)]
        t = time.perf_counter()
        for p in procs:
            p.start()
        for p in procs:
            p.join()
        return time.perf_counter() - t
    ratios = []
    for _ in range(rounds):
        alone = together(1)
        ratios.append(2 * alone / together(2))
    return float(np.median(ratios)), ratios


#: (label, workers, processes on): the configurations baked in turn, in this order
CONFIGS = (("1", 1, True), ("2", 2, True), ("2 thr", 2, False))
#: with ``--gather-threads``: 2 workers, processes on, but the final gather on threads (as
#: before it forked), for a comparison in one run
GATHER_THREADS = ("2 gthr", 2, True)


def bake_config(meshes, kw, workers, processes, label=""):
    from hemicube_radiosity.core.output import gather
    forked.PROCESSES = processes
    forked_from = gather.PROCESS_RAYS
    if label == GATHER_THREADS[0]:
        gather.PROCESS_RAYS = None
    try:
        return timed_bake(meshes, BakeSettings(workers=workers, **kw))
    finally:
        forked.PROCESSES = True
        gather.PROCESS_RAYS = forked_from


def identical(a, b):
    fa, fb = a.form_factors, b.form_factors
    return bool(np.array_equal(fa.indptr, fb.indptr) and np.array_equal(fa.indices, fb.indices)
                and np.array_equal(fa.data, fb.data) and np.array_equal(fa.sky, fb.sky)
                and np.array_equal(a.vertex_radiosity, b.vertex_radiosity))


def print_case(label, results, best, configs):
    """The stage table of one case; returns its rows for the JSON report."""
    r1 = results["1"]
    same = {c: identical(r1, results[c]) for c, _, _ in configs[1:]}
    print(f"\n{label}: {r1.unknowns} unknowns, {len(r1.patches)} patches, "
          f"{len(r1.elements)} output elements; identical to 1 worker: "
          + ", ".join(f"{c} {ok}" for c, ok in same.items()))
    head = "".join(f" {'wall ' + c:>10s}" for c, _, _ in configs)
    head += "".join(f" {'1/' + c:>8s}" for c, _, _ in configs[1:])
    head += "".join(f" {'cpu ' + c:>9s}" for c, _, _ in configs)
    print(f"  {'stage':14s}{head}")
    rows = {}
    for st in STAGES + ["total"]:
        wall = {c: best[c]["wall"].get(st, 0.0) for c, _, _ in configs}
        cpu = {c: best[c]["cpu"].get(st, 0.0) for c, _, _ in configs}
        sp = {c: wall["1"] / wall[c] if wall[c] > 0 else float("nan") for c, _, _ in configs[1:]}
        rows[st] = {"wall": wall, "cpu": cpu, "speedup": sp}
        line = "".join(f" {wall[c]:10.2f}" for c, _, _ in configs)
        line += "".join(f" {sp[c]:7.2f}x" for c, _, _ in configs[1:])
        line += "".join(f" {cpu[c]:9.2f}" for c, _, _ in configs)
        print(f"  {st:14s}{line}")
    return {"identical": same, "stages": rows, "unknowns": int(r1.unknowns), "patches": len(r1.patches),
            "elements": len(r1.elements)}


def gather_only(rounds):
    """The final gather alone (gather_matrix of the dense box's 51,200 faces at their vertices,
    the default rays, with hits) at 1 worker, 2 forked workers and 2 threads, ``rounds`` times
    in turn: wall and CPU (with the workers') per configuration, best and median. A whole bake
    on a shared machine buries this stage's difference in the other stages' noise."""
    from hemicube_radiosity.core.output import gather
    from hemicube_radiosity.core.light.emitters import vertex_frames
    from hemicube_radiosity.core.mesh.subdivide import build_patches
    from hemicube_radiosity.core.rays import embree_scene
    el = build_patches(scenes.tessellate(scenes.cornell_box(), 40), None)
    x, n, _ = vertex_frames(el)
    scene, rays = embree_scene(el), BakeSettings().gather_rays
    runs, first, forked_from = {}, None, gather.PROCESS_RAYS
    try:
        for _ in range(rounds):
            for name, w, by_fork in (("1", 1, True), ("2 forked", 2, True), ("2 threads", 2, False)):
                gather.PROCESS_RAYS = 0 if by_fork else None
                c, t = cpu_time(), time.perf_counter()
                G, sky, H = gather.gather_matrix(el, x, n, scene, rays=rays, workers=w, hits=True)
                runs.setdefault(name, []).append((time.perf_counter() - t, cpu_time() - c))
                first = first or (G, H)
                assert np.array_equal(G.data, first[0].data) and np.array_equal(G.indices, first[0].indices) \
                    and np.array_equal(H, first[1]), "gather differs with the worker count"
    finally:
        gather.PROCESS_RAYS = forked_from
    print(f"final gather alone: {len(x)} points x {rays} rays, {first[0].nnz} entries, {len(first[1])} "
          f"hits, identical for every configuration; load average {os.getloadavg()[0]:.2f}")
    best1 = min(t for t, _ in runs["1"])
    for name, v in runs.items():
        v = np.array(v)
        print(f"  {name:10s} wall best {v[:, 0].min():.2f} s ({best1 / v[:, 0].min():.2f}x), median "
              f"{np.median(v[:, 0]):.2f} s; CPU median {np.median(v[:, 1]):.2f} s")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=2, help="runs of each worker count (best kept)")
    ap.add_argument("--quick", action="store_true", help="one run of each, the coarse box only")
    ap.add_argument("--only", choices=("dense", "coarse", "curved"))
    ap.add_argument("--method", choices=("hemicube", "embree"), help="this method only")
    ap.add_argument("--no-threads", action="store_true",
                    help="leave out '2 thr' (2 workers on threads only, as before processes)")
    ap.add_argument("--gather-threads", action="store_true",
                    help="add '2 gthr' (2 workers, the final gather on threads as before it forked)")
    ap.add_argument("--gather", type=int, metavar="ROUNDS",
                    help="time the final gather alone, ROUNDS times each (no bakes)")
    args = ap.parse_args(argv)
    if args.gather:
        gather_only(args.gather)
        return 0
    repeat = 1 if args.quick else args.repeat
    configs = CONFIGS[:2] if args.no_threads else CONFIGS
    if args.gather_threads:
        configs = configs + (GATHER_THREADS,)
    load0 = os.getloadavg()
    print(f"{cpu_count()} CPUs; load average before: {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}; "
          f"worker processes {'available' if forked.processes_available() else 'NOT available'}",
          flush=True)
    print("configurations: 1 = one worker; 2 = two workers (form factors, large transports and "
          "the final gather on forked processes); 2 thr = two workers on threads only; 2 gthr = "
          "two workers, the final gather on threads", flush=True)
    ceiling, rounds = two_process_ceiling()
    print(f"this machine's ceiling: two processes of plain Python arithmetic at once did {ceiling:.2f}x "
          f"the work of one in the same time (rounds: {', '.join(f'{r:.2f}' for r in rounds)}; 2.00 on "
          "two free cores)", flush=True)
    m0, w0 = machine_cpu() or (0, 0), time.perf_counter()
    own0 = cpu_time()
    report = {"quick": args.quick, "repeat": repeat, "cpus": cpu_count(), "load_before": load0, "ceiling": ceiling, "ceiling_rounds": rounds,
              "cases": {}}
    all_ok = True
    for label, meshes, kw in cases("coarse" if args.quick else args.only, args.method):
        best, results = {}, {}
        c0, t0, o0 = machine_cpu() or (0, 0), time.perf_counter(), cpu_time()
        for r in range(repeat):
            for c, w, proc in configs:
                res, wall, cpu = bake_config(meshes, kw, w, proc, c)
                results[c] = res
                b = best.setdefault(c, {"wall": {}, "cpu": {}})
                for st, t in wall.items():           # each stage's best run (and its CPU)
                    if st not in b["wall"] or t < b["wall"][st]:
                        b["wall"][st], b["cpu"][st] = t, cpu.get(st, 0.0)
        case = print_case(label, results, best, configs)
        whole = case["stages"]["total"]["speedup"]["2"]
        print(f"  whole bake on 2 workers: {whole:.2f}x, {whole / ceiling:.0%} of this machine's ceiling "
              f"({ceiling:.2f}x)", flush=True)
        if not args.quick:
            own, own_rounds = bake_ceiling(meshes, kw)
            case.update(bake_ceiling=own, bake_ceiling_rounds=own_rounds)
            print(f"  this bake's own ceiling: two one-worker bakes at once did {own:.2f}x the work of one in"
                  f" the same time (rounds: {', '.join(f'{r:.2f}' for r in own_rounds)}); 2 workers reached "
                  f"{whole / own:.0%} of it")
        case["other_cpus"] = others_cpu(c0, machine_cpu() or (0, 0), cpu_time() - o0,
                                        time.perf_counter() - t0)
        print(f"  other processes used {case['other_cpus']:.2f} of {cpu_count()} CPUs during "
              f"this case; load average now {os.getloadavg()[0]:.2f}")
        all_ok &= all(case["identical"].values())
        report["cases"][label] = case
        sys.stdout.flush()
    m1, w1 = machine_cpu() or (0, 0), time.perf_counter()
    elapsed = w1 - w0
    others = others_cpu(m0, m1, cpu_time() - own0, elapsed)
    load1 = os.getloadavg()
    print(f"\nload average after: {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}; during the run "
          f"({elapsed:.0f} s) other processes used {others:.2f} of {cpu_count()} CPUs on average")
    if others > 0.3:
        print("  (a loaded machine: a 2-worker stage gets less than two cores and the speed-ups "
              "above understate what an idle machine shows; compare the CPU columns)")
    report.update(other_cpus=others, load_after=load1, seconds=elapsed)
    os.makedirs(os.path.join(HERE, "out"), exist_ok=True)
    with open(os.path.join(HERE, "out", "bench_parallel.json"), "w") as f:
        json.dump(report, f, indent=1)
    ff = [c["stages"]["form_factors"]["speedup"]["2"] for c in report["cases"].values()]
    if ff and max(ff) < TARGET:
        print(f"target not met: best form-factor speed-up {max(ff):.2f}x < {TARGET}x")
    return 0 if all_ok else 1


if __name__ == "__main__":
    sys.exit(main())
