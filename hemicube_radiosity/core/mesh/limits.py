"""Limits before cutting: how many patches and output elements a size makes, counted from the
faces' edges and areas before anything is cut, and refusals that name a size that passes.

:func:`.subdivide.build_patches` cuts a triangle whose longest edge spans g sizes into g * g
triangles and a quad into nu x nv cells (nu, nv its opposite sides' longer spans): what
:func:`pieces_at_least` counts per face, a lower bound (neighbours only ever raise an edge's
count). A patch size of half a millimetre in a room is refused from these counts in a fraction
of a second, where cutting it first took minutes and gigabytes.

Grouping (:mod:`.clusters`) merges the small pieces into cells of the patch size, so the patches
of a size are estimated (:func:`patches_about`): a cut face's pieces one patch each where they
have a third of a patch's area (they stay alone), the rest of each object's area a patch per
``size ** 2``. A cluster spans at most a cell and the pieces reaching out of it, so it covers
at most about :data:`CLUSTER_SPAN` patches' area: an estimate that many times over the limit is
refused before cutting; nearer the limit the patches are cut and counted.

Units: world units for sizes, their squares for areas.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .patches import MeshInput, read_only
from ..runtime.cache import Memo, PER_MESH, frozen

_SPANS = Memo(PER_MESH, max_bytes=256 << 20)     # a mesh's arrays -> face_spans (the last bakes')

__all__ = ["face_spans", "pieces_at_least", "patches_about", "CLUSTER_SPAN", "passing_size"]

#: The most patch areas one cluster covers (a cell of the patch size and the pieces whose centres
#: are in it, reaching half a cell out on each side: a 2 x 2 cell square, tilted across a cube).
CLUSTER_SPAN = 6.0


def face_spans(mesh: MeshInput):
    """Per face of ``mesh``: (areas (F,), sides (F, 2) the longer of each pair of opposite sides
    of a quad, the longest edge twice for a triangle or an n-gon, corners (F,) int).
    Areas from the face's corners (Newell's formula: n-gons, non-planar quads). Made once per
    mesh's read-only arrays (a bake counts at several sizes; a relight reads the same arrays);
    read only."""
    arrays = (mesh.verts, mesh.face_offsets, mesh.face_indices)
    if not all(read_only(a) for a in arrays):          # may change in place: made every time
        return _face_spans(mesh)
    return _SPANS.of(arrays, lambda: _face_spans(mesh))


def _face_spans(mesh: MeshInput):
    v = np.asarray(mesh.verts, dtype=np.float64)
    off = np.asarray(mesh.face_offsets, dtype=np.int64)
    idx = np.asarray(mesh.face_indices, dtype=np.int64)
    k = np.diff(off)
    F = len(k)
    face = np.repeat(np.arange(F), k)
    nxt = np.arange(1, idx.size + 1)
    nxt[off[1:] - 1] = off[:-1]
    a, b = v[idx], v[idx[nxt]]
    c = np.cross(a, b)       # summed by bincount: np.add.at's sums in its order, bit for bit
    cross = np.stack([np.bincount(face, c[:, j], F) for j in range(3)], 1)
    areas = 0.5 * np.linalg.norm(cross, axis=1)
    length = np.linalg.norm(b - a, axis=1)
    longest = np.zeros(F)
    some = k > 0
    if some.any():
        longest[some] = np.maximum.reduceat(length, off[:-1][some])
    sides = np.stack([longest, longest], 1)
    quad = np.flatnonzero(k == 4)
    if quad.size:
        q = length[off[quad][:, None] + np.arange(4)]
        sides[quad] = np.stack([np.maximum(q[:, 0], q[:, 2]), np.maximum(q[:, 1], q[:, 3])], 1)
    return frozen(areas, sides, k)


def _spans(length, size):
    """Segments of an edge ``length`` long at ``size`` (as :func:`.subdivide._segment_counts`,
    without its float slack: at most one more)."""
    return np.maximum(1.0, np.ceil(length / size - 1e-6))


def _grids(mesh, size):
    """Per face of ``mesh`` at ``size`` times its ``size_scale``: (areas (F,), n (F,) the cells of
    its grid (an n-gon: the square of its longest side's count), corners (F,), that size, sides
    (F, 2) of :func:`face_spans`)."""
    areas, sides, k = face_spans(mesh)
    s = size * mesh.size_scale
    return areas, _spans(sides[:, 0], s) * _spans(sides[:, 1], s), k, s, sides


def pieces_at_least(meshes, size) -> float:
    """How many pieces :func:`.subdivide.build_patches` makes at ``size`` at least (None or 0:
    the faces, an n-gon at least one)."""
    if not size:
        return float(sum(len(m.face_offsets) - 1 for m in meshes))
    total = 0.0
    for m in meshes:
        areas, n, k, s, sides = _grids(m, size)
        big = k > 4                          # an n-gon: split first, into pieces of its area
        n[big] = np.maximum(areas[big] / s ** 2, _spans(sides[big, 0], s))
        total += float(n.sum())
    return total


def patches_about(meshes, size, group=True) -> float:
    """About how many patches ``size`` makes (the module docstring says how): the pieces of
    :func:`pieces_at_least` when faces are not grouped."""
    if not size or not group:
        return pieces_at_least(meshes, size)
    total = 0.0
    for m in meshes:
        areas, n, k, s, _ = _grids(m, size)
        n[k > 4] = np.maximum(1.0, areas[k > 4] / s ** 2)
        alone = (n > 1) & (areas / n >= s * s / 3)
        total += float(n[alone].sum()) + max(1.0, float(areas[~alone].sum()) / s ** 2)
    return total


def passing_size(meshes, settings, limit, count, tries=4):
    """(size, patches): a patch size found to make at most ``limit`` patches, as few sizes above
    the smallest as a few counts find, each counted by ``count(settings at that size)`` (a real
    cut: measured, not guessed); None when none of ``tries`` counts passed.

    The first size is where the estimate (:func:`patches_about`) is 90% of the limit; from each
    count the next size is the one that count predicts for 90% of the limit (patches go as the
    size's inverse square), at least 1.25 times larger after a count over the limit."""
    size = float(settings.patch_size or 0.0)
    if not size:
        return None
    for _ in range(80):
        if patches_about(meshes, size, settings.group_faces) <= 0.9 * limit:
            break
        size *= 1.25
    best = None
    for _ in range(tries):
        n = count(replace(settings, patch_size=size))
        if n <= limit:
            best = (size, int(n)) if best is None or size < best[0] else best
            smaller = size * float(np.sqrt(n / (0.9 * limit)))
            if smaller > 0.9 * size:
                break
            size = smaller
        else:
            size *= max(1.25, float(np.sqrt(n / (0.9 * limit))))
            if best is not None and size >= best[0]:
                break
    return best
