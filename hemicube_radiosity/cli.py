# SPDX-License-Identifier: GPL-3.0-or-later
"""Command line: ``python -m hemicube_radiosity bake|demo ...`` (bpy module) and, registered by the
add-on, ``blender -b -c hemicube_radiosity bake ...`` (same code, :func:`main` with
``in_blender=True``: returns the exit code and never calls ``sys.exit``).

bake INPUT [-o OUTPUT] [--objects NAME ...] [--patch-size S] [--resolution R]
     [--method hemicube|embree|embree_stochastic] [--solver gauss_seidel|jacobi|progressive]
     [--report REPORT.json] [--patches PATCHES.npz] ...
    INPUT: .blend, .obj (+.mtl), .gltf or .glb. Without --objects every visible mesh is baked.
    OUTPUT: .glb/.gltf (baked glTF: COLOR_0 + unlit materials) or .blend (the baked scene).
demo [--output-dir DIR]
    Builds the Cornell box, bakes it, writes DIR/cornell.glb and DIR/cornell.png.

Errors: exit status 1 and one line ``hemicube_radiosity: error: ...`` on stderr.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

__all__ = ["main", "build_parser", "CLIError"]

PROG = "hemicube_radiosity"
INPUT_EXT = (".blend", ".obj", ".gltf", ".glb")
OUTPUT_EXT = (".blend", ".gltf", ".glb")


class CLIError(Exception):
    """A user error: printed as one line, exit status 1 (2 for bad arguments)."""

    def __init__(self, message, status=1):
        super().__init__(message)
        self.status = status


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # never sys.exit from inside Blender
        raise CLIError(f"{self.prog}: {message}", status=2)


def _size(text):
    """A size argument: 'auto' or a number >= 0."""
    if text == "auto":
        return text
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected 'auto' or a number, got {text!r}") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {v:g}")
    return v


def _add_bake_settings(p, defaults):
    p.add_argument("--patch-size", type=_size, default=defaults.patch_size, metavar="S",
                   help="target patch edge length in scene units; 0 = one patch per face; auto = "
                        "the scene's diagonal / 14 (default %(default)s)")
    p.add_argument("--resolution", type=int, default=defaults.resolution, metavar="R",
                   help="hemi-cube top-face resolution, even (default %(default)s)")
    p.add_argument("--method", choices=("hemicube", "embree", "embree_stochastic"),
                   default=defaults.method, help="form-factor method (default %(default)s)")
    p.add_argument("--rays-per-patch", type=int, default=defaults.rays_per_patch, metavar="N",
                   help="rays per patch for embree_stochastic (default %(default)s)")
    p.add_argument("--direct", choices=("exact", "hemicube"), default=getattr(defaults, "direct", "exact"),
                   help="direct light from emitters: exact (shadow rays) or through the hemi-cube "
                        "form factors as in the paper (default %(default)s)")
    p.add_argument("--direct-samples", type=int, default=getattr(defaults, "direct_samples", 16),
                   metavar="N", help="shadow rays per point and emitting face (default %(default)s)")
    p.add_argument("--element-size", type=_size, default=defaults.element_size, metavar="S",
                   help="cut the baked mesh finer than the patches (direct light exact at every "
                        "vertex, bounced light from the patches); 0 = the patches; auto = a third "
                        "of the patch size (default %(default)s)")
    p.add_argument("--gather-rays", type=int, default=defaults.gather_rays, metavar="N",
                   help="with --element-size: gather bounced light at every vertex with N rays "
                        "instead of interpolating it (needs Embree; default %(default)s)")
    p.add_argument("--solver", choices=("gauss_seidel", "jacobi", "progressive"),
                   default=defaults.solver, help="(default %(default)s)")
    p.add_argument("--tolerance", type=float, default=defaults.tolerance,
                   help="relative residual to stop at (default %(default)s)")
    p.add_argument("--max-iterations", type=int, default=defaults.max_iterations,
                   help="(default %(default)s)")
    p.add_argument("--attribute", default="Radiosity", help="colour attribute name (default %(default)s)")
    p.add_argument("--exposure", type=float, default=0.0,
                   help="stops; written colours are radiance x 2^exposure (default 0: radiance)")
    p.add_argument("--no-lights", action="store_true",
                   help="ignore light objects and the world (only emissive surfaces light the scene)")
    p.add_argument("--cache", metavar="DIR", help="form-factor cache directory (reused across runs)")
    p.add_argument("--report", metavar="REPORT.json", help="write timings, counts and energy balance")
    p.add_argument("--patches", metavar="PATCHES.npz", help="write per-patch arrays")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines on stdout")


def build_parser():
    from .core.pipeline import BakeSettings

    d = BakeSettings()
    p = _Parser(prog=PROG, description="Hemi-cube radiosity baking with Blender (bpy).")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    b = sub.add_parser("bake", help="bake a scene file", description="Bake a .blend/.obj/.gltf/.glb.")
    b.add_argument("input", metavar="INPUT", help="scene file: .blend, .obj, .gltf or .glb")
    b.add_argument("-o", "--output", metavar="OUTPUT", help="baked .glb/.gltf or .blend to write")
    b.add_argument("--objects", nargs="+", metavar="NAME",
                   help="objects to bake (default: every visible mesh); other visible meshes "
                        "still occlude and emit unless --no-others")
    b.add_argument("--no-others", action="store_true",
                   help="with --objects: leave the other meshes out of the bake entirely")
    b.add_argument("--in-place", action="store_true",
                   help="write the attribute on the original meshes instead of baked copies")
    _add_bake_settings(b, d)
    m = sub.add_parser("demo", help="bake the Cornell box demo and render a preview",
                       description="Build the Cornell box, bake it, write cornell.glb and cornell.png.")
    m.add_argument("--output-dir", default=os.path.join("demo", "out"), metavar="DIR")
    m.add_argument("--render-size", type=int, default=512, metavar="PX", help="PNG size (default %(default)s)")
    m.add_argument("--samples", type=int, default=16, help="Cycles samples for the PNG (default %(default)s)")
    m.add_argument("--no-render", action="store_true", help="skip the PNG")
    _add_bake_settings(m, d)
    return p


# ----------------------------------------------------------------------------- helpers
def _settings(args):
    from .blender.bake import BakeOptions
    from .core.pipeline import BakeSettings

    s = BakeSettings(patch_size=args.patch_size or None,
                     resolution=args.resolution, method=args.method,
                     rays_per_patch=args.rays_per_patch, solver=args.solver,
                     tolerance=args.tolerance, max_iterations=args.max_iterations)
    if hasattr(s, "direct"):
        s.direct, s.direct_samples = args.direct, args.direct_samples
    s.element_size = args.element_size or None
    s.gather_rays = args.gather_rays
    try:
        s.validate()
    except ValueError as ex:
        raise CLIError(str(ex), status=2) from None
    mode = "IN_PLACE" if getattr(args, "in_place", False) else "COPY"
    return BakeOptions(s, mode, args.attribute, args.exposure,
                       include_others=not getattr(args, "no_others", False),
                       use_lights=not args.no_lights)


def _cache(args):
    if not args.cache:
        return None
    from .core.cache import FormFactorCache

    return FormFactorCache(args.cache)


def load_input(path):
    """Replace the current file with INPUT (an empty scene plus the import for .obj/.gltf/.glb)."""
    import bpy

    ext = os.path.splitext(path)[1].lower()
    if ext not in INPUT_EXT:
        raise CLIError(f"unsupported input {path!r}: expected one of {', '.join(INPUT_EXT)}", 2)
    if not os.path.isfile(path):
        raise CLIError(f"input file not found: {path}")
    path = os.path.abspath(path)
    if ext == ".blend":
        bpy.ops.wm.open_mainfile(filepath=path, load_ui=False)
        return
    bpy.ops.wm.read_homefile(use_empty=True)
    if ext == ".obj":
        bpy.ops.wm.obj_import(filepath=path)
    else:
        bpy.ops.import_scene.gltf(filepath=path)


def _select_objects(names):
    import bpy

    vl = bpy.context.view_layer
    if not names:
        objs = [o for o in vl.objects if o.type == "MESH" and o.visible_get()]
        if not objs:
            raise CLIError("no visible mesh objects in the input")
        return objs
    out = []
    for n in names:
        o = bpy.data.objects.get(n)
        if o is None:
            raise CLIError(f"no object named {n!r} in the input")
        if o.type != "MESH":
            raise CLIError(f"{n!r} is not a mesh object (it is a {o.type.lower()})")
        out.append(o)
    return out


def write_patches(path, result):
    import numpy as np

    P = result.patches
    names = np.array([P.object_names[i] for i in P.owner], dtype=str)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    np.savez_compressed(path, centers=P.centers, normals=P.normals, areas=P.areas,
                        radiosity=result.solution.B, emission=P.emission, reflectance=P.rho,
                        object=names)


def _jsonable(x):
    import numpy as np

    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    return x


def make_report(job, timings, extra=None):
    r = job.result
    s = r.settings or job.options.settings   # as used: 'auto' sizes in scene units
    rep = {
        "timings": {k: float(v) for k, v in timings.items()},
        "patches": int(len(r.patches)),
        "elements": int(len(r.elements)),
        "nonzeros": int(r.form_factors.nnz),
        "iterations": int(r.solution.iterations),
        "residual": float(r.solution.residual),
        "converged": bool(r.solution.converged),
        "energy": _jsonable(r.solution.energy),
        "form_factor_source": r.form_factor_source,
        "settings": {"patch_size": s.patch_size, "resolution": s.resolution, "method": s.method,
                     "rays_per_patch": s.rays_per_patch, "solver": s.solver,
                     "tolerance": s.tolerance, "max_iterations": s.max_iterations,
                     "direct": getattr(s, "direct", None),
                     "direct_samples": getattr(s, "direct_samples", None),
                     "element_size": s.element_size, "gather_rays": s.gather_rays,
                     "output_mode": job.options.output_mode,
                     "attribute": job.options.attribute_name, "exposure": job.options.exposure},
        "objects": [o.name for o in job.scene_input.objects if o.bake],
        "occluders": [o.name for o in job.scene_input.objects if not o.bake],
        "written": [o.name for o in job.written],
        "notes": list(job.notes),
    }
    rep.update(extra or {})
    return rep


def _write_json(path, data):
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w", encoding="utf-8") as f:
        json.dump(data, f, indent=2)


# ----------------------------------------------------------------------------- commands
def _run_bake(job, args, out):
    from .blender.bake import StagePrinter

    printer = None if args.quiet else StagePrinter(stream=out)
    job.run(progress=printer)
    return printer


def cmd_bake(args, out):
    import bpy

    from .blender.bake import BakeJob
    from .blender.gltf import export_gltf

    t_start = time.perf_counter()
    options = _settings(args)
    if args.output and os.path.splitext(args.output)[1].lower() not in OUTPUT_EXT:
        raise CLIError(f"unsupported output {args.output!r}: expected one of {', '.join(OUTPUT_EXT)}", 2)
    load_input(args.input)
    t_loaded = time.perf_counter()
    objects = _select_objects(args.objects)
    job = BakeJob.prepare(bpy.context, objects, options, cache=_cache(args))
    printer = _run_bake(job, args, out)
    t = time.perf_counter()
    job.write(bpy.context, progress=printer)
    outputs = {}
    if args.output:
        ext = os.path.splitext(args.output)[1].lower()
        path = os.path.abspath(args.output)
        if ext == ".blend":
            os.makedirs(os.path.dirname(path), exist_ok=True)
            bpy.ops.wm.save_as_mainfile(filepath=path, copy=True)
        else:
            export_gltf(path, job.written)
        outputs["output"] = path
    if args.patches:
        write_patches(args.patches, job.result)
        outputs["patches"] = os.path.abspath(args.patches)
    t_end = time.perf_counter()
    timings = {k: job.timings[k] for k in ("patches", "form_factors", "solve") if k in job.timings}
    timings.update(load=t_loaded - t_start, read=job.timings.get("read", 0.0), write=t_end - t,
                   total=t_end - t_start)
    if args.report:
        outputs["report"] = os.path.abspath(args.report)
        _write_json(args.report, make_report(job, timings, {"input": os.path.abspath(args.input),
                                                            "outputs": outputs}))
    if not args.quiet:
        for line in job.notes:
            print(f"radiosity: note: {line}", file=out)
        for v in outputs.values():
            print(f"radiosity: wrote {v}", file=out)
        print(f"radiosity: done in {t_end - t_start:.2f} s", file=out, flush=True)
    return job


def cmd_demo(args, out):
    import bpy

    from .blender import demo
    from .blender.bake import BakeJob
    from .blender.gltf import export_gltf

    t_start = time.perf_counter()
    options = _settings(args)
    bpy.ops.wm.read_homefile(use_empty=True)
    objects = demo.build_cornell_box(bpy.context)
    job = BakeJob.prepare(bpy.context, objects, options, cache=_cache(args))
    printer = _run_bake(job, args, out)
    t = time.perf_counter()
    job.write(bpy.context, progress=printer)
    d = os.path.abspath(args.output_dir)
    os.makedirs(d, exist_ok=True)
    paths = {"glb": export_gltf(os.path.join(d, "cornell.glb"), job.written)}
    t_write = time.perf_counter() - t
    if not args.no_render:
        t = time.perf_counter()
        demo.add_preview_camera(bpy.context)
        paths["png"] = demo.render_preview(bpy.context, os.path.join(d, "cornell.png"),
                                           resolution=args.render_size, samples=args.samples)
        t_render = time.perf_counter() - t
    else:
        t_render = 0.0
    timings = {k: job.timings[k] for k in ("patches", "form_factors", "solve") if k in job.timings}
    timings.update(write=t_write, render=t_render, total=time.perf_counter() - t_start)
    report = args.report or os.path.join(d, "cornell_report.json")
    _write_json(report, make_report(job, timings, {"outputs": paths}))
    if args.patches:
        write_patches(args.patches, job.result)
    print(f"radiosity: {job.summary()}", file=out)
    for k, v in paths.items():
        print(f"radiosity: wrote {v}", file=out)
    print(f"radiosity: wrote {os.path.abspath(report)}", file=out, flush=True)
    return job


def main(argv=None, in_blender=False, out=None, err=None):
    """Run a command; returns the exit status (0 ok, 1 failure, 2 bad arguments)."""
    out = out or sys.stdout
    err = err or sys.stderr
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        try:
            args = build_parser().parse_args(argv)
        except SystemExit as ex:  # --help
            return int(ex.code or 0)
        try:
            import bpy  # noqa: F401
        except ImportError:
            raise CLIError("the 'bpy' module is needed: pip install bpy (or run inside Blender "
                           "with: blender -b -c hemicube_radiosity ...)") from None
        (cmd_bake if args.command == "bake" else cmd_demo)(args, out)
        return 0
    except CLIError as ex:
        msg, status = str(ex), ex.status
    except Exception as ex:  # one clear line, whatever went wrong
        from .blender.bake import BakeError

        status = 1
        msg = str(ex) if isinstance(ex, BakeError) else f"{type(ex).__name__}: {ex}"
        if not isinstance(ex, BakeError) and os.environ.get("HEMICUBE_RADIOSITY_DEBUG"):
            import traceback

            traceback.print_exc(file=err)
    msg = msg.strip().splitlines()[0] if msg.strip() else "failed"
    print(f"{PROG}: error: {msg}", file=err, flush=True)
    return status
