"""The performance report: docs/performance.md and its plots, from the results in bench/out/.

    .venv/bin/python bench/report.py            # rewrite the report, run nothing
    .venv/bin/python bench/report.py --quick    # from the --quick runs' results

``bench/run_all.py`` (``make bench``) calls this after the benchmarks. Every benchmark saves its
results as JSON in bench/out/ (git-ignored); this file only reads them, so the whole report can
be rewritten without running anything. A missing file leaves its section and targets out.

    results.json, results_quick.json   speed_vs_error.py: Cycles sweep, our candidates, relight,
                                       form factors and peak memory, profile (the headline)
    dense.json, dense_quick.json       bench_dense.py: the tessellation sweep (issue 9)
    bench_parallel.json                bench_parallel.py: stages on 1 and 2 workers
    bench_batch.json                   bench_batch.py: ``batch -j 2`` against ``-j 1``
    relight_dense.json                 bench_relight_dense.py: a dense room's relight
    curved.json                        bench_curved.py: Suzanne subdivided in the Cornell box
    formfactors.json                   bench_formfactors.py: ms per hemi-cube, NumPy and Embree
    real_scenes.json, real_scenes_quick.json
                                       real_scenes.py: the defaults on ../shared/scenes against Cycles
    lightmap_real.json                 lightmap_real.py: lightmaps on a real scene against Cycles' image bake

Of a pair, the newer file is read (``--quick``: the quick one). The targets are those each
benchmark prints (speed_vs_error.targets, bench_dense.targets) and the thresholds of issue 9 the
other benchmarks measure. History stays in git: the report holds this run only.
"""
from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)

import bench_dense  # noqa: E402
import lightmap_real  # noqa: E402
import real_scenes  # noqa: E402
import speed_vs_error as sve  # noqa: E402

OUT_DIR = os.path.join(ROOT, "bench", "out")
DOC = os.path.join(ROOT, "docs", "performance.md")
IMG_DIR = os.path.join(ROOT, "docs", "img")
METRIC = sve.METRIC
RELIGHT_TARGET = 50.0      # issue 9: a relight of a ~4,000-face room >= 50x a Cycles re-bake
CORES_TARGET = 1.8         # issue 9: two workers ~1.8x one (bench_parallel.TARGET, bench_batch.TARGET)


# ----------------------------------------------------------------------------- inputs
def _read(name):
    path = os.path.join(OUT_DIR, name)
    if not os.path.exists(path):
        return None
    with open(path) as f:
        return json.load(f)


def _newer(full, quick, force_quick):
    """The newer of a full run's and a quick run's file (the quick one with ``force_quick``)."""
    paths = [p for p in ((quick,) if force_quick else (full, quick)) if os.path.exists(os.path.join(OUT_DIR, p))]
    return _read(max(paths, key=lambda p: os.path.getmtime(os.path.join(OUT_DIR, p)))) if paths else None


def load(force_quick=False):
    return {"sve": _newer("results.json", "results_quick.json", force_quick),
            "dense": _newer("dense.json", "dense_quick.json", force_quick),
            "parallel": _read("bench_parallel.json"), "batch": _read("bench_batch.json"),
            "relight": _read("relight_dense.json"), "curved": _read("curved.json"),
            "formfactors": _read("formfactors.json"),
            "real": _newer("real_scenes.json", "real_scenes_quick.json", force_quick),
            "lightmap": _read("lightmap_real.json")}


# ----------------------------------------------------------------------------- formatting
def _pct(x, d=2):
    return "n/a" if x is None or not np.isfinite(x) else f"{100 * x:.{d}f}%"


def _s(x):
    if x is None or not np.isfinite(x):
        return "n/a"
    return f"{x:.3f}" if x < 1 else f"{x:.2f}" if x < 100 else f"{x:.0f}"


def _x(x):
    return "n/a" if x is None or not np.isfinite(x) else f"{x:.2f}x"


def _table(head, rows):
    return ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)] + ["| " + " | ".join(r) + " |" for r in rows]


def _quick(d):
    return " (`--quick`)" if d and d.get("quick") else ""


def _best_of(d):
    return f", best of {d['repeat']}" if d.get("repeat") else ""


