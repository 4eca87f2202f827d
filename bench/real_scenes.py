"""Real scenes: the add-on's defaults on third-party files, against Cycles at the same corners.

    .venv/bin/python bench/real_scenes.py                      # every scene of ../shared/scenes
    .venv/bin/python bench/real_scenes.py --quick              # the two smallest (living room, bunny)
    .venv/bin/python bench/real_scenes.py --scenes godot_zdm2,sauer_pandora
    make bench-real BENCH_ARGS=--quick                         # the same through make

``make bench`` (bench/run_all.py) runs it too, with its ``--quick`` when given one.

The scenes are those of ``../shared/scenes`` (see its README.md; credit their authors when results
are published), and ``generated_terrain`` (bench/terrain.py: 1 km of ground as 128 x 128 quads
and five buildings, the large lit terrain issue 32 names). Without that folder this prints one line and exits 0. Smallest first; each scene:

1. **Loading.** A .blend is opened, a .gltf/.glb/.obj goes through the CLI's own ``load_input``
   (Blender's importers), the bunny's .ply through ``bpy.ops.wm.ply_import`` (Y up turned to Z up).
   ``sauer_pandora`` is in Cube 2 units: its objects are scaled by 0.05 (metres). Image-texture
   nodes whose file is missing (pandora's textures are not included) are removed from the materials
   (:func:`drop_missing_images`): Cycles would shade them magenta.
2. **Light**, the same for Cycles and for us (:func:`light_scene`):

   * ``file``: the light the file has (``bitterli_grey_white_room``: its equirectangular HDR world,
     which our reader takes as an environment light by direction; ``bitterli_wooden_staircase``:
     its emissive rectangle);
   * ``sun_sky`` (godot_truck_town, godot_zdm2, godot_living_room, stanford_bunny: no light in the
     file): a sun of irradiance ``SUN_STRENGTH`` W/m^2, ``SUN_ELEVATION`` deg high from azimuth
     ``SUN_AZIMUTH`` deg, Blender's default angle, and a constant world colour ``SKY`` (strength 1);
   * ``sun`` (bitterli_breakfast_room, whose README says "add a sun"): the same sun; the file's
     constant blue world stays as the sky;
   * ``lamps`` (sauer_pandora, a closed indoor level that no sun or sky reaches): ``LAMPS`` point
     lamps of ``LAMP_POWER`` W and radius ``LAMP_RADIUS`` m put in the level's open rooms by
     :func:`indoor_points`: on a grid over its bounding box, the points from which rays along the
     six axes and eight diagonals all hit a face from its front (inside the level) with at least
     ``LAMP_CLEARANCE`` m free, then the roomiest first and each next one as far from those chosen
     as possible (deterministic, so the Cycles cache key holds).

3. **Cycles** (one child process, ``--cycles-child``): every render-visible mesh made single-user
   and its modifiers applied (a vertex-colour bake writes to the mesh itself), then COMBINED vertex
   bakes (``tools/cycles_reference.py``, 32 bounces, ``GLOSSY`` = 4 glossy bounces with reflective
   caustics as a user's render has them, so light off metal and glossy layers reaches the walls;
   ``--glossy 0`` for none; Filter Glossy off, ``FILTER_GLOSSY``: unbiased, as the tests compare,
   where Blender's default 1.0 loses light that glossy layers hand on after a diffuse bounce,
   ``--filter-glossy default`` for it; 2 threads, no denoising): the reference at
   ``REF_SPP`` = 256 samples (not the 4,096 of ``speed_vs_error.py``: a 270k-triangle scene takes
   minutes per 64 samples on this 2-core machine) and the candidate at 64 samples with another
   seed, both cached in ``bench/cache`` (key: every mesh, material, light and the world, plus the
   samples and seed: a rerun bakes nothing), and a 1-sample EMIT bake that marks the emitters.
4. **Ours** (one child process per bake, ``--ours-child``): the same loading and light, then what
   ``python -m hemicube_radiosity bake`` runs (``BakeJob.prepare`` on every render-visible object,
   ``run``, ``write``), with ``BakeSettings()`` as shipped, then once more with the patches twice as
   large (``patch_size`` x2, ``element_size`` kept at the defaults' resolved value: only the
   grouping of the solve is coarser). After the defaults' bake the same child relights: every
   lamp, emitting material and the world's strength x ``RELIGHT``, then prepare + run + write again in the same
   process (the session's cache holds form factors and transports), timed against Cycles'
   64-spp bake (a Cycles re-bake costs as much) and checked to be ``RELIGHT`` x the first. And
   through ``--cache`` in a new process: one child bakes the defaults with a cache folder, a
   second scales the light the same way and bakes with that folder (its bake timed). Each child has a timeout (``--timeout``, 20 min); a refusal,
   a crash or a timeout is a row saying so (the first line of the error), not the end of the run.
   Peak memory: the child's peak resident set (``VmHWM``) after the write, Blender included, and
   the whole process's from ``wait4``.

**Error.** At every Cycles face corner (its world position and its face's normal) our result is read
where ``core.output.interpolate.locate`` finds it on the object of the same name (matched by
position and normal): the element's corner values (what the writer writes at its corners, a
textured face's corners each their own colour) interpolated bilinearly; a corner of a bent face
that Cycles baked on another of its triangles than the one we found is read at Cycles' own bake
point on that triangle (:func:`values_at_corners`). Left out: corners of
zero-area faces (a point-domain Cycles bake would average their black corners in), corners Cycles
shades on a triangle without area (:func:`flat_bake_corners`: it bakes them at another vertex with
an undefined normal), of emitters (EMIT bake > 0), corners the reference never lights (its
luminance <= 1e-4 x the median) where the geometry says why (``dark_corners``: another face passes
through Cycles' bake point, or no ray from it reaches light; the others are compared, and counted in
``cycles.never_lit``), and those of objects we did not bake. ``errors`` of
``speed_vs_error.py``: RMS of the luminance-weighted difference / the reference's mean luminance.
``rms`` has the reference's own noise taken out, estimated from Cycles 64 against 256 samples
(independent seeds, variance ~ 1/spp: sigma_256^2 = rms_64^2 / 5); ``rms_raw`` is as measured.

Targets printed per scene: the defaults bake in under 4 GB; their error and time next to Cycles
64 spp's (ours: read + bake + write; Cycles: ``bpy.ops.object.bake``); the defaults' error no worse
than at the coarser grouping. Writes bench/out/real_scenes.json (``--quick``: real_scenes_quick.json);
bench/report.py turns it into a section of docs/performance.md. Child logs: bench/out/real/.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")   # as speed_vs_error.py: one BLAS thread

import numpy as np  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
for p in (ROOT, HERE, os.path.join(ROOT, "tools")):
    if p not in sys.path:
        sys.path.insert(0, p)

import dark_corners  # noqa: E402
import speed_vs_error as sve  # noqa: E402
from hemicube_radiosity.core.settings import QUALITY  # noqa: E402
from hemicube_radiosity.core.util.unique import run_positions  # noqa: E402

SCENES_DIR = os.path.normpath(os.path.join(ROOT, "..", "shared", "scenes"))
CACHE_DIR = os.path.join(ROOT, "bench", "cache")
OUT_DIR = os.path.join(ROOT, "bench", "out")
WORK_DIR = os.path.join(OUT_DIR, "real")
REF_SPP = 256
GLOSSY = 4           # the references' glossy bounces (with reflective caustics): a user's render
FILTER_GLOSSY = 0.0  # ... without Filter Glossy: unbiased (Blender's default 1.0 lost 5.2% of
                     # godot_zdm2's light, all of it off its default surface's specular layer)
CAND_SPP = 64
OFF_ULPS = 16        # float32 steps off an element's plane that put Cycles' bake point off it
RELIGHT = 1.5        # the relight after the defaults' bake: every lamp and the world this much brighter
MEMORY_TARGET_MB = 4096
TIMEOUT = 20 * 60          # a bake of ours
CYCLES_TIMEOUT = 60 * 60   # the Cycles child: reference, 64 spp and EMIT (cached afterwards)

SUN_STRENGTH = 3.0                   # W/m^2 at normal incidence
SUN_ELEVATION, SUN_AZIMUTH = 50.0, 35.0   # degrees
SKY = (0.35, 0.45, 0.6)              # constant world radiance
LAMPS, LAMP_POWER, LAMP_RADIUS, LAMP_CLEARANCE = 6, 1500.0, 0.1, 1.5


GENERATED = "(generated by bench/terrain.py)"   # a Spec's file: made, not read from ../shared/scenes


@dataclass(frozen=True)
class Spec:
    folder: str
    file: str
    light: str           # 'file', 'sun_sky', 'sun' or 'lamps' (module docstring)
    triangles: int       # the README's count: the order of the run (smallest first)
    scale: float = 1.0


SPECS = (
    Spec("godot_living_room", "living_room.blend", "sun_sky", 5086),
    Spec("godot_truck_town", "model/town_model.gltf", "sun_sky", 30477),
    Spec("godot_zdm2", "zdm2.blend", "sun_sky", 58772),
    Spec("sauer_pandora", "pandora.obj", "lamps", 60690, scale=0.05),
    Spec("stanford_bunny", "bun_zipper.ply", "sun_sky", 69451),
    Spec("bitterli_grey_white_room", "grey_white_room.blend", "file", 143163),
    Spec("bitterli_wooden_staircase", "wooden_staircase.blend", "file", 262663),
    Spec("bitterli_breakfast_room", "breakfast_room.blend", "sun", 269538),
    Spec("generated_terrain", GENERATED, "sun_sky", 2 * 128 * 128 + 60),
)
QUICK = ("godot_living_room", "stanford_bunny")
SPEC = {s.folder: s for s in SPECS}


def log(*a):
    print(*a, flush=True)


def scene_list(scenes_dir=SCENES_DIR, names=None, quick=False):
    """The specs to run, smallest first: ``names`` (folder names), or the quick pair, or every
    folder of ``scenes_dir`` that has a spec. Raises ValueError for a name with no spec; a folder
    with no spec is skipped with a line."""
    if names:
        bad = [n for n in names if n not in SPEC]
        if bad:
            raise ValueError(f"no such scene: {', '.join(bad)} (known: {', '.join(SPEC)})")
        chosen = [SPEC[n] for n in names]
    elif quick:
        chosen = [SPEC[n] for n in QUICK]
    else:
        present = sorted(d for d in os.listdir(scenes_dir) if os.path.isdir(os.path.join(scenes_dir, d)))
        for d in present:
            if d not in SPEC:
                log(f"real scenes: {d}: no entry in bench/real_scenes.py SPECS; skipped")
        chosen = [SPEC[d] for d in present if d in SPEC] + [s for s in SPECS if s.file == GENERATED]
    return sorted(chosen, key=lambda s: s.triangles)


# ----------------------------------------------------------------------------- Blender side
def load_scene(path, scale=1.0):
    """Replace the current file with ``path``: the CLI's ``load_input`` (.blend, .obj, .gltf,
    .glb) or the PLY importer; then scale every root object about the origin by ``scale``."""
    import bpy

    if path.lower().endswith(".ply"):
        bpy.ops.wm.read_homefile(use_empty=True)
        bpy.ops.wm.ply_import(filepath=path, forward_axis="NEGATIVE_Z", up_axis="Y")
    else:
        from hemicube_radiosity.blender.cli.main import load_input

        load_input(path)
    if scale != 1.0:
        for ob in bpy.context.scene.objects:
            if ob.parent is None:
                ob.location = ob.location * scale
                ob.scale = ob.scale * scale
        bpy.context.view_layer.update()


def add_sun(scene):
    import cycles_reference as cr

    el, az = np.radians(SUN_ELEVATION), np.radians(SUN_AZIMUTH)
    # a sun shines along its -Z: tilt it (90 - elevation) about X, then turn it to the azimuth
    return cr.add_light("SUN", (0.0, 0.0, 10.0), (float(np.pi / 2 - el), 0.0, float(az)), name="BenchSun",
                        scene=scene, energy=SUN_STRENGTH)


def indoor_points(scene, n, clearance, grid=24):
    """Up to ``n`` points inside a closed level (module docstring, step 2): [(x, y, z), ...]."""
    import bpy
    from mathutils import Vector

    dg = bpy.context.evaluated_depsgraph_get()
    lo, hi = _bounds(scene, dg)
    step = (hi - lo) / grid
    dirs = [np.array(d, float) for d in ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1))]
    dirs += [np.array((x, y, z), float) / np.sqrt(3) for x in (1, -1) for y in (1, -1) for z in (1, -1)]
    cands = []
    for i in range(grid):
        for j in range(grid):
            for k in range(grid):
                p = lo + step * (np.array([i, j, k]) + 0.5)
                free = np.inf
                for d in dirs:
                    hit, loc, nrm, *_ = scene.ray_cast(dg, Vector(p), Vector(d))
                    if not hit or float(np.dot(nrm, d)) >= 0:   # escapes, or sees a back face: outside
                        free = -1
                        break
                    free = min(free, float((Vector(loc) - Vector(p)).length))
                if free >= clearance:
                    cands.append((free, tuple(map(float, p))))
    if not cands:
        return []
    cands.sort(key=lambda c: (-c[0], c[1]))
    pts = np.array([c[1] for c in cands])
    chosen = [0]
    dist = np.linalg.norm(pts - pts[0], axis=1)
    while len(chosen) < min(n, len(pts)):
        i = int(np.argmax(dist))
        chosen.append(i)
        dist = np.minimum(dist, np.linalg.norm(pts - pts[i], axis=1))
    return [tuple(pts[i]) for i in chosen]


def _bounds(scene, dg):
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for ob in scene.objects:
        if ob.type != "MESH":
            continue
        me = ob.evaluated_get(dg).to_mesh()
        co = np.empty(len(me.vertices) * 3)
        me.vertices.foreach_get("co", co)
        ob.evaluated_get(dg).to_mesh_clear()
        if co.size:
            M = np.array(ob.matrix_world)
            w = co.reshape(-1, 3) @ M[:3, :3].T + M[:3, 3]
            lo, hi = np.minimum(lo, w.min(0)), np.maximum(hi, w.max(0))
    return lo, hi


def light_scene(spec):
    """Add the light ``spec.light`` asks for to the current scene; returns a line saying what."""
    import bpy
    import cycles_reference as cr

    scene = bpy.context.scene
    if spec.light == "file":
        return "the file's own light"
    if spec.light in ("sun", "sun_sky"):
        add_sun(scene)
        what = (f"sun {SUN_STRENGTH:g} W/m^2 at {SUN_ELEVATION:g} deg elevation, azimuth {SUN_AZIMUTH:g} deg")
        if spec.light == "sun":
            return what + " + the file's world"
        cr.set_world(SKY, 1.0, scene=scene)
        return what + f" + sky ({', '.join(f'{c:g}' for c in SKY)})"
    if spec.light == "lamps":
        pts = indoor_points(scene, LAMPS, LAMP_CLEARANCE)
        if not pts:
            raise RuntimeError("no open point inside the level for a lamp")
        for i, p in enumerate(pts):
            cr.add_light("POINT", p, name=f"BenchLamp{i}", scene=scene, energy=LAMP_POWER,
                         shadow_soft_size=LAMP_RADIUS)
        return (f"{len(pts)} point lamps of {LAMP_POWER:g} W, radius {LAMP_RADIUS:g} m at "
                + "; ".join(f"({x:.1f}, {y:.1f}, {z:.1f})" for x, y, z in pts))
    raise ValueError(f"unknown light {spec.light!r}")


def drop_missing_images():
    """Remove material image-texture nodes whose file is missing (sauer_pandora ships without its
    textures): Cycles would shade them magenta, so the colour falls back to the socket's own value
    on both sides. Returns how many nodes went."""
    import bpy

    gone = 0
    for mat in bpy.data.materials:
        nt = mat.node_tree
        if nt is None:
            continue
        for node in list(nt.nodes):
            if node.type != "TEX_IMAGE":
                continue
            im = node.image
            path = bpy.path.abspath(im.filepath, library=im.library) if im is not None else ""
            if im is None or (im.source == "FILE" and im.packed_file is None and not os.path.exists(path)):
                nt.nodes.remove(node)
                gone += 1
    return gone


def prepare(spec):
    """Load ``spec``'s file, drop its missing textures and light it; returns (seconds, what light)."""
    t = time.perf_counter()
    if spec.file == GENERATED:
        import terrain

        terrain.build()
    else:
        load_scene(os.path.join(SCENES_DIR, spec.folder, spec.file), spec.scale)
    gone = drop_missing_images()
    what = light_scene(spec) + (f"; {gone} image nodes with a missing file removed" if gone else "")
    return time.perf_counter() - t, what


