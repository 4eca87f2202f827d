"""Gallery: each real scene from a camera, Cycles' render beside a render of our baked copies.

    .venv/bin/python bench/gallery.py                        # the six default scenes
    .venv/bin/python bench/gallery.py --scenes godot_zdm2    # some of them (others' rows are kept)
    .venv/bin/python bench/gallery.py --all                  # every scene of ../shared/scenes
    .venv/bin/python bench/gallery.py --quick                # real_scenes.py's quick pair
    make gallery BENCH_ARGS="--scenes godot_zdm2"            # the same through make

``make bench`` (bench/run_all.py) runs it after bench/real_scenes.py (``--quick`` when given one).
Without ``../shared/scenes`` this prints one line and exits 0.

Each scene runs in a child process of its own (``--timeout``, 30 min), which:

1. loads and lights it exactly as the real-scene bench does (``real_scenes.prepare``);
2. puts a camera where :data:`VIEWS` says (:func:`place_camera`): the file's own camera
   (``scene.camera``) where it has one, else the camera of the scene's Godot demo (``test.tscn``,
   turned from Godot's Y up to Z up), else a view framing the bounding box of some of the objects
   from :data:`FRAME_AZIMUTH` / :data:`FRAME_ELEVATION`, else (a closed level) a view from inside;
3. renders the original with Cycles: :data:`SIZE` pixels, :data:`CYCLES_SPP` samples, 32 diffuse
   bounces (as the bench's reference), Blender's default glossy and transmission bounces, 2
   threads, OpenImageDenoise;
4. bakes as ``python -m hemicube_radiosity bake`` does with its defaults (``BakeJob.prepare`` on
   every render-visible object, ``run``, ``write``): the write adds baked copies whose material shows
   the colour attribute as emission and hides the originals;
5. renders the copies from the same camera with Cycles: no light bounces (the copies emit what was
   baked; nothing lights them), :data:`BAKED_SPP` samples for anti-aliasing, no denoising.

Both pictures: same size, view transform :data:`VIEW_TRANSFORM`, the view's exposure, the world as
background (the same sky in both). Writes docs/gallery/<scene>_cycles.jpg and _baked.jpg (JPEG
quality :data:`JPEG_QUALITY`), bench/out/gallery.json (one record per scene, kept across runs) and
docs/gallery.md from it. Child logs: bench/out/gallery/.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
for p in (ROOT, HERE, os.path.join(ROOT, "tools")):
    if p not in sys.path:
        sys.path.insert(0, p)

import real_scenes as rs  # noqa: E402

IMG_DIR = os.path.join(ROOT, "docs", "gallery")
DOC = os.path.join(ROOT, "docs", "gallery.md")
RESULTS = os.path.join(rs.OUT_DIR, "gallery.json")
LOG_DIR = os.path.join(rs.OUT_DIR, "gallery")
DEFAULT = ("godot_living_room", "stanford_bunny", "godot_truck_town", "godot_zdm2", "sauer_pandora", "generated_terrain")
SIZE = (480, 270)
CYCLES_SPP = 64
BAKED_SPP = 16
VIEW_TRANSFORM = "AgX"
JPEG_QUALITY = 90          # ~40 KB a picture (a PNG: 80-160 KB)
FRAME_AZIMUTH, FRAME_ELEVATION, FRAME_FOV = -75.0, 35.0, 40.0   # degrees; the sun is at azimuth -55
TIMEOUT = 30 * 60


@dataclass(frozen=True)
class View:
    """Where the camera goes when the file has none (module docstring, step 2).

    ``kind``: 'pose' (``location``, looking along ``look``, vertical field of view ``fov`` degrees),
    'frame' (the bounding box of the meshes whose name starts with ``prefix``, all when empty, from
    FRAME_AZIMUTH and FRAME_ELEVATION) or 'inside' (1 m below one of the lamps' points,
    ``real_scenes.indoor_points``, looking 10 deg below level: of those points and 16 level
    directions, the longest view onto a face, :func:`longest_level_look`). ``exposure``: stops, for
    both pictures."""
    kind: str = "frame"
    location: tuple = ()
    look: tuple = ()
    fov: float = FRAME_FOV
    prefix: str = ""
    exposure: float = 0.0
    says: str = ""


VIEWS = {
    # Godot demo cameras (test.tscn): Godot (x, y, z) is Blender (x, -z, y); fov is vertical there
    "godot_living_room": View("pose", (-2.932, 1.895, 2.207), (0.565, -0.824, -0.045), 51.28,
                              says="the Godot demo's camera (test.tscn)"),
    "godot_zdm2": View("pose", (11.798, -9.542, 1.499), (-0.070, -0.992, -0.102), 75.0,
                       says="the Godot demo's camera (test.tscn)"),
    "godot_truck_town": View("frame", prefix="House", says="the houses' bounding box (the town's streets, not "
                             "the 2 km terrain) framed from the south, 35 deg above the horizon"),
    "stanford_bunny": View("frame", says="its bounding box framed from the south, 35 deg above the horizon"),
    "generated_terrain": View("frame", says="the whole terrain framed from the south, 35 deg above the horizon"),
    "sauer_pandora": View("inside", says="from inside, 1 m below a lamp, along the longest level line of sight "
                          "from below any lamp, 10 deg down", exposure=-4.0),
}


def log(*a):
    print(*a, flush=True)


# ----------------------------------------------------------------------------- Blender side
def frame_distance(corners, right, up, forward, tan_h, tan_v):
    """How far back along ``-forward`` from the corners' centre a camera must stand so that every
    point of ``corners`` (N, 3; relative to that centre) falls inside a frame of half-width ``tan_h``
    and half-height ``tan_v`` (at distance 1). The unit vectors are the camera's axes."""
    import numpy as np

    x, y, z = corners @ right, corners @ up, corners @ forward
    return float(np.max(np.maximum(np.abs(x) / tan_h, np.abs(y) / tan_v) - z))