# ----------------------------------------------------------------------------- plots
def plot_group(c):
    """One plotted line per method family (frontier of its candidates)."""
    if c.get("direct", "exact") == "hemicube":
        return "paper: emitters through F"
    if c.get("element_size"):
        return f"{c['method']} + elements"
    return c["method"]


def _pyplot():
    """matplotlib's pyplot on the Agg backend (no display here)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _save(plt, fig, img_dir, name, dpi):
    """Lay ``fig`` out, write it to ``img_dir/name`` and close it; returns the path."""
    fig.tight_layout()
    os.makedirs(img_dir, exist_ok=True)
    path = os.path.join(img_dir, name)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path


def plot_time_vs_error(results, img_dir):
    """Error against time, Cycles' sweep and our candidates' frontiers, one panel a scene:
    docs/img/perf_time_vs_error.png."""
    plt = _pyplot()

    scs = results["scenes"]
    fig, axes = plt.subplots(1, len(scs), figsize=(5.2 * len(scs), 4.4), squeeze=False)
    group_colours = {"hemicube": "tab:blue", "embree": "tab:orange", "embree_stochastic": "tab:green",
                     "hemicube + elements": "tab:purple", "embree_stochastic + elements": "tab:red",
                     "paper: emitters through F": "tab:gray"}
    for ax, sc in zip(axes[0], scs):
        c = sorted(sc["cycles"], key=lambda c: c["seconds"])
        ax.plot([x["seconds"] for x in c], [100 * x["error"][METRIC] for x in c], "o-", color="k", label="Cycles")
        for x in c:
            ax.annotate(f"{x['spp']}", (x["seconds"], 100 * x["error"][METRIC]), fontsize=7,
                        textcoords="offset points", xytext=(3, 3))
        groups = {}
        for x in sc["ours"]:
            groups.setdefault(plot_group(x), []).append(x)
        for m, o in sorted(groups.items()):
            col = group_colours.get(m, None)
            ax.scatter([x["seconds"] for x in o], [100 * x["error"][METRIC] for x in o], s=10, alpha=0.4, color=col)
            pts = [(x["seconds"], x["error"][METRIC]) for x in o]
            f = [o[i] for i in sve.pareto(pts)]
            ax.plot([x["seconds"] for x in f], [100 * x["error"][METRIC] for x in f], "s-", ms=4,
                    color=col, label=f"ours: {m}")
        for x in sc["ours"]:
            if x.get("defaults"):
                ax.scatter([x["seconds"]], [100 * x["error"][METRIC]], marker="*", s=140, color="gold",
                           edgecolors="k", zorder=5, label="ours: defaults")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("time, scene -> colours written (s)")
        ax.set_ylabel("relative RMS error, reference noise removed (%)")
        ax.set_title(f"{sc['name']}: {sc['fine_faces']} faces", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    return _save(plt, fig, img_dir, "perf_time_vs_error.png", dpi=110)


def plot_dense(res, img_dir):
    """Bake time and probe error against triangles, ours and Cycles: docs/img/perf_dense.png."""
    plt = _pyplot()

    rows = [r for r in res["rows"] if "core_seconds" in r.get("ours", {})]
    if not rows:
        return None
    tri = [r["ours"]["triangles"] for r in rows]
    cyc = [(r["ours"]["triangles"], r["cycles"]) for r in rows if "seconds" in r.get("cycles", {})]
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    a.plot(tri, [bench_dense.ours_total(r["ours"]) for r in rows], "s-", label="ours (defaults, read + bake + write)")
    b.plot(tri, [100 * r["ours"]["error"]["rms"] for r in rows], "s-", label="ours")
    if cyc:
        spp = cyc[0][1]["spp"]
        a.plot([t for t, _ in cyc], [c["seconds"] for _, c in cyc], "o-", color="k", label=f"Cycles {spp} spp")
        b.plot([t for t, _ in cyc], [100 * c["error"]["rms"] for _, c in cyc], "o-", color="k", label=f"Cycles {spp} spp")
    for ax, y in ((a, "time (s)"), (b, "probe RMS against the reference (%)")):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("triangles")
        ax.set_ylabel(y)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    return _save(plt, fig, img_dir, "perf_dense.png", dpi=100)


def plot_parallel(res, img_dir):
    """Each stage's wall time on 1 and 2 workers, one panel a case: docs/img/perf_parallel.png."""
    plt = _pyplot()

    cases = res.get("cases") or {}
    if not cases:
        return None
    fig, axes = plt.subplots(1, len(cases), figsize=(5 * len(cases), 3.6), squeeze=False)
    for ax, (label, case) in zip(axes[0], cases.items()):
        st = [k for k in case["stages"] if k not in ("total", "estimate")]
        configs = list(case["stages"]["total"]["wall"])
        w = 0.8 / len(configs)
        for i, c in enumerate(configs):
            ax.bar(np.arange(len(st)) + i * w, [case["stages"][k]["wall"][c] for k in st], w,
                   label=f"{c} worker{'s' if c != '1' else ''}")
        ax.set_xticks(np.arange(len(st)) + w * (len(configs) - 1) / 2)
        ax.set_xticklabels(st, rotation=30, fontsize=8)
        ax.set_ylabel("wall time (s)")
        ax.set_title(label, fontsize=10)
        ax.legend(fontsize=8)
    return _save(plt, fig, img_dir, "perf_parallel.png", dpi=100)