def corner_geometry(objects):
    """Per face corner of ``objects`` (world space): positions (L, 3), their face's centroid and
    normal (L, 3) each,
    the face's area (L,), the object's index (L,), the face's index in its mesh (L,); and the
    triangle count. Corner order is each
    mesh's loop order, objects one after the other: the order of CyclesBake.corner."""
    pos, mid, nrm, area, own, fid, tris = [], [], [], [], [], [], 0
    for oi, ob in enumerate(objects):
        me = ob.data
        w, lv = _world_corners(ob)
        tot = np.empty(len(me.polygons), np.int64)
        me.polygons.foreach_get("loop_total", tot)
        face = np.repeat(np.arange(len(tot)), tot)
        start = np.r_[0, np.cumsum(tot)[:-1]]
        # Newell normal of each face in world space (its length is twice the area)
        nxt = np.arange(len(lv)) + 1
        nxt[np.cumsum(tot) - 1] = start
        cr = np.cross(w, w[nxt])
        fn = np.stack([np.bincount(face, cr[:, k], len(tot)) for k in range(3)], 1)
        a = 0.5 * np.linalg.norm(fn, axis=1)
        fn = fn / np.maximum(2 * a, 1e-300)[:, None]
        cen = np.stack([np.bincount(face, w[:, k], len(tot)) for k in range(3)], 1) / np.maximum(tot, 1)[:, None]
        pos.append(w)
        mid.append(cen[face])
        nrm.append(fn[face])
        area.append(a[face])
        own.append(np.full(len(lv), oi))
        fid.append(face)
        tris += int(np.sum(tot - 2))
    cat = (lambda x: np.concatenate(x) if x else np.zeros((0, 3)))
    return cat(pos), cat(mid), cat(nrm), np.concatenate(area), np.concatenate(own), np.concatenate(fid), tris


