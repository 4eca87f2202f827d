"""Speed against error: our hemi-cube/Embree bakes against Cycles' vertex bake, same vertices.

    .venv/bin/python bench/speed_vs_error.py            # full run (~30 min; references cached)
    .venv/bin/python bench/speed_vs_error.py --quick    # smoke run (~4 min)

For every scene of ``bench/scenes_bench.py`` a fixed fine evaluation mesh (~4,000 faces) is built
in Blender. Reference: Cycles' COMBINED vertex bake of that mesh at ``--ref-spp`` (4,096) samples,
cached under ``bench/cache/`` (tools/cycles_reference.cached_bake). Candidates, each timed:

* Cycles at {4, 16, 64, 256, 1024} spp on the same mesh (a different seed from the reference):
  time of ``bpy.ops.object.bake`` (scene -> colours written on the mesh);
* ours, ``core.pipeline.bake`` on the scene's MeshInputs (faces-as-patches on the fine mesh, or
  the coarse scene cut into patches of a given size) + the add-on's ``write_copies`` (scene ->
  colour attribute written), per method / resolution / rays; evaluated at the fine vertices by
  ``core.output.interpolate.interpolate_at``.

Error of a candidate at the fine vertices, emitters left out, with luminance weights
w = (0.2126, 0.7152, 0.0722) per channel: e_v = sqrt(sum_c w_c (x_c - r_c)^2).
``rms`` = sqrt(mean e_v^2) / mean(Y_ref) (relative RMS), ``p95`` = 95th percentile of
e_v / max(Y_ref,v, 0.05 mean Y_ref) (relative error per vertex, dark vertices floored).

Smoothness (issue 11; :func:`flat_vertices`, :func:`smoothness`): on flat faces away from shadow
boundaries and contacts, the RMS of (vertex luminance - mean of its edge neighbours) / that mean.
Measured for the reference itself, every Cycles sweep point and every candidate of ours; ours at
the defaults must be no worse than the reference's own value, on each scene.

Also: a relight (new light strength and wall colour, cached form factors) against a Cycles
re-bake at the same error, form factors for ~2,000 patches at resolution 64 (ms per hemi-cube),
peak memory for 2k/8k/32k patches (one subprocess each), a profile of the hemi-cube hot loop.
Writes bench/out/results.json (results_quick.json with ``--quick``) and prints the targets;
bench/report.py turns it into docs/performance.md.
"""
from __future__ import annotations

import argparse
import dataclasses
import cProfile
import io
import json
import os
import platform
import pstats
import subprocess
import sys
import time

# One BLAS thread: on a loaded 2-core machine OpenBLAS's worker threads wait for a free core and a
# 10 ms matrix product in the core's vertex stage took seconds of wall time (0.07 s of CPU).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "bench"))
sys.path.insert(0, os.path.join(ROOT, "tools"))

from hemicube_radiosity.core import pipeline  # noqa: E402
from hemicube_radiosity.core.runtime.cache import FormFactorCache  # noqa: E402
from hemicube_radiosity.core.light.direct import DirectLight  # noqa: E402
from hemicube_radiosity.core.output.interpolate import interpolate_at  # noqa: E402
from hemicube_radiosity.core.mesh.patches import MeshInput  # noqa: E402
from hemicube_radiosity.core.mesh.subdivide import build_patches  # noqa: E402

import scenes_bench  # noqa: E402

CACHE_DIR = os.path.join(ROOT, "bench", "cache")
OUT_DIR = os.path.join(ROOT, "bench", "out")
LUMA = np.array([0.2126, 0.7152, 0.0722])
REF_SEED = 4242          # reference seed; candidates use CAND_SEED (independent noise)
CAND_SEED = 7
BOUNCES = 32
METRIC = "rms_true"       # relative RMS with the reference's own noise taken out (see correct())


def log(*a):
    print(*a, flush=True)


# ----------------------------------------------------------------------------- error
def errors(x, ref, mask):
    d = np.asarray(x, float)[mask] - np.asarray(ref, float)[mask]
    e = np.sqrt((d * d) @ LUMA)
    Y = np.asarray(ref, float)[mask] @ LUMA
    mY = float(Y.mean())
    rms = float(np.sqrt(np.mean(e * e)) / mY)
    p95 = float(np.percentile(e / np.maximum(Y, 0.05 * mY), 95))
    bias = float(((np.asarray(x, float)[mask] @ LUMA).mean() - mY) / mY)
    return {"rms": rms, "p95": p95, "bias": bias}


def reference_noise(cyc, ref_spp):
    """The reference's own noise, from the Cycles sweep (independent seeds): the measured mean
    square error of a run with s samples is A s^-alpha (its noise) + A ref_spp^-alpha (the
    reference's). Fit A and alpha (least squares on log MSE); return the reference's RMS part."""
    s = np.array([c["spp"] for c in cyc], float)
    mse = np.array([c["error"]["rms"] ** 2 for c in cyc])
    best = None
    for alpha in np.linspace(0.6, 1.6, 201):
        x = s ** -alpha + ref_spp ** -alpha
        logA = np.mean(np.log(mse) - np.log(x))
        r = np.sum((np.log(mse) - logA - np.log(x)) ** 2)
        if best is None or r < best[0]:
            best = (r, alpha, logA)
    _, alpha, logA = best
    return {"alpha": float(alpha), "A": float(np.exp(logA)),
            "rms": float(np.sqrt(np.exp(logA) * ref_spp ** -alpha)), "ref_spp": ref_spp}


def correct(err, noise):
    """Add ``rms_true``: the RMS with the reference's noise variance taken out,
    sqrt(max(rms^2 - sigma_ref^2, 0)) (the candidate's error and the reference's noise are
    independent, so their variances add)."""
    err["rms_raw"] = err["rms"]
    err["rms_true"] = float(np.sqrt(max(err["rms"] ** 2 - noise["rms"] ** 2, 0.0)))
    return err


# ----------------------------------------------------------------------------- smoothness
def fine_edges(fine):
    """(E, 2) unique vertex pairs joined by an edge of the evaluation mesh ``fine`` (indices in the
    order of ``scenes_bench.fine_points``: the meshes' vertices one after the other)."""
    e, off = [], 0
    for m in fine:
        for f in range(len(m.face_offsets) - 1):
            ids = m.face_indices[m.face_offsets[f]:m.face_offsets[f + 1]] + off
            e.append(np.stack([ids, np.roll(ids, -1)], 1))
        off += len(m.verts)
    return np.unique(np.sort(np.concatenate(e), 1), axis=0)


