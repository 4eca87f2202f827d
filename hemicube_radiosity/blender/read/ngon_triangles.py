# SPDX-License-Identifier: GPL-3.0-or-later
"""Blender's own triangles of the n-gons that are not planar, for ``MeshInput.face_triangles``.

Cycles renders a face as its loop triangles. A planar n-gon is the same surface however it is
cut, and the core cuts it its own way; a folded one is not (:mod:`core.mesh.ngons`), so for the
n-gons that :func:`core.mesh.ngons.bent_faces` calls bent the reader passes Blender's triangles
on. Which are bent is decided in the object's own space: a transform keeps a planar face planar
(it only scales the deviation, by the transform's stretch).
"""
from __future__ import annotations

import hashlib

import numpy as np

from ...core.mesh.ngons import bent_faces
from ...core.runtime.cache import Memo, PER_MESH, frozen

__all__ = ["bent_ngon_triangles", "reversed_rings"]

_ROWS = Memo(PER_MESH)       # the rows' values -> the same read-only array (a relight reads them again)


def _kept(rows):
    """``rows`` (T, 4) int64 as a read-only array, the same object for the same values as the
    last meshes read: what the core memoises by the mesh's arrays (their n-gons' split, the
    meshes' key) takes ``face_triangles`` with the rest, by identity, and only read-only."""
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    key = hashlib.sha256(str(rows.shape).encode() + rows.tobytes()).digest()
    return _ROWS.get(key, lambda: frozen(rows))


def bent_ngon_triangles(me, co, loop_vertex, poly_start, poly_total):
    """(T, 4) int64 rows (face, i, j, k) of the loop triangles of the bent n-gons of the
    evaluated mesh ``me``, ``i, j, k`` the triangle's corners as positions in its face's loops
    (counter-clockwise, as the face), or None when no n-gon is bent. ``co`` (V, 3) local
    positions, ``loop_vertex`` (L,), ``poly_start`` (F,), ``poly_total`` (F,) the mesh's arrays."""
    if not np.any(poly_total >= 4):
        return None
    offsets = np.concatenate([poly_start, [loop_vertex.size]]).astype(np.int64)
    bent = bent_faces(co, offsets, loop_vertex)
    if not bent.any():
        return None
    T = len(me.loop_triangles)
    loops = np.empty(T * 3, np.int64)
    face = np.empty(T, np.int64)
    me.loop_triangles.foreach_get("loops", loops)
    me.loop_triangles.foreach_get("polygon_index", face)
    take = bent[face]
    face, loops = face[take], loops.reshape(-1, 3)[take]
    return _kept(np.column_stack([face, loops - poly_start[face][:, None]]))


def reversed_rings(rows, counts):
    """``face_triangles`` rows (T, 4) for the same faces with every ring reversed (corner j of a
    face of n corners becomes n - 1 - j, a mirroring transform's read): the same triangles,
    their corners in reverse order so that they stay counter-clockwise as the face."""
    if rows is None:
        return None
    n = np.asarray(counts, dtype=np.int64)[rows[:, 0]][:, None]
    return _kept(np.column_stack([rows[:, 0], (n - 1 - rows[:, 1:])[:, ::-1]]))
