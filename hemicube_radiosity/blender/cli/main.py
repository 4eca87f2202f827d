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
batch FILE ... --out-dir DIR [-j N] [--format glb] [--force] [bake settings]
    Bakes every FILE in its own worker process (``bake FILE -o DIR/NAME.glb --report
    DIR/NAME.json``), N at a time; one line per file, a table at the end, exit status 1 if any
    failed. A file whose content and settings are unchanged since its last successful bake is
    skipped (the key is kept in its report) unless --force. See ``docs/pipeline.md``.

The bake settings' options are generated from the core schema (``core/settings.py``): every
setting has one, named ``--field-name`` unless the schema says otherwise.
Errors: exit status 1 (2 for bad arguments) and one line ``hemicube_radiosity: error: ...``;
a bad argument prints the command's usage line before its ``... error: ...`` line.
``-q``: nothing on stdout (not even Blender's own lines), errors only on stderr.
"""
from __future__ import annotations

import argparse
import concurrent.futures
import contextlib
import dataclasses
import hashlib
import json
import os
import subprocess
import sys
import threading
import time

import bpy

from ... import __version__
from ...core.runtime.errors import RadiosityError
from ...core.settings import BakeSettings, schema
from ..bake import BakeJob, StagePrinter
from ..export import EXPORTERS, check_output, export, operator_error_reason
from ..read.scene import GEOMETRY_TYPES, render_visible_objects

__all__ = ["main", "build_parser", "CLIError"]

PROG = "hemicube_radiosity"
INPUT_EXT = (".blend", ".obj", ".gltf", ".glb")


class CLIError(RadiosityError):
    """A user error on the command line: printed as one line, exit status ``status``; ``usage``
    (argparse's errors) is printed on the line before."""

    def __init__(self, message, status=1, usage=None, prog=PROG):
        super().__init__(message)
        self.status = status
        self.usage = usage
        self.prog = prog


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # never sys.exit from inside Blender: main() prints it
        raise CLIError(message, status=2, usage=self.format_usage().strip(), prog=self.prog)


def _number(kind, lowest, expected, auto=False):
    """An argparse type: a ``kind`` (int or float) >= ``lowest``, or 'auto' where allowed."""
    def parse(text):
        if auto and text == "auto":
            return text
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None
        if v < lowest:
            raise argparse.ArgumentTypeError(f"must be >= {lowest}, got {v:g}")
        return v
    return parse


_size = _number(float, 0, "'auto' or a number", auto=True)        # a size: 'auto' or >= 0
_positive_int = _number(int, 1, "a whole number")                   # a count: >= 1


def _flag(s):
    """The command-line option of setting ``s``: ``--field-name`` unless the schema names another."""
    return s.meta.get("cli", "--" + s.name.replace("_", "-"))


def add_setting_options(p):
    """One option per setting of the core schema, with its default, choices and help."""
    for s in schema():
        flag = _flag(s)
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
    b = sub.add_parser("bake", help="bake a scene file", description="Bake a .blend/.obj/.gltf/.glb.",
                       usage="%(prog)s INPUT [-o OUTPUT ...] [options]  (--help lists them)")
    b.add_argument("input", metavar="INPUT", help="scene file: " + ", ".join(INPUT_EXT))
    b.add_argument("-o", "--output", action="append", default=[], metavar="OUTPUT",
                   help="file to write, by extension: " + "; ".join(
                       f"{ext} {what}" for ext, (_, what, _) in EXPORTERS.items()) + " (repeatable)")
    b.add_argument("--objects", nargs="+", metavar="NAME",
                   help="objects to bake (default: every visible mesh); other visible meshes "
                        "still occlude and emit unless --no-others")
    m = sub.add_parser("demo", help="bake the Cornell box demo and render a preview",
                       description="Build the Cornell box, bake it, write cornell.glb and cornell.png.",
                       usage="%(prog)s [--output-dir DIR] [options]  (--help lists them)")
    m.add_argument("--output-dir", default=os.path.join("demo", "out"), metavar="DIR")
    m.add_argument("--render-size", type=int, default=512, metavar="PX", help="PNG size (default %(default)s)")
    m.add_argument("--samples", type=int, default=16, help="Cycles samples for the PNG (default %(default)s)")
    m.add_argument("--no-render", action="store_true", help="skip the PNG")
    for q in (b, m):
        q.add_argument("--report", metavar="REPORT.json", help="write the bake report (a .json output)")
        q.add_argument("--patches", metavar="PATCHES.npz", help="write per-patch arrays (a .npz output)")
    t = sub.add_parser("batch", help="bake many files, one worker process each",
                       description="Bake every FILE in its own process (python -m hemicube_radiosity "
                                   "bake, or Blender itself inside Blender), N at a time, into "
                                   "DIR/NAME.FORMAT with DIR/NAME.json as its report. Unchanged files "
                                   "(same content, same settings) are skipped unless --force.",
                       usage="%(prog)s FILE [FILE ...] --out-dir DIR [-j N] [options]  (--help lists them)")
    t.add_argument("files", nargs="+", metavar="FILE", help="scene files: " + ", ".join(INPUT_EXT))
    t.add_argument("--out-dir", required=True, metavar="DIR", help="where NAME.FORMAT and NAME.json go")
    t.add_argument("-j", "--jobs", type=_positive_int, default=_cpu_count(), metavar="N",
                   help="files baked at once (default: the number of cores, %(default)s here)")
    t.add_argument("--format", choices=BATCH_FORMATS, default="glb", type=str.lower,
                   help="output format (default %(default)s)")
    t.add_argument("--force", action="store_true", help="bake even the files whose last bake is current")
    t.add_argument("--timeout", type=float, default=None, metavar="SECONDS",
                   help="stop a file's worker after this long and count the file as failed")
    for q in (b, m, t):
        q.add_argument("-q", "--quiet", action="store_true",
                       help="print nothing on stdout (no stage lines, notes or Blender output); errors only")
        add_setting_options(q)
    return p


def _cpu_count():
    try:
        return len(os.sched_getaffinity(0)) or 1
    except AttributeError:  # macOS, Windows
        return os.cpu_count() or 1


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
        raise CLIError(f"cannot read {path}: {operator_error_reason(ex, path, 'importer')} (is it a complete, "
                       f"undamaged {ext} file?)") from None


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
        if o.type not in GEOMETRY_TYPES:
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
    source = os.path.realpath(args.input)
    for p in (*outputs, args.report):
        if p and os.path.realpath(p) == source:
            raise CLIError(f"the output {p} would overwrite the input: write to another file", 2)
    load_input(args.input)
    t_loaded = time.perf_counter()
    objects = _select_objects(args.objects, os.path.abspath(args.input))
    job = BakeJob.prepare(bpy.context, objects, settings, cache=_cache(settings))
    job.timings["load"] = t_loaded - t_start
    _bake_and_write(job, args, outputs, out, t_start, input=os.path.abspath(args.input))
    return job


def cmd_demo(args, out):
    from .. import demo

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


# ----------------------------------------------------------------------------- batch
BATCH_FORMATS = ("glb", "gltf", "blend")


def setting_argv(args):
    """The bake-setting options of ``args`` as command-line words: only those that differ from
    the schema's defaults, so a worker parses exactly the settings the batch was given."""
    words = []
    for s in schema():
        v = getattr(args, s.name)
        if v == s.default:
            continue
        flag = _flag(s)
        words += [flag] if s.type is bool else [flag, str(v)]
    return words


def batch_worker_argv(args):
    """The settings a batch's workers are given: :func:`setting_argv`, and where several files
    bake at once and the threads per bake were left to 'every core', the cores shared between
    them (2 files on 2 cores: one thread each, not four threads fighting for two cores)."""
    words = setting_argv(args)
    if args.workers == 0 and args.jobs > 1:
        words += ["--workers", str(max(1, _cpu_count() // args.jobs))]
    return words


def worker_command(bake_argv, blender=None):
    """(argv, env) of a fresh process that runs ``bake`` with ``bake_argv``.

    With the bpy module (``python -m hemicube_radiosity``): this Python, ``-m
    hemicube_radiosity``, the folder holding this package first on PYTHONPATH (so the worker runs
    this very code from any directory). Inside Blender (``bpy.app.binary_path`` is set;
    ``sys.executable`` is then Blender's bundled Python, which cannot import bpy): Blender
    itself, ``-b ... -c hemicube_radiosity bake``, with this add-on enabled by ``--addons``.
    Extensions in the default user repository are found under ``--factory-startup`` (no user
    add-ons or preferences in the worker); one in another repository needs the user preferences
    that define that repository, so those are kept. ``blender``: the executable to use instead of
    ``bpy.app.binary_path`` (tests)."""
    env = dict(os.environ)
    blender = bpy.app.binary_path if blender is None else blender
    if blender:
        addon = __package__.rsplit(".", 3)[0]          # bl_ext.<repo>.hemicube_radiosity
        repo = addon.split(".")[1] if addon.startswith("bl_ext.") else None
        factory = ["--factory-startup"] if repo == "user_default" else []
        return [blender, "--background", *factory, "--addons", addon, "-c", PROG, "bake", *bake_argv], env
    root = os.path.abspath(os.path.join(os.path.dirname(__file__), os.pardir, os.pardir, os.pardir))
    env["PYTHONPATH"] = os.pathsep.join([root, *filter(None, [env.get("PYTHONPATH")])])
    return [sys.executable, "-m", PROG, "bake", *bake_argv], env


def batch_key(path, settings, fmt):
    """What decides whether a file's last bake is current: its content, the settings, the output
    format and the add-on's version. (sha256 hex of both, the input's own sha256)"""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    content = h.hexdigest()
    recipe = json.dumps({"input": content, "settings": dataclasses.asdict(settings), "format": fmt,
                         "version": __version__}, sort_keys=True)
    return hashlib.sha256(recipe.encode()).hexdigest(), content


@dataclasses.dataclass
class BatchItem:
    input: str
    output: str
    report: str
    log: str
    status: str = "pending"          # ok, skipped, failed
    seconds: float = 0.0
    message: str = ""
    patches: int | None = None

    @property
    def name(self):
        return os.path.basename(self.input)


def _last_report(item):
    try:
        with open(item.report, encoding="utf-8") as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def _error_line(text):
    lines = [ln for ln in text.splitlines() if ln.strip()]
    errors = [ln for ln in lines if ": error: " in ln]
    if errors:
        return errors[-1].split(": error: ", 1)[1]
    return lines[-1].strip() if lines else ""


class _Workers:
    """The running worker processes, so that an interrupted batch stops them all."""

    def __init__(self):
        self.lock = threading.Lock()
        self.procs = set()
        self.stopping = False

    def run(self, argv, env, timeout):
        with self.lock:
            if self.stopping:
                return None, "", "stopped"
            p = subprocess.Popen(argv, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True, errors="replace")
            self.procs.add(p)
        try:
            out, err = p.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            p.kill()
            out, err = p.communicate()
            err += f"\n{PROG}: error: stopped after {timeout:g} s (--timeout)\n"
        finally:
            with self.lock:
                self.procs.discard(p)
        return p.returncode, out, err

    def stop(self):
        with self.lock:
            self.stopping = True
            for p in self.procs:
                p.kill()


def _bake_one(item, key, content, settings_words, workers, timeout):
    t = time.perf_counter()
    argv, env = worker_command([item.input, "-o", item.output, "--report", item.report, *settings_words])
    rc, out, err = workers.run(argv, env, timeout)
    item.seconds = time.perf_counter() - t
    rep = _last_report(item) if rc == 0 else None
    if rc == 0 and rep is not None and os.path.exists(item.output):
        rep["batch"] = {"key": key, "input_sha256": content, "input": item.input, "seconds": item.seconds}
        tmp = f"{item.report}.partial-{os.getpid()}-{threading.get_ident()}"
        with open(tmp, "w", encoding="utf-8") as f:
            json.dump(rep, f, indent=2)
        os.replace(tmp, item.report)
        item.status, item.patches = "ok", rep.get("patches")
        if os.path.exists(item.log):
            os.remove(item.log)
        return item
    item.status = "failed"
    if rc is None:
        item.message = "not started (batch interrupted)"
        return item
    why = _error_line(err) or _error_line(out)
    if rc < 0:
        why = f"worker killed by signal {-rc}" + (f" ({why})" if why else "")
    elif rc == 0:
        why = f"the worker wrote no {os.path.basename(item.output)} or report"
    item.message = why or f"worker exit status {rc}"
    with open(item.log, "w", encoding="utf-8") as f:
        f.write(f"$ {subprocess.list2cmdline(argv)}\n# exit status {rc}\n{out}\n{err}")
    return item


def _plan(args):
    """One BatchItem per input, checked for clashing output names before any work."""
    out_dir = os.path.abspath(args.out_dir)
    items, seen = [], {}
    for f in args.files:
        stem = os.path.splitext(os.path.basename(f))[0]
        if stem.lower() in seen:
            raise CLIError(f"{f} and {seen[stem.lower()]} would both write {stem}.{args.format} in "
                           f"{args.out_dir}: rename one or bake them in two batches", 2)
        seen[stem.lower()] = f
        base = os.path.join(out_dir, stem)
        items.append(BatchItem(os.path.abspath(f), f"{base}.{args.format}", f"{base}.json", f"{base}.log"))
    return out_dir, items


def _batch_todo(items, settings, args):
    """The items to bake, as (item, key, input sha256). The others get their status here: failed
    (unsupported input, output over the input, unreadable input) or skipped (the last bake is
    current: same key and its output still there; never with --force)."""
    todo = []
    for it in items:
        ext = os.path.splitext(it.input)[1].lower()
        if ext not in INPUT_EXT:
            it.status, it.message = "failed", f"unsupported input: expected one of {', '.join(INPUT_EXT)}"
            continue
        if it.input == it.output:
            it.status, it.message = "failed", "the output would overwrite the input: use another --out-dir"
            continue
        try:
            key, content = batch_key(it.input, settings, args.format)
        except OSError as ex:
            it.status, it.message = "failed", ("input file not found" if isinstance(ex, FileNotFoundError)
                                               else f"cannot read it: {ex.strerror or ex}")
            continue
        last = None if args.force else _last_report(it)
        if last and last.get("batch", {}).get("key") == key and os.path.exists(it.output):
            it.status, it.message, it.patches = "skipped", "unchanged since its last bake", last.get("patches")
            continue
        todo.append((it, key, content))
    return todo


class _ProgressLines:
    """Prints ``[n/total] status name seconds ...`` for each finished item (not with -q), from
    any thread; n counts the items finished so far."""

    def __init__(self, total, out, quiet):
        self.lock = threading.Lock()
        self.done = 0
        self.total = total
        self.out = out
        self.quiet = quiet

    def __call__(self, it):
        with self.lock:
            self.done += 1
            if not self.quiet:
                what = f"  {it.message}" if it.status != "ok" else f"  -> {os.path.basename(it.output)}"
                print(f"[{self.done}/{self.total}] {it.status:<7} {it.name}  {it.seconds:.1f} s{what}",
                      file=self.out, flush=True)


def _run_workers(todo, words, args, out_dir, line, out):
    """Bake every (item, key, content) of ``todo`` in its own worker, ``args.jobs`` at a time,
    calling ``line(item)`` as each one ends. An interruption (Ctrl-C, or Blender stopping us)
    ends every running worker before it goes on."""
    workers = _Workers()
    jobs = min(args.jobs, len(todo))
    if not args.quiet:
        print(f"radiosity: baking {len(todo)} of {line.total} files, {jobs} at a time, into {out_dir}",
              file=out, flush=True)
    pool = concurrent.futures.ThreadPoolExecutor(max_workers=jobs)
    try:
        futures = [pool.submit(_bake_one, it, key, content, words, workers, args.timeout)
                   for it, key, content in todo]
        for fut in concurrent.futures.as_completed(futures):
            line(fut.result())
    except BaseException:
        workers.stop()
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _batch_status(items, args, out, err, t_start):
    """The closing table (not with -q) and one error line on ``err`` per failed file (with its
    log, if one was kept); the exit status: 1 if any file failed, else 0."""
    failed = [it for it in items if it.status == "failed"]
    if not args.quiet:
        _batch_table(items, out, time.perf_counter() - t_start)
    for it in failed:
        log = f" (log: {it.log})" if os.path.exists(it.log) else ""
        print(f"{PROG}: error: {it.input}: {it.message}{log}", file=err, flush=True)
    return 1 if failed else 0


def cmd_batch(args, out, err):
    """``batch``: bake every FILE in a worker process (module docstring); the exit status."""
    t_start = time.perf_counter()
    settings = _settings(args)
    out_dir, items = _plan(args)
    os.makedirs(out_dir, exist_ok=True)
    words = batch_worker_argv(args)
    todo = _batch_todo(items, settings, args)
    line = _ProgressLines(len(items), out, args.quiet)
    for it in items:
        if it.status != "pending":
            line(it)
    if todo:
        _run_workers(todo, words, args, out_dir, line, out)
    return _batch_status(items, args, out, err, t_start)


def _batch_table(items, out, seconds):
    w = max(len("file"), *(len(it.name) for it in items))
    print(f"\n{'file':<{w}}  {'status':<7}  {'time s':>7}  {'patches':>7}  output / reason", file=out)
    for it in items:
        what = it.output if it.status != "failed" else it.message
        patches = "" if it.patches is None else str(it.patches)
        print(f"{it.name:<{w}}  {it.status:<7}  {it.seconds:>7.1f}  {patches:>7}  {what}", file=out)
    counts = {k: sum(it.status == k for it in items) for k in ("ok", "skipped", "failed")}
    print(f"radiosity: {counts['ok']} baked, {counts['skipped']} skipped, {counts['failed']} failed "
          f"in {seconds:.1f} s", file=out, flush=True)


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