def neighbour_mean(Y, edges):
    """(mean of ``Y`` over each vertex's edge neighbours, number of neighbours)."""
    V = len(Y)
    s = np.bincount(edges[:, 0], Y[edges[:, 1]], V) + np.bincount(edges[:, 1], Y[edges[:, 0]], V)
    c = np.bincount(edges[:, 0], None, V) + np.bincount(edges[:, 1], None, V)
    return s / np.maximum(c, 1), c


def flat_vertices(sc, pts, normals, mask, edges):
    """The vertices the smoothness figure is measured on: flat faces away from shadow boundaries and
    contacts. A vertex counts when

    * it has >= 4 edge neighbours: it lies inside an original face (the evaluation mesh has hard
      edges between original faces, so a vertex on a face's border or corner has 2-3);
    * it is compared at all (``mask``: not an emitter, not a never-lit hidden vertex);
    * it is lit by the direct light: D_v > 5% of the mean of D over ``mask``, where D is the exact
      direct luminance at the vertex (``core.light.direct.DirectLight.plan`` on a patches-only bake
      of the coarse scene: emitters, lamps and the world's sky seen from the vertex, shadow rays);
    * no neighbour's D differs from its own by more than 30% (of the larger): no shadow boundary;
    * and none of its neighbours fails one of the tests above (a one-vertex margin).

    A scene with no light at all has no D: only the flat/interior test (and the margin round
    masked vertices) applies. Returns (flat (V,) bool, whether D was used)."""
    V = len(pts)
    has_light = (bool(sc.lights) or sc.world is not None
                 or any(float(np.max(m.face_emission, initial=0)) > 0 for m in sc.coarse))
    dl = None
    if has_light:
        res0 = pipeline.bake(sc.coarse, pipeline.BakeSettings(element_size=None, gather_rays=0),
                             world=sc.world, lights=sc.lights)
        dl = DirectLight.plan(res0.patches, res0.settings, list(sc.lights), world=sc.world)
    _, count = neighbour_mean(np.zeros(V), edges)
    bad = ~mask
    if dl is not None:
        D = dl.at(pts + 1e-4 * normals, normals, "smoothness") @ LUMA
        a, b = D[edges[:, 0]], D[edges[:, 1]]
        rel = np.abs(a - b) / np.maximum(np.maximum(a, b), 1e-12)
        jump = np.zeros(V)
        np.maximum.at(jump, edges[:, 0], rel)
        np.maximum.at(jump, edges[:, 1], rel)
        bad = bad | (jump > 0.3) | ~(D > 0.05 * D[mask].mean())
    near_bad = bad.copy()
    np.logical_or.at(near_bad, edges[:, 0], bad[edges[:, 1]])
    np.logical_or.at(near_bad, edges[:, 1], bad[edges[:, 0]])
    return (count >= 4) & ~near_bad, dl is not None


def smoothness(Y, edges, flat):
    """The smoothness figure of vertex luminances ``Y`` (V,): over the ``flat`` vertices
    (:func:`flat_vertices`), the RMS of (Y_v - m_v) / m_v, m_v = mean of Y over v's edge
    neighbours. 0 = every flat vertex equals its neighbours' mean (locally linear); noise and
    blotches raise it. NaN when no vertex is flat."""
    Y = np.asarray(Y, float)
    m, _ = neighbour_mean(Y, edges)
    ok = flat & (m > 0)
    if not ok.any():
        return float("nan")
    return float(np.sqrt(np.mean(((Y - m)[ok] / m[ok]) ** 2)))


# ----------------------------------------------------------------------------- Blender side
def build_blender_scene(sc):
    """The fine mesh as Blender objects (one per MeshInput, materials per distinct rho/emission)."""
    import bpy
    import cycles_reference as cr

    scene = cr.new_empty_scene()
    if sc.world is not None:
        cr.set_world(tuple(sc.world), 1.0, scene=scene)
    else:
        cr.set_world((0.0, 0.0, 0.0), 0.0, scene=scene)
    objs = []
    for m in sc.fine:
        faces = [m.face_indices[m.face_offsets[f]:m.face_offsets[f + 1]].tolist()
                 for f in range(len(m.face_offsets) - 1)]
        key = [tuple(np.round(np.r_[m.face_rho[f], m.face_emission[f]], 6)) for f in range(len(faces))]
        kinds = sorted(set(key))
        mats = [_material(k[:3], k[3:], f"{m.name}_{i}") for i, k in enumerate(kinds)]
        me = bpy.data.meshes.new(m.name)
        me.from_pydata([tuple(map(float, v)) for v in m.verts], [], faces)
        me.update()
        for mat in mats:
            me.materials.append(mat)
        mi = np.array([kinds.index(k) for k in key], np.int32)
        me.polygons.foreach_set("material_index", mi)
        me.update()
        ob = bpy.data.objects.new(m.name, me)
        scene.collection.objects.link(ob)
        objs.append(ob)
    return scene, objs


def _material(rho, emission, name):
    """Diffuse ``rho`` plus, on an emitter, an Emission of colour ``emission`` (strength 1): a plain
    emitter as an artist's file has it, lighting both faces in Cycles, as our bake does by default
    (``BakeSettings.two_sided_emission``). Until issue 10 the bench gave Cycles' emitters a black back
    (a Backfacing mix) to match the paper's front-only patches; those references are not comparable."""
    import cycles_reference as cr

    if max(emission) <= 0:
        return cr.diffuse_material(tuple(rho), 0.0, name=name)
    return cr.diffuse_material(tuple(rho), 1.0, emission_color=tuple(map(float, emission)), name=name)


def cycles_values(bake, sc):
    return np.concatenate([bake.point[m.name] for m in sc.fine])