def _img(path, doc, alt):
    return [f"![{alt}]({os.path.relpath(path, os.path.dirname(doc))})", ""] if path else []


# ----------------------------------------------------------------------------- targets
def targets(r):
    """(target, measured, holds) rows of every benchmark whose results are present."""
    out = []
    if r["sve"]:
        out += [(t, m + _quick(r["sve"]), ok) for t, m, ok in sve.targets(r["sve"])]
    if r["dense"]:
        out += [(f"Dense box: {t}", m + _quick(r["dense"]), ok) for t, m, ok in bench_dense.targets(r["dense"])]
    rl = r["relight"]
    if rl:
        out.append((f"Relight of a {rl['faces']:,}-face room >= {RELIGHT_TARGET:.0f}x a Cycles {rl['spp']}-spp re-bake"
                    " (issue 9)", f"{_s(rl['relight_seconds'])} s (median of {rl['repeat']}) vs Cycles"
                    f" {_s(rl['cycles_seconds'])} s: {rl['ratio']:.0f}x" + _quick(rl), rl["ratio"] >= RELIGHT_TARGET))
    par = r["parallel"]
    if par and par.get("cases"):
        whole = {k: c["stages"]["total"]["speedup"]["2"] for k, c in par["cases"].items()}
        ff = {k: c["stages"]["form_factors"]["speedup"]["2"] for k, c in par["cases"].items()}
        best = max(whole, key=whole.get)
        out.append((f"Both cores: a bake on 2 workers ~{CORES_TARGET}x one (issue 9)",
                    f"whole bake {_x(whole[best])} ({best}; the machine's ceiling {_x(par.get('ceiling'))});"
                    f" form factors best {_x(max(ff.values()))}" + _quick(par), whole[best] >= CORES_TARGET))
    if r.get("real"):
        out += [(f"Real scenes: {t}", m + _quick(r["real"]), ok) for t, m, ok in real_scenes.targets(r["real"])]
    b = r["batch"]
    if b:
        out.append((f"Batch: {b['files']} demo-size files, `-j 2` ~{b['target']}x `-j 1` on {b['cores']} cores",
                    f"{_s(b['j1_s'])} s -> {_s(b['j2_s'])} s: {_x(b['speedup'])}" + _quick(b), b["speedup"] >= 0.95 * b["target"]))
    return out


# ----------------------------------------------------------------------------- sections
def machine_section(r):
    src = r["sve"] or r["dense"] or {}
    m = src.get("machine") or sve.machine_info()
    load = [x for x in (m.get("load_avg_start"), m.get("load_avg_end")) if x]
    return ["## Machine", "",
            f"- {m.get('cpus')} logical CPUs ({m.get('cpu', '?')}), {m.get('mem_gb', '?')} GB RAM; {m.get('platform')}",
            f"- Python {m.get('python')}, NumPy {m.get('numpy')}, bpy {m.get('bpy', '?')} (Cycles on the CPU,"
            f" 2 threads), embreex {m.get('embreex')}",
            f"- Commit {m.get('git', '?')}" + (f" with uncommitted changes to {', '.join(m['dirty'])}"
                                                if m.get("dirty") else ""),
            "- Load average " + " -> ".join(f"{x[0]:.1f}" for x in load) + " (a shared machine: ratios measured"
            " side by side carry over to other machines, absolute seconds do not)" if load else "", ""]


