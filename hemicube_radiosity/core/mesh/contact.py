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

from .contact_lines import face_pieces, pieces_segments, split_polygon
from .patches import PatchSet, poly_geometry
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
    nothing: :func:`.rays.open_fraction`). ``scene``: the Embree scene of ``elements``
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
    lo, hi = cut_corners.min(axis=1) - eps, cut_corners.max(axis=1) + eps
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
    # the faces that may cut each group: boxes overlapping (a grid of cells) and corners on
    # both sides of, or on, the group's plane
    gi_all, ci_all = _crossing_candidates(g_lo, g_hi, g_n, lo, hi, faces.normals)
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
    pieces = {}                       # element -> list of (polygon, tags)
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
    bounds = np.r_[0, np.flatnonzero(np.diff(gi_all)) + 1, len(gi_all)] if len(gi_all) else [0]
    for k0, k1 in zip(bounds[:-1], bounds[1:]):
        gi = gi_all[k0]
        ids = order[start[gi]:start[gi + 1]]
        c = corners[ids]
        n = elements.normals[ids[0]]
        size = np.sqrt(elements.areas[ids])
        for (a, b), g in zip(seg_all[k0:k1], ci_all[k0:k1]):
            length = float(np.linalg.norm(b - a))
            d = (b - a) / length
            # sides: in front of the cutter (its normal's part in this plane) or behind it, the
            # same on every face it cuts
            m = faces.normals[g] - (faces.normals[g] @ n) * n
            m /= np.linalg.norm(m)
            ext = (c - a) @ d                                             # (M, 4) along the line
            h = (c - a) @ m                                               # (M, 4) across it
            tol = np.maximum(tol_rel * size, eps)[:, None]
            # alongside the segment, not just touching its end (a block's corner does not part
            # the floor beyond it)
            along = (ext.max(axis=1) > tol[:, 0]) & (ext.min(axis=1) < length - tol[:, 0])
            both = (h.max(axis=1) > tol[:, 0]) & (h.min(axis=1) < -tol[:, 0])
            on = (np.abs(h) <= tol).any(axis=1)
            hit = along & (both | on)
            side = np.sign((np.where(np.abs(h) <= tol, 0.0, h)).sum(axis=1))
            # a line along the face's own border (its neighbour face, a wall meeting a floor
            # at the floor's edge) has elements on one side only: nothing to keep apart
            if not (hit & both).any() and np.unique(side[hit & ~both]).size < 2:
                continue
            for e, tl in zip(ids[hit], tol[hit, 0]):
                line = (int(g), a, m, float(tl), d, length)
                todo = pieces.get(e) or [(_polygon(elements, e), ())]
                out = []
                for poly, tags in todo:
                    t = (poly - a) @ d
                    if t.max() <= line[3] or t.min() >= length - line[3]:
                        out.append((poly, tags))          # this piece lies beyond the segment
                        continue
                    sp = split_polygon(poly, a, m, line[3])
                    if sp is None:
                        hs = (poly - a) @ m
                        out.append((poly, tags + ((line, 1 if hs.sum() >= 0 else -1),)))
                    else:
                        out += [(sp[0], tags + ((line, 1),)), (sp[1], tags + ((line, -1),))]
                pieces[e] = out
    if not pieces:
        return elements
    return _assemble(elements, pieces, eps)


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


