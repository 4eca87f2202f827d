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
complete, so a failed write (a full disk) never leaves a half-written file under the final name.
To add a format: one writer function and one row in :data:`EXPORTERS` (and its test).
"""
from __future__ import annotations

import json
import os

import bpy
import numpy as np

from ..core.errors import RadiosityError
from .gltf import export_gltf

__all__ = ["EXPORTERS", "export", "check_output"]


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


def export(path, job, report=None) -> str:
    """Write ``job``'s result to ``path`` in the format its extension names; returns the absolute
    path. ``report``: the dict a ``.json`` output holds (default ``job.report()``)."""
    writer, _, single_file = EXPORTERS[check_output(path)]
    path = os.path.abspath(path)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    if not single_file:
        writer(path, job, report)
        return path
    stem, ext = os.path.splitext(path)
    tmp = f"{stem}.partial-{os.getpid()}{ext}"
    try:
        writer(tmp, job, report)
        os.replace(tmp, path)
    except OSError as ex:
        raise RadiosityError(f"could not write {path}: {ex.strerror or ex}") from None
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return path