# ----------------------------------------------------------------------------- our bake
class Writer:
    """Times the add-on's write_copies for a result (read once; copies removed after)."""

    def __init__(self, objs):
        self.ok = False
        self.read_seconds = 0.0
        try:
            import bpy
            from hemicube_radiosity.blender.read import scene as read
            from hemicube_radiosity.blender import write
            t = time.perf_counter()
            dg = bpy.context.evaluated_depsgraph_get()
            self.scene_input = read.read_scene(dg, objs)
            self.read_seconds = time.perf_counter() - t
            self.write = write
            self.names = [o.name for o in objs]
            self.ok = True
        except Exception as exc:  # noqa: BLE001 - the add-on layer may be missing or changing
            self.error = f"{type(exc).__name__}: {exc}"

    def __call__(self, result):
        if not self.ok:
            return float("nan")
        import bpy
        t = time.perf_counter()
        self.write.write_copies(bpy.context, self.scene_input, result)
        dt = time.perf_counter() - t
        self.write.remove_bakes(self.names, unhide=True)
        return dt


def defaults_candidate():
    """The shipped defaults, ``BakeSettings()`` as they are (the scene's world and lights added by
    run_ours), as one labelled candidate; its fields are copied only for labels and bookkeeping."""
    d = pipeline.BakeSettings()
    c = dict(defaults=True, method=d.method, patch_size=d.patch_size, resolution=d.resolution,
             direct=d.direct, direct_samples=d.direct_samples, solver=d.solver)
    if d.method == "embree_stochastic":
        c["rays"] = d.rays_per_patch
    if d.uses_elements():
        c.update(element_size=d.element_size, gather_rays=d.gather_rays)
    return c


def settings_of(c):
    if c.get("defaults"):
        return pipeline.BakeSettings()
    # a candidate without elements is the patch solution itself, whatever BakeSettings defaults to
    kw = {"element_size": None, "gather_rays": 0}
    for k in ("direct", "direct_samples", "element_size", "gather_rays"):
        if k in c:
            kw[k] = c[k]
    return pipeline.BakeSettings.from_mapping(dict(
        kw, patch_size=c["patch_size"], resolution=c.get("resolution", 64), method=c["method"],
        rays_per_patch=c.get("rays", 512), solver=c.get("solver", "gauss_seidel"), tolerance=1e-4,
        max_iterations=500))


def run_ours(sc, cand, pts, owner, normals, writer, cache=None):
    s = settings_of(cand)
    meshes = sc.fine if cand["patch_size"] is None else sc.coarse
    t = time.perf_counter()
    res = pipeline.bake(meshes, s, world=sc.world, lights=sc.lights, cache=cache)
    core_s = time.perf_counter() - t
    wt = writer(res) if writer is not None else float("nan")
    vals = interpolate_at(res.elements, res.vertex_radiosity, pts, owner, normals)
    return res, core_s, wt, vals


# ----------------------------------------------------------------------------- frontier
def pareto(points):
    """Indices of (time, err) points not dominated (sorted by time)."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    out, best = [], float("inf")
    for i in order:
        if points[i][1] < best:
            out.append(i)
            best = points[i][1]
    return out


def cycles_time_at(cyc, err):
    """Cycles' time to reach RMS ``err``: log-log interpolation along its spp sweep; below its
    lowest error, extrapolated from the most accurate point with time ~ spp ~ error^-2 (Monte
    Carlo); above its highest error, the time of its cheapest run (fewer samples save little).
    NaN for an error of 0 or less: below the reference's own noise (the noise-corrected RMS of a
    noisy reference, the room's) no time can be claimed."""
    if not err > 0:
        return float("nan")
    pts = sorted((c["error"][METRIC], c["seconds"]) for c in cyc)
    e = np.log([p[0] for p in pts])
    t = np.log([p[1] for p in pts])
    if err < pts[0][0]:
        return float(pts[0][1] * (pts[0][0] / err) ** 2)
    if err >= pts[-1][0]:
        return float(min(p[1] for p in pts))
    return float(np.exp(np.interp(np.log(err), e, t)))


def ours_time_at(ours, err):
    ok = [o["seconds"] for o in ours if o["error"][METRIC] <= err]
    return min(ok) if ok else float("nan")


# ----------------------------------------------------------------------------- candidates
def candidate_grid(sc, quick, full_grid=True):
    """Our candidates: method x patch size x resolution/rays (direct light 'exact', the default),
    plus the paper's way (direct='hemicube': emitted light through F) and shadow-ray counts."""
    if quick:
        sizes = [sc.patch_sizes[-1], sc.patch_sizes[-2]]
        if sc.name != "cornell":
            return [dict(method="hemicube", patch_size=p, resolution=32) for p in sizes] + [
                dict(method="embree_stochastic", patch_size=sizes[0], rays=1024),
                dict(method="hemicube", patch_size=sizes[1], resolution=32, element_size=sc.fine_size,
                     gather_rays=256), defaults_candidate()]
        grid = [dict(method="hemicube", patch_size=p, resolution=r) for p in sizes for r in (32, 64)]
        grid += [dict(method="embree", patch_size=p, resolution=64) for p in sizes]
        grid += [dict(method="embree_stochastic", patch_size=p, rays=1024) for p in sizes]
        grid += [dict(method="hemicube", patch_size=sizes[0], resolution=64, direct="hemicube")]
        grid += [dict(method="hemicube", patch_size=p, resolution=32, element_size=sc.fine_size, gather_rays=g)
                 for p in sizes for g in (0, 256)]
        return grid + [defaults_candidate()]
    sizes = [None, *sc.patch_sizes]
    coarse = list(sc.patch_sizes)
    el = sc.fine_size
    if full_grid:
        grid = [dict(method="hemicube", patch_size=p, resolution=r) for p in sizes for r in (32, 64, 128, 256)]
        grid += [dict(method="embree", patch_size=p, resolution=r) for p in sizes for r in (32, 64, 128)]
        grid += [dict(method="embree_stochastic", patch_size=p, rays=n) for p in sizes for n in (256, 1024, 4096)]
        grid += [dict(method="hemicube", patch_size=p, resolution=r, direct="hemicube") for p in sizes[:3]
                 for r in (64, 128)]
        grid += [dict(method="hemicube", patch_size=p, resolution=r, element_size=el, gather_rays=g)
                 for p in coarse for r in (32, 64) for g in (0, 64, 256, 1024)]
        grid += [dict(method="embree_stochastic", patch_size=p, rays=256, element_size=el, gather_rays=g)
                 for p in coarse for g in (64, 256)]
        return grid + [defaults_candidate()]
    # the other scenes: a lighter grid (the full run must stay near 30 minutes)
    grid = [dict(method="hemicube", patch_size=p, resolution=r) for p in sizes for r in (32, 64)]
    grid += [dict(method="embree_stochastic", patch_size=p, rays=1024) for p in sizes]
    grid += [dict(method="hemicube", patch_size=p, resolution=64, direct="hemicube") for p in sizes[:2]]
    grid += [dict(method="hemicube", patch_size=p, resolution=32, element_size=el, gather_rays=g)
             for p in coarse for g in (0, 256, 1024)]
    grid += [dict(method="hemicube", patch_size=p, resolution=64, element_size=el, gather_rays=256) for p in coarse]
    return grid + [defaults_candidate()]