def _world_corners(ob, dtype=np.float64):
    """(positions (L, 3) of each face corner of mesh object ``ob`` in world space, cast to
    ``dtype`` after the transform; its vertex indices (L,))."""
    me = ob.data
    M = np.array(ob.matrix_world)
    co = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", co)
    lv = np.empty(len(me.loops), np.int64)
    me.loops.foreach_get("vertex_index", lv)
    return (co.reshape(-1, 3) @ M[:3, :3].T + M[:3, 3]).astype(dtype)[lv], lv


def flat_bake_corners(objects):
    """Per face corner of ``objects`` (the order of :func:`corner_geometry`): whether Cycles shades
    it on a triangle without area, and so not at the corner. A colour-attribute bake gives each
    corner the first of its face's loop triangles that holds it (``object_bake_api.cc``,
    ``bake_targets_populate_pixels_color_attributes``: "first triangle wins"), at that vertex;
    Cycles moves a point that sits on a vertex toward the triangle's centre by solving for its
    barycentric coordinates (``init_from_bake.h``, ``bake_offset_towards_center``), and where that
    system's determinant ``|e1|^2 |e2|^2 - (e1.e2)^2`` is 0 it bakes at the triangle's third vertex
    instead, with the triangle's own normal: NaN where the edges are parallel (two vertices at one
    place, or three in a line), rounding noise where they nearly are. With a NaN normal the sky
    and all bounced light drop out: a flat-shaded face reads 0, one with custom normals the sun
    alone through the third corner's normal (``tests/blender/test_bench_corners.py``; the living
    room's wall corner 744 reads 0.265, the sun alone, at its neighbour's place). Zero here: within
    float32 rounding of the products (Cycles' arithmetic), in world space (Cycles applies the
    objects' transforms)."""
    from hemicube_radiosity.core.output.uv_raster import flat_triangles

    out = []
    for ob in objects:
        me = ob.data
        w, lv = _world_corners(ob, np.float32)
        tl = np.empty(len(me.loop_triangles) * 3, np.int64)
        me.loop_triangles.foreach_get("loops", tl)
        flat = flat_triangles(w[tl.reshape(-1, 3)], np.float32)
        loops, first = np.unique(tl, return_index=True)        # first triangle holding each corner
        f = np.zeros(len(lv), bool)
        f[loops] = flat[first // 3]
        out.append(f)
    return np.concatenate(out) if out else np.zeros(0, bool)


def own_evaluated_meshes(objects):
    """Each of ``objects`` as a mesh object with its own mesh, modifiers applied (a vertex-colour
    bake writes one value per corner of the mesh itself, and a mesh shared by two objects would get
    both their bakes); a curve or text becomes a new mesh object in its place. Returns those with
    faces, visible and selectable."""
    import bpy

    ob = bpy.context.view_layer.objects.active
    if ob is not None and ob.mode != "OBJECT":   # a file saved in edit mode: its mesh data is empty till then
        bpy.ops.object.mode_set(mode="OBJECT")
    dg = bpy.context.evaluated_depsgraph_get()
    out = []
    for ob in objects:
        me = bpy.data.meshes.new_from_object(ob.evaluated_get(dg), preserve_all_data_layers=True, depsgraph=dg)
        if ob.type == "MESH":
            ob.modifiers.clear()
            ob.shape_key_clear()
            ob.data = me
        else:
            new = bpy.data.objects.new(ob.name + ".mesh", me)
            new.matrix_world = ob.matrix_world
            for coll in ob.users_collection:
                coll.objects.link(new)
            ob.hide_render = True
            ob = new
        ob.hide_viewport = False
        ob.hide_set(False)
        if len(me.polygons):
            out.append(ob)
    return out


def cycles_child(name, out_npz, ref_spp, cand_spp, glossy=str(GLOSSY), filter_glossy=str(FILTER_GLOSSY)):
    import bpy
    import cycles_reference as cr
    from hemicube_radiosity.blender.read.scene import GEOMETRY_TYPES
    from hemicube_radiosity.blender.read.visibility import render_visible_objects

    spec = SPEC[name]
    load_s, light = prepare(spec)
    objs = own_evaluated_meshes(render_visible_objects(bpy.context.view_layer, GEOMETRY_TYPES))
    pos, mid, nrm, area, own, face, tris = corner_geometry(objs)
    log(f"{name}: {len(objs)} objects, {tris:,} triangles, {len(pos):,} corners; light: {light}")
    cr.PASS_FILTERS.setdefault("EMIT", {"EMIT"})     # emitters: a 1-sample EMIT bake
    rec = {"objects": len(objs), "triangles": tris, "corners": int(len(pos)), "light": light, "load_seconds": load_s}
    arrays = {}
    for key, kw in (("ref", dict(samples=ref_spp, seed=sve.REF_SEED)), ("cand", dict(samples=cand_spp,
                                                                                     seed=sve.CAND_SEED)),
                    ("emit", dict(samples=1, seed=0, mode="EMIT")),
                    ("point", dict(samples=1, seed=0, mode="POSITION"))):
        t = time.perf_counter()
        b = cr.cached_bake(objs, CACHE_DIR, bounces=sve.BOUNCES, threads=2, glossy=int(glossy),
                           filter_glossy=None if filter_glossy == "default" else float(filter_glossy), **kw)
        arrays[key] = np.concatenate([b.corner[o.name] for o in objs])
        rec[key] = {"seconds": b.seconds, "cached": b.cached, **b.settings}
        log(f"{name}: {key} {b.settings['samples']} spp {'cached' if b.cached else 'baked'}: {b.seconds:.1f} s"
            f" ({time.perf_counter() - t:.1f} s here)")
    flat = flat_bake_corners(objs)
    rec["flat_corners"] = int(flat.sum())
    np.savez(out_npz, pos=pos, centroid=mid, normal=nrm, area=area, owner=own, face=face,
             flat=flat, names=np.array([o.name for o in objs]), **arrays)
    return rec


def _vm_hwm_mb():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def scale_light(factor):
    """Every lamp's power, every emitting material's strength (a Principled BSDF's Emission
    Strength, an Emission shader's Strength, where not linked) and the world's Background strength
    times ``factor`` (a relight: no geometry changes, so the result must scale by exactly
    ``factor``); returns how many were scaled (0: nothing in the scene gives light)."""
    import bpy

    n = 0
    for light in bpy.data.lights:
        light.energy *= factor
        n += 1
    for material in bpy.data.materials:
        for node in (material.node_tree.nodes if material.node_tree is not None else ()):
            name = {"BSDF_PRINCIPLED": "Emission Strength", "EMISSION": "Strength"}.get(node.type)
            socket = node.inputs.get(name) if name else None
            if socket is not None and not socket.is_linked and socket.default_value > 0:
                socket.default_value *= factor
                n += 1
    world = bpy.context.scene.world
    for node in (world.node_tree.nodes if world is not None and world.node_tree is not None else ()):
        if node.type == "BACKGROUND":
            node.inputs["Strength"].default_value *= factor
            n += 1
    return n


def relight(objs, settings, first):
    """Bake again in this process after :func:`scale_light` by :data:`RELIGHT`, as an artist's
    second bake after changing a lamp: the session's cache holds the form factors and
    transports. The time (prepare + run + write), its stages, and how far the new corner values
    are from ``RELIGHT`` x ``first`` (a check that the relight is the same bake)."""
    import bpy
    from hemicube_radiosity.blender.bake import BakeJob

    if not scale_light(RELIGHT):
        return {"skipped": "no lamp or world to change"}
    t = time.perf_counter()
    job = BakeJob.prepare(bpy.context, objs, settings)
    job.run()
    job.write(bpy.context)
    seconds = time.perf_counter() - t
    new = np.asarray(job.result.corner_values(), float)
    want = RELIGHT * np.asarray(first, float)
    dev = float(np.nanmax(np.abs(new - want)) / max(float(np.nanmax(np.abs(want))), 1e-30)) \
        if new.shape == want.shape else None
    return {"seconds": seconds, "stages": {k: float(v) for k, v in job.timings.items()},
            "max_deviation": dev}


def _cpu_seconds():
    """CPU seconds of this process and of its children it has reaped (the forked workers): user
    plus system, every thread (the machine is shared: compare this, not the wall time)."""
    import resource

    return sum(r.ru_utime + r.ru_stime for r in (resource.getrusage(resource.RUSAGE_SELF),
                                                 resource.getrusage(resource.RUSAGE_CHILDREN)))


def ours_child(name, corners_npz, out_npz, settings_json, relit="0"):
    import bpy
    from hemicube_radiosity.blender.bake import BakeJob
    from hemicube_radiosity.blender.read.scene import GEOMETRY_TYPES
    from hemicube_radiosity.blender.read.visibility import render_visible_objects
    from hemicube_radiosity.core.settings import BakeSettings

    spec = SPEC[name]
    load_s, light = prepare(spec)
    settings = BakeSettings.from_mapping(json.loads(settings_json))
    objs = render_visible_objects(bpy.context.view_layer, GEOMETRY_TYPES)
    rec = {"light": light, "settings_asked": json.loads(settings_json), "load_seconds": load_s}
    if relit == "scaled":                     # a relight in a new process: the light changed first
        rec["scaled"] = scale_light(RELIGHT)
    t, cpu = time.perf_counter(), _cpu_seconds()
    job = BakeJob.prepare(bpy.context, objs, settings)
    job.run()
    job.write(bpy.context)
    r = job.result
    rec.update(seconds=time.perf_counter() - t, cpu_seconds=_cpu_seconds() - cpu, peak_mb=_vm_hwm_mb(),
               stages={k: float(v) for k, v in job.timings.items()}, patches=int(r.unknowns),
               pieces=int(len(r.patches)), elements=int(len(r.elements)), iterations=int(r.solution.iterations),
               converged=bool(r.solution.converged), nnz=int(r.form_factors.nnz),
               resolved={k: getattr(r.settings, k) for k in ("patch_size", "element_size", "resolution", "method")},
               triangles=int(sum(np.sum(np.diff(m.face_offsets) - 2) for m in job.scene_input.meshes)),
               forecast=None if r.forecast is None else r.forecast.as_dict(),
               warnings=list(job.messages().warnings), notes=list(job.messages().notes),
               n_notes=len(job.notes))
    if corners_npz and os.path.exists(corners_npz):
        t = time.perf_counter()
        with np.load(corners_npz) as z:
            names = [str(n) for n in z["names"]]
            index = {n: i for i, n in enumerate(r.elements.object_names)}
            owner = np.array([index.get(names[o], -1) for o in z["owner"]])
            vals, matched = values_at_corners(r.elements, r.corner_values(), z["pos"], z["centroid"], z["normal"],
                                              owner, z["face"] if "face" in z.files else None,
                                              point=z["point"] if "point" in z.files else None)
        np.save(out_npz, np.where(matched[:, None], vals, np.inf))   # inf: not matched, NaN: ours is NaN
        rec["evaluate_seconds"] = time.perf_counter() - t
        rec["corners_unmatched"] = int((~matched).sum())
        rec["corners_nan"] = int((matched & ~np.all(np.isfinite(vals), 1)).sum())
    rec["vertices_nan"] = int((~np.all(np.isfinite(r.vertex_radiosity), 1)).sum())
    rec["vertices"] = int(len(r.vertex_radiosity))
    if relit == "1":
        rec["relight"] = relight(objs, settings, r.corner_values())
    return rec


def values_at_corners(elements, corner_values, pos, centroid, normal, owner, face=None, nudge=1e-3,
                      min_facing=0.9, cap=None, point=None):
    """Our values at Cycles' corners, matched by position and normal: (values (L, 3), matched (L,)).
    ``corner_values`` (N, 4, 3): what we write at every element corner (``BakeResult.corner_values``:
    a textured face's corners each with their own colour), interpolated bilinearly in the element.

    Each corner is moved ``nudge`` of the way to its face's centroid, so it lies inside its own face
    and not on the edge it shares with the next face (where the two would tie), but no further than
    Cycles moves its bake point (``cap`` of the corner's largest coordinate, at least of 1; default
    :data:`hemicube_radiosity.core.output.lift.BAKE_NUDGE`): a corner of a face 500 m across (truck
    town's ground ring) is read 6 mm in, where Cycles baked it, not half a metre in, under the grass
    beside it (which read a lit corner black and a dark one lit). Then it is located with
    ``interpolate_at``'s ``locate`` among the elements of the object of its name (``owner``, -1:
    none), rejecting elements facing another way. ``face`` (L,): each corner's face in the object's
    evaluated mesh (the bake's ``source_face``); a corner found on an element of another face (a
    face folded over or lying on its neighbour) is located again among its own face's elements. A
    corner counts as matched when the element found faces within acos(``min_facing``) of the
    corner's face and passes within the distance moved (+1e-6 of the scene) of the point; the
    others are left out.

    ``point`` (L, 3): where Cycles baked each corner (a POSITION bake), or None. A bent face
    (an n-gon or warped quad: :mod:`hemicube_radiosity.core.mesh.ngons`) is Blender's loop
    triangles, and Cycles bakes a corner on the first of them that holds it, which need not be
    the one the nudge toward the face's centroid lands on, nor face the way the face does (the
    living room's wall corner 7281: baked on a sliver turned up under a bevel, which we read 0.005
    as Cycles reads 0, where the wall's own triangle beside it reads 0.39). Where ``point`` lies
    off the element found and on another of its face, the corner is read at
    the point of the element of its face nearest to ``point`` (:func:`_at_bake_points`), whichever
    way that element faces."""
    from hemicube_radiosity.core.output.interpolate import interpolate_corner_values, locate
    from hemicube_radiosity.core.output.lift import BAKE_NUDGE
    from hemicube_radiosity.core.util.geometry import bilinear

    cap = BAKE_NUDGE if cap is None else cap
    span = np.linalg.norm(centroid - pos, axis=1)
    step = np.minimum(nudge * span, cap * np.maximum(np.abs(pos).max(axis=1), 1.0))
    p = pos + (step / np.maximum(span, 1e-300))[:, None] * (centroid - pos)
    ok = owner >= 0
    vals = np.full((len(pos), 3), np.nan)
    matched = np.zeros(len(pos), bool)
    if not ok.any():
        return vals, matched
    idx, uv = locate(elements, p[ok], owner[ok], normal[ok])
    if face is not None:
        idx, uv = _on_own_face(elements, p[ok], owner[ok], normal[ok], np.asarray(face)[ok], idx, uv)
    vals[ok] = interpolate_corner_values(corner_values, idx, uv)
    c = elements.corners()[idx]
    on = bilinear(c, uv[:, :1], uv[:, 1:])
    diag = float(np.linalg.norm(np.ptp(elements.verts, axis=0)))
    tol = step[ok] + 1e-6 * diag
    facing = np.einsum("ij,ij->i", elements.normals[idx], normal[ok])
    matched[ok] = (facing >= min_facing) & (np.linalg.norm(on - p[ok], axis=1) <= tol)
    if point is not None and face is not None:
        _at_bake_points(elements, corner_values, np.asarray(point, float), owner, np.asarray(face), ok, idx,
                        vals, matched)
    return vals, matched


def _face_keys(elements, owner, face):
    """(one int64 per element, one per corner of ``owner``, ``face``): equal exactly where the
    object and face are the same."""
    stride = max(int(elements.source_face.max()), int(np.max(face, initial=0))) + 2
    return (elements.owner.astype(np.int64) * stride + elements.source_face,
            np.asarray(owner, np.int64) * stride + face)


def _on_own_face(elements, p, owner, normal, face, idx, uv):
    """``idx``, ``uv`` with the points found on an element of another face than their own
    (``face``) located again among the elements of their own face, where it has any."""
    from dataclasses import replace

    from hemicube_radiosity.core.output.interpolate import locate

    key_e, key_p = _face_keys(elements, owner, face)
    wrong = np.flatnonzero(key_e[idx] != key_p)
    if wrong.size == 0:
        return idx, uv
    groups, group_of = np.unique(key_p[wrong], return_inverse=True)
    cand = np.flatnonzero(np.isin(key_e, groups))
    if cand.size == 0:
        return idx, uv
    sub = replace(elements.take(cand), owner=np.searchsorted(groups, key_e[cand]))
    has = np.isin(group_of, np.unique(sub.owner))
    w = wrong[has]
    j, uv2 = locate(sub, p[w], group_of[has], normal[w])
    idx, uv = idx.copy(), uv.copy()
    idx[w], uv[w] = cand[j], uv2
    return idx, uv


def _at_bake_points(elements, corner_values, point, owner, face, ok, idx, vals, matched):
    """In place: ``vals``, ``matched`` (L,) read again at Cycles' bake ``point`` (L, 3) for the
    corners (of those ``ok``) whose bake point lies off the plane of the element ``idx`` (n,) they
    were found on (farther than :data:`OFF_ULPS` float32 steps of its largest coordinate) and on
    another element of their own face (``owner``, ``face``): under a quarter of that distance
    from it. There they are read at the point of that element nearest to ``point`` (see
    :func:`values_at_corners`), and matched."""
    from dataclasses import replace

    from hemicube_radiosity.core.output.interpolate import interpolate_corner_values, locate

    rows = np.flatnonzero(ok)
    x = point[rows]
    off = np.abs(np.einsum("ij,ij->i", x - elements.centers[idx], elements.normals[idx]))
    floor = OFF_ULPS * 2.0 ** -23 * np.maximum(np.abs(x).max(axis=1), 1.0)
    w = np.flatnonzero(np.isfinite(off) & (off > floor))
    if w.size == 0:
        return
    rows, off = rows[w], off[w]
    key_e, key_p = _face_keys(elements, owner[rows], face[rows])
    order = np.argsort(key_e, kind="stable")
    lo, hi = np.searchsorted(key_e[order], key_p, "left"), np.searchsorted(key_e[order], key_p, "right")
    cnt = hi - lo
    r = np.repeat(np.arange(rows.size), cnt)
    e = order[np.repeat(lo, cnt) + run_positions(cnt)]
    d = _to_elements(point[rows][r], elements, e)
    best = np.full(rows.size, np.inf)
    np.minimum.at(best, r, d)
    pick = np.full(rows.size, -1, np.int64)
    at = d <= best[r]
    pick[r[at]] = e[at]
    take = np.flatnonzero((pick >= 0) & (best < 0.25 * off))
    if take.size == 0:
        return
    rows, pick = rows[take], pick[take]
    one = replace(elements.take(pick), owner=np.arange(pick.size))
    _, uv = locate(one, point[rows], np.arange(pick.size))
    vals[rows] = interpolate_corner_values(corner_values, pick, uv)
    matched[rows] = True


def _to_elements(x, elements, e):
    """(k,) the distance from points ``x`` (k, 3) to the elements ``e`` (k,) (a quad as its two
    triangles (0, 1, 2), (0, 2, 3))."""
    c = elements.corners()[e]
    return np.minimum(_to_triangles(x, c[:, 0], c[:, 1], c[:, 2]), _to_triangles(x, c[:, 0], c[:, 2], c[:, 3]))


def _to_triangles(p, a, b, c):
    """(k,) the distance from points ``p`` (k, 3) to triangles ``a``, ``b``, ``c`` (k, 3 each):
    the nearest point of each (Ericson, *Real-Time Collision Detection* 5.1.5), on a triangle
    without area the nearest of its corners."""
    dot = lambda u, v: np.einsum("ij,ij->i", u, v)  # noqa: E731
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = dot(ab, ap), dot(ac, ap)
    bp, cp = p - b, p - c
    d3, d4, d5, d6 = dot(ab, bp), dot(ac, bp), dot(ab, cp), dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        den = va + vb + vc
        v, w = vb / den, vc / den
        q = a + v[:, None] * ab + w[:, None] * ac                          # inside the face region
        t_ab = np.clip(d1 / (d1 - d3), 0, 1)
        t_ac = np.clip(d2 / (d2 - d6), 0, 1)
        t_bc = np.clip((d4 - d3) / ((d4 - d3) + (d5 - d6)), 0, 1)
    edges = [a + np.nan_to_num(t_ab)[:, None] * ab, a + np.nan_to_num(t_ac)[:, None] * ac,
             b + np.nan_to_num(t_bc)[:, None] * (c - b)]
    dist = np.min([np.linalg.norm(p - y, axis=1) for y in edges + [a, b, c]], axis=0)
    inside = (va >= 0) & (vb >= 0) & (vc >= 0) & (den > 0)
    dist[inside] = np.linalg.norm(p - q, axis=1)[inside]
    return dist


# ----------------------------------------------------------------------------- parent side
def run_child(argv, log_path, timeout, script=__file__):
    """Run ``script`` (this file) with ``argv`` in its own process group; (status, max RSS MB,
    wall s). status: 'ok', 'exit N', 'signal NAME' or 'timeout'."""
    t = time.perf_counter()
    with open(log_path, "w") as logf:
        p = subprocess.Popen([sys.executable, os.path.abspath(script), *argv], cwd=ROOT, stdout=logf,
                             stderr=subprocess.STDOUT, start_new_session=True)
        status = None
        while True:
            pid, st, ru = os.wait4(p.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() - t > timeout:
                os.killpg(p.pid, signal.SIGKILL)
                pid, st, ru = os.wait4(p.pid, 0)
                status = "timeout"
                break
            time.sleep(0.5)
    p.returncode = 0   # reaped by wait4 above; keep Popen from waiting again
    if status is None:
        if os.WIFSIGNALED(st):
            status = f"signal {signal.Signals(os.WTERMSIG(st)).name}"
        else:
            status = "ok" if os.WEXITSTATUS(st) == 0 else f"exit {os.WEXITSTATUS(st)}"
    return status, ru.ru_maxrss / 1024.0, time.perf_counter() - t


def _child_result(status, log_path, json_path, timeout):
    """The child's JSON record, or {'failure': one line} when it failed."""
    if status == "ok" and os.path.exists(json_path):
        with open(json_path) as f:
            return json.load(f)
    if status == "timeout":
        return {"failure": f"timeout after {timeout / 60:g} min"}
    with open(log_path, errors="replace") as f:
        lines = [l.strip() for l in f if l.strip()]
    err = next((l for l in reversed(lines) if "Error" in l or "error" in l), lines[-1] if lines else "")
    return {"failure": f"{status}: {err}"[:300]}


def child_main(kind, argv):
    """The child's entry: run, write the JSON record; an exception is a record with its first line."""
    json_path = argv[-1]
    try:
        rec = cycles_child(*argv[:-1]) if kind == "cycles" else ours_child(*argv[:-1])
    except Exception as exc:  # noqa: BLE001 - a refusal or a bug: the row says which
        import traceback

        traceback.print_exc()
        msg = (str(exc).strip().splitlines() or [""])[0]
        rec = {"failure": f"{type(exc).__name__}: {msg}"[:300]}
    with open(json_path, "w") as f:
        json.dump(rec, f, default=float)
    sys.stdout.flush()
    os._exit(0)   # skip Blender's teardown (slow on big scenes); everything is written


def compared_corners(cyc_npz):
    """(L,) bool: the Cycles corners the errors are measured at (see the module's "Error"), and the
    counts of never-lit corners left out as explained (``dark_corners``): {"covered", "sealed",
    "counted"}. Worked out once per reference file."""
    key = (cyc_npz, os.path.getmtime(cyc_npz))
    if key not in _COMPARED:
        with np.load(cyc_npz) as z:
            z = {k: z[k] for k in z.files}
        ref, emit, area = z["ref"], z["emit"], z["area"]
        flat = z.get("flat", np.zeros(len(area), bool))
        diag = float(np.linalg.norm(np.ptp(z["pos"], axis=0))) if len(z["pos"]) else 1.0
        Yr = ref @ sve.LUMA
        mask = (area > 1e-12 * diag * diag) & ~flat & ((emit @ sve.LUMA) <= 0) & np.all(np.isfinite(ref), 1)
        lit = Yr > 1e-4 * np.median(Yr[mask]) if mask.any() else np.zeros(len(Yr), bool)
        never = mask & ~lit
        covered, sealed = dark_corners.explained(z, never, lit | ((emit @ sve.LUMA) > 0))
        mask &= ~(covered | sealed)
        counts = {"covered": int(covered.sum()), "sealed": int(sealed.sum()),
                  "counted": int((never & mask).sum())}
        _COMPARED.clear()
        _COMPARED[key] = (mask, counts)
    return _COMPARED[key]


_COMPARED = {}


def compare(cyc_npz, vals):
    """(errors against the reference, Cycles 64's errors, corners compared) at the Cycles corners."""
    with np.load(cyc_npz) as z:
        ref, cand = z["ref"], z["cand"]
    mask = compared_corners(cyc_npz)[0].copy()
    if vals is not None:   # inf: not matched; NaN: our bake gave NaN there (counted in the row)
        mask &= np.all(np.isfinite(vals), 1)
    if mask.sum() < 10:
        return None, None, int(mask.sum())
    c = _errors(cand, ref, mask)
    noise = {"rms": c["rms"] / np.sqrt(1 + REF_SPP / CAND_SPP)}
    sve.correct(c, noise)
    o = sve.correct(_errors(vals, ref, mask), noise) if vals is not None else None
    return o, c, int(mask.sum())


def _errors(x, ref, mask):
    """``speed_vs_error.errors`` plus ``median``: the median corner's luminance-weighted error / the
    reference's mean luminance (the RMS of a real scene is mostly a few corners on edges where the
    light jumps; the median says how the rest fare)."""
    out = sve.errors(x, ref, mask)
    d = np.asarray(x, float)[mask] - np.asarray(ref, float)[mask]
    out["median"] = float(np.median(np.sqrt((d * d) @ sve.LUMA)) / float((ref[mask] @ sve.LUMA).mean()))
    return out


def coarser_settings(defaults, cyc_npz):
    """The coarser run's settings: patches twice the defaults' size, output elements as fine as
    theirs. From the defaults' resolved sizes; where the defaults were refused, from the 'auto'
    rule on the scene's diagonal (Cycles' corners span the same render-visible meshes). None when
    neither is known."""
    from hemicube_radiosity.core.settings import AUTO_ELEMENTS_PER_PATCH, AUTO_PATCHES_PER_DIAGONAL

    res = defaults.get("resolved") if not failed(defaults) else None
    if res and res.get("patch_size"):
        return {"patch_size": 2 * res["patch_size"], "element_size": res["element_size"] or 0}
    if cyc_npz is None or not os.path.exists(cyc_npz):
        return None
    with np.load(cyc_npz) as z:
        if not len(z["pos"]):
            return None
        patch = float(np.linalg.norm(np.ptp(z["pos"], axis=0))) / AUTO_PATCHES_PER_DIAGONAL
    return {"patch_size": 2 * patch, "element_size": patch / AUTO_ELEMENTS_PER_PATCH}


def run_scene(spec, args):
    log(f"\n=== {spec.folder}: {spec.file} ({spec.triangles:,} triangles in the README), light '{spec.light}'")
    os.makedirs(WORK_DIR, exist_ok=True)
    base = os.path.join(WORK_DIR, spec.folder)
    row = {"name": spec.folder, "file": spec.file, "light_kind": spec.light, "scale": spec.scale,
           "load_avg": [os.getloadavg()[0]]}
    cyc_npz = base + "_cycles.npz"
    if os.path.exists(cyc_npz):
        os.remove(cyc_npz)
    st, rss, wall = run_child(["--cycles-child", spec.folder, cyc_npz, str(args.ref_spp), str(CAND_SPP),
                               str(args.glossy), args.filter_glossy, base + "_cycles.json"], base + "_cycles.log",
                              args.cycles_timeout)
    row["cycles"] = dict(_child_result(st, base + "_cycles.log", base + "_cycles.json", args.cycles_timeout),
                         wall_seconds=wall, max_rss_mb=rss)
    log(f"cycles: {json.dumps(row['cycles'], default=float)[:400]}")
    have_ref = not failed(row["cycles"]) and os.path.exists(cyc_npz)
    given = json.loads(args.set)
    runs = [("defaults", given)] + [(f"quality_{lv}", {**given, "quality": lv}) for lv in args.levels]
    for label, asked in runs:
        out = base + f"_{label}"
        st, rss, wall = run_child(["--ours-child", spec.folder, cyc_npz if have_ref else "", out + ".npy",
                                   json.dumps(asked), "1" if label == "defaults" and not args.bake_only else "0",
                                   out + ".json"],
                                  out + ".log", args.timeout)
        rec = dict(_child_result(st, out + ".log", out + ".json", args.timeout), wall_seconds=wall, max_rss_mb=rss)
        if have_ref and not failed(rec) and os.path.exists(out + ".npy"):
            o, c, n = compare(cyc_npz, np.load(out + ".npy"))
            rec.update(error=o, compared=n)
            if label == "defaults":
                row["cycles"].update(error=c, compared=n)
        row[label] = rec
        if label == "defaults" and not failed(rec) and not args.bake_only:
            row["relight_cache"] = relight_through_cache(spec, args, base, asked)
        brief = {k: rec.get(k) for k in ("error", "patches", "seconds", "cpu_seconds", "peak_mb", "max_rss_mb", "relight")}
        log(f"{label}: {json.dumps(brief, default=float)[:500]}")
        if label == "defaults" and not args.bake_only:
            coarser = coarser_settings(rec, cyc_npz if have_ref else None)
            if coarser:
                runs.append(("coarser", {**given, **coarser}))
    if have_ref and row["cycles"].get("error") is None:   # Cycles' own error, when no bake of ours ran
        _, c, n = compare(cyc_npz, None)
        row["cycles"].update(error=c, compared=n)
    if have_ref:
        row["cycles"]["never_lit"] = compared_corners(cyc_npz)[1]
    row["load_avg"].append(os.getloadavg()[0])   # a shared machine: how busy it was around the scene
    return row


def relight_through_cache(spec, args, base, asked):
    """The relight through ``--cache`` in a new process: one child bakes with a cache folder
    (filling it), a second loads the scene, scales every lamp and the world by ``RELIGHT`` and
    bakes with the same folder. Their records (the second's ``seconds`` is the relight's time)."""
    import shutil

    folder = base + "_cache"
    shutil.rmtree(folder, ignore_errors=True)
    out = {}
    for step, relit in (("fill", "0"), ("relit", "scaled")):
        path = base + f"_cache_{step}"
        st, rss, wall = run_child(["--ours-child", spec.folder, "", path + ".npy",
                                   json.dumps({**asked, "cache_dir": folder}), relit, path + ".json"],
                                  path + ".log", args.timeout)
        out[step] = dict(_child_result(st, path + ".log", path + ".json", args.timeout), wall_seconds=wall)
        if failed(out[step]):
            break
    shutil.rmtree(folder, ignore_errors=True)
    return out


def failed(rec):
    """The failure line of a child record (refused, crashed, timed out), or None."""
    return (rec or {}).get("failure")


def targets(res):
    """(target, measured, holds) per scene."""
    out = []
    for r in res["scenes"]:
        n, d, c, k = r["name"], r.get("defaults") or {}, r.get("cycles") or {}, r.get("coarser") or {}
        if failed(d):
            out.append((f"`{n}`: bakes with the defaults", failed(d), False))
            if k and not failed(k):
                out.append((f"`{n}`: (refused defaults) bakes with patches x2", f"{k['patches']:,} patches in"
                            f" {k['seconds']:.1f} s, peak {k['peak_mb']:,.0f} MB, RMS "
                            f"{_f((k.get('error') or {}).get(sve.METRIC), '{:.2%}')}", True))
            continue
        out.append((f"`{n}`: the defaults bake in under {MEMORY_TARGET_MB / 1024:g} GB",
                    f"peak {d['peak_mb']:,.0f} MB (Blender included)", d["peak_mb"] < MEMORY_TARGET_MB))
        ce, oe = (c.get("error") or {}).get(sve.METRIC), (d.get("error") or {}).get(sve.METRIC)
        if oe is not None and ce is not None and not failed(c):
            t_ours = d["seconds"]
            out.append((f"`{n}`: error and time next to Cycles {CAND_SPP} spp's",
                        f"ours {100 * oe:.2f}% in {t_ours:.1f} s; Cycles {100 * ce:.2f}% in {c['cand']['seconds']:.1f} s",
                        oe <= ce and t_ours <= c["cand"]["seconds"]))
        fc = d.get("forecast")
        if fc:      # what the forecast covers: the form factors and the output stage
            from hemicube_radiosity.core.runtime.forecast import SPREAD

            took = sum(d.get("stages", {}).get(s, 0.0) for s in ("form_factors", "vertices"))
            lo, hi = (fc["seconds"] * k for k in SPREAD)
            out.append((f"`{n}`: the forecast's range holds the form factors and output's time",
                        f"{took:.1f} s measured, {lo:.1f}-{hi:.1f} s forecast", lo <= took <= hi))
        rl = d.get("relight") or {}
        if rl.get("seconds") is not None and not failed(c) and (c.get("cand") or {}).get("seconds"):
            ratio = c["cand"]["seconds"] / rl["seconds"]
            out.append((f"`{n}`: a relight (lamps and world x{RELIGHT:g}) 20x faster than a Cycles {CAND_SPP} spp re-bake",
                        f"{rl['seconds']:.2f} s vs {c['cand']['seconds']:.1f} s: {ratio:.1f}x"
                        f" (result off {RELIGHT:g}x the first by {rl.get('max_deviation') or 0:.1e})", ratio >= 20))
        rc = (r.get("relight_cache") or {}).get("relit") or {}
        if rc.get("seconds") is not None and not failed(c) and (c.get("cand") or {}).get("seconds"):
            ratio = c["cand"]["seconds"] / rc["seconds"]
            out.append((f"`{n}`: a relight through --cache in a new process 20x faster than a Cycles {CAND_SPP} spp re-bake",
                        f"{rc['seconds']:.2f} s vs {c['cand']['seconds']:.1f} s: {ratio:.1f}x", ratio >= 20))
        ke = (k.get("error") or {}).get(sve.METRIC)
        if oe is not None and ke is not None:
            out.append((f"`{n}`: error no worse than at the coarser grouping (patches x2)",
                        f"{100 * oe:.2f}% vs {100 * ke:.2f}% ({d['patches']:,} vs {k['patches']:,} patches)", oe <= ke))
        elif oe is not None and failed(k):
            out.append((f"`{n}`: error no worse than at the coarser grouping (patches x2)",
                        f"coarser bake failed: {failed(k)}", False))
    return out


def _f(x, fmt="{:.1f}"):
    return "n/a" if x is None or (isinstance(x, float) and not np.isfinite(x)) else fmt.format(x)


def _rms(err):
    """'RMS (median)' of an errors dict (the median where the run recorded it)."""
    if not err:
        return "n/a"
    med = err.get("median")
    return _f(err.get(sve.METRIC), "{:.2%}") + ("" if med is None else f" ({_f(med, '{:.2%}')})")


def levels_table(res):
    """Markdown rows of the quality levels: per scene and level, RMS against the reference and
    seconds, beside Cycles 64 spp (None when no run had levels)."""
    rows = []
    for r in res["scenes"]:
        c = r.get("cycles") or {}
        for lv in QUALITY:
            d = r.get("defaults" if lv == "production" else f"quality_{lv}")
            if not d or (lv != "production" and failed(d)):
                continue
            if failed(d):
                rows.append([f"`{r['name']}`", lv, f"failed: {failed(d)}", "", "", ""])
                continue
            rows.append([f"`{r['name']}`", lv, f"{d['patches']:,}", _f(d["seconds"]), _rms(d.get("error")),
                         _rms(c.get("error")) + f" in {_f((c.get('cand') or {}).get('seconds'))} s"])
    if not any(r[1] != "production" for r in rows):
        return None
    head = ["scene", "quality", "patches", "ours (s)", "RMS ours (median)", f"Cycles {CAND_SPP} spp: RMS (median)"]
    return ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)] + ["| " + " | ".join(r) + " |" for r in rows]