def _mesh_bounds(objects):
    import numpy as np
    from mathutils import Vector

    pts = np.array([tuple(ob.matrix_world @ Vector(c)) for ob in objects for c in ob.bound_box])
    return pts.min(0), pts.max(0)


def longest_level_look(scene, points, below=1.0):
    """(point, unit direction): of ``points`` each lowered by ``below``, and 16 level directions, the
    pair whose ray travels furthest before it meets a face from its front (a miss or a back face:
    a way out of the level, left out)."""
    import bpy
    from mathutils import Vector

    dg = bpy.context.evaluated_depsgraph_get()
    best = (-1.0, None, None)
    for p in points:
        q = Vector(p) - Vector((0.0, 0.0, below))
        for k in range(16):
            a = 2 * math.pi * k / 16
            d = Vector((math.cos(a), math.sin(a), 0.0))
            hit, loc, nrm, *_ = scene.ray_cast(dg, q, d)
            if hit and nrm.dot(d) < 0 and (loc - q).length > best[0]:
                best = ((loc - q).length, q, d)
    return best[1], best[2]


def place_camera(name):
    """Set ``scene.camera`` as the module docstring says; returns a line saying which view."""
    import bpy
    import numpy as np
    from mathutils import Vector

    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = SIZE
    scene.render.resolution_percentage = 100
    if scene.camera is not None:
        return "the file's own camera"
    v = VIEWS.get(name, View(says="the scene's bounding box framed from the south, 35 deg above the horizon"))
    data = bpy.data.cameras.new("GalleryCamera")
    data.sensor_fit = "VERTICAL"
    data.angle_y = math.radians(v.fov)
    cam = bpy.data.objects.new("GalleryCamera", data)
    scene.collection.objects.link(cam)
    if v.kind == "pose":
        loc, look = Vector(v.location), Vector(v.look).normalized()
        data.clip_start, data.clip_end = 0.05, 1000.0
    elif v.kind == "inside":
        loc, d = longest_level_look(scene, rs.indoor_points(scene, rs.LAMPS, rs.LAMP_CLEARANCE))
        look = Vector((d[0], d[1], -math.tan(math.radians(10.0)))).normalized()
        data.clip_start, data.clip_end = 0.05, 1000.0
    else:
        obs = [o for o in scene.objects if o.type == "MESH" and o.name.startswith(v.prefix) and not o.hide_render]
        lo, hi = _mesh_bounds(obs)
        centre = (lo + hi) / 2
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]) - centre
        az, el = math.radians(FRAME_AZIMUTH), math.radians(FRAME_ELEVATION)
        back = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        fwd = -back
        right = np.cross(fwd, (0.0, 0.0, 1.0))
        right /= np.linalg.norm(right)
        up = np.cross(right, fwd)
        tan_v = math.tan(data.angle_y / 2)
        dist = frame_distance(corners, right, up, fwd, tan_v * SIZE[0] / SIZE[1], tan_v)
        loc, look = Vector(centre + dist * back), Vector(fwd)
        size = float(np.linalg.norm(hi - lo))
        data.clip_start, data.clip_end = dist / 1000, 100 * (dist + size)
    cam.location = loc
    cam.rotation_euler = look.to_track_quat("-Z", "Y").to_euler()
    scene.camera = cam
    return v.says


