"""Lightmaps on a real scene: our ``--target lightmap`` against Cycles' own bake to an image through
the same UV map, texel by texel.

    .venv/bin/python bench/lightmap_real.py                  # godot_living_room
    .venv/bin/python bench/lightmap_real.py --ref-spp 256    # a cheaper reference (another cache key)
    make bench-lightmap                                      # the same through make

The scene is one of ``../shared/scenes`` (README there; without the folder this prints one line and
exits 0), loaded and lit as ``bench/real_scenes.py`` does (``godot_living_room``: its deterministic
sun and constant sky). Steps, each in a child process of its own:

1. **Ours** (``--ours-child``): ``BakeJob`` with ``BakeSettings(target='lightmap')`` (the
   defaults otherwise: lightmap density 32, at most 1024 texels a side) on every render-visible
   mesh, timed as ``python -m hemicube_radiosity bake`` runs it (read + bake + write: the lightmaps'
   texels, files and materials included). The scene's meshes have one UV map each, so each baked
   copy gets its lightmap UV map from Lightmap Pack. For each lightmap the child keeps the .exr as
   written (read back with Blender's image loader), the copy's lightmap UVs per loop, and per
   texel: whether its centre lies inside a UV triangle (:func:`core.output.lightmap.rasterize`)
   and that triangle's material.
2. **Cycles** (``--cycles-child``): the same scene and light; each baked object gets its own mesh
   with its modifiers applied (the copy's vertices and loops, checked), the copy's lightmap UVs as
   a second UV map, and is baked by ``tools/cycles_reference.bake_image`` (DIFFUSE: direct +
   indirect + colour, 32 bounces, the real scenes' 4 glossy bounces with reflective caustics and
   Filter Glossy off, ``real_scenes.GLOSSY``, as their vertex references: the glossy layer of the
   floor's Principled lights the ceiling; 2 threads, margin 0) at the lightmap's size: the reference at
   ``REF_SPP`` samples (seed ``REF_SEED``) and the candidate at ``CAND_SPP`` (seed ``CAND_SEED``).
   Both are cached in ``bench/cache`` (``cycles_lightmap_<key>.npz``; key: the scene as
   ``cycles_reference.cache_key`` sees it, the UVs, the size, samples, seed and glossy bounces).
3. **Error** per texel whose centre lies inside a UV triangle (not the dilated margin, which Cycles
   does not write), but not those that the reference never lights (luminance <= 1e-4 of the
   median) on a coincident surface (below; as ``real_scenes.py`` leaves out a never-lit corner
   only where the geometry says why; a texel inside a solid is not told apart and counts): the
   luminance-weighted RMS difference over the reference's mean luminance (``speed_vs_error.errors``,
   as ``real_scenes.py``), with the reference's own noise taken out (``rms_true``; ``rms_raw`` as
   measured: Cycles 64 against the reference has variance sigma_64^2 + sigma_ref^2, and
   sigma_ref^2 = sigma_64^2 x 64 / REF_SPP); the median texel's error on the same scale; the
   share of the squared error that the worst 1% of texels carry. Per object and per material.
   Beside the object's row, the same without the texels on **coincident surfaces**
   (:func:`coincident_texels`: a point of the texel's footprint lies within ``COINCIDENT`` of
   another face's triangle facing along the same line, a duplicate face or a face modelled on
   another): there Cycles' rays start on the surface and hit the other face at once, its light
   is float32's tie (the living room's roof, where a bevel's twisted quads lie in the roof's
   plane, and the strips beside its door, covered by a self-overlapping six-sided face: black or
   half black in Cycles, lit in ours, which starts its rays a hair off the surface). The verdict
   stays on every texel but the never-lit coincident ones; the row says how much of the error
   the others carry.

Time: ours is the whole scene's read + bake + write; Cycles' the ``bpy.ops.object.bake`` calls
of every object at ``CAND_SPP``. Writes bench/out/lightmap_real.json and prints the table that
``docs/performance.md`` ("Lightmaps") quotes.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
for p in (ROOT, HERE, os.path.join(ROOT, "tools")):
    if p not in sys.path:
        sys.path.insert(0, p)

import dark_corners  # noqa: E402
import real_scenes as rs  # noqa: E402
import speed_vs_error as sve  # noqa: E402
from hemicube_radiosity.core.util.unique import run_positions  # noqa: E402

OUT_DIR = os.path.join(ROOT, "bench", "out")
WORK_DIR = os.path.join(OUT_DIR, "lightmap_real")
SCENE = "godot_living_room"
REF_SPP = 1024
CAND_SPP = 64
COINCIDENT = 1e-4          # world units: a point this close to another face's parallel triangle lies on it
COINCIDENT_PART = "all but coincident surfaces"
TIMEOUT = 3 * 60 * 60      # a child: the reference at 1024 spp takes most of it when not cached


def log(*a):
    print(*a, flush=True)


# ----------------------------------------------------------------------------- Blender side
def ours_child(name, out_dir, out_npz, settings_json):
    """Bake ``name`` with the lightmap target; save each lightmap's arrays in ``out_npz``."""
    import bpy
    from hemicube_radiosity.blender.bake import BakeJob
    from hemicube_radiosity.blender.read.scene import GEOMETRY_TYPES
    from hemicube_radiosity.blender.read.visibility import render_visible_objects
    from hemicube_radiosity.blender import lightmap as blm
    from hemicube_radiosity.core.output import lightmap as core_lightmap
    from hemicube_radiosity.core.settings import BakeSettings

    load_s, light = rs.prepare(rs.SPEC[name])
    asked = dict(json.loads(settings_json), target="lightmap", lightmap_dir=out_dir)
    objs = render_visible_objects(bpy.context.view_layer, GEOMETRY_TYPES)
    t = time.perf_counter()
    job = BakeJob.prepare(bpy.context, objs, BakeSettings.from_mapping(asked))
    job.run()
    copies = job.write(bpy.context)
    seconds = time.perf_counter() - t
    arrays, maps = {}, []
    by_source = {c["radiosity_source"]: c for c in copies}
    every = _scene_triangles([by_source[lm["object"]] for lm in job.lightmaps], blm)
    for k, lm in enumerate(job.lightmaps):
        me = by_source[lm["object"]].data
        w, h = lm["size"]
        im = bpy.data.images.load(lm["exr"], check_existing=False)       # the file as written
        px = np.empty(w * h * 4, np.float32)
        im.pixels.foreach_get(px)
        me.calc_loop_triangles()
        tl = np.empty(len(me.loop_triangles) * 3, np.int64)
        me.loop_triangles.foreach_get("loops", tl)
        mi = np.empty(len(me.loop_triangles), np.int64)
        me.loop_triangles.foreach_get("material_index", mi)
        uv = np.empty(len(me.loops) * 2)
        me.uv_layers[lm["uv_map"]].data.foreach_get("uv", uv)
        tri, _, inside = core_lightmap.rasterize(uv.reshape(-1, 2)[tl].reshape(-1, 3, 2), w, h)
        # texels of a triangle without area measure no point of the surface (Cycles shades them
        # with a NaN normal: the sun alone): left out, as the real scenes' corners on such triangles
        flat = core_lightmap.flat_triangles(blm._world_triangles(me, np.array(by_source[lm["object"]].matrix_world)))
        on_flat = inside & (tri >= 0) & flat[np.maximum(tri, 0)]
        inside &= ~on_flat
        src = bpy.data.objects[lm["object"]]
        names = [m.name if m else "" for m in src.data.materials] or [""]
        world, faces = every[0][every[2] == k], every[1][every[2] == k]
        coincident = inside & coincident_texels(world, faces, uv.reshape(-1, 2)[tl].reshape(-1, 3, 2), tri,
                                                every[0], every[1])
        arrays.update({f"ours{k}": px.reshape(h, w, 4)[..., :3], f"uv{k}": uv.reshape(-1, 2),
                       f"inside{k}": inside, f"material{k}": np.where(tri >= 0, mi[np.maximum(tri, 0)], -1),
                       f"coincident{k}": coincident})
        maps.append({"object": lm["object"], "size": [w, h], "uv_map": lm["uv_map"], "made_uvs": lm["made_uvs"],
                     "materials": names, "loops": len(me.loops), "unset": lm["unset"],
                     "flat_texels": int(on_flat.sum()), "coincident_texels": int(coincident.sum())})
    np.savez(out_npz, **arrays)
    r = job.result
    return {"light": light, "load_seconds": load_s, "seconds": seconds, "settings_asked": asked,
            "stages": {k: float(v) for k, v in job.timings.items()}, "patches": int(r.unknowns),
            "elements": int(len(r.elements)), "lightmaps": maps,
            "notes": [line for _, line in job.messages().lines()]}