def table(res):
    """The Markdown table of a results dict (also what report.py puts in docs/performance.md)."""
    head = ["scene", "triangles", "patches", "ours (s)", "read / form factors / direct / solve / vertices / write (s)",
            "peak (MB)", f"relight x{RELIGHT:g}: in process / --cache (s)", "RMS ours (median)", "RMS coarser (patches)", f"Cycles {CAND_SPP} spp (s)",
            f"RMS Cycles {CAND_SPP} (median)", "reference (s)"]
    rows = []
    for r in res["scenes"]:
        d, c, k = r.get("defaults") or {}, r.get("cycles") or {}, r.get("coarser") or {}
        tri = c.get("triangles") or d.get("triangles")
        cyc_t = _f((c.get("cand") or {}).get("seconds"))
        cyc_e = _rms(c.get("error")) if not failed(c) else "**failed**"
        ref_t = _f((c.get("ref") or {}).get("seconds"), "{:.0f}")
        if failed(c):
            cyc_t = f"failed: {failed(c)}"
        ke = "n/a" if not k else (f"failed: {failed(k)}" if failed(k) else
                                  f"{_f((k.get('error') or {}).get(sve.METRIC), '{:.2%}')} ({k.get('patches', 0):,};"
                                  f" {_f(k.get('seconds'))} s, {_f(k.get('peak_mb'), '{:,.0f}')} MB)")
        if failed(d):
            rows.append([f"`{r['name']}`", _f(tri, "{:,}"), "", f"**failed**: {failed(d)}", "", _f(d.get("max_rss_mb"), "{:,.0f}"),
                         "", "", ke, cyc_t, cyc_e, ref_t])
            continue
        st = d.get("stages", {})
        stages = " / ".join(_f(st.get(s), "{:.2f}") for s in ("read", "form_factors", "direct", "solve", "vertices", "write"))
        rl = d.get("relight") or {}
        rc = (r.get("relight_cache") or {}).get("relit") or {}
        relit = (f"{_f(rl.get('seconds'), '{:.2f}')} / "
                 + (f"failed: {failed(rc)}" if failed(rc) else _f(rc.get("seconds"), "{:.2f}")))
        rows.append([f"`{r['name']}`", _f(tri, "{:,}"), f"{d['patches']:,}", _f(d["seconds"]), stages,
                     _f(d["peak_mb"], "{:,.0f}"), relit, _rms(d.get("error")), ke, cyc_t, cyc_e,
                     ref_t])
    return ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)] + ["| " + " | ".join(r) + " |" for r in rows]


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    for kind in ("cycles", "ours"):
        if argv[:1] == [f"--{kind}-child"]:
            return child_main(kind, argv[1:])
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help=f"only {', '.join(QUICK)}")
    ap.add_argument("--scenes", default=None, help="comma-separated folder names of ../shared/scenes")
    ap.add_argument("--ref-spp", type=int, default=REF_SPP)
    ap.add_argument("--timeout", type=float, default=TIMEOUT, help="seconds a bake of ours may take")
    ap.add_argument("--cycles-timeout", type=float, default=CYCLES_TIMEOUT)
    ap.add_argument("--results", default=None)
    ap.add_argument("--glossy", type=int, default=GLOSSY,
                    help="the Cycles references' glossy bounces (0: none, and no caustics)")
    ap.add_argument("--filter-glossy", default=str(FILTER_GLOSSY),
                    help="the Cycles references' Filter Glossy ('default': Blender's 1.0, which "
                         "loses light off glossy layers after a diffuse bounce)")
    ap.add_argument("--set", default="{}", help="settings of ours as JSON, e.g. "
                    "'{\"specular_bounce\": false}' (default: the defaults)")
    ap.add_argument("--bake-only", action="store_true",
                    help="only the defaults' bake (or --set's): no relights, no coarser run (for trials)")
    ap.add_argument("--levels", action="store_true",
                    help="also bake at every quality level but Production (the defaults)")
    args, _ = ap.parse_known_args(argv)   # make bench passes its own flags through
    args.levels = [lv for lv in QUALITY if lv != "production"] if args.levels else []
    if not os.path.isdir(SCENES_DIR):
        log(f"real scenes: {SCENES_DIR} not found; skipped")
        return 0
    try:
        specs = scene_list(names=args.scenes.split(",") if args.scenes else None, quick=args.quick)
    except ValueError as exc:
        ap.error(str(exc))
    path = args.results or os.path.join(OUT_DIR, "real_scenes_quick.json" if args.quick else "real_scenes.json")
    res = {"quick": args.quick, "machine": sve.machine_info(), "started": time.strftime("%Y-%m-%d %H:%M:%S"),
           "ref_spp": args.ref_spp, "cand_spp": CAND_SPP, "glossy": args.glossy,
           "filter_glossy": args.filter_glossy, "command": " ".join(["bench/real_scenes.py", *argv]),
           "scenes": []}
    if args.scenes and os.path.exists(path):   # a subset: keep the other scenes' rows of the last run
        with open(path) as f:
            old = json.load(f)
        res["scenes"] = [s for s in old.get("scenes", []) if s["name"] not in {x.folder for x in specs}]
    t0 = time.perf_counter()
    for spec in specs:
        res["scenes"].append(run_scene(spec, args))
        res["scenes"].sort(key=lambda s: SPEC[s["name"]].triangles if s["name"] in SPEC else 0)
        os.makedirs(OUT_DIR, exist_ok=True)
        with open(path, "w") as f:   # after every scene: a stopped run keeps what it measured
            json.dump(res, f, indent=1, default=float)
    res["seconds"] = time.perf_counter() - t0
    with open(path, "w") as f:
        json.dump(res, f, indent=1, default=float)
    log("\n" + "\n".join(table(res)))
    log("\nTargets:")
    for t, m, ok in targets(res):
        log(f"  [{'HOLDS' if ok else 'FAILS'}] {t}: {m}")
    log(f"\nreal scenes done in {res['seconds']:.0f} s; results {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