def cost_key(c, npatch):
    return (family(c), npatch, c.get("resolution", c.get("rays")))


def family(c):
    return (c["method"], c.get("direct", "exact"), c.get("direct_samples", 16), bool(c.get("element_size")),
            c.get("gather_rays", 0), bool(c.get("defaults")))


def dominated_by_slow(c, n, done, cap):
    """Skip when a cheaper run of the same method (fewer patches and lower res/rays) exceeded cap."""
    work = c.get("resolution", c.get("rays", 0))
    for d in done:
        if family(d) != family(c) or d.get("skipped"):
            continue
        if d["patches"] <= n and d["work"] <= work and d["seconds"] > cap:
            return True
    return False


def label(c):
    if c.get("defaults"):
        return "defaults: " + label({k: v for k, v in c.items() if k != "defaults"})
    p = _size(c["patch_size"], c.get("resolved", {}).get("patch_size"), "faces")
    if c["method"] == "embree_stochastic":
        s = f"embree_stochastic {c['rays']} rays, patches {p}"
    else:
        s = f"{c['method']} res {c['resolution']}, patches {p}"
    if c.get("direct", "exact") != "exact":
        s += f", direct {c['direct']}"
    if c.get("direct_samples", 16) != 16:
        s += f", {c['direct_samples']} shadow rays"
    if c.get("element_size"):
        s += ", elements " + _size(c["element_size"], c.get("resolved", {}).get("element_size")) + (f" + {c['gather_rays']} gather rays" if c.get("gather_rays")
                                                      else " (interpolated)")
    return s


def _size(v, resolved=None, none="none"):
    """A size for labels: world units, or 'auto' with the size it resolved to when known."""
    if v is None:
        return none
    if isinstance(v, str):
        return v if resolved is None else f"{v} = {resolved:.3g} m"
    return f"{v:g} m"


def _patch_count(sc, p):
    if p is None:
        return sc.n_fine_faces
    if isinstance(p, str):   # 'auto': what the pipeline resolves it to on the coarse scene
        p = pipeline.BakeSettings(patch_size=p).resolved(sc.coarse).patch_size
    return len(build_patches(sc.coarse, p))


