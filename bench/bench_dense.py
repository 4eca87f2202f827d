"""Dense meshes: cost set by the light, not by the mesh (issue 9). A tessellation sweep of the Cornell box.

    .venv/bin/python bench/bench_dense.py            # full sweep (~25 min on 2 cores; reference cached)
    .venv/bin/python bench/bench_dense.py --quick    # smoke run: 3 small sizes (~3 min)

The Cornell box of ``core.builtin_scenes.cornell_box`` (16 quads: floor, ceiling, three walls, light, two
blocks without bottoms) is modelled densely by ``tessellate(cornell_box(), n)``: every quad cut into
n x n quads of two triangles, 2 n^2 triangles per quad. For each n, in child processes:

* ours: ``core.pipeline.bake`` with ``BakeSettings()`` as shipped (no world, no lamps, as the bench's
  Cornell scene) on the tessellated MeshInputs; triangles, pieces (``len(result.patches)``), patches
  (``result.unknowns``: the clusters solved for), output vertices (``len(result.elements.verts)``),
  ``result.timings`` per stage, peak resident memory of the child (ru_maxrss, taken right after the
  bake, before bpy is imported), then the add-on's ``read_scene`` and ``write_copies`` timed on the
  same scene built as Blender objects (as bench/speed_vs_error.py does);
* Cycles: the same tessellated scene as Blender objects (``build_scene``: the meshes of
  bench/speed_vs_error.build_blender_scene, with emitters built here as plain two-sided emitters,
  Diffuse + Emission, as an artist's file has them and as our default ``two_sided_emission=True``
  bakes them, whatever speed_vs_error's own emitter material is), ``bpy.ops.object.bake`` COMBINED
  vertex bake at 64 spp, 32 bounces (tools/cycles_reference.py); its time and the child's peak memory.

Error: one high-sample Cycles bake (``--ref-spp``, 1024) of the Cornell box's fixed 0.08 m
evaluation mesh (bench/scenes_bench.cornell().fine, same surfaces), cached in ``bench/cache/``;
its vertices are the **probe points** (emitters and never-lit vertices left out, and the ceiling
within ``LAMP_BAND`` = 0.3 m of the lamp's footprint: lit through the 2 mm gap by the lamp's back, a
small very bright spot that would dominate the RMS). Every
tessellation, ours and Cycles 64 spp alike, is evaluated at those same points by
``core.output.interpolate.interpolate_at`` (ours: its output elements and vertex radiosities; Cycles: its
per-corner colours on the tessellated triangles). Reported: probe RMS relative error (luminance
weighted, as speed_vs_error), floor luminance ratio (mean luminance of the floor probes / the
reference's) and red bleeding ratio ((R/G) over the floor probes within 0.3 m of the red wall /
the reference's).

Writes bench/out/dense.json (dense_quick.json with ``--quick``) and prints the targets (issue 9);
bench/report.py turns it into a section of docs/performance.md.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(ROOT, "tools"))

from hemicube_radiosity.core import pipeline, builtin_scenes as scenes  # noqa: E402
from hemicube_radiosity.core.output.interpolate import interpolate_at  # noqa: E402
from hemicube_radiosity.core.mesh.patches import PatchSet, poly_geometry  # noqa: E402

import scenes_bench  # noqa: E402
import speed_vs_error as sve  # noqa: E402

CACHE_DIR = sve.CACHE_DIR
OUT_DIR = os.path.join(ROOT, "bench", "out")
LUMA = sve.LUMA
# 16 quads -> 32 n^2 triangles: 32, 512, 2,048, 8,192, 14,112, 26,912, 53,792, 199,712
FULL_N = (1, 4, 8, 16, 21, 29, 41, 79)
QUICK_N = (1, 4, 8)
CYCLES_SPP = 64
RED_BAND = 0.3          # floor probes within this distance of the red wall (x = 0), m
LAMP_BAND = 0.3         # ceiling probes within this distance of the lamp's footprint: out of the RMS, m


def log(*a):
    print(*a, flush=True)


def tess(n):
    return scenes.tessellate(scenes.cornell_box(), n)


def n_triangles(meshes):
    return int(sum(len(m.face_offsets) - 1 for m in meshes))


class _Scene:
    """What speed_vs_error.build_blender_scene reads: the meshes to build (``fine``) and the world."""

    def __init__(self, meshes, world=None):
        self.fine, self.world, self.lights = meshes, world, ()


def _peak_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _material(rho, emission, name):
    """Diffuse ``rho``; an emitter adds an Emission of colour ``emission`` (strength 1) and lights
    both faces: a plain emitter as an artist's file has it (our default ``two_sided_emission=True``)."""
    import cycles_reference as cr

    if max(emission) <= 0:
        return cr.diffuse_material(tuple(rho), 0.0, name=name)
    return cr.diffuse_material(tuple(rho), 1.0, emission_color=tuple(map(float, emission)), name=name)