METHOD = [
    "## Method", "",
    "- **Error against Cycles.** Each scene has a fixed evaluation mesh (~4,000 faces). The reference is a Cycles"
    " COMBINED vertex bake of it at high samples (cached in `bench/cache/`); Cycles at fewer samples (another seed)"
    " and our bakes are read at its vertices (ours by `interpolate_at`). Per vertex, with luminance weights"
    " w = (0.2126, 0.7152, 0.0722), e_v = sqrt(sum_c w_c (x_c - r_c)^2); **RMS** = sqrt(mean e_v^2) / mean"
    " luminance of the reference, with the reference's own noise (fitted over the Cycles sweep) taken out; raw ="
    " as measured. **smooth** = RMS of (vertex - mean of its edge neighbours) / that mean on flat, evenly lit"
    " faces (the reference's own value is the bar).",
    "- **Time.** Cycles: `bpy.ops.object.bake` (scene -> colours on the mesh). Ours: the add-on's read +"
    " `pipeline.bake` + write. A ratio is Cycles' time / ours to the same error (Cycles interpolated log-log"
    " along its samples sweep).",
    "- **Defaults** = `BakeSettings()` as shipped. The dense sweep reads every tessellation at one set of probe"
    " points; memory is a child process's peak resident set.", ""]


def headline_section(res):
    L = ["## Headline ratios", "", "Cycles' time / ours to the same RMS error (ours: the fastest candidate at or"
         " below it).", ""]
    rows = []
    for sc in res["scenes"]:
        h = sve.headline(sc)
        a = h.get("at_c64", {})
        cells = [f"{_s(h[k]['cycles_seconds'])} / {_s(h[k]['ours_seconds'])} s = "
                 + (f"**{h[k]['ratio']:.1f}x**" if np.isfinite(h[k]["ratio"]) else "not reached")
                 for k in ("at_0.02", "at_0.01")]
        rows.append([sc["name"], _pct(a.get("error", float("nan"))), f"{_s(a.get('cycles_seconds'))} /"
                     f" {_s(a.get('ours_seconds'))} s = " + (f"**{a['ratio']:.1f}x**" if a and np.isfinite(a["ratio"])
                                                            else "not reached"), *cells])
    return L + _table(["scene", "Cycles 64 spp's error", "at that error", "at 2% RMS", "at 1% RMS"], rows) + [""]


def targets_section(r):
    rows = [[t, m, "yes" if ok else "**no**"] for t, m, ok in targets(r)]
    return ["## Targets", ""] + _table(["target", "measured", "holds"], rows) + [""]