def run_scene(sc, args):
    import cycles_reference as cr

    log(f"\n=== {sc.name}: {sc.title}; {sc.n_fine_faces} fine faces")
    scene, objs = build_blender_scene(sc)
    pts, owner, normals, emitter = scenes_bench.fine_points(sc.fine)
    ref_spp = args.ref_spp
    if ref_spp is None:   # quick run: the full run's reference when cached, else a cheaper one
        key = cr.cache_key(objs, dict(samples=4096, seed=REF_SEED, mode="COMBINED", bounces=BOUNCES))
        ref_spp = 4096 if os.path.exists(os.path.join(CACHE_DIR, f"cycles_{key}.npz")) else 1024
    t = time.perf_counter()
    ref = cr.cached_bake(objs, CACHE_DIR, samples=ref_spp, seed=REF_SEED, bounces=BOUNCES, threads=2)
    log(f"reference {ref_spp} spp: {'cached' if ref.cached else 'baked'} ({ref.seconds:.1f} s bake,"
        f" {time.perf_counter() - t:.1f} s here)")
    R = cycles_values(ref, sc)
    # vertices no light path reaches (floor under a block without a bottom, ceiling behind the
    # lamp's back) are never seen: leave them out with the emitters
    Yr = R @ LUMA
    hidden = Yr <= 1e-4 * np.median(Yr[~emitter])
    # and vertices on a contact line across their surface (the ground's on a wall's foot): the
    # light jumps there, Cycles gives about the mean of the two sides, ours the open side's
    contact = scenes_bench.contact_vertices(sc.coarse, pts, normals) & ~emitter & ~hidden
    mask = ~emitter & ~hidden & ~contact
    log(f"{int(mask.sum())} vertices compared ({int(emitter.sum())} emitter, {int((hidden & ~emitter).sum())} hidden,"
        f" {int(contact.sum())} on contact lines left out)")
    edges = fine_edges(sc.fine)
    t = time.perf_counter()
    flat, flat_lit = flat_vertices(sc, pts, normals, mask, edges)
    smooth_ref = smoothness(Yr, edges, flat)
    log(f"smoothness: {int(flat.sum())} flat vertices ({'direct light tested' if flat_lit else 'interior test only'},"
        f" {time.perf_counter() - t:.1f} s); reference {100 * smooth_ref:.2f}%")
    out = {"name": sc.name, "title": sc.title, "fine_faces": sc.n_fine_faces, "vertices": int(len(pts)),
           "compared": int(mask.sum()), "hidden": int((hidden & ~emitter).sum()), "contact": int(contact.sum()),
           "ref_spp": ref_spp, "ref_seconds": ref.seconds, "smooth_ref": smooth_ref,
           "smooth_vertices": int(flat.sum()), "smooth_light_tested": bool(flat_lit), "cycles": [], "ours": []}
    # Cycles sweep
    spps = args.cycles_spp
    for spp in spps:
        b = cr.bake_vertex_radiance(objs, samples=spp, seed=CAND_SEED, bounces=BOUNCES, threads=2)
        C = cycles_values(b, sc)
        err = errors(C, R, mask)
        sm = smoothness(C @ LUMA, edges, flat)
        out["cycles"].append({"spp": spp, "seconds": b.seconds, "error": err, "smooth": sm})
        log(f"cycles {spp:5d} spp: {b.seconds:7.2f} s  raw rms {100 * err['rms']:6.2f}%  p95 {100 * err['p95']:6.2f}%"
            f"  smooth {100 * sm:.2f}%")
    noise = reference_noise(out["cycles"], ref_spp)
    out["ref_noise"] = noise
    log(f"reference noise (fit over the Cycles sweep): {100 * noise['rms']:.2f}% RMS, Cycles RMS ~ spp^-{noise['alpha'] / 2:.2f}")
    for c in out["cycles"]:
        correct(c["error"], noise)
    # Ours
    writer = Writer(objs)
    out["read_seconds"] = writer.read_seconds
    out["writer"] = "write_copies" if writer.ok else f"unavailable ({writer.error})"
    done = []
    grid = candidate_grid(sc, args.quick, full_grid=(sc.name == "cornell"))
    npatch = {}
    for c in grid:
        p = c["patch_size"]
        if p not in npatch:
            npatch[p] = _patch_count(sc, p)
    grid.sort(key=lambda c: (family(c), npatch[c["patch_size"]], c.get("resolution", c.get("rays"))))
    for c in grid:
        n = npatch[c["patch_size"]]
        rec = dict(c, label=label(c), patches=n, work=c.get("resolution", c.get("rays", 0)))
        if dominated_by_slow(c, n, done, args.cap):
            rec.update(skipped=True)
            done.append(rec)
            log(f"skip  {label(c)} ({n} patches): a cheaper run took > {args.cap:g} s")
            continue
        try:
            res, core_s, wt, vals = run_ours(sc, c, pts, owner, normals, writer)
        except Exception as exc:  # noqa: BLE001 - report and go on
            rec.update(skipped=True, error=f"{type(exc).__name__}: {exc}")
            done.append(rec)
            log(f"FAIL  {label(c)}: {rec['error']}")
            continue
        err = correct(errors(vals, R, mask), out["ref_noise"])
        if res.settings is not None and any(isinstance(c.get(k), str) for k in ("patch_size", "element_size")):
            # 'auto' sizes: label with what the bake resolved them to
            rec["resolved"] = {k: getattr(res.settings, k) for k in ("patch_size", "element_size")}
            rec["label"] = label(rec)
            n = rec["patches"] = len(res.patches.areas)
        total = core_s + (wt if np.isfinite(wt) else 0.0) + writer.read_seconds
        rec.update(seconds=total, core_seconds=core_s, write_seconds=wt,
                   stages={k: float(v) for k, v in res.timings.items()},
                   iterations=int(res.solution.iterations), nnz=int(res.form_factors.nnz),
                   ff_mb=res.form_factors.nbytes / 1e6, error=err, smooth=smoothness(vals @ LUMA, edges, flat))
        done.append(rec)
        st = res.timings
        log(f"ours  {rec['label']:48s} N={n:5d} {total:7.2f} s (ff {st['form_factors']:.2f}, direct"
            f" {st.get('direct', 0):.2f}, solve {st['solve']:.2f}, vertices {st.get('vertices', 0):.2f}, write {wt:.2f})  rms {100 * err[METRIC]:6.2f}% (raw {100 * err['rms']:.2f}%)  p95 {100 * err['p95']:6.2f}%"
            f"  smooth {100 * rec['smooth']:.2f}%")
    out["ours"] = [d for d in done if not d.get("skipped")]
    out["skipped"] = [d for d in done if d.get("skipped")]
    # issue 11: the report's estimated error (core.output.estimate) beside the error measured here
    try:
        s = dataclasses.replace(settings_of(defaults_candidate()), estimate_error=True)
        res = pipeline.bake(sc.coarse, s, world=sc.world, lights=sc.lights)
        vals = interpolate_at(res.elements, res.vertex_radiosity, pts, owner, normals)
        err = correct(errors(vals, R, mask), out["ref_noise"])
        est = res.error_estimate.as_dict() if res.error_estimate is not None else None
        out["estimate"] = {"measured": err[METRIC], "measured_raw": err["rms"], "estimate": est,
                           "seconds": float(res.timings.get("estimate", 0.0)),
                           "bake_seconds": float(res.timings["total"])}
        log(f"estimate: defaults measured {100 * err[METRIC]:.2f}% (raw {100 * err['rms']:.2f}%), estimated "
            + (f"{100 * est['error']:.2f}% (noise {100 * est['noise']:.2f}%, detail {100 * est['detail']:.2f}%)"
               if est else "none") + f" in {out['estimate']['seconds']:.2f} s more")
    except Exception as exc:  # noqa: BLE001 - report and go on
        out["estimate"] = {"error": f"{type(exc).__name__}: {exc}"}
        log(f"FAIL  estimate: {out['estimate']['error']}")
    # relight on this scene: best of ours at Cycles-64 error (or the most accurate)
    if args.relight and out["ours"]:
        picks = [pick_default(out)[0]]
        c64 = next((c for c in out["cycles"] if c["spp"] == 64), out["cycles"][-1])
        within = [o for o in out["ours"] if o["seconds"] <= c64["seconds"]]
        if within:
            acc = min(within, key=lambda o: o["error"][METRIC])
            if acc is not picks[0]:
                picks.append(acc)
        dflt = next((o for o in out["ours"] if o.get("defaults")), None)
        if dflt is not None and all(p is not dflt for p in picks):
            picks.append(dflt)   # the shipped defaults: a relight with cached elements + gather
        out["relight"] = [relight(sc, out, best, pts, owner, normals, writer) for best in picks]
    return out


def pick_default(out):
    """Fastest of ours that reaches Cycles' 64-spp error, else our most accurate."""
    c64 = next((c for c in out["cycles"] if c["spp"] == 64), out["cycles"][-1])
    ok = [o for o in out["ours"] if o["error"][METRIC] <= c64["error"][METRIC]]
    if ok:
        return min(ok, key=lambda o: o["seconds"]), True
    return min(out["ours"], key=lambda o: o["error"][METRIC]), False


