# SPDX-License-Identifier: GPL-3.0-or-later
"""The shading normal Cycles gives each face corner, where it is not Blender's corner normal.

Blender's corner normals (``Mesh.corner_normals``) break a smooth fan at a sharp edge, at the
edge of a flat face, and also where the fan cannot go on: an edge that three or more faces share
(a fin on a box, the partition between two solids of a game level), or one whose two faces wind
against each other. Cycles up to Blender 5.0 does not read them per corner
(``intern/cycles/blender/mesh.cpp`` ``create_mesh``, ``util.h`` ``object_to_mesh``):

* a mesh with no sharp edge and no custom normals (Blender's normals domain, sharp faces
  allowed, is per point) is shaded with Blender's vertex normals, the angle-weighted mean of
  every face at the vertex, a flat face with its own normal;
* any other mesh is split at its sharp edges and at the edges of its flat faces only, and one
  normal is stored per vertex of that split mesh, each corner of each loop triangle in turn
  writing its own corner normal over the vertex's: the last corner written wins.

Where a vertex's corners lie in fans that nothing splits, every one of them is shaded with that
one normal, which may face away from its own triangle; Cycles then turns that triangle around
(:mod:`..output.crease`) and bakes its back: a game level's knife-edge fins and the faces
that meet a partition along an unsplit edge bake black in Cycles where Blender's own normal
would light them.

:func:`shading_normals` gives every corner the normal Cycles shades it with, from Blender's
corner and vertex normals and the mesh's topology, which ``blender/read/split_normals.py`` reads
(``godot_zdm2``: 17,603 of its 176,211 corners; 99.9% of its corners within 8 degrees of the
normal Cycles' NORMAL bake reads, against 90% for Blender's own); elsewhere (manifold fans) the
two agree and nothing changes.
"""
from __future__ import annotations

import numpy as np

from ..util.unique import linked_labels

__all__ = ["shading_normals", "split_vertex_normals"]


def shading_normals(normals, vert_normals, loop_vert, loop_edge, poly_start, poly_total, face_smooth,
                    edge_sharp, tri_loops, custom=False) -> np.ndarray:
    """(L, 3) the normal Cycles shades each corner with (module docstring), from Blender's corner
    ``normals`` (L, 3), its ``vert_normals`` (V, 3) and the mesh's arrays (as
    :func:`split_vertex_normals`); ``custom``: the mesh has custom normals. With no sharp edge
    and no custom normals the smooth faces' corners take their vertex's normal, otherwise
    :func:`split_vertex_normals`."""
    normals = np.asarray(normals, dtype=np.float64)
    if custom or np.any(edge_sharp):
        return split_vertex_normals(normals, loop_vert, loop_edge, poly_start, poly_total, face_smooth,
                                    edge_sharp, tri_loops)
    face = np.repeat(np.arange(len(poly_start)), np.asarray(poly_total, dtype=np.int64))
    smooth = np.asarray(face_smooth, bool)[face]
    return np.where(smooth[:, None], np.asarray(vert_normals, dtype=np.float64)[loop_vert], normals)


def split_vertex_normals(normals, loop_vert, loop_edge, poly_start, poly_total, face_smooth,
                         edge_sharp, tri_loops) -> np.ndarray:
    """(L, 3) the normal Cycles shades each corner with (module docstring), from Blender's corner
    ``normals`` (L, 3) and the mesh's arrays: ``loop_vert`` (L,), ``loop_edge`` (L,) the edge
    from each corner to the next, ``poly_start`` (F,), ``poly_total`` (F,), ``face_smooth`` (F,)
    bool, ``edge_sharp`` (E,) bool, and ``tri_loops`` (T, 3) the corners of the loop triangles
    in Blender's order (the order Cycles writes them in).

    The vertices are split into groups of corners joined through edges that are neither sharp
    nor on a flat face (a vertex with no such split edge stays one group, as
    ``geometry::split_edges`` leaves it whole); each group takes the normal of its corner
    written last."""
    normals = np.asarray(normals, dtype=np.float64)
    L = len(loop_vert)
    if L == 0:
        return normals
    loop_vert = np.asarray(loop_vert, dtype=np.int64)
    loop_edge = np.asarray(loop_edge, dtype=np.int64)
    poly_start = np.asarray(poly_start, dtype=np.int64)
    poly_total = np.asarray(poly_total, dtype=np.int64)
    face = np.repeat(np.arange(len(poly_start)), poly_total)
    split = np.array(edge_sharp, dtype=bool, copy=True)
    split[loop_edge[~np.asarray(face_smooth, bool)[face]]] = True
    prev = poly_start[face] + (np.arange(L) - poly_start[face] - 1) % poly_total[face]
    ends = np.concatenate([loop_edge[prev], loop_edge])          # the two edges at each corner
    corner = np.concatenate([np.arange(L), np.arange(L)])
    V = int(loop_vert.max()) + 1
    touched = np.zeros(V, bool)
    touched[loop_vert[corner[split[ends]]]] = True
    # a key per (edge, vertex) of an edge that joins, and one per vertex no split edge touches
    whole = ~touched[loop_vert]
    keys = np.concatenate([(ends * V + loop_vert[corner])[~split[ends]], -1 - loop_vert[whole]])
    members = np.concatenate([corner[~split[ends]], np.flatnonzero(whole)])
    order = np.argsort(keys, kind="stable")
    keys, members = keys[order], members[order]
    head = np.flatnonzero(np.r_[True, keys[1:] != keys[:-1]])
    first = members[np.repeat(head, np.diff(np.r_[head, len(keys)]))]
    group = linked_labels(L, first, members)
    # Cycles writes corner after corner of the loop triangles: the last write of a group wins
    tri = np.asarray(tri_loops, dtype=np.int64).reshape(-1)
    when = np.full(L, -1, dtype=np.int64)
    np.maximum.at(when, tri, np.arange(tri.size))   # a corner's last place in the triangles
    last = np.full(L, -1, dtype=np.int64)
    np.maximum.at(last, group, when)
    written = np.full(tri.size + 1, -1, dtype=np.int64)
    written[when[when >= 0]] = np.flatnonzero(when >= 0)
    winner = written[last[group]]
    return np.where((winner >= 0)[:, None], normals[np.maximum(winner, 0)], normals)