def sve_section(res, doc, img_dir):
    L = ["## Speed against error" + _quick(res), "",
         f"`bench/speed_vs_error.py`: every scene's Cycles sweep and our candidates (method, hemi-cube resolution or"
         f" rays, patch and element sizes). Below: the candidates on our time-error frontier and the defaults; the"
         f" rest are in `bench/out/results{'_quick' if res.get('quick') else ''}.json`.", ""]
    L += _img(plot_time_vs_error(res, img_dir), doc, "time against error")
    for sc in res["scenes"]:
        L += [f"### `{sc['name']}`: {sc['title']}", "",
              f"{sc['fine_faces']:,} evaluation faces; reference {sc['ref_spp'] or '?'} spp ({sc['ref_seconds']:.0f} s),"
              f" its noise {_pct(sc['ref_noise']['rms'])} RMS, its smoothness {_pct(sc.get('smooth_ref'))};"
              f" {sc.get('compared', '?')} vertices compared.", ""]
        L += _table(["Cycles spp", "time (s)", "RMS", "raw RMS", "p95", "smooth"],
                    [[str(c["spp"]), _s(c["seconds"]), _pct(c["error"][METRIC]), _pct(c["error"]["rms"]),
                      _pct(c["error"]["p95"]), _pct(c.get("smooth"))] for c in sc["cycles"]]) + [""]
        front = set(sve.pareto([(o["seconds"], o["error"][METRIC]) for o in sc["ours"]]))
        shown = [o for i, o in enumerate(sc["ours"]) if i in front or o.get("defaults")]
        L += _table(["ours", "patches", "time (s)", "form factors", "direct", "solve", "vertices", "RMS", "raw RMS",
                     "p95", "smooth"],
                    [[o["label"], str(o["patches"]), _s(o["seconds"]), _s(o["stages"]["form_factors"]),
                      _s(o["stages"].get("direct")), _s(o["stages"]["solve"]), _s(o["stages"].get("vertices")),
                      _pct(o["error"][METRIC]), _pct(o["error"]["rms"]), _pct(o["error"]["p95"]), _pct(o.get("smooth"))]
                     for o in sorted(shown, key=lambda o: o["seconds"])]) + [""]
        rls = sc.get("relight") or []
        for rl in ([rls] if isinstance(rls, dict) else rls):
            L += [f"Relight ({rl['label']}): {_s(rl['seconds'])} s against a Cycles re-bake to the same"
                  f" {_pct(rl['error_rms'])} RMS, {_s(rl['cycles_seconds'])} s: **{rl['ratio']:.0f}x**.", ""]
    mem = [m for m in res.get("memory", []) if "nnz" in m]
    if mem:
        L += ["### Form factors and peak memory", "",
              "One child process a row, the Cornell box cut into N patches; peaks are the resident set's growth in the"
              " stage. 'Rest' = direct light, solve and vertices with F cached.", ""]
        L += _table(["patches", "method", "res / rays", "form factors (s wall / CPU)", "ms per row", "nnz", "F (MB)",
                     "FF peak (MB)", "rest (s)", "rest peak (MB)", "dense N x N float32 (MB)"],
                    [[str(m["patches"]), m["method"], str(m["work"]), f"{m['ff_seconds']:.2f} /"
                      f" {m.get('ff_cpu_seconds', float('nan')):.2f}", f"{m['ms_per_row']:.2f}", f"{m['nnz']:,}",
                      f"{m['ff_mb']:.0f}", f"{m['ff_peak_mb']:.0f}", f"{m['rest_seconds']:.2f}",
                      f"{m['rest_peak_mb']:.0f}", f"{m['dense_mb']:.0f}"] for m in mem]) + [""]
    pr = res.get("profile")
    if pr:
        L += [f"Hemi-cube rasteriser under cProfile ({pr['patches']} patches, resolution {pr['resolution']},"
              f" {pr['seconds']:.2f} s), by own time: " + "; ".join(
                  f"`{x['function']}` {x['tottime']:.3f} s" for x in pr["rows"][:6]) + ".", ""]
    return L


def dense_section(res, doc, img_dir):
    ref = res["reference"]
    L = ["## Dense meshes: a tessellation sweep" + _quick(res), "",
         "`bench/bench_dense.py`: the Cornell box with every quad cut into n x n quads of two triangles, baked with"
         f" the defaults (fastest of {res.get('repeat', 1)} child processes) and by Cycles at 64 spp; both read at"
         f" {ref['probes']:,} probe points of a {ref['spp']}-spp reference. floor = mean floor luminance / the"
         " reference's; red = R/G of the floor near the red wall / the reference's. Times in seconds.", ""]
    L += _img(plot_dense(res, img_dir), doc, "dense sweep")
    rows = []
    for r in res["rows"]:
        o, c = r.get("ours", {}), r.get("cycles", {})
        if "core_seconds" not in o:
            rows.append([f"n={r['n']}", "failed"] + [""] * 11)
            continue
        st, e, ce = o["stages"], o["error"], c.get("error", {})
        cy = "seconds" in c
        rows.append([f"{o['triangles']:,}", f"{o['patches']:,}", f"{o['output_vertices']:,}", _s(st.get("form_factors")),
                     _s(st.get("vertices")), _s(o["core_seconds"]), f"{o['peak_mb']:.0f}", _pct(e["rms"], 1),
                     f"{e['floor_ratio']:.3f} / {e['red_ratio']:.3f}", _s(c["seconds"]) if cy else "failed",
                     _pct(ce.get("rms"), 1) if cy else "", f"{ce['floor_ratio']:.3f} / {ce['red_ratio']:.3f}" if cy else "",
                     _x(c["seconds"] / bench_dense.ours_total(o)) if cy else ""])
    L += _table(["triangles", "patches", "output vertices", "form factors", "vertices", "bake", "peak (MB)",
                 "probe RMS", "floor / red", "Cycles (s)", "Cycles RMS", "Cycles floor / red", "Cycles / ours"], rows)
    said = [(r["ours"]["triangles"], r["ours"]["forecast"], r["ours"]["core_seconds"]) for r in res["rows"]
            if "core_seconds" in r.get("ours", {}) and r["ours"].get("forecast")]
    if said:
        L += ["", "Each bake's forecast (`result.forecast`) / its time: " + "; ".join(
            f"{t:,} triangles {f / b:.2f}x" for t, f, b in said) + "."]
    return L + [""]