def build_scene(sc):
    """speed_vs_error.build_blender_scene with this bench's two-sided emitter materials (until a1b501c
    speed_vs_error gave Cycles' emitters a black back; the emitters here do not depend on it)."""
    saved = sve._material
    sve._material = _material
    try:
        return sve.build_blender_scene(sc)
    finally:
        sve._material = saved


# ----------------------------------------------------------------------------- metrics
def metrics(vals, probes):
    """Probe RMS (relative, luminance weighted), floor luminance ratio, red bleeding ratio."""
    R, mask = probes["ref"], probes["mask"]
    err = sve.errors(vals, R, mask)
    floor, red = probes["floor"], probes["red"]
    Y = vals @ LUMA
    Yr = R @ LUMA
    rg = vals[red, 0].mean() / vals[red, 1].mean()
    rg_ref = R[red, 0].mean() / R[red, 1].mean()
    return {"rms": err["rms"], "p95": err["p95"], "bias": err["bias"],
            "floor_ratio": float(Y[floor].mean() / Yr[floor].mean()),
            "rg": float(rg), "rg_ref": float(rg_ref), "red_ratio": float(rg / rg_ref)}


def load_probes(path):
    z = np.load(path)
    return {k: z[k] for k in z.files}


def corner_patches(meshes):
    """A PatchSet whose vertices are the meshes' face corners in loop order (Blender's corner
    order for a mesh made by from_pydata), so Cycles' per-corner colours interpolate on it."""
    verts, polys, owner = [], [], []
    base = 0
    for o, m in enumerate(meshes):
        off = np.asarray(m.face_offsets)
        cnt = np.diff(off)
        if np.any(cnt > 4):
            raise ValueError("n-gons are not expected in a tessellated scene")
        L = int(off[-1])
        verts.append(np.asarray(m.verts, float)[np.asarray(m.face_indices)])
        p = np.full((len(cnt), 4), -1, np.int64)
        for k in (3, 4):
            sel = np.flatnonzero(cnt == k)
            p[sel, :k] = off[sel, None] + np.arange(k)
        polys.append(np.where(p >= 0, p + base, -1))
        owner.append(np.full(len(cnt), o, np.int32))
        base += L
    v = np.concatenate(verts)
    p = np.concatenate(polys)
    c, nrm, a = poly_geometry(v, p)
    N = len(p)
    return PatchSet(v, p, c, nrm, a, np.zeros((N, 3)), np.zeros((N, 3)), np.concatenate(owner),
                    np.zeros(N, np.int32), [m.name for m in meshes])