def _scene_triangles(obs, blm):
    """(world (T, 3, 3), face (T,), which (T,)) the loop triangles of every object of ``obs`` (the
    baked copies) in world space, each with a face id unique over the objects and the index of its
    object in ``obs``."""
    world, faces, which, base = [], [], [], 0
    for k, ob in enumerate(obs):
        w = blm._world_triangles(ob.data, np.array(ob.matrix_world))
        world.append(w)
        faces.append(blm._triangle_faces(ob.data) + base)
        which.append(np.full(len(w), k))
        base += len(ob.data.polygons)
    return np.concatenate(world), np.concatenate(faces), np.concatenate(which)


def coincident_texels(world, faces, uv, tri, others=None, other_faces=None, eps=COINCIDENT):
    """(H, W) bool: texels (``tri`` (H, W) from :func:`core.output.lightmap.rasterize` of ``uv``
    (T, 3, 2), image size ``tri.shape``) of which a point of the square Cycles' bake jitters its
    samples over (``core.output.lightmap.FOOTPRINT`` texels wide, ``SUBTEXELS`` squared points,
    those inside the triangle) lies within ``eps`` of a triangle of ``others`` (M, 3, 3) (default:
    ``world`` (T, 3, 3), the texels' triangles in world space) of another face (``other_faces``
    (M,) against ``faces`` (T,)) parallel to its own (|cos| > 0.999): a duplicate face, or a face
    modelled onto another. Cycles' rays from such a point hit the other face at once, or not, as
    float32 rounds."""
    from hemicube_radiosity.core.output import lightmap as core_lightmap

    others = np.asarray(world if others is None else others, dtype=np.float64)
    other_faces = np.asarray(faces if other_faces is None else other_faces)
    world, faces = np.asarray(world, dtype=np.float64), np.asarray(faces)
    H, W = tri.shape
    out = np.zeros((H, W), bool)

    def unit_normals(w):
        n = np.cross(w[:, 1] - w[:, 0], w[:, 2] - w[:, 0])
        length = np.linalg.norm(n, axis=1)
        return n / np.maximum(length, 1e-300)[:, None], length > 1e-12
    n, ok = unit_normals(world)
    m, ok_m = unit_normals(others)
    lo, hi = world.min(axis=1) - eps, world.max(axis=1) + eps
    lo_m, hi_m = others.min(axis=1) - eps, others.max(axis=1) + eps
    pi, pj = [], []
    for s in range(0, len(world), 256):          # pairs: parallel, another face, boxes overlap
        a = slice(s, s + 256)
        i, j = np.nonzero((np.abs(n[a] @ m.T) > 0.999) & (faces[a, None] != other_faces[None])
                          & ok[a, None] & ok_m[None])
        i += s
        i, j = (x[np.all((lo[i] <= hi_m[j]) & (hi[i] >= lo_m[j]), axis=1)] for x in (i, j))
        # and the other's plane passes within eps of the triangle (its corners' heights over it)
        h = np.einsum("ikc,ic->ik", world[i], m[j]) - np.einsum("ic,ic->i", others[j, 0], m[j])[:, None]
        near = (h.min(axis=1) < eps) & (h.max(axis=1) > -eps)
        pi.append(i[near])
        pj.append(j[near])
    pi, pj = np.concatenate(pi), np.concatenate(pj)
    keep = _overlap(world[pi], n[pi], others[pj], eps)        # not faces side by side in a plane
    pi, pj = pi[keep], pj[keep]
    if not pi.size:
        return out
    rows, cols = np.nonzero(np.isin(tri, pi))
    t = tri[rows, cols]
    px = np.asarray(uv, dtype=np.float64).reshape(-1, 3, 2) * np.array([W, H], float)
    which, bary = core_lightmap._sub_texels(px, t, np.stack([cols + 0.5, rows + 0.5], 1))
    points = np.einsum("nk,nkj->nj", bary, world[t[which]])
    order = np.argsort(pi, kind="stable")                         # each triangle's partners
    pi, pj = pi[order], pj[order]
    first = np.searchsorted(pi, t[which])
    count = np.searchsorted(pi, t[which], side="right") - first
    hit = np.zeros(len(points), bool)
    ends = np.cumsum(count)
    start = 0
    while start < len(points):              # about a million point-triangle pairs at a time
        stop = max(int(np.searchsorted(ends, (ends[start - 1] if start else 0) + 1_000_000)), start + 1)
        stop = min(stop, len(points))
        c = count[start:stop]
        point = np.repeat(np.arange(start, stop), c)
        j = pj[np.repeat(first[start:stop], c) + run_positions(c)]
        p, a = points[point], others[j]
        inbox = np.all((p >= lo_m[j]) & (p <= hi_m[j]), axis=1)
        p, a, j, point = p[inbox], a[inbox], j[inbox], point[inbox]
        close = np.abs(np.einsum("nj,nj->n", p - a[:, 0], m[j])) < eps
        hit[point[close & dark_corners.inside_triangles(p, a, 0.0)]] = True      # inside the other
        start = stop
    texel = np.zeros(len(t), bool)
    texel[which[hit]] = True
    out[rows[texel], cols[texel]] = True
    return out


