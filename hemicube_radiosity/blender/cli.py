# SPDX-License-Identifier: GPL-3.0-or-later
"""Command line: ``python -m hemicube_radiosity bake|demo ...`` (bpy module) and, registered by the
add-on, ``blender -b -c hemicube_radiosity bake ...`` (same code, :func:`main` with
``in_blender=True``: returns the exit code and never calls ``sys.exit``).

bake INPUT [-o OUTPUT ...] [--objects NAME ...] [bake settings]
    INPUT: .blend, .obj (+.mtl), .gltf or .glb. Without --objects every visible mesh is baked.
    OUTPUT: any format of :data:`.export.EXPORTERS` (.glb, .gltf, .blend, .npz, .json), by its
    extension; ``--report`` and ``--patches`` are the .json and .npz outputs by another name.
demo [--output-dir DIR]
    Builds the Cornell box, bakes it, writes DIR/cornell.glb, DIR/cornell.png and a report.

The bake settings' options are generated from the core schema (``core/settings.py``): every
setting has one, named ``--field-name`` unless the schema says otherwise.
Errors: exit status 1 (2 for bad arguments) and one line ``hemicube_radiosity: error: ...``.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import bpy

from ..core.errors import RadiosityError
from ..core.settings import BakeSettings, schema
from .bake import BakeJob, StagePrinter
from .export import EXPORTERS, check_output, export
from .read import render_visible_objects

__all__ = ["main", "build_parser", "CLIError"]

PROG = "hemicube_radiosity"
INPUT_EXT = (".blend", ".obj", ".gltf", ".glb")


class CLIError(RadiosityError):
    """A user error on the command line: printed as one line, exit status ``status``."""

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


def add_setting_options(p):
    """One option per setting of the core schema, with its default, choices and help."""
    for s in schema():
        flag = s.meta.get("cli", "--" + s.name.replace("_", "-"))
        help = s.help.replace("%", "%%")
        if s.type is bool:
            action = "store_false" if s.default else "store_true"
            p.add_argument(flag, dest=s.name, action=action, default=s.default, help=help)
            continue
        kw = dict(dest=s.name, default=s.default, help=f"{help} (default %(default)s)")
        if s.choices is not None:
            kw.update(choices=s.values, type=str.lower)
        elif s.meta.get("size"):
            kw.update(type=_size, metavar="S")
        else:
            kw.update(type=s.type, metavar=s.name.split("_")[-1].upper())
        p.add_argument(flag, **kw)


def build_parser():
    p = _Parser(prog=PROG, description="Hemi-cube radiosity baking with Blender (bpy).")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    b = sub.add_parser("bake", help="bake a scene file", description="Bake a .blend/.obj/.gltf/.glb.")
    b.add_argument("input", metavar="INPUT", help="scene file: " + ", ".join(INPUT_EXT))
    b.add_argument("-o", "--output", action="append", default=[], metavar="OUTPUT",
                   help="file to write, by extension: " + "; ".join(
                       f"{ext} {what}" for ext, (_, what, _) in EXPORTERS.items()) + " (repeatable)")
    b.add_argument("--objects", nargs="+", metavar="NAME",
                   help="objects to bake (default: every visible mesh); other visible meshes "
                        "still occlude and emit unless --no-others")
    m = sub.add_parser("demo", help="bake the Cornell box demo and render a preview",
                       description="Build the Cornell box, bake it, write cornell.glb and cornell.png.")
    m.add_argument("--output-dir", default=os.path.join("demo", "out"), metavar="DIR")
    m.add_argument("--render-size", type=int, default=512, metavar="PX", help="PNG size (default %(default)s)")
    m.add_argument("--samples", type=int, default=16, help="Cycles samples for the PNG (default %(default)s)")
    m.add_argument("--no-render", action="store_true", help="skip the PNG")
    for q in (b, m):
        q.add_argument("--report", metavar="REPORT.json", help="write the bake report (a .json output)")
        q.add_argument("--patches", metavar="PATCHES.npz", help="write per-patch arrays (a .npz output)")
        q.add_argument("-q", "--quiet", action="store_true", help="no progress lines on stdout")
        add_setting_options(q)
    return p


# ----------------------------------------------------------------------------- helpers
def _settings(args) -> BakeSettings:
    s = BakeSettings.from_mapping(args)
    try:
        s.validate()
    except RadiosityError as ex:
        raise CLIError(str(ex), status=2) from None
    return s


def load_input(path):
    """Replace the current file with INPUT (an empty scene plus the import for .obj/.gltf/.glb)."""
    ext = os.path.splitext(path)[1].lower()
    if ext not in INPUT_EXT:
        raise CLIError(f"unsupported input {path!r}: expected one of {', '.join(INPUT_EXT)}", 2)
    if not os.path.isfile(path):
        raise CLIError(f"input file not found: {path}")
    path = os.path.abspath(path)
    try:
        if ext == ".blend":
            bpy.ops.wm.open_mainfile(filepath=path, load_ui=False)
            return
        bpy.ops.wm.read_homefile(use_empty=True)
        if ext == ".obj":
            bpy.ops.wm.obj_import(filepath=path)
        else:
            bpy.ops.import_scene.gltf(filepath=path)
    except RuntimeError as ex:
        reason = str(ex).strip().splitlines()[0] if str(ex).strip() else "unreadable"
        raise CLIError(f"cannot read {path}: {reason}") from None


def _select_objects(names):
    if not names:
        objs = render_visible_objects(bpy.context.view_layer, {"MESH"})
        if not objs:
            raise CLIError("no mesh objects that a render shows in the input")
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


def _outputs(args, *paths):
    """Every output the command line asks for, checked before any work: (path, ...)."""
    wanted = [p for p in (*paths, *getattr(args, "output", []), args.patches) if p]
    for p in wanted:
        try:
            check_output(p)
        except RadiosityError as ex:
            raise CLIError(str(ex), status=2) from None
    if args.report:
        if os.path.splitext(args.report)[1].lower() != ".json":
            raise CLIError(f"the report is JSON: {args.report!r} should end in .json", 2)
    return wanted


def _bake_and_write(job, args, outputs, out, t_start, after_write=None, **extra):
    """Run the job, write it to the scene and to ``outputs``, then the report; print the lines.
    ``after_write()`` (e.g. the demo's preview render) runs once the scene holds the result and
    returns more report entries."""
    printer = None if args.quiet else StagePrinter(stream=out)
    job.run(progress=printer)
    job.write(bpy.context, progress=printer)
    written = {p: export(p, job) for p in outputs}
    if after_write is not None:
        extra.update(after_write())
        written.update({v: v for v in extra.values() if isinstance(v, str)})
    job.timings["total"] = time.perf_counter() - t_start
    if args.report:
        written[args.report] = export(args.report, job, job.report(outputs=list(written.values()), **extra))
    if not args.quiet:
        for line in job.notes:
            print(f"radiosity: note: {line}", file=out)
        for path in written.values():
            print(f"radiosity: wrote {path}", file=out)
        print(f"radiosity: {job.summary()}", file=out)
        print(f"radiosity: done in {job.timings['total']:.2f} s", file=out, flush=True)
    return written


# ----------------------------------------------------------------------------- commands
def cmd_bake(args, out):
    t_start = time.perf_counter()
    settings = _settings(args)
    outputs = _outputs(args)
    if not outputs and not args.report:
        raise CLIError("nothing would be written: give -o OUTPUT (" + ", ".join(EXPORTERS) + ")", 2)
    load_input(args.input)
    t_loaded = time.perf_counter()
    job = BakeJob.prepare(bpy.context, _select_objects(args.objects), settings, cache=_cache(settings))
    job.timings["load"] = t_loaded - t_start
    _bake_and_write(job, args, outputs, out, t_start, input=os.path.abspath(args.input))
    return job


def cmd_demo(args, out):
    from . import demo

    t_start = time.perf_counter()
    settings = _settings(args)
    d = os.path.abspath(args.output_dir)
    args.report = args.report or os.path.join(d, "cornell_report.json")
    outputs = _outputs(args, os.path.join(d, "cornell.glb"))
    bpy.ops.wm.read_homefile(use_empty=True)
    objects = demo.build_cornell_box(bpy.context)
    job = BakeJob.prepare(bpy.context, objects, settings, cache=_cache(settings))

    def render():
        if args.no_render:
            return {}
        t = time.perf_counter()
        demo.add_preview_camera(bpy.context)
        png = demo.render_preview(bpy.context, os.path.join(d, "cornell.png"),
                                  resolution=args.render_size, samples=args.samples)
        job.timings["render"] = time.perf_counter() - t
        return {"preview": png}

    _bake_and_write(job, args, outputs, out, t_start, after_write=render)
    return job


def _cache(settings):
    """A command-line run keeps form factors on disk only when asked (``--cache DIR``)."""
    if not settings.cache_dir:
        return None
    from ..core.cache import FormFactorCache

    return FormFactorCache(settings.cache_dir)


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
        (cmd_bake if args.command == "bake" else cmd_demo)(args, out)
        return 0
    except RadiosityError as ex:
        msg, status = str(ex), getattr(ex, "status", 1)
    msg = msg.strip().splitlines()[0] if msg.strip() else "failed"
    print(f"{PROG}: error: {msg}", file=err, flush=True)
    return status