def relight(sc, out, best, pts, owner, normals, writer):
    """Bake ``best``'s settings once (fills a FormFactorCache), then time a bake of the same
    geometry with the lights 1.5x stronger and warmer reflectances against a Cycles re-bake
    reaching the same error (the first bake's error; a re-bake's error is the same in law)."""
    cand = {k: best[k] for k in ("defaults", "method", "patch_size", "resolution", "rays", "direct",
                                 "direct_samples", "element_size", "gather_rays") if k in best}
    cache = FormFactorCache()
    run_ours(sc, cand, pts, owner, normals, None, cache=cache)          # fills the cache
    meshes = sc.fine if cand["patch_size"] is None else sc.coarse
    relit = []
    for m in meshes:   # light x1.5, every reflectance a little warmer
        relit.append(MeshInput(m.verts, m.face_offsets, m.face_indices,
                               np.clip(m.face_rho * np.array([1.05, 1.0, 0.9]), 0, 0.95),
                               m.face_emission * 1.5, m.name))
    s = settings_of(cand)
    t = time.perf_counter()
    res = pipeline.bake(relit, s, world=sc.world, lights=sc.lights, cache=cache)
    core_s = time.perf_counter() - t
    wt = writer(res)
    # a relight in Blender re-reads the scene (materials changed) and writes the colours again
    total = core_s + (wt if np.isfinite(wt) else 0.0) + writer.read_seconds
    err = best["error"][METRIC]
    cyc_t = cycles_time_at(out["cycles"], err)
    log(f"relight {best['label']}: {total:.3f} s (source {res.form_factor_source}, solve"
        f" {res.timings['solve']:.3f} s, write {wt:.3f} s); Cycles at {100 * err:.2f}% rms: {cyc_t:.2f} s"
        f" -> {cyc_t / total:.0f}x")
    return {"label": best["label"], "defaults": bool(best.get("defaults")),
            "elements": bool(best.get("element_size")), "seconds": total, "core_seconds": core_s, "write_seconds": wt,
            "read_seconds": writer.read_seconds,
            "stages": {k: float(v) for k, v in res.timings.items()}, "ff_source": res.form_factor_source,
            "error_rms": err, "cycles_seconds": cyc_t, "ratio": cyc_t / total}


# ----------------------------------------------------------------------------- memory / FF
def memory_child(n, method, res):
    """Run in a subprocess: cut the Cornell box into ~n patches; peak resident memory of the
    form factors alone, then of the rest of the bake (direct light, solve, vertices) with F
    cached; the peak is reset between the two (/proc/self/clear_refs). Prints JSON."""
    from hemicube_radiosity.core import builtin_scenes as scenes
    from hemicube_radiosity.core.runtime.cache import cache_key
    from hemicube_radiosity.core.mesh.patches import PatchError
    from hemicube_radiosity.core.solve.solvers import solve

    coarse = scenes.cornell_box()
    area = sum(build_patches(coarse, None).areas)
    size = np.sqrt(area / n)
    for _ in range(6):  # adjust the size to land near n
        ps = build_patches(coarse, size)
        size *= np.sqrt(len(ps) / n)
    ps = build_patches(coarse, size)
    s = pipeline.BakeSettings(patch_size=None, resolution=res, method=method, rays_per_patch=res,
                              element_size=None, gather_rays=0)   # the patches are the output here
    _reset_peak()
    base = _vm("VmRSS")
    t = time.perf_counter()
    cpu = time.process_time()
    recv = pipeline.receivers_needed(ps)
    F = pipeline.compute_form_factors(ps, s, receivers=recv)
    ff_s = time.perf_counter() - t
    ff_cpu = time.process_time() - cpu
    ff_peak = _vm("VmHWM") - base
    rec = {"patches": len(ps), "method": method, "work": res, "ff_seconds": ff_s, "ff_cpu_seconds": ff_cpu,
           "ms_per_row": 1e3 * ff_s / len(recv), "receivers": int(len(recv)), "nnz": int(F.nnz),
           "ff_mb": F.nbytes / 1e6, "ff_peak_mb": ff_peak, "dense_mb": 4 * len(ps) ** 2 / 1e6}
    cache = FormFactorCache()
    cache.put(cache_key(ps.geometry_key(), s.form_factor_key()), F)
    _reset_peak()
    base = _vm("VmRSS")
    t = time.perf_counter()
    try:
        r = pipeline.bake(None, s, patches=ps, cache=cache)
        rec.update(rest_seconds=time.perf_counter() - t, stages={k: float(v) for k, v in r.timings.items()},
                   iterations=int(r.solution.iterations), rest="direct + solve + vertices")
    except PatchError as exc:   # the pipeline refuses very large patch counts: solve alone
        rec["pipeline_refused"] = str(exc).split(":")[0]
        sol = solve(F, ps.rho, ps.emission, "gauss_seidel", 1e-4, 500)
        rec.update(rest_seconds=time.perf_counter() - t, iterations=int(sol.iterations), rest="solve only")
    rec["rest_peak_mb"] = _vm("VmHWM") - base
    rec["peak_mb"] = max(rec["ff_peak_mb"], rec["rest_peak_mb"])
    rec["seconds"] = ff_s + rec["rest_seconds"]
    print(json.dumps(rec))


def _reset_peak():
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        pass


