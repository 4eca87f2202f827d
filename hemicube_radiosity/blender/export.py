# SPDX-License-Identifier: GPL-3.0-or-later
"""Every file a bake can write, chosen by the file's extension: one table for the CLI, the demo
and scripts.

=========  ==========================================================================
``.glb``   binary glTF of the baked objects: COLOR_0 + unlit materials (:mod:`.gltf`)
``.gltf``  the same as text glTF with its ``.bin`` beside it
``.blend`` the whole baked scene (a copy: the open file keeps its own path)
``.npz``   per-patch arrays: centres, normals, areas, radiosity, emission, reflectance, object
``.json``  the bake report (:meth:`.bake.BakeJob.report`)
=========  ==========================================================================

A single-file output is written under a temporary name beside the target and renamed when
complete (a ``.gltf`` and its ``.bin``: in a temporary folder beside it, moved out when both are
complete), so a failed write (a full disk) never leaves a half-written file under the final name;
the failure is one :class:`RadiosityError` line naming the file.
To add a format: one writer function and one row in :data:`EXPORTERS` (and its test).
"""
from __future__ import annotations

import gc
import io
import json
import os
import re
import shutil
import sys

import bpy
import numpy as np

from ..core.runtime.errors import RadiosityError
from .gltf import export_gltf

__all__ = ["EXPORTERS", "export", "check_output", "operator_error_reason"]


def _glb(path, job, report):
    export_gltf(path, job.written, view_transform=job.settings.view_transform)


def _blend(path, job, report):
    bpy.ops.wm.save_as_mainfile(filepath=path, copy=True)


def _patches(path, job, report):
    r = job.result
    P = r.patches
    names = np.array([P.object_names[i] for i in P.owner], dtype=str)
    with open(path, "wb") as f:
        np.savez_compressed(f, centers=P.centers, normals=P.normals, areas=P.areas,
                            radiosity=r.solution.B, emission=P.emission, reflectance=P.rho, object=names)


def _report(path, job, report):
    with open(path, "w", encoding="utf-8") as f:
        json.dump(report if report is not None else job.report(), f, indent=2)


# extension -> (writer(path, job, report), what it holds, written in one file)
EXPORTERS = {
    ".glb": (_glb, "binary glTF with COLOR_0", True),
    ".gltf": (_glb, "glTF with COLOR_0 (and its .bin)", False),
    ".blend": (_blend, "the baked scene", True),
    ".npz": (_patches, "per-patch arrays", True),
    ".json": (_report, "the bake report", True),
}


def check_output(path):
    """Raise a one-line :class:`RadiosityError` if ``path`` is not a format we write."""
    ext = os.path.splitext(path)[1].lower()
    if ext not in EXPORTERS:
        raise RadiosityError(f"unsupported output {path!r}: expected one of {', '.join(EXPORTERS)}")
    return ext


def operator_error_reason(ex, path=None, what="operator"):
    """One line saying why a Blender operator (an importer, an exporter, save) failed: its
    ``RuntimeError`` text without the ``Error:`` prefix, or, when a Python importer/exporter
    crashed, the last line of the traceback it carries (``OSError: [Errno 28] No space left on
    device`` -> ``No space left on device``). ``path`` is left out of the reason (the caller's
    line names it once)."""
    lines = [ln.strip() for ln in str(ex).strip().splitlines() if ln.strip()]
    lines = [ln for ln in lines if not ln.startswith("Location:")]
    if not lines:
        return "failed"
    crashed = "Traceback (most recent call last)" in lines[0]
    line = lines[-1] if crashed else lines[0]
    for prefix in ("Error:", "Python:"):
        if line.startswith(prefix):
            line = line[len(prefix):].strip()
    if "Error: " in line and line.split("Error: ", 1)[0].replace(".", "").isidentifier():
        kind, line = line.split("Error: ", 1)          # OSError: ..., TypeError: ...
        if kind not in ("OS", "IO", "FileNotFound", "Permission", "IsADirectory"):
            line = f"Blender's {what} stopped ({kind}Error: {line})"
    elif crashed:
        line = f"Blender's {what} stopped ({line})"
    line = re.sub(r"^\[Errno \d+\]\s*", "", line)
    if path is not None:
        for quoted in (f'"{path}"', f"'{path}'", path):
            line = line.replace(f" in file {quoted}", "").replace(f" {quoted}", "")
        # Blender's "Loading X failed: Failed to read blend file X: <why>": keep <why>
        line = line.rsplit("failed: ", 1)[-1].rsplit(": ", 1)[-1] if "failed: " in line else line
    return line.strip() or "failed"


def _fail(path, ex):
    reason = (ex.strerror if isinstance(ex, OSError) and ex.strerror
              else operator_error_reason(ex, what="exporter"))
    return RadiosityError(f"could not write {path}: {reason}")


def export(path, job, report=None) -> str:
    """Write ``job``'s result to ``path`` in the format its extension names; returns the absolute
    path. ``report``: the dict a ``.json`` output holds (default ``job.report()``).

    Nothing is left under the final name unless the write completed: a single file is written as
    ``NAME.partial-PID.EXT`` and renamed; a ``.gltf`` and its ``.bin`` are written into a
    temporary folder beside the target and moved out (the ``.bin`` first, the ``.gltf`` last)
    when both are complete. A full disk, a missing permission or a failing exporter is one
    :class:`RadiosityError` line naming the file."""
    writer, _, single_file = EXPORTERS[check_output(path)]
    path = os.path.abspath(path)
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
    except OSError as ex:
        raise _fail(path, ex) from None
    if not single_file:
        return _export_folder(writer, path, job, report)
    stem, ext = os.path.splitext(path)
    tmp = f"{stem}.partial-{os.getpid()}{ext}"
    try:
        writer(tmp, job, report)
        os.replace(tmp, path)
    except (OSError, RuntimeError) as ex:   # RuntimeError: Blender's exporter or save failed
        raise _fail(path, ex) from None
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
            _close_dropped_files(tmp)
    return path


def _close_dropped_files(tmp):
    """Close the files under the temporary path ``tmp`` that a failed writer left open.

    Blender's glTF exporter opens its output without ``with``. When a write fails (a full
    disk), Blender prints the operator's error, which keeps its traceback in
    ``sys.last_traceback``, and with it the exporter's frame and the open file: the removed
    partial file would hold its space on the full disk until the next error replaced it."""
    tb = getattr(sys, "last_traceback", None)
    while tb is not None:
        for value in list(tb.tb_frame.f_locals.values()):
            # type(), not isinstance(): that asks a removed Blender struct for its __class__
            if issubclass(type(value), io.IOBase) and str(getattr(value, "name", "")).startswith(tmp):
                value.close()
        tb = tb.tb_next
    gc.collect()


def _export_folder(writer, path, job, report):
    """A multi-file output (.gltf + .bin): written in a temporary folder, then moved in place."""
    folder, name = os.path.split(path)
    tmp_dir = os.path.join(folder, f".{name}.partial-{os.getpid()}")
    try:
        os.makedirs(tmp_dir, exist_ok=True)
        writer(os.path.join(tmp_dir, name), job, report)
        files = sorted(os.listdir(tmp_dir), key=lambda f: f == name)   # the .gltf last
        for f in files:
            os.replace(os.path.join(tmp_dir, f), os.path.join(folder, f))
    except (OSError, RuntimeError) as ex:
        shutil.rmtree(tmp_dir, ignore_errors=True)
        _close_dropped_files(tmp_dir)
        raise _fail(path, ex) from None
    finally:
        shutil.rmtree(tmp_dir, ignore_errors=True)
    return path
