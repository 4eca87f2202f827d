"""Automatic sizes: the patch size of a scene from the extent of what was modelled in it, and a
coarser one for an object that reaches far beyond the rest (a ground plane around a room, a
terrain around a town).

The 'auto' patch size is a fraction of the scene's bounding-box diagonal. One huge plane under a
10 m room (221 m across, two triangles) made that diagonal 22 times the room's: patches of 22 m,
the room one patch. Here an object is *huge* when its own diagonal is more than
:data:`HUGE_EXTENT` times that of everything else together while it holds less than
:data:`HUGE_FACES` of the scene's faces (a room modelled as one mesh holds most of them: it is
the scene, not beside it; an object of fewer than :data:`HUGE_FEW` faces always may be huge).
Huge objects are left out of the extent, one at a time, largest
first, and are cut at a size of their own: the same fraction of their own diagonal, never finer
than the scene's (:attr:`.patches.MeshInput.size_scale`), whether the scene's size is automatic
or set by hand (a 32 m patch size set for a town left its 2.9 km terrain 900,000 detail elements).

Units: world units.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..runtime.cache import PER_MESH, Memo

__all__ = ["auto_sizes", "mesh_boxes", "with_auto_scales", "fitted_detail", "DETAIL_SHARE", "HUGE_EXTENT", "HUGE_FACES", "HUGE_FEW"]

#: An object this many times larger across than the rest of the scene together may be huge...
HUGE_EXTENT = 3.0
#: ... if it holds less than this fraction of the scene's faces, or fewer than HUGE_FEW faces.
HUGE_FACES = 0.1
HUGE_FEW = 100


#: The 'auto' detail size makes at most this share of ``max_elements`` (counted before cutting).
DETAIL_SHARE = 0.5


def fitted_detail(meshes, detail, patch, max_elements):
    """The 'auto' detail size ``detail`` raised in steps of 1.25 until the elements it makes at
    least (:func:`.limits.pieces_at_least`) are within :data:`DETAIL_SHARE` of ``max_elements``;
    None (no finer output than the patches) when that reaches ``patch``. A scene of many long
    thin faces (curtains, cables) cut at a third of the patch size made 641,000 elements at
    least, past the limit: the default must bake."""
    from .limits import pieces_at_least

    if not detail:
        return detail
    while pieces_at_least(meshes, detail) > DETAIL_SHARE * max_elements:
        detail *= 1.25
        if patch and detail >= patch:
            return None
    return detail


#: Each mesh's bounding box, by the identity of its ``verts`` (never changed in place: a relight's
#: meshes read from the same Blender data are the same arrays; their boxes were 20 ms of the
#: bunny's relight, asked twice a bake)
_BOXES = Memo(PER_MESH)


def _box(verts):
    if not len(verts):
        return (np.full(3, np.nan),) * 2
    return _BOXES.of((verts,), lambda: (np.min(verts, axis=0), np.max(verts, axis=0)))


def mesh_boxes(meshes):
    """(M, 3) lower and upper corners of each mesh's bounding box (NaN for a mesh of no vertices)."""
    box = [_box(m.verts) for m in meshes]
    return (np.array([b[0] for b in box], dtype=np.float64).reshape(-1, 3),
            np.array([b[1] for b in box], dtype=np.float64).reshape(-1, 3))


def auto_sizes(meshes, per_diagonal, size=None):
    """(size, scales): the patch size, the diagonal of the scene without its huge objects divided
    by ``per_diagonal`` (None for a scene of no extent; ``size`` when given, a size set by hand),
    and (M,) float each mesh's factor on it (1, or for a huge object its own diagonal /
    ``per_diagonal`` / size where that is larger)."""
    meshes = [m for m in meshes]
    some = np.array([len(m.verts) > 0 for m in meshes], bool)
    if not some.any():                          # nothing to measure: build_patches says why
        return None, np.ones(len(meshes))
    lo, hi = mesh_boxes(meshes)
    lo[~some], hi[~some] = lo[some].min(axis=0), hi[some].max(axis=0)   # no extent of their own
    diag = np.linalg.norm(hi - lo, axis=1)
    faces = np.array([len(m.face_offsets) - 1 for m in meshes], dtype=np.float64)
    core = np.ones(len(meshes), bool)
    for i in np.argsort(-diag, kind="stable")[:len(meshes) - 1]:
        rest = core.copy()
        rest[i] = False
        extent = float(np.linalg.norm(hi[rest].max(axis=0) - lo[rest].min(axis=0)))
        if diag[i] > HUGE_EXTENT * extent and faces[i] < max(HUGE_FACES * faces.sum(), HUGE_FEW):
            core[i] = False
        else:
            break
    if size is None:
        size = float(np.linalg.norm(hi[core].max(axis=0) - lo[core].min(axis=0))) / per_diagonal or None
    scales = np.ones(len(meshes))
    if size:
        scales[~core] = np.maximum(1.0, diag[~core] / per_diagonal / size)
    return size, scales


def with_auto_scales(meshes, per_diagonal, size=None) -> list:
    """``meshes`` with each huge object's ``size_scale`` set (:func:`auto_sizes`; ``size``: a
    patch size set by hand, else the automatic one): copies sharing the arrays; the others as
    they are."""
    _, scales = auto_sizes(meshes, per_diagonal, size)
    return [m if s == 1.0 else replace(m, size_scale=float(s)) for m, s in zip(meshes, scales)]
