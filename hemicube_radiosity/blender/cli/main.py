# SPDX-License-Identifier: GPL-3.0-or-later
"""Command line: ``python -m hemicube_radiosity bake|demo|batch ...`` (bpy module) and, registered
by the add-on, ``blender -b -c hemicube_radiosity bake ...`` (same code, :func:`main` with
``in_blender=True``: returns the exit code and never calls ``sys.exit``).

bake INPUT [-o OUTPUT ...] [--objects NAME ...] [bake settings]
    INPUT: .blend, .obj (+.mtl), .gltf, .glb or .ply. Without --objects every visible mesh is baked.
    OUTPUT: any format of :data:`.export.EXPORTERS` (.glb, .gltf, .blend, .npz, .json), by its
    extension; ``--report`` and ``--patches`` are the .json and .npz outputs by another name.
demo [--output-dir DIR]
    Builds the Cornell box, bakes it, writes DIR/cornell.glb, DIR/cornell.png and a report.
batch FILE ... --out-dir DIR [-j N] [--format glb] [--force] [bake settings]
    Bakes every FILE in its own worker process, N at a time (:mod:`.batch`).

The options are :mod:`.parser`'s (one per bake setting, from the core schema).
Errors: exit status 1 (2 for bad arguments) and one line ``hemicube_radiosity: error: ...``;
a bad argument prints the command's usage line before its ``... error: ...`` line.
``-q``: nothing on stdout (not even Blender's own lines), errors only on stderr.
"""
from __future__ import annotations

import contextlib
import dataclasses
import os
import sys
import time

import bpy
import numpy as np

from ...core.runtime.errors import RadiosityError
from ..bake import BakeJob, StagePrinter
from ..export import EXPORTERS, check_output, export, operator_error_reason
from ..read.scene import GEOMETRY_TYPES
from ..read.visibility import render_visible_objects
from .batch import cmd_batch
from .parser import INPUT_EXT, PROG, CLIError, bake_settings, build_parser

__all__ = ["main", "flush_c_stdio"]


# ----------------------------------------------------------------------------- helpers
def load_input(path):
    """Replace the current file with INPUT (an empty scene plus the import for .obj/.gltf/.glb/.ply)."""
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
            import_obj(path)
        elif ext == ".ply":
            bpy.ops.wm.ply_import(filepath=path)
        else:
            bpy.ops.import_scene.gltf(filepath=path)
    except RuntimeError as ex:
        raise CLIError(f"cannot read {path}: {operator_error_reason(ex, path, 'importer')} (is it a complete, "
                       f"undamaged {ext} file?)") from None


def import_obj(path):
    """Blender's OBJ importer, its meshes validated so that the same file always gives the same
    faces. The importer's own validation (``validate_meshes``) keeps one of the faces that use
    the same vertices (a thin wall modelled as two faces back to back, often of two materials),
    but which one came out of an unstable parallel sort and changed from run to run
    (sauer_pandora: about one import in twelve kept another face of such a pair, and the bake
    moved by 0.3 points of RMS). Here the first in the file is kept: the others' corners are
    made to repeat one vertex (:func:`repeated_faces`), which Blender's validation removes as it
    removes any face with a repeated vertex, with nothing left to choose. (A file with faces the
    importer itself finds broken, a repeated vertex in one face, is validated by the importer as
    before.)"""
    bpy.ops.wm.obj_import(filepath=path, validate_meshes=False)
    for me in bpy.data.meshes:
        lv, start, total = face_loops(me)
        drop = repeated_faces(lv, start, total)
        if drop.any():
            f = np.flatnonzero(drop)
            lv[np.repeat(start[f], total[f]) + _ranks(total[f])] = np.repeat(lv[start[f]], total[f])
            me.loops.foreach_set("vertex_index", lv)
        me.validate(verbose=False, clean_customdata=False)


def _ranks(counts):
    """0 .. c - 1 for each count c of ``counts``, laid end to end."""
    return np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)


def face_loops(me):
    """(vertex index per loop (L,), loop start per face (F,), loops per face (F,)) of mesh
    ``me``, int32."""
    lv, start, total = (np.empty(n, np.int32) for n in (len(me.loops), len(me.polygons), len(me.polygons)))
    me.loops.foreach_get("vertex_index", lv)
    me.polygons.foreach_get("loop_start", start)
    me.polygons.foreach_get("loop_total", total)
    return lv, start, total


def repeated_faces(lv, start, pt):
    """(F,) bool: the faces that use the same vertices as an earlier face (in any order or
    winding), of a mesh whose loops' vertices are ``lv`` (L,) and whose faces start at loop
    ``start`` (F,) with ``pt`` (F,) loops (:func:`face_loops`)."""
    nf = len(pt)
    out = np.zeros(nf, bool)
    if nf < 2:
        return out
    first = np.concatenate([[0], np.cumsum(pt)[:-1]])
    v = lv[np.repeat(start, pt) + _ranks(pt)]                     # the corners face by face
    sv = v[np.lexsort((v, np.repeat(np.arange(nf), pt)))]        # each face's vertices, ascending
    for k in np.unique(pt):
        f = np.flatnonzero(pt == k)
        rows = sv[first[f][:, None] + np.arange(k)]
        _, keep = np.unique(rows, axis=0, return_index=True)      # the first of each vertex set
        out[f] = True
        out[f[keep]] = False
    return out


