# SPDX-License-Identifier: GPL-3.0-or-later
"""The shading normal Cycles gives each face corner (:mod:`...core.mesh.cycles_normals`): Blender's
corner normals as Cycles of this Blender stores them, read with the mesh's vertex normals and loop
triangles."""
from __future__ import annotations

import hashlib

import numpy as np

from ...core.mesh.cycles_normals import shading_normals
from ...core.runtime.cache import PER_MESH, Memo, frozen

__all__ = ["cycles_corner_normals", "CYCLES_SPLITS_VERTICES"]

#: From this Blender on Cycles reads Blender's corner normals as they are (up to 5.0 it stores
#: one normal per vertex: :mod:`...core.mesh.cycles_normals`).
CYCLES_SPLITS_VERTICES = (5, 1, 0)


def cycles_corner_normals(me, normals, loop_vert, loop_edge, poly_start, poly_total, face_smooth,
                          edge_sharp, version=None) -> np.ndarray:
    """Blender's corner ``normals`` (L, 3) of the evaluated mesh ``me`` as Cycles of this Blender
    (``version``: ``bpy.app.version`` unless given) shades them: :func:`shading_normals` with
    ``me``'s vertex normals and loop triangles before :data:`CYCLES_SPLITS_VERTICES`, as they are
    from it on."""
    if version is None:
        import bpy

        version = bpy.app.version
    if tuple(version) >= CYCLES_SPLITS_VERTICES or normals is None:
        return normals
    tl = np.empty(len(me.loop_triangles) * 3, np.int64)
    if len(tl):
        me.loop_triangles.foreach_get("loops", tl)
    vn = np.empty(len(me.vertices) * 3, np.float32)
    if len(vn):
        me.vertices.foreach_get("normal", vn)
    custom = bool(getattr(me, "has_custom_normals", False))
    arrays = (normals, vn, loop_vert, loop_edge, poly_start, poly_total, face_smooth, edge_sharp, tl)
    h = hashlib.sha256(b"custom" if custom else b"")
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(str((a.dtype, a.shape)).encode() + a.tobytes())

    def make():
        return frozen(shading_normals(normals, vn.reshape(-1, 3), loop_vert, loop_edge, poly_start, poly_total,
                                      face_smooth, edge_sharp, tl.reshape(-1, 3), custom=custom))
    return _SHADED.get(h.digest(), make)


# a mesh's arrays (by value) -> its corner normals as Cycles shades them, read only: a relight
# reads the same meshes again (0.08 s of godot_zdm2's, 0.6 s of the staircase's 775 meshes)
_SHADED = Memo(PER_MESH)