def configure(scene, samples, bounces, denoise, exposure):
    import cycles_reference as cr

    cr.configure_cycles(scene, samples=samples, seed=0, bounces=bounces, threads=2)
    cy = scene.cycles
    if bounces:        # a user's render: Blender's default glossy and transmission bounces
        cy.glossy_bounces, cy.transmission_bounces = 4, 12
    cy.use_denoising = denoise
    if denoise:
        cy.denoiser = "OPENIMAGEDENOISE"
    scene.render.film_transparent = False
    vs = scene.view_settings
    vs.view_transform, vs.look, vs.exposure, vs.gamma = VIEW_TRANSFORM, "None", exposure, 1.0
    scene.display_settings.display_device = "sRGB"
    im = scene.render.image_settings
    im.file_format, im.color_mode, im.quality = "JPEG", "RGB", JPEG_QUALITY


def render(path):
    import bpy

    bpy.context.scene.render.filepath = path
    t = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    return time.perf_counter() - t


def gallery_child(name, no_bake=False):
    import bpy
    import numpy as np
    from hemicube_radiosity.blender.bake import BakeJob
    from hemicube_radiosity.blender.read.scene import GEOMETRY_TYPES
    from hemicube_radiosity.blender.read.visibility import render_visible_objects
    from hemicube_radiosity.core.settings import BakeSettings

    spec = rs.SPEC[name]
    load_s, light = rs.prepare(spec)
    scene = bpy.context.scene
    view = place_camera(name)
    exposure = VIEWS[name].exposure if name in VIEWS and scene.camera.name == "GalleryCamera" else 0.0
    rec = {"light": light, "view": view, "exposure": exposure, "size": list(SIZE), "load_seconds": load_s}
    os.makedirs(IMG_DIR, exist_ok=True)
    configure(scene, CYCLES_SPP, 32, True, exposure)
    rec["cycles_seconds"] = render(os.path.join(IMG_DIR, f"{name}_cycles.jpg"))
    rec["cycles_spp"] = CYCLES_SPP
    log(f"{name}: Cycles {CYCLES_SPP} spp in {rec['cycles_seconds']:.1f} s; view: {view}")
    if no_bake:
        return rec
    objs = render_visible_objects(bpy.context.view_layer, GEOMETRY_TYPES)
    t = time.perf_counter()
    job = BakeJob.prepare(bpy.context, objs, BakeSettings())
    job.run()
    job.write(bpy.context)
    rec["bake_seconds"] = time.perf_counter() - t
    rec["triangles"] = int(sum(np.sum(np.diff(m.face_offsets) - 2) for m in job.scene_input.meshes))
    rec["patches"] = int(job.result.unknowns)
    rec["warnings"] = list(job.messages().warnings)
    log(f"{name}: baked in {rec['bake_seconds']:.1f} s ({rec['patches']:,} patches)")
    configure(scene, BAKED_SPP, 0, False, exposure)
    rec["baked_seconds"] = render(os.path.join(IMG_DIR, f"{name}_baked.jpg"))
    rec["baked_spp"] = BAKED_SPP
    log(f"{name}: baked copies rendered in {rec['baked_seconds']:.1f} s")
    return rec