def _overlap(a, n, b, eps):
    """(k,) bool: triangles ``a`` (k, 3, 3) (unit normals ``n`` (k, 3)) and ``b`` (k, 3, 3), seen
    along ``n``, overlap by more than ``eps`` across every edge of either (separating axes): two
    faces side by side, sharing an edge, do not."""
    u = a[:, 1] - a[:, 0]
    u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-300)
    v = np.cross(n, u)
    flat = [np.stack([np.einsum("kic,kc->ki", t, u), np.einsum("kic,kc->ki", t, v)], -1) for t in (a, b)]
    ok = np.ones(len(a), bool)
    for t in flat:
        for e in range(3):
            edge = t[:, (e + 1) % 3] - t[:, e]
            axis = np.stack([-edge[:, 1], edge[:, 0]], 1)
            axis /= np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-300)
            pa, pb = (np.einsum("kic,kc->ki", f, axis) for f in flat)
            ok &= np.minimum(pa.max(1), pb.max(1)) - np.maximum(pa.min(1), pb.min(1)) > eps
    return ok


def cached_image(ob, size, uv_layer, uv_hash, samples, seed):
    """(image (size, size, 3), seconds, cached) of :func:`cycles_reference.bake_image` through a
    cache in ``rs.CACHE_DIR``."""
    import cycles_reference as cr

    key = cr.cache_key([ob], {"kind": "lightmap_image", "object": ob.name, "size": size, "uv": uv_hash,
                              "samples": samples, "seed": seed, "bounces": sve.BOUNCES, "glossy": rs.GLOSSY,
                              "filter_glossy": rs.FILTER_GLOSSY})
    path = os.path.join(rs.CACHE_DIR, f"cycles_lightmap_{key}.npz")
    if os.path.exists(path):
        with np.load(path) as z:
            return z["image"], float(z["seconds"]), True
    img, seconds = cr.bake_image(ob, size, samples=samples, uv_layer=uv_layer, seed=seed, threads=2,
                                 glossy=rs.GLOSSY, filter_glossy=rs.FILTER_GLOSSY)
    os.makedirs(rs.CACHE_DIR, exist_ok=True)
    tmp = path + f".{os.getpid()}.tmp.npz"
    np.savez(tmp, image=img, seconds=seconds)
    os.replace(tmp, path)
    return img, seconds, False


