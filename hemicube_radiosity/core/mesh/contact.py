"""Output vertices buried where another surface stands on theirs: the open side's limit instead.

A ground modelled as one large face runs on under the houses standing on it; a floor under a
block sunk into it; a block's side below the floor line. The output mesh is cut without regard
to them, so an element can straddle a wall's foot: one corner in the open, one under the house.
The buried corner sees only the inside of the house, its light is ~0, and bilinear interpolation
across the element (in the viewport, in glTF, at a reference's vertices) spreads that dark
corner over the open half: a dark halo at every wall's foot (the bench yard: 43% RMS error at
ground vertices within 15 cm of a wall, 96% of the scene's squared error).

Here a buried corner takes, for each element edge that runs to it from an open corner, the light
at the point where that edge meets the surface standing on it (one ray along the edge, a hair
above the surface), as lightmap bakers dilate texels into hidden ones: interpolating across the
element goes from the open corner's value to the value at the wall's foot. What a buried corner
shows is never seen; what matters is what it does to the open side."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .contact_pieces import assemble_pieces
from .contact_lines import face_pieces, outside, pieces_segments, segment_hits, split_polygon
from .patches import PatchSet
from ..util.unique import run_positions, unique_ints, unique_rows
from ..rays import ray_offsets

__all__ = ["OpenSide", "open_side"]


@dataclass
class OpenSide:
    """Edges from open output vertices to buried ones, and where each meets what buries it.

    ``open_v`` (E,) and ``buried_v`` (E,): vertex ids at the edge's ends; ``points`` (E, 3) the
    last point of the edge on the open side (world units, on the surface), ``normals`` (E, 3)
    the normal there (its element's). ``count`` (V,) how many edges end at each vertex (0: it
    keeps its own value)."""

    open_v: np.ndarray
    buried_v: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    count: np.ndarray

    def __len__(self) -> int:
        return len(self.open_v)

    def spread(self, values_v, at_points=None) -> np.ndarray:
        """(V, k) ``values_v`` with each buried vertex given the mean over its edges of
        ``at_points`` (E, k) (the light at the edges' meeting points), or of the open ends'
        values when None."""
        out = np.array(values_v, dtype=np.float64, copy=True)
        if not len(self):
            return out
        src = out[self.open_v] if at_points is None else np.asarray(at_points, dtype=np.float64)
        on = self.count > 0
        acc = np.zeros((len(out),) + out.shape[1:])
        np.add.at(acc, self.buried_v, src)
        out[on] = acc[on] / self.count[on].reshape((-1,) + (1,) * (out.ndim - 1))
        return out


def _edges(polys) -> np.ndarray:
    """(E, 2) directed element edges, both ways, with the element's index: (from, to, element)."""
    valid = polys >= 0
    nxt = np.where(valid, polys, polys[:, :1])            # triangles: last corner is the first
    rows = []
    for c in range(4):
        a = polys[:, c]
        b = np.where(valid[:, (c + 1) % 4], nxt[:, (c + 1) % 4], polys[:, 0])
        ok = (a >= 0) & (a != b)
        e = np.flatnonzero(ok)
        rows += [np.stack([a[ok], b[ok], e], 1), np.stack([b[ok], a[ok], e], 1)]
    return np.concatenate(rows) if rows else np.zeros((0, 3), np.int64)


def open_side(elements: PatchSet, buried, scene, opened=None) -> OpenSide:
    """The :class:`OpenSide` of ``elements``' vertices ``buried`` (V,) bool (they see (almost)
    nothing: :func:`.hemisphere.open_fraction`). ``scene``: the Embree scene of ``elements``
    (:func:`.rays.embree_scene`, whose ``intersect`` gives hit distances along unit directions).
    ``opened`` (N,): elements the scene sees (> 0; None: all); only their edges count, as only
    they are ever seen and interpolated across (a floor wholly under a block stays dark).

    An edge counts when it runs along a seen element from an open vertex to a buried one and a ray along it, lifted
    a hair (:func:`.rays.ray_offsets` of the element) above it, hits a surface before its end: a wall standing
    on the floor between them. A buried vertex with no such edge (the ceiling behind a lamp's
    back, a face hidden in a fold) is left alone. Geometry only."""
    buried = np.asarray(buried, bool)
    V = len(elements.verts)
    E = _edges(elements.polys)
    E = E[~buried[E[:, 0]] & buried[E[:, 1]]]
    if opened is not None:
        E = E[np.asarray(opened)[E[:, 2]] > 0]
    empty = OpenSide(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)),
                     np.zeros(V, np.int64))
    if not len(E):
        return empty
    a, b, e = E.T
    n = elements.normals[e]
    start, end = elements.verts[a], elements.verts[b]
    d = end - start
    length = np.linalg.norm(d, axis=1)
    d = d / np.maximum(length, 1e-300)[:, None]
    pid, t = scene.intersect(start + ray_offsets(elements, owner=elements.owner[e])[:, None] * n, d)
    pid, t = np.asarray(pid), np.asarray(t, dtype=np.float64)
    met = (pid >= 0) & (t < length * (1 - 1e-3))
    if not met.any():
        return empty
    a, b, n, d, t, length = a[met], b[met], n[met], d[met], t[met], length[met]
    # a hair short of the wall (a thousandth of the edge), on the surface itself
    points = elements.verts[a] + np.maximum(t - 1e-3 * length, 0.0)[:, None] * d
    return OpenSide(a, b, points, n, np.bincount(b, minlength=V))