def child_main(argv):
    name, json_path, no_bake = argv[0], argv[1], "--no-bake" in argv
    try:
        rec = gallery_child(name, no_bake)
    except Exception as exc:  # noqa: BLE001 - the doc's row says what went wrong
        import traceback

        traceback.print_exc()
        rec = {"failure": f"{type(exc).__name__}: {(str(exc).strip().splitlines() or [''])[0]}"[:300]}
    with open(json_path, "w") as f:
        json.dump(rec, f, default=float)
    sys.stdout.flush()
    os._exit(0)   # skip Blender's teardown


# ----------------------------------------------------------------------------- parent side
def run_child(name, timeout, no_bake):
    os.makedirs(LOG_DIR, exist_ok=True)
    base = os.path.join(LOG_DIR, name)
    if os.path.exists(base + ".json"):
        os.remove(base + ".json")
    t, load = time.perf_counter(), os.getloadavg()[0]
    argv = [sys.executable, os.path.abspath(__file__), "--child", name, base + ".json"] + (["--no-bake"] * no_bake)
    with open(base + ".log", "w") as logf:
        p = subprocess.Popen(argv, cwd=ROOT, stdout=logf, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            p.wait(timeout)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
            return {"failure": f"timeout after {timeout / 60:g} min"}
    if os.path.exists(base + ".json"):
        with open(base + ".json") as f:
            rec = json.load(f)
    else:
        rec = {"failure": f"exit {p.returncode} (log: bench/out/gallery/{name}.log)"}
    rec["wall_seconds"] = time.perf_counter() - t
    rec["load_avg"] = [load, os.getloadavg()[0]]   # a shared machine: how busy it was around the scene
    return rec


def credits(scenes_dir=rs.SCENES_DIR):
    """{folder: the licence / credit cell of ../shared/scenes/README.md's table}."""
    out = {}
    with open(os.path.join(scenes_dir, "README.md")) as f:
        for line in f:
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if line.startswith("| `") and len(cells) > 2:
                out[cells[0].strip("`")] = cells[-1]
    return out


def write_doc(results, doc=DOC):
    cred = credits()
    L = ["# Gallery", "",
         "Each real scene of `../shared/scenes` (made by others; credits below each scene), and the terrain"
         " `bench/real_scenes.py` generates, from one camera: on the left"
         f" Cycles' render of the original, on the right a Cycles render of the copies that a bake with default"
         " settings writes (`python -m hemicube_radiosity bake`: `BakeJob.prepare` on every render-visible mesh,"
         " `run`, `write`). The copies show the baked colour attribute as emission, so the right picture is what the"
         " bake stored and nothing else: it is rendered with no light bounces and a few samples for anti-aliasing"
         " only. Both are lit as `bench/real_scenes.py` lights the scene (a sun and a sky where the file has no light,"
         " point lamps inside the closed `sauer_pandora`), keep the world as background, and use the same view"
         f" transform ({VIEW_TRANSFORM}) and exposure, at {SIZE[0]}x{SIZE[1]} pixels. Cycles: 32 diffuse bounces (as"
         " the bench's reference), Blender's default glossy and transmission bounces, OpenImageDenoise. A scene with"
         " no camera of its own is seen from the camera its Godot demo uses, or from a view framing it (the module"
         " docstring of `bench/gallery.py` says which).", "",
         "Regenerate: `.venv/bin/python bench/gallery.py` (`--scenes a,b`, `--all`; `make gallery`; also part of"
         f" `make bench`). Times on a 2-core machine shared with other jobs (the load average around each"
         " scene is given), each scene rendered on the commit it names.", ""]
    for spec in rs.SPECS:
        rec = results.get(spec.folder)
        if rec is None:
            continue
        L += [f"## `{spec.folder}`", ""]
        if rec.get("failure"):
            L += [f"Failed: {rec['failure']}", ""]
        else:
            L += [f"| Cycles ({rec['cycles_spp']} spp) | hemicube_radiosity, baked copy |", "|---|---|",
                  f"| ![Cycles](gallery/{spec.folder}_cycles.jpg) | ![baked copy](gallery/{spec.folder}_baked.jpg) |",
                  "",
                  f"Rendered on {rec.get('commit', 'an unknown commit')}: "
                  f"{rec['triangles']:,} triangles, {rec['patches']:,} patches; bake (read + bake + write) "
                  f"{rec['bake_seconds']:.1f} s; Cycles render {rec['cycles_seconds']:.1f} s, baked copies' render"
                  f" {rec['baked_seconds']:.1f} s ({rec['baked_spp']} spp)"
                  + ("; load average " + "-".join(f"{x:.1f}" for x in sorted(rec["load_avg"]))
                     if rec.get("load_avg") else "") + ".", "",
                  f"Light: {rec['light']}. View: {rec['view']}"
                  + (f", exposure {rec['exposure']:+g}" if rec.get("exposure") else "") + ".", ""]
        if spec.file == rs.GENERATED:
            L += ["Scene: generated by `bench/terrain.py` (1 km of ground as 128 x 128 quads and five buildings; not a"
                  " third-party file).", ""]
        if spec.folder in cred:
            L += [f"Scene: `../shared/scenes/{spec.folder}/{spec.file}`; licence and credit"
                  f" (../shared/scenes/README.md): {cred[spec.folder]}.", ""]
    with open(doc, "w") as f:
        f.write("\n".join(L).rstrip("\n") + "\n")


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--child"]:
        return child_main(argv[1:])
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", help="comma-separated folder names")
    ap.add_argument("--all", action="store_true", help="every scene of ../shared/scenes")
    ap.add_argument("--quick", action="store_true", help="real_scenes.py's quick pair")
    ap.add_argument("--timeout", type=float, default=TIMEOUT, help="seconds per scene")
    ap.add_argument("--no-bake", action="store_true", help="Cycles' pictures only (to try a view); no doc")
    args = ap.parse_args(argv)
    if not os.path.isdir(rs.SCENES_DIR):
        log(f"gallery: {rs.SCENES_DIR} is absent; skipped")
        return 0
    names = args.scenes.split(",") if args.scenes else None if args.all else list(rs.QUICK if args.quick else DEFAULT)
    specs = rs.scene_list(names=names)
    results = {}
    if os.path.exists(RESULTS):
        with open(RESULTS) as f:
            results = json.load(f)
    t = time.perf_counter()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                            text=True).stdout.strip() or "an unknown commit"
    for spec in specs:
        log(f"gallery: {spec.folder} ...")
        rec = dict(run_child(spec.folder, args.timeout, args.no_bake), commit=commit)
        log(f"gallery: {spec.folder}: " + (rec.get("failure") or f"Cycles {rec['cycles_seconds']:.1f} s"
            + ("" if args.no_bake else f", bake {rec['bake_seconds']:.1f} s, baked render {rec['baked_seconds']:.1f} s")
            + f" ({rec['wall_seconds']:.0f} s in all)"))
        if not args.no_bake:
            results[spec.folder] = rec
    if args.no_bake:
        return 0
    os.makedirs(rs.OUT_DIR, exist_ok=True)
    with open(RESULTS, "w") as f:
        json.dump(results, f, indent=1, default=float)
    write_doc(results)
    log(f"gallery: {len(specs)} scene(s) in {time.perf_counter() - t:.0f} s; wrote {os.path.relpath(DOC, ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