def cycles_child(name, ours_json, ours_npz, out_npz, ref_spp, cand_spp):
    """Cycles' image bakes of every object ``ours_json`` lists, through its lightmap's UVs."""
    import bpy
    from hemicube_radiosity.blender.read.scene import GEOMETRY_TYPES
    from hemicube_radiosity.blender.read.visibility import render_visible_objects

    with open(ours_json) as f:
        ours = json.load(f)
    _, light = rs.prepare(rs.SPEC[name])
    objs = {o.name: o for o in rs.own_evaluated_meshes(render_visible_objects(bpy.context.view_layer,
                                                                              GEOMETRY_TYPES))}
    rec, arrays = {"light": light, "objects": []}, {}
    with np.load(ours_npz) as z:
        uvs = [z[f"uv{k}"] for k in range(len(ours["lightmaps"]))]
    for k, lm in enumerate(ours["lightmaps"]):
        ob = objs[lm["object"]]
        me = ob.data
        if len(me.loops) != lm["loops"]:
            raise RuntimeError(f"{ob.name}: {len(me.loops)} loops here, {lm['loops']} in the baked copy")
        layer = me.uv_layers.new(name="BenchLightmap")
        layer.data.foreach_set("uv", uvs[k].astype(np.float32).ravel())
        uv_hash = hashlib.sha256(uvs[k].astype(np.float32).tobytes()).hexdigest()
        size = lm["size"][0]
        row = {"object": ob.name}
        for key, spp, seed in (("cand", cand_spp, sve.CAND_SEED), ("ref", ref_spp, sve.REF_SEED)):
            img, seconds, cached = cached_image(ob, size, layer.name, uv_hash, spp, seed)
            arrays[f"{key}{k}"] = img
            row[key] = {"samples": spp, "seed": seed, "seconds": seconds, "cached": cached}
            log(f"{ob.name}: Cycles {spp} spp at {size}x{size} {'cached' if cached else 'baked'}: {seconds:.1f} s")
        rec["objects"].append(row)
    np.savez(out_npz, **arrays)
    return rec