def real_section(res):
    """bench/real_scenes.py: one row a scene of ../shared/scenes, failures as rows."""
    L = ["## Real scenes" + _quick(res), "",
         f"`bench/real_scenes.py` (`make bench-real`): the scenes of `../shared/scenes`, made by others (credits in its"
         f" README.md), and `generated_terrain` (`bench/terrain.py`: 1 km of ground as 128 x 128 quads with five"
         f" buildings), each lit as the module says (a sun and a sky where the file has no light, point lamps inside"
         f" the closed `sauer_pandora`), baked by us with `BakeSettings()` through the CLI's `BakeJob` (one child"
         f" process a bake, peak resident set with Blender) and once with patches twice as large (\"coarser\");"
         f" Cycles COMBINED vertex bakes of the same scene at {res['cand_spp']} spp and, as the reference,"
         f" {res['ref_spp']} spp (not 4,096: minutes per 64 samples on the big scenes on 2 cores)"
         + (f", with {res['glossy']} glossy bounces and reflective caustics as a user's render has them (light off"
            " metal and glossy layers reaches the walls)" if res.get("glossy") else ", with no glossy bounce")
         + (", and Filter Glossy off (unbiased, as the tests compare: Blender's default 1.0 loses light that"
            " glossy layers hand on after a diffuse bounce, 5.2% of `godot_zdm2`'s)"
            if str(res.get("filter_glossy", "default")) not in ("default", "None") else "")
         + ". RMS at Cycles' face"
         " corners matched by position and normal, zero-area faces, corners Cycles shades on a triangle without area"
         " (it bakes them at another vertex with an undefined normal), emitters, and corners Cycles never lights where"
         " the geometry says why (another face passes through its bake point, a duplicated or back-to-back face, or no"
         " ray from it reaches light, a solid buried in another: `bench/dark_corners.py`; the other never-lit corners"
         " are compared) left out, the reference's own noise taken out. Ours: read + bake + write (s); Cycles: `bpy.ops.object.bake` (the run that"
         " filled the cache). Relight: after the defaults' bake, every lamp, emitting material and the world's strength x"
         f" {real_scenes.RELIGHT:g} and the bake again, in the same process (the session's cache) and through"
         " `--cache` in a new process (a first child fills the folder), against Cycles' 64-spp time (a re-bake"
         " costs Cycles as much). Failures (refused, crashed, timed out) are rows with their first error line."
         + (f" The run took {res['seconds'] / 60:.0f} min." if res.get("seconds") else ""), ""]
    L += real_scenes.table(res) + [""]
    notes = []
    for sc in res["scenes"]:
        d, c = sc.get("defaults") or {}, sc.get("cycles") or {}
        bits = [c.get("light") or d.get("light") or sc.get("light_kind", "")]
        if not real_scenes.failed(d) and d:
            bits.append(f"{d.get('compared', 0):,} of {c.get('corners', 0):,} corners compared")
            if c.get("flat_corners"):
                bits.append(f"{c['flat_corners']:,} on triangles without area left out")
            nl = c.get("never_lit")
            if nl and sum(nl.values()):
                bits.append(f"never lit by Cycles: {nl['covered']:,} on another face and {nl['sealed']:,} sealed"
                            f" left out, {nl['counted']:,} compared")
            if d.get("corners_unmatched"):
                bits.append(f"{d['corners_unmatched']:,} not matched to a face of ours")
            if d.get("vertices_nan"):
                bits.append(f"**{d['vertices_nan']:,} of {d['vertices']:,} output vertices NaN**")
        notes.append(f"- `{sc['name']}`: " + "; ".join(b for b in bits if b) + ".")
    done = {sc["name"] for sc in res["scenes"]}
    missing = [s.folder for s in real_scenes.SPECS if s.folder not in done]
    if missing:
        notes.append("- Not in this run: " + ", ".join(f"`{m}`" for m in missing) + ".")
    notes.append("- Each scene from a camera, Cycles' render beside a render of our baked copies:"
                 " [gallery.md](gallery.md) (`bench/gallery.py`).")
    levels = real_scenes.levels_table(res)
    if levels:
        notes += ["", "### Quality levels", "",
                  "The same scenes at each level of the Quality setting (`bench/real_scenes.py --levels`):"
                  " Production is the defaults above; the others set the detailed settings that"
                  " `core/settings.py` `QUALITY` names. Error against the same reference.", ""] + levels
    return L + notes + [""]