# ----------------------------------------------------------------------------- children
def ours_child(n, probes_path, out_path):
    meshes = tess(n)
    load0 = os.getloadavg()
    before = _peak_mb()
    t = time.perf_counter()
    res = pipeline.bake(meshes, pipeline.BakeSettings(), world=None, lights=())
    core_s = time.perf_counter() - t
    peak = _peak_mb()
    rec = {"n": n, "triangles": n_triangles(meshes), "pieces": len(res.patches), "patches": int(res.unknowns),
           "output_vertices": int(len(res.elements.verts)), "output_faces": int(len(res.elements)),
           "core_seconds": core_s, "stages": {k: float(v) for k, v in res.timings.items()},
           "forecast": None if res.forecast is None else float(res.forecast.seconds),
           "iterations": int(res.solution.iterations), "nnz": int(res.form_factors.nnz),
           "peak_mb": peak, "start_mb": before,
           "settings": {k: getattr(res.settings, k) for k in ("patch_size", "element_size", "gather_rays",
                                                               "resolution", "method")},
           "notes": list(res.notes)}
    probes = load_probes(probes_path)
    vals = interpolate_at(res.elements, res.vertex_radiosity, probes["pts"], probes["owner"], probes["normals"])
    rec["error"] = metrics(vals, probes)
    # the add-on's read and write on the same scene as Blender objects (bpy only now: the peak above is the bake's)
    try:
        import bpy  # noqa: F401
        scene, objs = build_scene(_Scene(meshes))
        w = sve.Writer(objs)
        rec["read_seconds"] = w.read_seconds if w.ok else float("nan")
        rec["write_seconds"] = w(res) if w.ok else float("nan")
        if not w.ok:
            rec["writer_error"] = w.error
    except Exception as exc:  # noqa: BLE001 - report and go on
        rec["read_seconds"] = rec["write_seconds"] = float("nan")
        rec["writer_error"] = f"{type(exc).__name__}: {exc}"
    rec["peak_mb_with_blender"] = _peak_mb()
    rec["load"] = [load0, os.getloadavg()]
    with open(out_path, "w") as f:
        json.dump(rec, f, default=float)


def cycles_child(n, spp, probes_path, out_path):
    import cycles_reference as cr

    meshes = tess(n)
    load0 = os.getloadavg()
    t = time.perf_counter()
    scene, objs = build_scene(_Scene(meshes))
    build_s = time.perf_counter() - t
    before = _peak_mb()
    b = cr.bake_vertex_radiance(objs, samples=spp, seed=sve.CAND_SEED, bounces=sve.BOUNCES, threads=2)
    peak = _peak_mb()
    corner = np.concatenate([b.corner[m.name] for m in meshes])
    probes = load_probes(probes_path)
    vals = interpolate_at(corner_patches(meshes), corner, probes["pts"], probes["owner"], probes["normals"])
    rec = {"n": n, "spp": spp, "triangles": n_triangles(meshes), "corners": int(len(corner)),
           "seconds": b.seconds, "build_seconds": build_s, "peak_mb": peak, "start_mb": before,
           "error": metrics(vals, probes), "load": [load0, os.getloadavg()]}
    with open(out_path, "w") as f:
        json.dump(rec, f, default=float)


def run_child(kind, args, timeout):
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "rec.json")
        t = time.perf_counter()
        try:
            p = subprocess.run([sys.executable, __file__, f"--{kind}-child", *map(str, args), out],
                               capture_output=True, text=True, timeout=timeout, cwd=ROOT)
            if not os.path.exists(out):
                raise RuntimeError((p.stderr or p.stdout)[-800:])
            with open(out) as f:
                rec = json.load(f)
        except subprocess.TimeoutExpired:
            rec = {"timeout": timeout}
        except Exception as exc:  # noqa: BLE001 - report and go on
            rec = {"error": str(exc)[-800:]}
        rec["wall_seconds"] = time.perf_counter() - t
        return rec