def child_main(fn, argv):
    """A child's entry: ``fn(*argv[:-1])``, its record written to the JSON file ``argv[-1]`` (an
    exception is a record with its first line)."""
    try:
        rec = fn(*argv[:-1])
    except Exception as exc:  # noqa: BLE001 - the run says which
        import traceback

        traceback.print_exc()
        rec = {"failure": f"{type(exc).__name__}: {(str(exc).strip().splitlines() or [''])[0]}"[:300]}
    with open(argv[-1], "w") as f:
        json.dump(rec, f, default=float)
    sys.stdout.flush()
    os._exit(0)   # skip Blender's teardown; everything is written


def child(argv, log_path, json_path, timeout):
    """Run this file with ``argv`` + [json_path]; its record plus wall time and peak memory."""
    status, rss, wall = rs.run_child([*argv, json_path], log_path, timeout, script=__file__)
    if status == "ok" and os.path.exists(json_path):
        with open(json_path) as f:
            rec = json.load(f)
    else:
        with open(log_path, errors="replace") as f:
            tail = [line.strip() for line in f if line.strip()][-1:] or [""]
        rec = {"failure": f"{status}: {tail[0]}"[:300]}
    return dict(rec, wall_seconds=wall, max_rss_mb=rss)


# ----------------------------------------------------------------------------- comparison
def texel_errors(ours, ref, cand, inside, material, names, ref_spp, cand_spp, coincident=None):
    """Rows of errors for one lightmap: the whole object, the same without the texels on
    ``coincident`` (H, W) bool surfaces (where any: :func:`coincident_texels`), then each
    material with texels. ``ours``/``ref``/``cand`` (H, W, 3), ``inside`` (H, W) bool,
    ``material`` (H, W) int."""
    Yr = ref @ sve.LUMA
    valid = inside & np.all(np.isfinite(ref), -1)
    lit = valid & (Yr > 0)
    never = valid & ~(Yr > 1e-4 * np.median(Yr[lit])) if lit.any() else valid
    # texels the reference never lights are compared, unless they lie on a coincident surface
    mask = valid & ~(never & coincident) if coincident is not None else valid
    rows = []
    apart = [] if coincident is None or not (mask & coincident).any() else [(COINCIDENT_PART, mask & ~coincident)]
    for label, m in [("all", mask)] + apart + [(n or f"slot {i}", mask & (material == i))
                                               for i, n in enumerate(names)]:
        if m.sum() < 10:
            continue
        c = _errors(cand[m], ref[m])
        noise = {"rms": c["rms"] / np.sqrt(1 + ref_spp / cand_spp)}
        row = {"part": label, "texels": int(m.sum()), "ours": sve.correct(_errors(ours[m], ref[m]), noise),
               "cycles": sve.correct(c, noise)}
        if label == COINCIDENT_PART:      # the share of ours' squared error on the texels left out
            d = ((ours[mask] - ref[mask]) ** 2) @ sve.LUMA
            row["left_out_share"] = float(d[(coincident & mask)[mask]].sum() / max(d.sum(), 1e-300))
        rows.append(row)
    return rows