def _overlapping(alo, ahi, blo, bhi, per_box=64):
    """(i, j): the pairs of boxes ``a`` (lo, hi (A, 3)) and ``b`` (B, 3) that overlap. A grid of
    cells twice the median box size finds the candidates (a box over more than ``per_box`` cells
    is tested against every box of the other set instead), then the boxes are compared."""
    ext = np.concatenate([ahi - alo, bhi - blo]).max(axis=1)
    size = 2.0 * max(float(np.median(ext)), 1e-12 * max(float(ext.max()), 1e-300))
    origin = np.minimum(alo.min(axis=0), blo.min(axis=0))

    def cells(lo, hi):
        i0 = np.floor((lo - origin) / size).astype(np.int64)
        i1 = np.floor((hi - origin) / size).astype(np.int64)
        return i0, i1, np.prod(i1 - i0 + 1, axis=1)

    def expand(i0, i1, ids):
        dims = (i1 - i0 + 1)[ids]
        n = np.prod(dims, axis=1)
        own = np.repeat(ids, n)
        off = run_positions(n)                                 # (no ids: empty)
        d = dims[np.repeat(np.arange(len(ids)), n)]
        g = i0[own] + np.stack([off // (d[:, 1] * d[:, 2]), (off // d[:, 2]) % d[:, 1], off % d[:, 2]], 1)
        return (g[:, 0] * 2097152 + g[:, 1]) * 2097152 + g[:, 2], own

    a0, a1, na = cells(alo, ahi)
    b0, b1, nb = cells(blo, bhi)
    small_a, small_b = np.flatnonzero(na <= per_box), np.flatnonzero(nb <= per_box)
    ka, ia = expand(a0, a1, small_a)
    kb, ib = expand(b0, b1, small_b)
    order = np.argsort(kb, kind="stable")
    kb, ib = kb[order], ib[order]
    lo_ = np.searchsorted(kb, ka, "left")
    hi_ = np.searchsorted(kb, ka, "right")
    cnt = hi_ - lo_
    ii = np.repeat(ia, cnt)
    jj = ib[np.repeat(lo_ - np.r_[0, np.cumsum(cnt)[:-1]], cnt) + np.arange(cnt.sum())] if cnt.sum() else \
        np.zeros(0, np.int64)
    pairs = [np.stack([ii, jj], 1)]
    for k in np.flatnonzero(na > per_box):                  # big boxes: against every box
        j = np.flatnonzero(np.all((blo <= ahi[k]) & (bhi >= alo[k]), axis=1))
        pairs.append(np.stack([np.full(len(j), k), j], 1))
    for k in np.flatnonzero(nb > per_box):
        i = np.flatnonzero(np.all((alo <= bhi[k]) & (ahi >= blo[k]), axis=1) & (na <= per_box))
        pairs.append(np.stack([i, np.full(len(i), k)], 1))
    p = np.concatenate(pairs).astype(np.int64)
    B = max(len(blo), 1)
    k = unique_ints(p[:, 0] * B + p[:, 1])
    p = np.stack([k // B, k % B], 1)
    if not len(p):
        return p[:, 0], p[:, 1]
    ok = np.all((alo[p[:, 0]] <= bhi[p[:, 1]]) & (ahi[p[:, 0]] >= blo[p[:, 1]]), axis=1)
    return p[ok, 0], p[ok, 1]


def _polygon(elements, e):
    p = elements.polys[e]
    return elements.verts[p[p >= 0]]


def _assemble(elements, pieces, eps):
    """The PatchSet of ``elements`` with each element of ``pieces`` replaced by its pieces: a
    corner on a cut line (within its tolerance, inside the segment's reach) is a vertex of its
    side only (and of its plane: a cut across a box's edge leaves its two faces apart, as the
    box's own corners are); other corners keep the element's vertices."""
    V = len(elements.verts)
    verts = [elements.verts]
    index = {}
    polys, parent = [], []
    q = max(eps, 1e-300)
    for e in range(len(elements)):
        if e not in pieces:
            polys.append(elements.polys[e])
            parent.append(e)
            continue
        src = elements.polys[e][elements.polys[e] >= 0]
        src_pts = elements.verts[src]
        for poly, tags in pieces[e]:
            ids = []
            for x in poly:
                on = tuple(sorted((ln[0], side) for ln, side in tags if _on_segment(x, ln)))
                same = np.flatnonzero(np.all(np.abs(src_pts - x) <= q, axis=1))
                if not on and same.size:
                    ids.append(int(src[same[0]]))
                    continue
                # one vertex a place, side and plane: faces meeting at an angle (a box's sides,
                # whose corners the mesh keeps apart) keep the cut's points apart too
                k = (int(elements.owner[e]),) + tuple(np.round(x / q).astype(np.int64)) + on \
                    + tuple(np.round(elements.normals[e] * 1e3).astype(np.int64))
                if k not in index:
                    index[k] = V + len(index)
                    verts.append(x[None])
                ids.append(index[k])
            ids = _dedupe(ids)
            if len(ids) < 3:
                continue
            for tri in _fan(ids):
                polys.append(np.array(tri + [-1] * (4 - len(tri)), np.int64))
                parent.append(e)
    verts = np.concatenate(verts)
    polys = np.array(polys, np.int64)
    parent = np.array(parent, np.int64)
    centers, _, areas = poly_geometry(verts, polys)
    keep = areas > 0
    polys, parent, centers, areas = polys[keep], parent[keep], centers[keep], areas[keep]
    used = np.unique(polys[polys >= 0])
    remap = np.full(len(verts), -1, np.int64)
    remap[used] = np.arange(used.size)
    polys = np.where(polys >= 0, remap[np.maximum(polys, 0)], -1)
    return PatchSet(verts[used], polys, centers, elements.normals[parent], areas, elements.rho[parent],
                    elements.emission[parent], elements.owner[parent], elements.source_face[parent],
                    list(elements.object_names))


def _on_segment(x, line) -> bool:
    """Whether the point ``x`` lies on the contact segment ``line`` (cutter, start, across,
    tolerance, along, length): within the tolerance of its line, inside its ends (at an end the
    surface stops and the light goes round it: a block's corner does not part the floor)."""
    _, a, m, tol, d, length = line
    t = float((x - a) @ d)
    return abs(float((x - a) @ m)) <= tol and tol < t < length - tol


def _dedupe(ids):
    out = []
    for i in ids:
        if not out or out[-1] != i:
            out.append(i)
    while len(out) > 1 and out[0] == out[-1]:
        out.pop()
    return out


def _fan(ids):
    """A convex polygon's corner ids as quads and triangles (<= 4 corners: itself)."""
    if len(ids) <= 4:
        return [list(ids)]
    out = []
    i = 1
    while i + 2 < len(ids):
        out.append([ids[0], ids[i], ids[i + 1], ids[i + 2]])
        i += 2
    if i + 1 < len(ids):
        out.append([ids[0], ids[i], ids[i + 1]])
    return out