def _vm(field):
    """MB of a /proc/self/status field (VmHWM: peak resident set since exec)."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024
    return float("nan")


def run_memory(jobs, timeout):
    out = []
    for n, method, res in jobs:
        t = time.perf_counter()
        try:
            p = subprocess.run([sys.executable, __file__, "--memory-child", str(n), method, str(res)],
                               capture_output=True, text=True, timeout=timeout)
            line = [l for l in p.stdout.splitlines() if l.startswith("{")]
            if not line:
                raise RuntimeError(p.stderr[-500:])
            rec = json.loads(line[-1])
        except subprocess.TimeoutExpired:
            rec = {"patches": n, "method": method, "work": res, "timeout": timeout}
        except Exception as exc:  # noqa: BLE001
            rec = {"patches": n, "method": method, "work": res, "error": str(exc)[-300:]}
        out.append(rec)
        log(f"memory {n:6d} {method:18s} {res:5d}: {json.dumps(rec)} ({time.perf_counter() - t:.0f} s)")
    return out


def profile_hemicube(n=500, res=64, top=14):
    from hemicube_radiosity.core import builtin_scenes as scenes
    from hemicube_radiosity.core.form_factors.hemicube import hemicube_form_factors

    coarse = scenes.cornell_box()
    area = sum(build_patches(coarse, None).areas)
    ps = build_patches(coarse, np.sqrt(area / n))
    pr = cProfile.Profile()
    t = time.perf_counter()
    pr.enable()
    hemicube_form_factors(ps, res)
    pr.disable()
    dt = time.perf_counter() - t
    s = io.StringIO()
    st = pstats.Stats(pr, stream=s)
    st.sort_stats("tottime").print_stats(top)
    rows = []
    for (fn, line, name), (cc, nc, tt, ct, _) in sorted(st.stats.items(), key=lambda kv: -kv[1][2])[:top]:
        rows.append({"function": f"{os.path.basename(fn)}:{line}({name})", "calls": nc, "tottime": tt,
                     "cumtime": ct})
    log(f"profile: hemicube {len(ps)} patches res {res}: {dt:.2f} s")
    for r in rows[:8]:
        log(f"  {r['tottime']:7.3f} s  {r['calls']:7d}  {r['function']}")
    return {"patches": len(ps), "resolution": res, "seconds": dt, "rows": rows}


# ----------------------------------------------------------------------------- machine
def machine_info():
    info = {"python": platform.python_version(), "platform": platform.platform(),
            "cpus": os.cpu_count(), "numpy": np.__version__}
    try:
        with open("/proc/cpuinfo") as f:
            info["cpu"] = next(l.split(":", 1)[1].strip() for l in f if l.startswith("model name"))
    except Exception:  # noqa: BLE001
        pass
    try:
        with open("/proc/meminfo") as f:
            info["mem_gb"] = round(int(f.readline().split()[1]) / 2**20, 1)
    except Exception:  # noqa: BLE001
        pass
    try:
        import bpy
        info["bpy"] = bpy.app.version_string
    except Exception:  # noqa: BLE001
        pass
    try:
        import embreex
        info["embreex"] = getattr(embreex, "__version__", "?")
    except Exception:  # noqa: BLE001
        info["embreex"] = "unavailable"
    try:
        info["load_avg_start"] = os.getloadavg()
    except OSError:
        pass
    try:
        info["git"] = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"], capture_output=True,
                                     text=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", ROOT, "status", "--short", "--untracked-files=no"],
                               capture_output=True, text=True).stdout.split("\n")
        info["dirty"] = [l[3:] for l in dirty if l.strip()]
    except Exception:  # noqa: BLE001
        pass
    return info


# ----------------------------------------------------------------------------- report
def _pct(x):
    return f"{100 * x:.2f}%"


def _pct_opt(x):
    """A percentage, or 'n/a' when missing (results written before the field existed) or NaN."""
    return "n/a" if x is None or not np.isfinite(x) else _pct(x)


def _fmt_s(x):
    if x is None or not np.isfinite(x):
        return "n/a"
    return f"{x:.3f}" if x < 1 else f"{x:.2f}"


def headline(sc):
    """Ratios for one scene: at Cycles-64-spp error, and at 2% / 1% RMS."""
    out = {}
    c64 = next((c for c in sc["cycles"] if c["spp"] == 64), None)
    if c64 is not None:
        e = c64["error"][METRIC]
        t_ours = ours_time_at(sc["ours"], e)
        out["at_c64"] = {"error": e, "cycles_seconds": c64["seconds"], "ours_seconds": t_ours,
                         "ratio": c64["seconds"] / t_ours if np.isfinite(t_ours) else float("nan")}
    for e in (0.02, 0.01):
        tc = cycles_time_at(sc["cycles"], e)
        to = ours_time_at(sc["ours"], e)
        out[f"at_{e:g}"] = {"error": e, "cycles_seconds": tc, "ours_seconds": to,
                            "ratio": tc / to if np.isfinite(to) and np.isfinite(tc) else float("nan")}
    return out


def targets(results):
    rows = []
    room = next((s for s in results["scenes"] if s["name"] == "cornell"), results["scenes"][0])
    h = headline(room).get("at_c64")
    if h:
        ok = np.isfinite(h["ratio"]) and h["ratio"] >= 2
        rows.append(("First bake, ~4,000-face Cornell room, at Cycles' 64-spp error "
                     f"({_pct(h['error'])} RMS): >= 2x faster than Cycles",
                     f"ours {_fmt_s(h['ours_seconds'])} s vs Cycles {_fmt_s(h['cycles_seconds'])} s: "
                     + (f"{h['ratio']:.2f}x" if np.isfinite(h["ratio"]) else "our candidates never reach that error"),
                     ok))
    rls = room.get("relight") or []
    if isinstance(rls, dict):
        rls = [rls]
    def _ratio(r):
        return r["ratio"] if np.isfinite(r["ratio"]) else -1
    # the target is measured on the shipped defaults (output elements + gather, all cached), else
    # on the best element configuration, else on the best relight
    el = [r for r in rls if r.get("defaults")] or [r for r in rls if r.get("elements")] or rls
    rl = max(el, key=_ratio) if el else None
    if rl:
        best = max(rls, key=_ratio)
        extra = (f"; best relight: {best['ratio']:.0f}x ({best['label']})" if best is not rl else "")
        rows.append(("Relight (light x1.5, warmer reflectances; cached F, element mesh and gather): >= 50x faster"
                     " than a Cycles re-bake of the same error",
                     f"{_fmt_s(rl['seconds'])} s vs Cycles {_fmt_s(rl['cycles_seconds'])} s at {_pct(rl['error_rms'])}"
                     f" RMS: {rl['ratio']:.0f}x ({rl['label']}){extra}",
                     bool(np.isfinite(rl["ratio"]) and rl["ratio"] >= 50)))
    ff = next((m for m in results.get("memory", []) if m.get("method") == "hemicube" and m.get("work") == 64
               and "ff_seconds" in m), None)
    if ff:
        rows.append((f"Form factors, {ff['patches']} patches, hemi-cube resolution 64: <= 3 s",
                     f"{ff['ff_seconds']:.2f} s wall ({ff.get('ff_cpu_seconds', float('nan')):.2f} s CPU), "
                     f"{ff['ms_per_row']:.2f} ms per hemi-cube ({ff['receivers']} hemi-cubes)",
                     ff["ff_seconds"] <= 3.0))
    mem = [m for m in results.get("memory", []) if "nnz" in m]
    if mem:
        big = [m for m in mem if m["patches"] > 5000]
        ok = all(m["peak_mb"] < m["dense_mb"] for m in big)
        rows.append(("Peak memory reported for 2k/8k/32k patches; sparse, never a dense N x N past 5,000",
                     "; ".join(f"{m['patches']} {m['method']}: peak {m['peak_mb']:.0f} MB"
                               f" (dense float32 would be {m['dense_mb']:.0f} MB)" for m in mem), ok))
    for sc in results["scenes"]:   # issue 11: Cycles 1,024 spp's error, 5x faster
        c = next((c for c in sc["cycles"] if c["spp"] == 1024), None)
        if c is None or not sc["ours"]:
            continue
        err_c = c["error"][METRIC]
        ok_runs = [o for o in sc["ours"] if o["error"][METRIC] <= err_c]
        if ok_runs:
            o = min(ok_runs, key=lambda o: o["seconds"])
            t_c = cycles_time_at(sc["cycles"], o["error"][METRIC])
            ratio = t_c / o["seconds"] if np.isfinite(t_c) else float("nan")
            rows.append((f"`{sc['name']}`: vertex RMS at or below Cycles 1,024 spp's ({_pct(err_c)}), >= 5x faster than"
                         " Cycles to the same error (issue 11)",
                         f"{o['label']}: {_pct(o['error'][METRIC])} in {o['seconds']:.2f} s; Cycles to that error"
                         f" {t_c:.1f} s: {ratio:.1f}x", bool(ratio >= 5)))
        else:
            best = min(sc["ours"], key=lambda o: o["error"][METRIC])
            rows.append((f"`{sc['name']}`: vertex RMS at or below Cycles 1,024 spp's ({_pct(err_c)}), >= 5x faster than"
                         " Cycles to the same error (issue 11)",
                         f"not reached: our best {_pct(best['error'][METRIC])} ({best['label']}, {best['seconds']:.2f} s)",
                         False))
    for sc in results["scenes"]:   # issue 11: the estimated error brackets the measured one
        e = sc.get("estimate")
        if not e:
            continue
        est = (e.get("estimate") or {}).get("error")
        meas = e.get("measured")
        ok = est is not None and meas is not None and meas > 0 and 0.5 <= est / meas <= 2.0
        rows.append((f"`{sc['name']}`: the report's estimated error within a factor 2 of the measured, at the"
                     " defaults (issue 11)",
                     f"estimated {_pct_opt(est)} (noise {_pct_opt((e.get('estimate') or {}).get('noise'))}, detail "
                     f"{_pct_opt((e.get('estimate') or {}).get('detail'))}; {e.get('seconds', float('nan')):.2f} s more)"
                     f" vs measured {_pct_opt(meas)}" if est is not None else e.get("error", "no estimate"), bool(ok)))
    for sc in results["scenes"]:   # issue 11: smoothness at the defaults, each scene
        ref = sc.get("smooth_ref")
        if ref is None:
            continue   # results from before the smoothness figure
        d = next((o for o in sc["ours"] if o.get("defaults")), None)
        ours = d.get("smooth") if d is not None else None
        ok = ours is not None and np.isfinite(ours) and np.isfinite(ref) and ours <= ref
        rows.append((f"`{sc['name']}`: smoothness at the defaults <= the {sc['ref_spp']:,}-spp reference's own"
                     f" (issue 11)",
                     (f"ours {_pct_opt(ours)} vs reference {_pct_opt(ref)}" if d is not None
                      else f"defaults not run; reference {_pct_opt(ref)}")
                     + f" ({sc.get('smooth_vertices', '?')} flat vertices)", bool(ok)))
    return rows


# ----------------------------------------------------------------------------- main
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="smoke run (~3 min): Cornell only, few candidates")
    ap.add_argument("--scenes", nargs="*", default=None)
    ap.add_argument("--ref-spp", type=int, default=None)
    ap.add_argument("--cycles-spp", type=int, nargs="*", default=None)
    ap.add_argument("--cap", type=float, default=None, help="skip candidates whose cheaper sibling took longer (s)")
    ap.add_argument("--no-memory", action="store_true")
    ap.add_argument("--refs-only", action="store_true", help="only bake (and cache) the references")
    ap.add_argument("--results", default=None)
    ap.add_argument("--memory-child", nargs=3, metavar=("N", "METHOD", "RES"))
    args = ap.parse_args(argv)
    if args.memory_child:
        n, m, r = args.memory_child
        memory_child(int(n), m, int(r))
        return 0
    results_path = args.results or os.path.join(OUT_DIR, "results_quick.json" if args.quick else "results.json")
    args.scenes = args.scenes or (["cornell"] if args.quick else list(scenes_bench.SCENES))
    args.ref_spp = args.ref_spp or (None if args.quick else 4096)
    args.cycles_spp = args.cycles_spp or ([4, 16, 64] if args.quick else [4, 16, 64, 256, 1024])
    args.cap = args.cap or (20.0 if args.quick else 45.0)
    args.relight = True
    if args.refs_only:
        import cycles_reference as cr
        for name in args.scenes:
            sc = scenes_bench.get_scene(name)
            _, objs = build_blender_scene(sc)
            t = time.perf_counter()
            r = cr.cached_bake(objs, CACHE_DIR, samples=args.ref_spp, seed=REF_SEED, bounces=BOUNCES, threads=2)
            log(f"{name}: reference {args.ref_spp} spp {'cached' if r.cached else 'baked'} in"
                f" {time.perf_counter() - t:.0f} s")
        return 0
    t0 = time.perf_counter()
    results = {"quick": args.quick, "machine": machine_info(), "started": time.strftime("%Y-%m-%d %H:%M:%S"),
               "scenes": [], "command": " ".join(["bench/speed_vs_error.py", *(argv if argv is not None else sys.argv[1:])])}
    for name in args.scenes:
        results["scenes"].append(run_scene(scenes_bench.get_scene(name), args))
    results["profile"] = profile_hemicube(300 if args.quick else 800, 64)
    if not args.no_memory:
        jobs = [(2000, "hemicube", 64)]
        if not args.quick:
            jobs += [(2000, "embree", 64), (8000, "embree", 32), (32000, "embree", 32),
                     (2000, "embree_stochastic", 256), (8000, "embree_stochastic", 256),
                     (32000, "embree_stochastic", 256)]
        results["memory"] = run_memory(jobs, timeout=150 if args.quick else 300)
    results["seconds"] = time.perf_counter() - t0
    try:
        results["machine"]["load_avg_end"] = os.getloadavg()
    except OSError:
        pass
    os.makedirs(OUT_DIR, exist_ok=True)
    with open(results_path, "w") as f:
        json.dump(results, f, indent=1, default=float)
    log("\nTargets:")
    for t, meas, ok in targets(results):
        log(f"  [{'HOLDS' if ok else 'FAILS'}] {t}: {meas}")
    for sc in results["scenes"]:
        h = headline(sc)
        log(f"  {sc['name']}: " + "; ".join(f"{k}: {v['ratio']:.2f}x" for k, v in h.items()))
    log(f"\nbench done in {results['seconds']:.0f} s; results {results_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