def _errors(x, ref):
    """``speed_vs_error.errors`` of texels ``x`` (n, 3) against ``ref`` (n, 3), plus ``median``:
    the median texel's luminance-weighted error over the reference's mean luminance, and
    ``worst_share``: the share of the squared error the worst 1% of texels carry."""
    out = sve.errors(x, ref, slice(None))
    d = x - ref
    e2 = (d * d) @ sve.LUMA
    out["median"] = float(np.median(np.sqrt(e2)) / float((ref @ sve.LUMA).mean()))
    top = np.sort(e2)[::-1][:max(1, len(e2) // 100)]
    out["worst_share"] = float(top.sum() / max(e2.sum(), 1e-300))
    return out


def run(args):
    os.makedirs(WORK_DIR, exist_ok=True)
    base = os.path.join(WORK_DIR, args.scene)
    res = {"scene": args.scene, "machine": sve.machine_info(), "started": time.strftime("%Y-%m-%d %H:%M:%S"),
           "ref_spp": args.ref_spp, "cand_spp": CAND_SPP, "command": " ".join(["bench/lightmap_real.py", *args.argv])}
    asked = {"lightmap_density": args.density} if args.density else {}
    ours = child(["--ours-child", args.scene, base + "_maps", base + "_ours.npz", json.dumps(asked)],
                 base + "_ours.log", base + "_ours.json", args.timeout)
    res["ours"] = ours
    if rs.failed(ours):
        return res
    log(f"ours: {ours['seconds']:.1f} s, {len(ours['lightmaps'])} lightmaps "
        + ", ".join(f"{m['object']} {m['size'][0]}x{m['size'][1]}" for m in ours["lightmaps"]))
    cyc = child(["--cycles-child", args.scene, base + "_ours.json", base + "_ours.npz", base + "_cycles.npz",
                 str(args.ref_spp), str(CAND_SPP)], base + "_cycles.log", base + "_cycles.json", args.timeout)
    res["cycles"] = cyc
    if rs.failed(cyc):
        return res
    res["maps"] = []
    with np.load(base + "_ours.npz") as zo, np.load(base + "_cycles.npz") as zc:
        for k, lm in enumerate(ours["lightmaps"]):
            rows = texel_errors(zo[f"ours{k}"].astype(np.float64), zc[f"ref{k}"], zc[f"cand{k}"], zo[f"inside{k}"],
                                zo[f"material{k}"], lm["materials"], args.ref_spp, CAND_SPP,
                                zo[f"coincident{k}"] if f"coincident{k}" in zo else None)
            c = cyc["objects"][k]
            res["maps"].append({**lm, "rows": rows, "cycles_seconds": c["cand"]["seconds"],
                                "reference_seconds": c["ref"]["seconds"]})
    return res


def _pct(x):
    return "n/a" if x is None else f"{100 * x:.2f}%"


def table(res):
    """Markdown rows: per lightmap and part, texels, our RMS (median), the share of our squared
    error in the worst 1% of texels, our bias, Cycles 64's RMS (median)."""
    head = ["object (size)", "part", "texels", "RMS ours (median)", "worst 1% of texels: share of ours' squared error",
            "bias ours", f"RMS Cycles {CAND_SPP} spp (median)"]
    rows = []
    for m in res.get("maps", []):
        for r in m["rows"]:
            o, c = r["ours"], r["cycles"]
            rows.append([f"`{m['object']}` ({m['size'][0]}x{m['size'][1]})", r["part"], f"{r['texels']:,}",
                         f"{_pct(o['rms_true'])} ({_pct(o['median'])})", _pct(o["worst_share"]),
                         f"{100 * o['bias']:+.2f}%", f"{_pct(c['rms_true'])} ({_pct(c['median'])})"])
    return ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)] + ["| " + " | ".join(r) + " |" for r in rows]


def summary(res):
    """Lines: the times and the target (ours at or below Cycles 64's RMS on every object, in less time)."""
    o, maps = res["ours"], res.get("maps", [])
    t_cyc = sum(m["cycles_seconds"] for m in maps)
    t_ref = sum(m["reference_seconds"] for m in maps)
    lines = [f"ours: {o['seconds']:.1f} s for the whole scene (read + bake + write; {o['patches']:,} patches); "
             f"Cycles {CAND_SPP} spp: {t_cyc:.1f} s; reference {res['ref_spp']} spp: {t_ref:.0f} s"]
    for m in maps:
        a = next(r for r in m["rows"] if r["part"] == "all")
        ok = a["ours"]["rms_true"] <= a["cycles"]["rms_true"]
        lines.append(f"[{'HOLDS' if ok else 'FAILS'}] `{m['object']}`: RMS ours {_pct(a['ours']['rms_true'])} "
                     f"<= Cycles {CAND_SPP} spp {_pct(a['cycles']['rms_true'])}")
        c = next((r for r in m["rows"] if r["part"] == COINCIDENT_PART), None)
        if c is not None:
            lines.append(f"[apart] `{m['object']}`: {a['texels'] - c['texels']:,} texels on coincident surfaces carry "
                         f"{_pct(c['left_out_share'])} of ours' squared error; without them RMS ours "
                         f"{_pct(c['ours']['rms_true'])}, Cycles {CAND_SPP} spp {_pct(c['cycles']['rms_true'])}")
    lines.append(f"[{'HOLDS' if o['seconds'] < t_cyc else 'FAILS'}] time: ours {o['seconds']:.1f} s < Cycles "
                 f"{CAND_SPP} spp {t_cyc:.1f} s")
    return lines