# ----------------------------------------------------------------------------- reference
def make_probes(ref_spp, path):
    """Bake (or load) the reference on the 0.08 m evaluation mesh; save its vertices as probes."""
    import cycles_reference as cr

    sc = scenes_bench.cornell()
    scene, objs = build_scene(sc)
    # the key hashes the meshes and the materials' node trees: two-sided emitters bake a new reference
    key = cr.cache_key(objs, dict(samples=ref_spp, seed=sve.REF_SEED, mode="COMBINED", bounces=sve.BOUNCES))
    t = time.perf_counter()
    ref = cr.cached_bake(objs, CACHE_DIR, samples=ref_spp, seed=sve.REF_SEED, bounces=sve.BOUNCES, threads=2)
    log(f"reference {ref_spp} spp on {sc.n_fine_faces} faces: {'cached' if ref.cached else 'baked'}"
        f" (its bake {ref.seconds:.0f} s, {time.perf_counter() - t:.0f} s here; cache key {key})")
    pts, owner, normals, emitter = scenes_bench.fine_points(sc.fine)
    R = sve.cycles_values(ref, sc)
    Yr = R @ LUMA
    hidden = Yr <= 1e-4 * np.median(Yr[~emitter])
    names = [m.name for m in sc.fine]
    lamp = np.asarray(sc.fine[names.index("Light")].verts, float)
    lo, hi = lamp[:, :2].min(0), lamp[:, :2].max(0)
    d_lamp = np.linalg.norm(np.maximum(0.0, np.maximum(lo - pts[:, :2], pts[:, :2] - hi)), axis=1)
    over_lamp = (owner == names.index("Ceiling")) & (d_lamp < LAMP_BAND)
    mask = ~emitter & ~hidden & ~over_lamp
    on_floor = owner == names.index("Floor")
    floor = mask & on_floor
    red = floor & (pts[:, 0] < RED_BAND)
    np.savez(path, pts=pts, owner=owner, normals=normals, ref=R, mask=mask, floor=floor, red=red)
    return {"spp": ref_spp, "seconds": ref.seconds, "cached": ref.cached, "faces": sc.n_fine_faces,
            "probes": int(mask.sum()), "floor_probes": int(floor.sum()), "red_probes": int(red.sum()),
            "over_lamp": int((over_lamp & ~emitter & ~hidden).sum()), "cache_key": key,
            "floor_Y": float(Yr[floor].mean()), "rg": float(R[red, 0].mean() / R[red, 1].mean()),
            # the reference's own noise, from speed_vs_error's fit on this mesh (Cycles RMS ~ spp^-0.54,
            # 0.92% at 4,096 spp): an estimate, not measured here
            "noise_rms_est": 0.0092 * (4096 / ref_spp) ** 0.54}


# ----------------------------------------------------------------------------- targets
def ours_total(o):
    extra = sum(x for x in (o.get("read_seconds"), o.get("write_seconds")) if x is not None and np.isfinite(x))
    return o["core_seconds"] + extra


def slope(rows):
    """Our bake time against output vertices, sizes from ~2k triangles up, ordered by output vertices:
    the log-log fit slope, and per consecutive pair (time ratio, vertex ratio)."""
    r = sorted((x["ours"] for x in rows if "core_seconds" in x.get("ours", {}) and x["ours"]["triangles"] >= 2000),
               key=lambda o: o["output_vertices"])
    if len(r) < 2:
        return float("nan"), []
    v = np.log([o["output_vertices"] for o in r])
    t = np.log([o["core_seconds"] for o in r])
    pair = [(a["triangles"], b["triangles"], b["core_seconds"] / a["core_seconds"],
             b["output_vertices"] / a["output_vertices"]) for a, b in zip(r, r[1:])]
    return float(np.polyfit(v, t, 1)[0]), pair


def _k(t):
    return f"{t / 1000:.0f}k" if t >= 1000 else str(t)