def _select_objects(names, input_path="the input"):
    if not names:
        objs = render_visible_objects(bpy.context.view_layer, GEOMETRY_TYPES)
        if not objs:
            raise CLIError(f"no mesh objects that a render shows in {input_path}")
        return objs
    out = []
    for n in names:
        o = bpy.data.objects.get(n)
        if o is None:
            raise CLIError(f"no object named {n!r} in the input")
        if o.type not in GEOMETRY_TYPES and not (o.type == "EMPTY" and o.instance_type == "COLLECTION"
                                                and o.instance_collection is not None):
            raise CLIError(f"{n!r} is not a mesh object (it is a {o.type.lower()})")
        out.append(o)
    return out


def _read_line(job):
    """What the read gave: '755 object(s) to bake (20 left out), 0 other(s), 262526 faces'."""
    si = job.scene_input
    baked = sum(o.bake for o in si.objects)
    faces = sum(len(o.mesh.face_offsets) - 1 for o in si.objects)
    left = f" ({len(si.skipped)} left out)" if si.skipped else ""
    return f"{baked} object(s) to bake{left}, {len(si.objects) - baked} other(s), {faces} faces"


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
        for level, line in job.messages().lines():
            print(f"radiosity: {level}: {line}", file=out)
        for path in written.values():
            print(f"radiosity: wrote {path}", file=out)
        print(f"radiosity: {job.summary()}", file=out)
        print(f"radiosity: done in {job.timings['total']:.2f} s", file=out, flush=True)
    return written


# ----------------------------------------------------------------------------- commands
def cmd_bake(args, out):
    t_start = time.perf_counter()
    settings = bake_settings(args)
    outputs = _outputs(args)
    if not outputs and not args.report:
        raise CLIError("nothing would be written: give -o OUTPUT (" + ", ".join(EXPORTERS) + ")", 2)
    source = os.path.realpath(args.input)
    for p in (*outputs, args.report):
        if p and os.path.realpath(p) == source:
            raise CLIError(f"the output {p} would overwrite the input: write to another file", 2)
    if settings.target == "lightmap" and not settings.lightmap_dir:   # lightmaps beside the outputs
        settings = dataclasses.replace(settings, lightmap_dir=os.path.dirname(os.path.abspath(
            (outputs or [args.report])[0])))
    load_input(args.input)
    t_loaded = time.perf_counter()
    objects = _select_objects(args.objects, os.path.abspath(args.input))
    job = BakeJob.prepare(bpy.context, objects, settings, cache=_cache(settings))
    job.timings["load"] = t_loaded - t_start
    if not args.quiet:
        print(f"radiosity: read: {_read_line(job)} ({job.timings['read']:.2f} s)", file=out, flush=True)
    _bake_and_write(job, args, outputs, out, t_start, input=os.path.abspath(args.input))
    return job


def cmd_demo(args, out):
    from .. import demo

    t_start = time.perf_counter()
    settings = bake_settings(args)
    d = os.path.abspath(args.output_dir)
    args.report = args.report or os.path.join(d, "cornell_report.json")
    outputs = _outputs(args, os.path.join(d, "cornell.glb"))
    if settings.target == "lightmap" and not settings.lightmap_dir:
        settings = dataclasses.replace(settings, lightmap_dir=d)
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
    from ...core.runtime.cache import FormFactorCache

    return FormFactorCache(settings.cache_dir)


@contextlib.contextmanager
def _silenced_stdout(active):
    """With ``-q``: the process's stdout (file descriptor 1) goes to the null device, so that
    Blender's own lines (``Read blend``, the glTF exporter's log) are gone too. stderr is kept."""
    try:
        fd = sys.stdout.fileno() if active else None
    except (AttributeError, OSError, ValueError):
        fd = None
    if fd is None:
        yield
        return
    sys.stdout.flush()
    saved = os.dup(fd)
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, fd)
    os.close(null)
    try:
        yield
    finally:
        sys.stdout.flush()
        flush_c_stdio()
        os.dup2(saved, fd)
        os.close(saved)


def flush_c_stdio():
    """fflush(NULL): what Blender printed through C stdio, before fd 1 changes or the process ends."""
    try:
        import ctypes

        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError, TypeError):  # no C library handle (Windows)
        pass


COMMANDS = {"bake": lambda args, out, err: cmd_bake(args, out) and 0,
            "demo": lambda args, out, err: cmd_demo(args, out) and 0,
            "batch": cmd_batch}


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
        with _silenced_stdout(args.quiet and out in (sys.stdout, sys.__stdout__)):
            return COMMANDS[args.command](args, out, err)
    except CLIError as ex:
        msg, status, usage, prog = str(ex), ex.status, ex.usage, ex.prog
    except RadiosityError as ex:
        msg, status, usage, prog = str(ex), 1, None, PROG
    msg = msg.strip().splitlines()[0] if msg.strip() else "failed"
    if usage:
        print(usage, file=err)
    print(f"{prog}: error: {msg}", file=err, flush=True)
    return status