def parallel_section(res, doc, img_dir):
    L = ["## Both cores: one worker against two" + _quick(res), "",
         f"`bench/bench_parallel.py`: each case baked with 1 worker, 2 workers (forked processes where they pay) and"
         f" 2 workers on threads only (each stage's best run{_best_of(res)}). This machine's ceiling (two"
         f" processes of plain Python at once against one): {_x(res.get('ceiling'))}; other processes used"
         f" {res.get('other_cpus', float('nan')):.2f} of {res.get('cpus')} CPUs during the run.", ""]
    L += _img(plot_parallel(res, img_dir), doc, "stages on 1 and 2 workers")
    rows = []
    for label, case in res["cases"].items():
        configs = list(case["stages"]["total"]["wall"])
        for i, (st, v) in enumerate((k, x) for k, x in case["stages"].items() if k != "estimate"):
            rows.append([label if i == 0 else "", st] + [_s(v["wall"][c]) for c in configs]
                        + [_x(v["speedup"][c]) for c in configs[1:]])
        same = ", ".join(f"{c}: {'yes' if ok else '**no**'}" for c, ok in case["identical"].items())
        rows.append(["", f"identical to 1 worker: {same}"] + [""] * (2 * len(configs) - 1))
    configs = list(next(iter(res["cases"].values()))["stages"]["total"]["wall"])
    L += _table(["case", "stage"] + [f"{c} (s)" for c in configs] + [f"1 / {c}" for c in configs[1:]], rows)
    return L + [""]


def batch_section(b):
    return ["## Batch: files on both cores" + _quick(b), "",
            f"`bench/bench_batch.py`: {b['files']} copies of the demo's Cornell box baked by `python -m"
            f" hemicube_radiosity batch` (best wall time{_best_of(b)}): `-j 1` {_s(b['j1_s'])} s, `-j 2`"
            f" {_s(b['j2_s'])} s, **{_x(b['speedup'])}** on {b['cores']} cores (target ~{b['target']}x).", ""]


def relight_section(rl):
    st = rl.get("stages", {})
    return ["## Relight of a dense room" + _quick(rl), "",
            f"`bench/bench_relight_dense.py`: the Cornell box as {rl['faces']:,} faces ({rl['patches']} patches,"
            f" {rl['output_vertices']:,} output vertices) baked once with a form-factor cache ({_s(rl['cold_seconds'])} s),"
            f" then relit {rl['repeat']} times (lamp brighter, red wall recoloured): median **{_s(rl['relight_seconds'])}"
            f" s** (fastest {_s(rl['fastest_seconds'])} s; solve {_s(st.get('solve'))}, vertices {_s(st.get('vertices'))})"
            f" against a Cycles {rl['spp']}-spp re-bake of {_s(rl['cycles_seconds'])} s: **{rl['ratio']:.0f}x**.", ""]