def targets(res):
    out = []

    def near(tri):
        ok = [x for x in res["rows"] if "core_seconds" in x.get("ours", {})
              and abs(np.log(x["ours"]["triangles"] / tri)) < np.log(1.5)]
        return min(ok, key=lambda x: abs(np.log(x["ours"]["triangles"] / tri))) if ok else None

    r54, r2k, r200 = near(54000), near(2000), near(200000)
    if r54 is not None and "seconds" in r54.get("cycles", {}):
        o, c = r54["ours"], r54["cycles"]
        t = ours_total(o)
        out.append((f"~54k triangles ({o['triangles']:,}), defaults, no slower than Cycles {c['spp']} spp",
                    f"ours {t:.1f} s (bake {o['core_seconds']:.1f} + read {o.get('read_seconds', float('nan')):.1f}"
                    f" + write {o.get('write_seconds', float('nan')):.1f}) vs Cycles {c['seconds']:.1f} s:"
                    f" {c['seconds'] / t:.2f}x", t <= c["seconds"]))
    if r54 is not None:
        e = r54["ours"]["error"]
        out.append(("~54k: floor luminance within 5% of Cycles (reference)",
                    f"{e['floor_ratio']:.3f} ({100 * (e['floor_ratio'] - 1):+.1f}%)", abs(e["floor_ratio"] - 1) <= 0.05))
        out.append(("~54k: red bleeding (floor within 0.3 m of the red wall, R/G) within 15% of Cycles",
                    f"R/G {e['rg']:.3f} vs {e['rg_ref']:.3f}: {e['red_ratio']:.3f} ({100 * (e['red_ratio'] - 1):+.1f}%)",
                    abs(e["red_ratio"] - 1) <= 0.15))
    if r200 is not None:
        o = r200["ours"]
        out.append((f"~200k triangles ({o['triangles']:,}) bakes under 4 GB",
                    f"peak {o['peak_mb']:.0f} MB (whole child process, ru_maxrss after the bake)", o["peak_mb"] < 4096))
    if r54 is not None and r2k is not None and r54 is not r2k:
        a, b = r2k["ours"]["error"]["rms"], r54["ours"]["error"]["rms"]
        out.append(("error at ~54k no worse than at ~2k (probe RMS)",
                    f"{100 * b:.2f}% at {r54['ours']['triangles']:,} vs {100 * a:.2f}% at {r2k['ours']['triangles']:,}",
                    b <= a))
    s, pairs = slope(res["rows"])
    if np.isfinite(s):
        out.append(("time grows at most linearly with the output vertex count (sizes from ~2k triangles up, ordered by"
                    " output vertices: time ratio <= vertex ratio for each step)",
                    f"log-log slope {s:.2f}; steps (triangles: time x / vertices x) "
                    + ", ".join(f"{_k(a)}->{_k(b)}: {tr:.2f} / {vr:.2f}" for a, b, tr, vr in pairs),
                    all(tr <= vr for _, _, tr, vr in pairs)))
    return out


def emission_mode():
    return "two-sided" if getattr(pipeline.BakeSettings(), "two_sided_emission", False) else "front-only"


def uptime():
    """The load averages of `uptime` (1, 5, 15 min)."""
    try:
        out = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
        return out.split("load average:")[-1].strip()
    except OSError:
        return "?"


