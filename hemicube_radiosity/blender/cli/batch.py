# SPDX-License-Identifier: GPL-3.0-or-later
"""``batch FILE ... --out-dir DIR [-j N] [--format glb] [--force] [bake settings]``.

Bakes every FILE in its own worker process (``bake FILE -o DIR/NAME.glb --report DIR/NAME.json``,
see :func:`worker_command`), N at a time; one line per file, a table at the end, exit status 1 if
any failed. A file whose content and settings are unchanged since its last successful bake is
skipped (the key, :func:`batch_key`, is kept in its report) unless --force. Where several files
bake at once and the threads per bake were left to every core, the cores are shared between
them (:func:`batch_worker_argv`). See ``docs/pipeline.md``.
"""
from __future__ import annotations

import concurrent.futures
import dataclasses
import hashlib
import json
import os
import subprocess
import sys
import threading
import time

import bpy

from ...version import __version__
from ...core.runtime.parallel import cpu_count
from ...core.settings import schema
from .parser import INPUT_EXT, PROG, CLIError, bake_settings, setting_flag

__all__ = ["setting_argv", "batch_worker_argv", "worker_command", "batch_key", "BatchItem",
           "cmd_batch"]


def setting_argv(args):
    """The bake-setting options of ``args`` as command-line words: only those that differ from
    the schema's defaults, so a worker parses exactly the settings the batch was given."""
    words = []
    for s in schema():
        v = getattr(args, s.name)
        if v == s.default:
            continue
        flag = setting_flag(s)
        words += [flag] if s.type is bool else [flag, str(v)]
    return words


def batch_worker_argv(args):
    """The settings a batch's workers are given: :func:`setting_argv`, and where several files
    bake at once and the threads per bake were left to 'every core', the cores shared between
    them (2 files on 2 cores: one thread each, not four threads fighting for two cores)."""
    words = setting_argv(args)
    if args.workers == 0 and args.jobs > 1:
        words += ["--workers", str(max(1, cpu_count() // args.jobs))]
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
        addon = __package__.rsplit(".", 3)[0]   # bl_ext.<repo>.hemicube_radiosity (of its .*.blender.cli)
        repo = addon.split(".")[1] if addon.startswith("bl_ext.") else None
        factory = ["--factory-startup"] if repo == "user_default" else []
        return [blender, "--background", *factory, "--addons", addon, "-c", PROG, "bake", *bake_argv], env
    # the folder that holds the hemicube_radiosity package: three up from this file's blender/cli
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
    settings = bake_settings(args)
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