def section(res):
    """The "Lightmaps" section of docs/performance.md (bench/report.py) from a results dict."""
    o = res["ours"]
    sizes = ", ".join(f"`{m['object']}` {m['size'][0]} x {m['size'][1]}" for m in res.get("maps", []))
    L = ["## Lightmaps", "",
         f"`bench/lightmap_real.py` (`make bench-lightmap`): `{res['scene']}` lit as in the real scenes above, baked"
         f" with `--target lightmap` (the defaults otherwise; lightmap UVs made by Lightmap Pack on the copies:"
         f" {sizes} texels), against Cycles' own DIFFUSE bake (direct + indirect + colour; {rs.GLOSSY} glossy bounces"
         " with reflective caustics and Filter Glossy off, as the real scenes' references) of the same objects to"
         f" images of the same size through the copies' lightmap UVs, at {res['cand_spp']} spp and, as the reference,"
         f" {res['ref_spp']} spp (another seed; cached in `bench/cache`). Texels whose centre lies inside a UV triangle"
         " (not the dilated margin), but not those of a triangle without area in the world (as the real scenes'"
         " corners Cycles bakes on one: they measure no point of the surface; "
         + ", ".join(f"`{m['object']}` {m.get('flat_texels', 0):,}" for m in res.get("maps", [])) + " texels);"
         " RMS of the luminance-weighted difference over the reference's mean luminance,"
         " the reference's own noise taken out, and the median texel's; per object and per material, and the object"
         f" without the texels on coincident surfaces (\"{COINCIDENT_PART}\": a point of the square Cycles' bake"
         " jitters over lies on another face's triangle in its plane, within 0.1 mm; Cycles' rays hit that face at"
         " once and its bake is black there, ours lit: `tests/blender/test_lightmap_coincident.py`; the verdict"
         " stays on every texel). Ours: the whole"
         " scene's read + bake + write (the lightmaps' texels and files included); Cycles: `bpy.ops.object.bake`"
         " of every object.", ""]
    L += table(res) + [""] + [f"- {line}" for line in summary(res)]
    stages = o.get("stages", {})
    if stages:
        L.append("- Our stages (s): " + ", ".join(f"{k} {v:.1f}" for k, v in stages.items() if k != "total")
                 + " (texels: the bake read at every texel of the lightmaps; write: the copies, files and materials).")
    return L + [""]


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["--ours-child"]:
        return child_main(ours_child, argv[1:])
    if argv[:1] == ["--cycles-child"]:
        return child_main(lambda *a: cycles_child(*a[:4], int(a[4]), int(a[5])), argv[1:])
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default=SCENE, choices=sorted(rs.SPEC))
    ap.add_argument("--ref-spp", type=int, default=REF_SPP)
    ap.add_argument("--density", type=float, default=None,
                    help="lightmap density, texels per metre (default: the setting's default)")
    ap.add_argument("--timeout", type=float, default=TIMEOUT, help="seconds a child may take")
    args, _ = ap.parse_known_args(argv)
    args.argv = argv
    if not os.path.isdir(rs.SCENES_DIR):
        log(f"lightmap bench: {rs.SCENES_DIR} not found; skipped")
        return 0
    t0 = time.perf_counter()
    res = run(args)
    res["seconds"] = time.perf_counter() - t0
    os.makedirs(OUT_DIR, exist_ok=True)
    path = os.path.join(OUT_DIR, "lightmap_real.json")
    with open(path, "w") as f:
        json.dump(res, f, indent=1, default=float)
    for who in ("ours", "cycles"):
        if rs.failed(res.get(who)):
            log(f"lightmap bench: {who} failed: {rs.failed(res[who])}")
            return 1
    log("\n" + "\n".join(table(res)) + "\n\n" + "\n".join(summary(res)))
    log(f"\nlightmap bench done in {res['seconds']:.0f} s; results {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