# ----------------------------------------------------------------------------- main
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="3 small sizes (n = 1, 4, 8)")
    ap.add_argument("--n", type=int, nargs="*", default=None, help="tessellation levels")
    ap.add_argument("--ref-spp", type=int, default=None)
    ap.add_argument("--spp", type=int, default=CYCLES_SPP)
    ap.add_argument("--timeout", type=float, default=1800)
    ap.add_argument("--repeat", type=int, default=3,
                    help="our bake runs per size, each in a new child process; the fastest is kept (this shared"
                         " machine's noise is larger than the steps the time rule compares)")
    ap.add_argument("--no-cycles", action="store_true")
    ap.add_argument("--results", default=None)
    ap.add_argument("--ours-child", nargs=3, metavar=("N", "PROBES", "OUT"))
    ap.add_argument("--cycles-child", nargs=4, metavar=("N", "SPP", "PROBES", "OUT"))
    args = ap.parse_args(argv)
    if args.ours_child:
        n, p, o = args.ours_child
        ours_child(int(n), p, o)
        return 0
    if args.cycles_child:
        n, spp, p, o = args.cycles_child
        cycles_child(int(n), int(spp), p, o)
        return 0
    results_path = args.results or os.path.join(OUT_DIR, "dense_quick.json" if args.quick else "dense.json")
    ns = args.n or (QUICK_N if args.quick else FULL_N)
    ref_spp = args.ref_spp or (256 if args.quick else 1024)
    if args.quick and args.ref_spp is None:   # the full run's reference when it is cached
        import cycles_reference as cr
        _, objs = build_scene(scenes_bench.cornell())
        key = cr.cache_key(objs, dict(samples=1024, seed=sve.REF_SEED, mode="COMBINED", bounces=sve.BOUNCES))
        if os.path.exists(os.path.join(CACHE_DIR, f"cycles_{key}.npz")):
            ref_spp = 1024
    t0 = time.perf_counter()
    res = {"quick": args.quick, "machine": sve.machine_info(), "started": time.strftime("%Y-%m-%d %H:%M:%S"),
           "uptime_start": uptime(), "command": " ".join(["bench/bench_dense.py", *(argv if argv is not None else sys.argv[1:])]),
           "emission": emission_mode(), "repeat": max(1, args.repeat), "rows": []}
    log(f"uptime: {res['uptime_start']}")
    os.makedirs(OUT_DIR, exist_ok=True)
    probes_path = os.path.join(OUT_DIR, "dense_probes.npz")
    res["reference"] = make_probes(ref_spp, probes_path)
    # ours first, in rounds over every size (the sizes' runs minutes apart, not tens of minutes with
    # Cycles' bakes between them: this machine's speed drifts by the hour), then Cycles
    rounds = {n: [] for n in ns}
    for i in range(max(1, args.repeat)):
        for n in ns:
            rounds[n].append(run_child("ours", [n, probes_path], args.timeout))
            r = rounds[n][-1]
            log(f"  round {i + 1}, n={n}: " + (f"bake {r['core_seconds']:.2f} s" if "core_seconds" in r else f"failed: {r}"))
    for n in ns:
        row = {"n": n}
        runs = rounds[n]
        done = [r for r in runs if "core_seconds" in r]
        row["ours"] = min(done, key=lambda r: r["core_seconds"]) if done else runs[0]
        row["ours"]["core_runs"] = [r["core_seconds"] for r in done]
        o = row["ours"]
        if "core_seconds" in o:
            st = o["stages"]
            log(f"n={n:3d} {o['triangles']:7d} tris: {o['pieces']} pieces, {o['patches']} patches,"
                f" {o['output_vertices']} out verts; bake {o['core_seconds']:.2f} s (runs "
                + " / ".join(f"{x:.2f}" for x in o["core_runs"]) + "; "
                + ", ".join(f"{k} {v:.2f}" for k, v in st.items() if k != "total")
                + f"), read {o.get('read_seconds', float('nan')):.2f}, write {o.get('write_seconds', float('nan')):.2f};"
                f" forecast {o.get('forecast') or float('nan'):.2f} s;"
                f" peak {o['peak_mb']:.0f} MB; probe rms {100 * o['error']['rms']:.2f}% floor {o['error']['floor_ratio']:.3f}"
                f" red {o['error']['red_ratio']:.3f}  (load {o['load'][0][0]:.1f})")
        else:
            log(f"n={n}: ours failed: {o}")
        if not args.no_cycles:
            row["cycles"] = run_child("cycles", [n, args.spp, probes_path], args.timeout)
            c = row["cycles"]
            if "seconds" in c:
                log(f"        Cycles {args.spp} spp: {c['seconds']:.2f} s (build {c['build_seconds']:.1f}), peak"
                    f" {c['peak_mb']:.0f} MB; probe rms {100 * c['error']['rms']:.2f}% floor {c['error']['floor_ratio']:.3f}"
                    f" red {c['error']['red_ratio']:.3f}")
            else:
                log(f"        Cycles failed: {c}")
        res["rows"].append(row)
        with open(results_path, "w") as f:
            json.dump(res, f, indent=1, default=float)
    res["seconds"] = time.perf_counter() - t0
    res["uptime_end"] = uptime()
    with open(results_path, "w") as f:
        json.dump(res, f, indent=1, default=float)
    log("\nTargets (issue 9):")
    for t, meas, ok in targets(res):
        log(f"  [{'HOLDS' if ok else 'FAILS'}] {t}: {meas}")
    log(f"\nbench_dense done in {res['seconds']:.0f} s; results {results_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