# ------------------------------------------------------------------------------------------
# Cutting output elements along contact lines


def cut_along_contacts(elements: PatchSet, faces: PatchSet, eps_rel=1e-6, tol_rel=1e-3, cuts=None) -> PatchSet:
    """``elements`` cut along the lines where other surfaces (``faces``: the scene's faces, e.g.
    :func:`.subdivide.build_patches` with no size) stand on or pass through them, with the
    vertices on those lines apart on each side (a seam): no element straddles a wall's foot,
    and a vertex on it is evaluated on its own side (the open side's limit; the side under a
    house sees nothing and is never seen). A piece of more than four corners is fanned into
    triangles; a cut closer than ``tol_rel`` of an element's size to its corner snaps to it.
    ``eps_rel``: of the scene's size, what counts as touching a plane; ``cuts`` (len(faces),)
    bool or None: which faces may cut (:func:`.backs.cutters`). Returns ``elements`` if uncut."""
    scale = float(np.ptp(faces.verts, axis=0).max()) or 1.0
    eps = eps_rel * scale
    corners = elements.corners()
    cut_corners = faces.corners()
    # a group: the elements of one plane of a source face (a warped quad's two triangles are two)
    plane = np.round(np.asarray(elements.normals, dtype=np.float64) * 1e3).astype(np.int64)
    key = np.column_stack([elements.owner.astype(np.int64), elements.source_face.astype(np.int64), plane])
    groups, inv, count = unique_rows(key, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    order = np.argsort(inv, kind="stable")
    start = np.r_[0, np.cumsum(count)]
    flat = corners.reshape(len(corners), -1, 3)
    g_lo = np.minimum.reduceat(flat.min(axis=1)[order], start[:-1]) - eps
    g_hi = np.maximum.reduceat(flat.max(axis=1)[order], start[:-1]) + eps
    g_n = elements.normals[order[start[:-1]]]
    g_pieces, g_piece_at, g_face = face_pieces(elements, order[start[:-1]], g_n, faces)
    gi_all, ci_all = _cutters(elements, faces, cut_corners, order, start, flat, g_lo, g_hi, g_n, g_face, eps, cuts)
    # where each cutter meets its group's plane, and the part of that segment on the group's
    # own face, any of its pieces (a cutter that crosses the face's plane beside the face, a curved mesh's
    # diagonal neighbour sharing one corner, meets it at that corner at most and cuts
    # nothing): every pair at once, in chunks
    seg_all = np.zeros((len(gi_all), 2, 3))
    kept_all = np.zeros(len(gi_all), bool)
    for c0 in range(0, len(gi_all), 1 << 14):
        sl = slice(c0, c0 + (1 << 14))
        g = gi_all[sl]
        seg_all[sl], kept_all[sl] = pieces_segments(flat[order[start[g]], 0], g_n[g], cut_corners[ci_all[sl]], g,
                                                    (g_pieces, g_piece_at), cut_corners, eps)
    gi_all, ci_all, seg_all = gi_all[kept_all], ci_all[kept_all], seg_all[kept_all]
    # the elements each segment parts (every segment against its group's elements at once), then
    # each hit element split along its segments' lines in turn
    (d_all, len_all, m_all), (hs, he, ht) = segment_hits(
        corners, order, start, gi_all, seg_all, faces.normals[ci_all], elements.normals[order[start[gi_all]]],
        np.sqrt(elements.areas), tol_rel, eps)
    pieces = _split_hits(elements, (hs, he, ht), seg_all[:, 0], m_all, d_all, len_all)
    if not pieces:
        return elements
    return assemble_pieces(elements, pieces, (ci_all[hs], seg_all[hs, 0], m_all[hs], ht, d_all[hs], len_all[hs]),
                           eps)


def _split_hits(elements, hits, a_all, m_all, d_all, len_all):
    """{element: [(polygon (k, 3), tags)]}: each element ``hits`` (segments, elements,
    tolerances) name split along its segments' lines in turn (segment s: start ``a_all[s]``,
    in-plane normal ``m_all[s]``, direction ``d_all[s]``, length ``len_all[s]``); a piece's tags
    ((line, side), ...) say which side of each line (the hit's index) it lies on."""
    pieces = {}
    hs, he, ht = hits
    for h, (s, e, tl) in enumerate(zip(hs.tolist(), he.tolist(), ht.tolist())):
        a, d, length = a_all[s], d_all[s], len_all[s]
        todo = pieces.get(e) or [(_polygon(elements, e), ())]
        out = []
        for poly, tags in todo:
            if outside(((poly - a) @ d).tolist(), tl, length - tl):
                out.append((poly, tags))          # this piece lies beyond the segment
                continue
            sp = split_polygon(poly, a, m_all[s], tl)
            if sp is None:
                hs_ = (poly - a) @ m_all[s]
                out.append((poly, tags + ((h, 1 if hs_.sum() >= 0 else -1),)))
            else:
                out += [(sp[0], tags + ((h, 1),)), (sp[1], tags + ((h, -1),))]
        pieces[e] = out
    return pieces


def _corners_met(src, cut, eps, quad):
    """(P,) how many corners of each ``cut`` (P, 4, 3) lie within ``eps`` (each coordinate) of
    a corner of its ``src`` (P, 4, 3); the 4th only where ``quad`` (P,) (a triangle's repeats
    its 3rd). Corner by corner and axis by axis: the same as comparing the (P, 4, 4, 3)
    differences at once, without them (a scanned bunny's 900,000 pairs of faces made 350 MB)."""
    count = np.zeros(len(src), np.int64)
    for b in range(4):
        met = np.zeros(len(src), bool)
        for a in range(4):
            near = np.abs(src[:, a, 0] - cut[:, b, 0]) <= eps
            near &= np.abs(src[:, a, 1] - cut[:, b, 1]) <= eps
            near &= np.abs(src[:, a, 2] - cut[:, b, 2]) <= eps
            met |= near
        count += met if b < 3 else met & quad
    return count


def _direction_keys(normals) -> np.ndarray:
    """(N,) int64 one key per direction up to sign, normals rounded to 1e-6 (parallel faces of
    a wall, a floor, share one)."""
    n = np.asarray(normals, dtype=np.float64)
    big = np.take_along_axis(n, np.abs(n).argmax(axis=1)[:, None], axis=1)
    n = np.round(np.where(big < 0, -n, n), 6) + 0.0
    return unique_rows(n, return_inverse=True)[1].reshape(-1)


def _crossing_candidates(g_lo, g_hi, g_n, lo, hi, c_n, share=0.01):
    """(i, j) sorted: the pairs of group boxes (``g_lo``, ``g_hi``, normals ``g_n``) and cutter
    boxes (``lo``, ``hi``, normals ``c_n``) that overlap, leaving out most pairs of parallel
    faces (which never cut: a dense floor's triangles against each other were most of the pairs
    of :func:`_overlapping`). The groups of each direction held by more than ``share`` of them
    are matched against the cutters of other directions near them only; the rest against all."""
    keys = _direction_keys(np.concatenate([g_n, c_n]))
    gk, ck = keys[:len(g_n)], keys[len(g_n):]
    count = np.bincount(gk)
    big = np.flatnonzero(count > max(64, share * len(g_n)))
    out_i, out_j = [], []
    rest = ~np.isin(gk, big)
    for k in big:
        a = np.flatnonzero(gk == k)
        box_lo, box_hi = g_lo[a].min(axis=0), g_hi[a].max(axis=0)
        b = np.flatnonzero((ck != k) & np.all((lo <= box_hi) & (hi >= box_lo), axis=1))
        if b.size:
            i, j = _overlapping(g_lo[a], g_hi[a], lo[b], hi[b])
            out_i.append(a[i])
            out_j.append(b[j])
    a = np.flatnonzero(rest)
    if a.size:
        i, j = _overlapping(g_lo[a], g_hi[a], lo, hi)
        out_i.append(a[i])
        out_j.append(j)
    if not out_i:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    i, j = np.concatenate(out_i), np.concatenate(out_j)
    # by i, then j (as a lexsort): one int64 key, sorted stably (each part comes sorted)
    o = np.argsort(i * np.int64(len(c_n) + 1) + j, kind="stable")
    return i[o], j[o]


def _cutters(elements, faces, cut_corners, order, start, flat, g_lo, g_hi, g_n, g_face, eps, cuts):
    """(group ids, face ids), sorted by group: the faces (``cut_corners`` their corners) that may
    cut each group of :func:`cut_along_contacts` (``order``/``start``: its elements by group,
    ``flat`` their corners, ``g_lo``/``g_hi``/``g_n`` its boxes and planes, ``g_face`` a face
    of each; ``eps``, ``cuts`` as there)."""
    lo, hi = cut_corners.min(axis=1) - eps, cut_corners.max(axis=1) + eps
    # the faces that may cut each group: boxes overlapping (a grid of cells) and corners on
    # both sides of, or on, the group's plane
    gi_all, ci_all = _crossing_candidates(g_lo, g_hi, g_n, lo, hi, faces.normals)
    # a face of the same object at a corner of the group's face (the same place) is left out
    # below (the mesh going on): most pairs of a scanned mesh, whose neighbours' boxes overlap
    weld = unique_rows(faces.verts, return_inverse=True)[1].reshape(-1)
    at = np.where(faces.polys < 0, weld[faces.polys[:, 2:3]], weld[np.maximum(faces.polys, 0)])
    goes_on = elements.owner[order[start[gi_all]]] == faces.owner[ci_all]
    goes_on &= (at[g_face[gi_all]][:, :, None] == at[ci_all][:, None, :]).any(axis=(1, 2))
    gi_all, ci_all = gi_all[~goes_on], ci_all[~goes_on]
    h = np.einsum("pkj,pj->pk", cut_corners[ci_all] - flat[order[start[gi_all]], 0][:, None], g_n[gi_all])
    tri = np.all(cut_corners[ci_all][:, 3] == cut_corners[ci_all][:, 2], axis=1)
    on = (np.abs(h) <= eps).sum(axis=1) - (tri & (np.abs(h[:, 3]) <= eps))
    keep = (((h.min(axis=1) < -eps) & (h.max(axis=1) > eps)) | (on >= 2)) & \
        (np.abs(np.einsum("pj,pj->p", faces.normals[ci_all], g_n[gi_all])) < 1 - 1e-6)
    keep &= True if cuts is None else np.asarray(cuts, dtype=bool)[ci_all]
    gi_all, ci_all = gi_all[keep], ci_all[keep]
    # a face sharing an edge with the group's face (two corners at the same places) meets it at
    # its border: nothing to cut (the faces of a tessellated box along its edges)
    shared = _corners_met(cut_corners[g_face[gi_all]], cut_corners[ci_all], eps, ~tri[keep])
    # nor does a face of the same object sharing a corner: the mesh going on (a subdivided
    # surface's quads are a little warped, so their diagonal neighbours cross each other's
    # planes: Suzanne at level 3 was cut along 60,000 such lines)
    own = elements.owner[order[start[gi_all]]] == faces.owner[ci_all]
    apart = (shared < 2) & ~(own & (shared >= 1))
    gi_all, ci_all = gi_all[apart], ci_all[apart]
    by = np.argsort(gi_all, kind="stable")
    gi_all, ci_all = gi_all[by], ci_all[by]
    return gi_all, ci_all


def _overlapping(alo, ahi, blo, bhi, per_box=64):
    """(i, j) sorted by i then j: the pairs of boxes ``a`` (lo, hi (A, 3)) and ``b`` (B, 3) that
    overlap. Grids of cells twice the median box size, and 2, 4, 8... times that, find the
    candidates: each box goes on the finest grid where it covers at most ``per_box`` cells (its
    level), and a pair is looked for on the grid of the coarser of its two boxes' levels, each
    box of a finer level on it covering a few cells; the boxes are compared there, and a pair
    that overlaps is kept in one cell only (its overlap's lowest corner's). The work
    grows with the boxes and the pairs found, not with the large boxes times all the others
    (a game level's 1,600 floor slabs, each tested against every other box, took 20 s)."""
    if not len(alo) or not len(blo):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    ext = np.concatenate([ahi - alo, bhi - blo]).max(axis=1)
    size = 2.0 * max(float(np.median(ext)), 1e-12 * max(float(ext.max()), 1e-300))
    grid = _Grids(np.minimum(alo.min(axis=0), blo.min(axis=0)), size, per_box)
    la, lb = grid.levels(alo, ahi), grid.levels(blo, bhi)
    pairs = [np.zeros((0, 2), np.int64)]
    for L in np.union1d(la, lb):
        s = size * 2.0 ** L
        if np.any(la == L):                       # a's boxes of this level against b's as fine
            pairs.append(grid.meet((alo, ahi), np.flatnonzero(la == L), (blo, bhi), np.flatnonzero(lb <= L), s))
        if np.any(lb == L) and np.any(la < L):    # b's against a's finer ones
            pairs.append(grid.meet((alo, ahi), np.flatnonzero(la < L), (blo, bhi), np.flatnonzero(lb == L), s))
    p = np.concatenate(pairs).astype(np.int64)
    B = max(len(blo), 1)
    k = unique_ints(p[:, 0] * B + p[:, 1])     # (sorted; once each, cell keys colliding too)
    return k // B, k % B


class _Grids:
    """The grids of :func:`_overlapping`: cells of edge ``size`` * 2^L from ``origin`` (3,),
    a box on the finest one where it covers at most ``per_box`` cells."""

    def __init__(self, origin, size, per_box):
        self.origin, self.size, self.per_box = origin, size, per_box

    def cells(self, lo, hi, s):
        """The first and last cell (n, 3) int64 of each box on the grid of edge s, and how many
        cells it covers (n,)."""
        i0 = np.floor((lo - self.origin) / s).astype(np.int64)
        i1 = np.floor((hi - self.origin) / s).astype(np.int64)
        return i0, i1, np.prod(i1 - i0 + 1, axis=1)

    def key(self, g):
        """(n,) int64 one key per cell (n, 3)."""
        return (g[:, 0] * 2097152 + g[:, 1]) * 2097152 + g[:, 2]

    def levels(self, lo, hi):
        """(n,) int64 each box's level L."""
        level = np.zeros(len(lo), np.int64)
        up = np.arange(len(lo))
        for L in range(64):                      # a grid of 2^63 cells holds any finite box
            up = up[self.cells(lo[up], hi[up], self.size * 2.0 ** L)[2] > self.per_box]
            if not up.size:
                break
            level[up] = L + 1
        return level

    def expand(self, lo, hi, ids, s):
        """(cell keys, box ids): every cell of edge s that boxes ``ids`` cover, once per box."""
        i0, i1, _ = self.cells(lo[ids], hi[ids], s)
        dims = i1 - i0 + 1
        n = np.prod(dims, axis=1)
        own = np.repeat(ids, n)
        off = run_positions(n)                                 # (no ids: empty)
        at = np.repeat(np.arange(len(ids)), n)
        d = dims[at]
        g = i0[at] + np.stack([off // (d[:, 1] * d[:, 2]), (off // d[:, 2]) % d[:, 1], off % d[:, 2]], 1)
        return self.key(g), own

    def meet(self, a, ia_, b, ib_, s):
        """(P, 2) the pairs of boxes ``a`` (lo, hi) ``ia_`` x ``b`` ``ib_`` that overlap, each
        found in the cell of edge s holding its overlap's lowest corner (a cell both boxes
        cover), so once."""
        (alo, ahi), (blo, bhi) = a, b
        ka, ia = self.expand(alo, ahi, ia_, s)
        kb, ib = self.expand(blo, bhi, ib_, s)
        order = np.argsort(kb, kind="stable")
        kb, ib = kb[order], ib[order]
        lo_ = np.searchsorted(kb, ka, "left")
        cnt = np.searchsorted(kb, ka, "right") - lo_
        ii = np.repeat(ia, cnt)
        jj = ib[np.repeat(lo_ - np.r_[0, np.cumsum(cnt)[:-1]], cnt) + np.arange(cnt.sum())] if cnt.sum() else \
            np.zeros(0, np.int64)
        kk = np.repeat(ka, cnt)
        for d in range(3):      # one axis at a time, on the pairs still overlapping (the same
            al, bl = alo[:, d].take(ii), blo[:, d].take(jj)    # pairs; a third of the time)
            ok = (al <= bhi[:, d].take(jj)) & (ahi[:, d].take(ii) >= bl)
            ii, jj, kk = ii[ok], jj[ok], kk[ok]
        g = np.floor((np.maximum(alo.take(ii, axis=0), blo.take(jj, axis=0)) - self.origin) / s).astype(np.int64)
        first = self.key(g) == kk
        return np.stack([ii[first], jj[first]], 1)


def _polygon(elements, e):
    p = elements.polys[e]
    return elements.verts[p[p >= 0]]
