"""Subdivision: triangles and quads cut into regular grids of patches about ``patch_size`` on a
side (world units), and :func:`build_patches`, the whole step from source meshes to a
:class:`.patches.PatchSet`.

Every unique edge gets a number of segments, equalised over the faces (a quad's opposite sides
alike, a triangle's three sides alike) so that each face is a regular grid and the faces on both
sides of an edge cut it at the same points: patches share vertices, without T-junctions. A
triangle cut in n becomes n * n triangles, a quad an nu x nv grid. :func:`keeps_faces_whole`
tells, from the edge lengths alone, when a size cuts no face.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from ..util.unique import unique_rows
from .ngons import to_tris_and_quads
from .patches import ZERO_AREA, MeshInput, PatchError, PatchSet, check_faces, compact, poly_geometry
from ..light.transmit import see_through

__all__ = ["build_patches", "keeps_faces_whole"]


def _edge_segments(verts, polys, patch_size):
    """Number of segments per unique edge: its own (:func:`_segment_counts`), raised towards
    its faces' other sides' so that faces are cut as regular grids (a quad's opposite sides
    alike, a triangle's three sides alike), but never into segments shorter than half the
    patch size (:data:`MIN_SEGMENT`).

    Returns (edges (E,2) sorted pairs, face_edges (F,4) edge ids with -1, flipped (F,4) bool, n (E,)).
    Where a face's sides still differ, the face is cut as the regular grid of its largest
    counts (:func:`_face_grids`) with its points on each side snapped to that side's own cuts
    (:meth:`_EdgeCuts.vertex`): both faces of an edge use the same points, so the cut has no
    T-junction. (Equalising without the floor spread one long edge's count over a whole
    connected triangle mesh: a game level of 58,737 triangles became 1.9 million pieces, 61,441
    with it.)
    """
    F = len(polys)
    tri = polys[:, 3] < 0
    a, b, valid, ea, eb = _poly_sides(polys)
    key = np.stack([ea, eb], axis=1)
    edges, inv = unique_rows(key, return_inverse=True)
    inv = inv.reshape(-1)
    face_edges = np.full((F, 4), -1, dtype=np.int64)
    face_edges[valid] = inv
    flipped = np.zeros((F, 4), bool)
    flipped[valid] = (a > b)[valid]
    va, vb = verts[edges[:, 0]], verts[edges[:, 1]]
    n = _segment_counts(va, vb, patch_size)
    if patch_size is None or patch_size <= 0:
        return edges, face_edges, flipped, n
    cap = np.maximum(n, np.floor(np.linalg.norm(vb - va, axis=1) / (MIN_SEGMENT * patch_size)).astype(np.int64))
    q = np.flatnonzero(~tri)
    t = np.flatnonzero(tri)
    for _ in range(len(edges) + 1):
        before = n.copy()
        if q.size:
            for i, j in ((0, 2), (1, 3)):
                m = np.maximum(n[face_edges[q, i]], n[face_edges[q, j]])
                np.maximum.at(n, face_edges[q, i], m)
                np.maximum.at(n, face_edges[q, j], m)
        if t.size:
            m = n[face_edges[t, :3]].max(axis=1)
            for i in range(3):
                np.maximum.at(n, face_edges[t, i], m)
        np.minimum(n, cap, out=n)
        if np.array_equal(before, n):
            break
    # an edge only small faces use is not cut: those faces are grouped whole (cutting a
    # triangle a whisker over the patch size into slivers only zigzags its cluster's outline)
    cut = np.zeros(len(edges), bool)
    big = ~_grouped_whole(verts, polys, patch_size)
    cut[face_edges[big][face_edges[big] >= 0]] = True
    n[~cut] = 1
    return edges, face_edges, flipped, n


def _grouped_whole(verts, polys, patch_size) -> np.ndarray:
    """(F,) bool faces that grouping (:mod:`.clusters`) takes whole: less than a third of a
    patch's area and no side past two patch sizes (a long sliver is cut along its length)."""
    _, _, area = poly_geometry(verts, polys)
    _, b, valid, _, _ = _poly_sides(polys)
    side = np.where(valid, np.linalg.norm(verts[b] - verts[np.maximum(polys, 0)], axis=2), 0.0)
    return (area < patch_size * patch_size / 3) & (side.max(axis=1) <= 2 * patch_size)


#: Equalising a face's sides never cuts an edge into segments shorter than this many patch sizes.
MIN_SEGMENT = 0.5


def _face_grids(polys, face_edges, n):
    """(F, 2) int64 each face's grid: a quad nu x nv (the longer count of sides 0 and 2, of
    sides 1 and 3), a triangle g x g (its longest side's count) in both columns."""
    tri = polys[:, 3] < 0
    c = np.where(face_edges >= 0, n[np.maximum(face_edges, 0)], 0)
    g = c[:, :3].max(axis=1)
    return np.where(tri[:, None], g[:, None],
                    np.stack([np.maximum(c[:, 0], c[:, 2]), np.maximum(c[:, 1], c[:, 3])], 1))


def _poly_sides(polys):
    """The sides of polys (F, 4) (-1 in column 3 for a triangle): ``a``, ``b`` (F, 4) each side's
    first and last vertex (side i runs corner i -> i + 1), ``valid`` (F, 4) False for a
    triangle's fourth, and the valid sides' vertices ``lo``, ``hi`` (S,), the lower id first."""
    tri = polys[:, 3] < 0
    b = np.where(tri[:, None], polys[:, [1, 2, 0, 0]], polys[:, [1, 2, 3, 0]])
    valid = np.ones(polys.shape, bool)
    valid[tri, 3] = False
    return polys, b, valid, np.minimum(polys, b)[valid], np.maximum(polys, b)[valid]


def _segment_counts(va, vb, patch_size):
    """(E,) int64 segments of the edges ``va`` -> ``vb`` (E, 3) at ``patch_size`` (1 each with no
    size), before they are equalised over faces."""
    if patch_size is None or patch_size <= 0:
        return np.ones(len(va), dtype=np.int64)
    length = np.linalg.norm(vb - va, axis=1)
    # An edge a whisker longer than k patches gets k segments, not k + 1. The whisker is
    # relative: coordinates often come in float32 (Blender), whose rounding is ~6e-8 of the
    # coordinates' magnitude, so a 1 mm edge cut at 0.125 mm measures 8.0000004 patches.
    # Scaling the scene or moving it away from the origin must not change the count.
    mag = np.maximum(np.abs(va).max(axis=1), np.abs(vb).max(axis=1))
    slack = 1e-6 * np.maximum(length, mag)
    return np.maximum(1, np.ceil((length - slack) / patch_size)).astype(np.int64)


def keeps_faces_whole(meshes, patch_size) -> bool:
    """True when :func:`build_patches` at ``patch_size`` cuts no face (every edge one segment):
    then it makes the same PatchSet, array for array, as with no size (the same steps, with every
    count 1), and a mesh finer than the size is its own patches or output elements. It measures
    the faces' edges and builds nothing (far cheaper than building the faces twice to compare
    them). Raises :class:`PatchError` as :func:`build_patches` does for faces that are unusable."""
    if patch_size is None or patch_size <= 0:
        return True
    for mesh in [meshes] if isinstance(meshes, MeshInput) else meshes:
        size = patch_size * mesh.size_scale
        verts = np.asarray(mesh.verts, dtype=np.float64)
        off = np.asarray(mesh.face_offsets, dtype=np.int64)
        idx = np.asarray(mesh.face_indices, dtype=np.int64)
        sizes = np.diff(off)
        check_faces(mesh, verts, idx, sizes)
        # the faces' own edges, each from its lower vertex id to its higher, as _edge_segments
        # measures them: none longer than the size, and no n-gon to split, cuts nothing
        nxt = np.arange(1, idx.size + 1)
        nxt[off[1:] - 1] = off[:-1]
        a, b = idx, idx[nxt]
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        if not np.any(sizes > 4) and np.all(_segment_counts(verts[lo], verts[hi], size) == 1):
            continue
        # else cut unless only faces grouped whole use the longer edges (the n-gons split first)
        v, polys, _ = to_tris_and_quads(mesh)
        if np.any(_edge_segments(v, polys, size)[3] > 1):
            return False
    return True


class _EdgeCuts(NamedTuple):
    """Every unique edge cut into segments, and the vertices on the cuts.

    edges:      (E, 2) int64 sorted vertex pairs.
    face_edges: (F, 4) int64 edge id of each poly side (side i runs corner i -> i + 1), -1 for a
                triangle's fourth.
    flipped:    (F, 4) bool, the side walks its edge from ``edges[e, 1]`` to ``edges[e, 0]``.
    n:          (E,) int64 segments per edge (from :func:`_edge_segments`).
    e_off:      (E + 1,) int64: edge e owns the vertices ``e_off[e] .. e_off[e] + n[e] - 2``, at
                t = k / n[e], k = 1 .. n[e] - 1, from ``edges[e, 0]``; ``e_off[-1]`` is the next free.
    """

    edges: np.ndarray
    face_edges: np.ndarray
    flipped: np.ndarray
    n: np.ndarray
    e_off: np.ndarray

    def vertex(self, face_ids, side, k, g):
        """(G,) global index of the vertex at k / g (k (G,) in 0..g) along side ``side`` of the
        polys ``face_ids`` (G,), walking in face order: the side's own cut nearest it (k itself
        where the side is cut in g, its face's grid count on that side; else snapped, so a
        face cut finer than a side shares that side's points)."""
        e = self.face_edges[face_ids, side]
        m = self.n[e]
        k = (2 * k * m + g) // (2 * g)               # k / g rounded to the side's m segments
        flip = self.flipped[face_ids, side]
        first = np.where(flip, self.edges[e, 1], self.edges[e, 0])
        last = np.where(flip, self.edges[e, 0], self.edges[e, 1])
        inner = self.e_off[e] + np.where(flip, m - k, k) - 1
        return np.where(k == 0, first, np.where(k == m, last, inner))


def _cut_edges(verts, polys, patch_size):
    """Cut the edges of polys (F, 4) over verts (V, 3) for ``patch_size``.

    Returns the :class:`_EdgeCuts` and the positions (e_off[-1] - V, 3) of the vertices inside
    edges, numbered from V on.
    """
    edges, face_edges, flipped, n = _edge_segments(verts, polys, patch_size)
    V = len(verts)
    e_off = V + np.concatenate([[0], np.cumsum(n - 1)])
    e_rep = np.repeat(np.arange(len(edges)), n - 1)
    k_in = np.arange(e_rep.size) - (e_off[e_rep] - V) + 1
    t = (k_in / n[e_rep])[:, None]
    edge_pos = (1 - t) * verts[edges[e_rep, 0]] + t * verts[edges[e_rep, 1]]
    return _EdgeCuts(edges, face_edges, flipped, n, e_off), edge_pos


def _quad_boundary(cuts, fid, gu, gv):
    """(G, gu + 1, gv + 1) int64 grid of the quads ``fid`` (G,) with the edge vertices filled in
    (the inside is left uninitialised); u along side 0 (c0 -> c1), v along side 3 reversed."""
    G = fid.size
    grid = np.empty((G, gu + 1, gv + 1), dtype=np.int64)
    for i in range(gu + 1):
        grid[:, i, 0] = cuts.vertex(fid, 0, np.full(G, i), gu)          # c0 -> c1
        grid[:, i, gv] = cuts.vertex(fid, 2, np.full(G, gu - i), gu)    # c2 -> c3 reversed
    for j in range(gv + 1):
        grid[:, gu, j] = cuts.vertex(fid, 1, np.full(G, j), gv)         # c1 -> c2
        grid[:, 0, j] = cuts.vertex(fid, 3, np.full(G, gv - j), gv)     # c3 -> c0 reversed
    return grid


def _cut_quads(verts, polys, cuts, fid, gu, gv, next_v):
    """Cut the quads ``fid`` (G,), gu segments along sides 0 and 2 and gv along 1 and 3, into
    gu x gv grids. Returns the bilinear positions (G * (gu-1) * (gv-1), 3) of the new inner
    vertices, numbered from ``next_v`` quad by quad, and the patches (G * gu * gv, 4)."""
    G = fid.size
    grid = _quad_boundary(cuts, fid, gu, gv)
    ni = (gu - 1) * (gv - 1)
    pos = np.zeros((0, 3))
    if ni > 0:
        c = verts[polys[fid]]  # (G,4,3)
        uu, vv = np.meshgrid(np.arange(1, gu) / gu, np.arange(1, gv) / gv, indexing="ij")
        uu = uu.reshape(-1)[None, :, None]
        vv = vv.reshape(-1)[None, :, None]
        pos = ((1 - uu) * (1 - vv) * c[:, None, 0] + uu * (1 - vv) * c[:, None, 1]
               + uu * vv * c[:, None, 2] + (1 - uu) * vv * c[:, None, 3]).reshape(-1, 3)
        grid[:, 1:gu, 1:gv] = next_v + np.arange(G * ni).reshape(G, gu - 1, gv - 1)
    p = np.stack([grid[:, :-1, :-1], grid[:, 1:, :-1], grid[:, 1:, 1:], grid[:, :-1, 1:]], axis=-1)
    return pos, p.reshape(-1, 4)


def _triangle_boundary(cuts, fid, g):
    """(G, g + 1, g + 1) int64 grid of the triangles ``fid`` (G,), vertex (i, j) at
    c0 + i/g (c1-c0) + j/g (c2-c0), with the edge vertices filled in and -1 elsewhere."""
    G = fid.size
    grid = np.full((G, g + 1, g + 1), -1, dtype=np.int64)
    for i in range(g + 1):
        grid[:, i, 0] = cuts.vertex(fid, 0, np.full(G, i), g)              # c0 -> c1
    for j in range(g + 1):
        grid[:, g - j, j] = cuts.vertex(fid, 1, np.full(G, j), g)          # c1 -> c2
        grid[:, 0, j] = cuts.vertex(fid, 2, np.full(G, g - j), g)          # c2 -> c0 reversed
    return grid


def _triangle_cells(grid, g):
    """(G, g * g, 4) the triangles of barycentric grids ``grid`` (G, g + 1, g + 1), -1 last:
    for each (i, j) the upright cell, then the inverted one beside it where there is one."""
    G = grid.shape[0]
    tris = []
    for i in range(g):
        for j in range(g - i):
            tris.append(np.stack([grid[:, i, j], grid[:, i + 1, j], grid[:, i, j + 1],
                                  np.full(G, -1)], axis=1))
            if i + j < g - 1:
                tris.append(np.stack([grid[:, i + 1, j], grid[:, i + 1, j + 1], grid[:, i, j + 1],
                                      np.full(G, -1)], axis=1))
    return np.stack(tris, axis=1)


def _cut_triangles(verts, polys, cuts, fid, g, next_v):
    """Cut the triangles ``fid`` (G,), g segments on every side, into g * g triangles each.
    Returns the positions (G * I, 3) of the I new inner vertices per triangle, numbered from
    ``next_v`` triangle by triangle, and the patches (G * g * g, 4)."""
    G = fid.size
    grid = _triangle_boundary(cuts, fid, g)
    ii, jj = np.nonzero((np.add.outer(np.arange(g + 1), np.arange(g + 1)) < g)
                        & (np.arange(g + 1)[:, None] > 0) & (np.arange(g + 1)[None, :] > 0))
    pos = np.zeros((0, 3))
    if ii.size:
        c = verts[polys[fid, :3]]
        a = (ii / g)[None, :, None]
        b = (jj / g)[None, :, None]
        pos = (c[:, None, 0] + a * (c[:, None, 1] - c[:, None, 0])
               + b * (c[:, None, 2] - c[:, None, 0])).reshape(-1, 3)
        grid[:, ii, jj] = next_v + np.arange(G * ii.size).reshape(G, ii.size)
    return pos, _triangle_cells(grid, g).reshape(-1, 4)


def _subdivide(verts, polys, patch_size):
    """Cut triangles/quads into regular grids of patches with shared vertices.

    verts (V, 3), polys (F, 4) with -1 for triangles. Returns new verts (V', 3), patch polys
    (P, 4), and the parent poly index per patch (P,). Polys are cut in groups of the same grid
    size, quads first; the new vertices follow in the same order.
    """
    cuts, edge_pos = _cut_edges(verts, polys, patch_size)
    next_v = int(cuts.e_off[-1])
    all_pos = [verts, edge_pos]
    out_polys, out_parent = [], []
    tri = polys[:, 3] < 0
    dims = _face_grids(polys, cuts.face_edges, cuts.n)
    q = np.flatnonzero(~tri)
    if q.size:
        nu, nv = dims[q, 0], dims[q, 1]
        for (gu, gv) in unique_rows(np.stack([nu, nv], 1)):
            fid = q[(nu == gu) & (nv == gv)]
            pos, cells = _cut_quads(verts, polys, cuts, fid, gu, gv, next_v)
            next_v += len(pos)
            all_pos.append(pos)
            out_polys.append(cells)
            out_parent.append(np.repeat(fid, gu * gv))
    t_ids = np.flatnonzero(tri)
    if t_ids.size:
        nt = dims[t_ids, 0]
        for g in np.unique(nt):
            fid = t_ids[nt == g]
            pos, cells = _cut_triangles(verts, polys, cuts, fid, g, next_v)
            next_v += len(pos)
            all_pos.append(pos)
            out_polys.append(cells)
            out_parent.append(np.repeat(fid, g * g))
    return (np.concatenate(all_pos),) + _without_collapsed(np.concatenate(out_polys), np.concatenate(out_parent))


def _without_collapsed(polys, parent):
    """Cells whose corners a side's snapping (:meth:`_EdgeCuts.vertex`) made meet: a quad with
    two neighbouring corners at one vertex is the triangle of the other three; a cell with no
    area left (a triangle with two corners at one vertex, a quad with more) is dropped. The
    rest of the face covers it: the snapped side's cells fan out from its points."""
    a, b, c, d = polys.T
    quad = d >= 0
    same = np.stack([a == b, b == c, np.where(quad, c == d, False), np.where(quad, d == a, c == a)], 1)
    k = same.sum(axis=1) + (quad & ((a == c) | (b == d)))
    if not k.any():
        return polys, parent
    keep = (k == 0) | (quad & (k == 1))
    fix = np.flatnonzero(quad & (k == 1))
    if fix.size:
        # the triangle of the three corners left, in order: drop the second of the equal pair
        drop = same[fix].argmax(axis=1) + 1
        order = (drop[:, None] + np.arange(1, 4)[None, :]) % 4
        polys = polys.copy()
        polys[fix] = np.concatenate([np.take_along_axis(polys[fix], order, 1), np.full((fix.size, 1), -1)], 1)
    return polys[keep], parent[keep]


def build_patches(meshes, patch_size=None, min_area=None) -> PatchSet:
    """Cut source meshes into patches of edge length about ``patch_size`` (world units; times
    a mesh's ``size_scale``).

    ``patch_size`` None or <= 0 keeps every triangle/quad as one patch (n-gons are still split).
    Triangles become n*n triangles, quads an nu*nv grid; n-gons are split first (convex: quads
    around the centre; concave: ear clipping). Faces with area below ``min_area`` are dropped;
    None (default) means :data:`.patches.ZERO_AREA` of the squared size (bounding-box diagonal)
    of each mesh, so the same scene in millimetres or kilometres keeps the same patches.
    Raises :class:`PatchError` naming the object when the input is unusable.
    """
    if isinstance(meshes, MeshInput):
        meshes = [meshes]
    if not meshes:
        raise PatchError("no meshes were given")
    parts = []
    v_base = 0
    for oi, mesh in enumerate(meshes):
        rho = np.asarray(mesh.face_rho, float)
        em = np.asarray(mesh.face_emission, float)
        F = len(mesh.face_offsets) - 1
        if rho.shape != (F, 3) or em.shape != (F, 3):
            raise PatchError(f"{mesh.name!r}: face_rho and face_emission must have shape ({F}, 3)")
        if not (np.all(np.isfinite(rho)) and np.all(np.isfinite(em))):
            raise PatchError(f"{mesh.name!r}: reflectivity or emission is not finite")
        if np.any(rho < 0) or np.any(rho >= 1):
            f = int(np.flatnonzero(np.any((rho < 0) | (rho >= 1), axis=1))[0])
            raise PatchError(f"{mesh.name!r}: face {f} has reflectivity {tuple(rho[f])}; "
                             "each band must be in [0, 1)")
        if np.any(em < 0):
            f = int(np.flatnonzero(np.any(em < 0, axis=1))[0])
            raise PatchError(f"{mesh.name!r}: face {f} has negative emission {tuple(em[f])}")
        v, p, src = to_tris_and_quads(mesh)
        v, p, parent = _subdivide(v, p, patch_size * mesh.size_scale if patch_size else patch_size)
        src = src[parent]
        v, p = compact(v, p)
        c, nrm, a = poly_geometry(v, p)
        if min_area is None:
            span = np.ptp(np.asarray(mesh.verts, float), axis=0) if len(mesh.verts) else np.zeros(3)
            keep = a > ZERO_AREA * float(span @ span)
        else:
            keep = a > min_area
        if not np.any(keep):
            raise PatchError(f"{mesh.name!r}: every face has zero area")
        p, c, nrm, a, src = p[keep], c[keep], nrm[keep], a[keep], src[keep]
        v, p = compact(v, p)
        parts.append((v, p + v_base * (p >= 0), c, nrm, a, rho[src], em[src],
                      np.full(len(p), oi, np.int32), src.astype(np.int32)))
        v_base += len(v)
    cat = [np.concatenate([part[i] for part in parts]) for i in range(9)]
    return PatchSet(*cat, object_names=[m.name for m in meshes], see_through=see_through(meshes))