def curved_section(c):
    st = c["stages"]
    return ["## A dense curved mesh: Suzanne subdivided" + _quick(c), "",
            f"`bench/bench_curved.py`: Suzanne with a level-{c['level']} Subdivision Surface on the Cornell box's floor,"
            " the defaults against a Cycles COMBINED vertex bake in the same run, both read at her vertices.", ""] + _table(
        ["Suzanne faces", "pieces", "patches", "output vertices", "form factors", "direct", "vertices", "bake (s)",
         "peak (MB)", f"Cycles {c['spp']} spp (s)", "Cycles / ours", "mean luminance, ours / Cycles",
         "per-vertex RMS vs Cycles (its noise included)"],
        [[f"{c['faces']:,}", f"{c['pieces']:,}", f"{c['patches']:,}", f"{c['output_vertices']:,}",
          _s(st.get("form_factors")), _s(st.get("direct")), _s(st.get("vertices")), _s(c["seconds"]),
          f"{c['peak_mb']:.0f}", _s(c["cycles_seconds"]), f"**{_x(c['ratio'])}**", f"{c['luminance_ratio']:.3f}",
          _pct(c["rms"], 1)]]) + [""]


def formfactors_section(ff):
    return ["## Form-factor speed" + _quick(ff), "",
            "`bench/bench_formfactors.py`: closed box rooms cut into patches, F by the NumPy hemi-cube rasteriser and"
            " by Embree through the same pixel centres, on one worker.", ""] + _table(
        ["patches", "resolution", "method", "ms per hemi-cube", "CPU ms per hemi-cube", "total (s)", "nnz", "F (MB)",
         "max abs(row sum - 1)"],
        [[f"{x['patches']:,}", str(x["resolution"]), x["method"], f"{x['ms_per_hemicube']:.2f}",
          f"{x['cpu_ms_per_hemicube']:.2f}", _s(x["seconds"]), f"{x['nnz']:,}", f"{x['f_mb']:.1f}",
          f"{x['rowsum_error']:.1e}"] for x in ff["rows"]]) + [""]


def write(r, doc=DOC, img_dir=IMG_DIR):
    quick = any(d and d.get("quick") for d in r.values())
    L = ["# Performance", "",
         "Generated by `make bench` (`bench/run_all.py`, then `bench/report.py`) from the results in `bench/out/`"
         + ("; sections marked `--quick` come from the smoke run (fewer scenes, sizes and samples)" if quick else "")
         + ". Rewrite it without running anything: `.venv/bin/python bench/report.py`.", ""]
    L += machine_section(r) + METHOD
    if r["sve"]:
        L += headline_section(r["sve"])
    L += targets_section(r)
    if r["sve"]:
        L += sve_section(r["sve"], doc, img_dir)
    if r["dense"]:
        L += dense_section(r["dense"], doc, img_dir)
    if r.get("real"):
        L += real_section(r["real"])
    if r.get("lightmap") and r["lightmap"].get("maps"):
        L += lightmap_real.section(r["lightmap"])
    if r["parallel"] and r["parallel"].get("cases"):
        L += parallel_section(r["parallel"], doc, img_dir)
    for key, section in (("relight", relight_section), ("curved", curved_section), ("batch", batch_section),
                         ("formfactors", formfactors_section)):
        if r[key]:
            L += section(r[key])
    os.makedirs(os.path.dirname(doc), exist_ok=True)
    with open(doc, "w") as f:
        f.write("\n".join(L).rstrip("\n") + "\n")
    return len(L)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="read the --quick runs' results")
    ap.add_argument("--doc", default=DOC)
    ap.add_argument("--img-dir", default=IMG_DIR)
    args = ap.parse_args(argv)
    r = load(args.quick)
    if not any(r.values()):
        print(f"no results in {OUT_DIR}: run `make bench` first", file=sys.stderr)
        return 1
    write(r, args.doc, args.img_dir)
    print(f"report: {args.doc} (from {', '.join(k for k, v in r.items() if v)})")
    print("\nTargets:")
    for t, m, ok in targets(r):
        print(f"  [{'HOLDS' if ok else 'FAILS'}] {t}: {m}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
