"""Where a cutter meets a face's plane, clipped to the face, and a polygon split by a line.

The geometry of :func:`.contact.cut_along_contacts`: a face the mesh reader split into pieces (an
n-gon fanned into triangles, a warped quad into two) is one source face, and a wall standing on
it parts it wherever the wall meets any of its pieces, not only where it meets the first."""
from __future__ import annotations

import numpy as np

from ..util.unique import run_positions

__all__ = ["face_pieces", "pair_segments", "pieces_segments", "row_dots", "segment_hits",
           "split_polygon", "outside"]


def face_pieces(elements, ids, normals, faces):
    """The pieces of ``faces`` (the scene's faces as patches) that the groups of ``elements``
    starting at ``ids`` (G,), with plane normals ``normals`` (G, 3), were cut from: those of the
    same object and source face whose normal is within 1e-3 of the group's (a warped quad's
    other triangle is another group's), or every piece of it where none is. Returns (group
    (K,), piece (K,)) sorted by group, and (G,) the piece nearest each group's plane."""
    key = faces.owner.astype(np.int64) * (1 << 32) + faces.source_face.astype(np.int64)
    want = elements.owner[ids].astype(np.int64) * (1 << 32) + elements.source_face[ids].astype(np.int64)
    order = np.argsort(key, kind="stable")
    lo = np.searchsorted(key[order], want, "left")
    cnt = np.searchsorted(key[order], want, "right") - lo
    gi = np.repeat(np.arange(len(ids)), cnt)
    fi = order[np.repeat(lo, cnt) + run_positions(cnt)]
    dot = np.einsum("kj,kj->k", faces.normals[fi], normals[gi])
    nearest = np.full(len(ids), -1.0)
    np.maximum.at(nearest, gi, dot)
    best = np.zeros(len(ids), np.int64)
    top = dot >= nearest[gi]
    best[gi[top]] = fi[top]
    match = dot > 1 - 1e-3
    keep = match | ~(np.bincount(gi[match], minlength=len(ids)) > 0)[gi]
    return gi[keep], fi[keep], best


def pieces_segments(origin, n, cutters, pairs_group, group_pieces, piece_corners, eps):
    """:func:`pair_segments` of P (group, cutter) pairs against every piece of their group's
    face, joined: (segments (P, 2, 3), kept (P,) bool), a segment from the first to the last
    of its pieces' parts along the line (every part lies on one line: the cutter's crossing of
    the group's plane). ``pairs_group`` (P,) each pair's group; ``group_pieces`` (group (K,),
    piece (K,)) sorted by group (:func:`face_pieces`); ``piece_corners`` (pieces, 4, 3)."""
    gk, pk = group_pieces
    first = np.searchsorted(gk, pairs_group, "left")
    cnt = np.searchsorted(gk, pairs_group, "right") - first
    row = np.repeat(np.arange(len(pairs_group)), cnt)
    at = np.repeat(first, cnt) + run_positions(cnt)
    seg, ok = pair_segments(origin[row], n[row], cutters[row], piece_corners[pk[at]], eps)
    if np.array_equal(cnt, np.ones_like(cnt)):
        return seg, ok
    row, seg = row[ok], seg[ok]
    kept = np.zeros(len(pairs_group), bool)
    kept[row] = True
    out = np.zeros((len(pairs_group), 2, 3))
    if not len(row):
        return out, kept
    first_part = np.r_[True, row[1:] != row[:-1]]
    start = np.flatnonzero(first_part)
    pair = np.cumsum(first_part) - 1                 # each part's pair, as a place in ``start``
    a0 = seg[start, 0]                               # measured from the pair's first part, along it
    d0 = seg[start, 1] - a0
    d0 /= np.linalg.norm(d0, axis=1)[:, None]
    a, d = a0[pair], d0[pair]
    t0 = np.einsum("kj,kj->k", seg[:, 0] - a, d)
    t1 = np.einsum("kj,kj->k", seg[:, 1] - a, d)
    lo = np.minimum.reduceat(np.minimum(t0, t1), start)
    hi = np.maximum.reduceat(np.maximum(t0, t1), start)
    r = row[start]
    out[r, 0] = a0 + lo[:, None] * d0
    out[r, 1] = a0 + hi[:, None] * d0
    return out, kept


def pair_segments(origin, n, cutters, face, eps):
    """Where P cutters meet the planes of P faces, clipped to the faces: the plane through
    ``origin`` (P, 3) with unit normal ``n`` (P, 3), the cutters' corners (P, 4, 3) (a triangle
    repeats its last corner: a wall standing on the face, a block's side through it), the
    faces' corners (P, 4, 3). Returns (segments (P, 2, 3), kept (P,) bool): a segment is the
    two farthest apart of the cutter's corners on the plane and its edges' crossings of it,
    clipped to the face with its border widened by ``eps``; kept when the cutter reaches the
    plane and more than ``eps`` of the segment is on the face. Cutters parallel to the face
    are left out by the caller. All pairs at once: pair by pair in a loop this was most of a
    dense mesh's cut."""
    P = len(origin)
    h = np.einsum("pkj,pj->pk", cutters - origin[:, None], n)              # (P, 4) heights
    pts = np.zeros((P, 8, 3))
    valid = np.zeros((P, 8), bool)
    valid[:, :4] = np.abs(h) <= eps                                      # corners on the plane
    pts[:, :4] = cutters
    for i in range(4):                                                   # edges through it
        j = (i + 1) % 4
        hi, hj = h[:, i], h[:, j]
        go = ((hi < -eps) & (hj > eps)) | ((hi > eps) & (hj < -eps))
        with np.errstate(divide="ignore", invalid="ignore"):
            t = hi / (hi - hj)
            pts[:, 4 + i] = cutters[:, i] + t[:, None] * (cutters[:, j] - cutters[:, i])
        valid[:, 4 + i] = go
    pts = pts - np.einsum("pk,pj->pkj", np.einsum("pkj,pj->pk", pts - origin[:, None], n), n)
    d2 = ((pts[:, :, None] - pts[:, None]) ** 2).sum(-1)
    d2 = np.where(valid[:, :, None] & valid[:, None], d2, -1.0).reshape(P, 64)
    best = d2.argmax(axis=1)
    a, b = pts[np.arange(P), best // 8], pts[np.arange(P), best % 8]
    ok = (h.min(axis=1) < eps) & (h.max(axis=1) > -eps) & (valid.sum(axis=1) >= 2) & \
        (np.linalg.norm(b - a, axis=1) > eps) & np.isfinite(n).all(axis=1)
    # clipped to the face, its border widened by eps (a triangle repeats its last corner)
    real = np.concatenate([np.ones((P, 1), bool), np.linalg.norm(np.diff(face, axis=1), axis=2) > 0], 1)
    centre = (face * real[:, :, None]).sum(axis=1) / real.sum(axis=1)[:, None]
    t0, t1 = np.zeros(P), np.ones(P)
    for i in range(4):
        p, q = face[:, i], face[:, (i + 1) % 4]
        m = np.cross(n, q - p)
        L = np.linalg.norm(m, axis=1)
        edge = L > 0
        m = m / np.where(edge, L, 1.0)[:, None]
        m = np.where((np.einsum("pj,pj->p", centre - p, m) < 0)[:, None], -m, m)     # inward
        fa = np.einsum("pj,pj->p", a - p, m) + eps
        fb = np.einsum("pj,pj->p", b - p, m) + eps
        with np.errstate(divide="ignore", invalid="ignore"):
            t = fa / (fa - fb)
        enter = edge & (fa < 0) & (fb >= 0)
        leave = edge & (fa >= 0) & (fb < 0)
        out = edge & (fa < 0) & (fb < 0)
        t0 = np.where(enter, np.maximum(t0, t), t0)
        t1 = np.where(leave, np.minimum(t1, t), t1)
        t1 = np.where(out, -1.0, t1)
    d = b - a
    ok &= (t1 - t0) * np.linalg.norm(d, axis=1) > eps
    return np.stack([a + t0[:, None] * d, a + t1[:, None] * d], axis=1), ok


def split_polygon(poly, a, m, tol):
    """A convex polygon (k, 3) split by the line through ``a`` with in-plane unit normal ``m``:
    (positive side, negative side), each None when the polygon lies on the other side (corners
    within ``tol`` of the line count as on it). The few heights as Python floats (the same
    doubles: NumPy's scalars and reductions cost more than the arithmetic, and a bake's contact
    cut splits tens of thousands of pieces)."""
    h = ((poly - a) @ m).tolist()
    if outside(h, tol, -tol):
        return None
    pos, neg = [], []
    k = len(poly)
    for i in range(k):
        j = (i + 1) % k
        p, hp, hq = poly[i], h[i], h[j]
        if hp >= -tol:
            pos.append(p)
        if hp <= tol:
            neg.append(p)
        if (hp > tol and hq < -tol) or (hp < -tol and hq > tol):
            x = p + (hp / (hp - hq)) * (poly[j] - p)
            pos.append(x)
            neg.append(x)
    return np.array(pos), np.array(neg)


def outside(values, lo, hi) -> bool:
    """``max(values) <= lo or min(values) >= hi`` for a short list of floats (``lo``, ``hi``
    finite), as NumPy's max and min of their array decide it: False where one is NaN (NumPy's
    are NaN then; their sum is too, and only then or with both infinities among them, where
    neither bound holds either)."""
    if max(values) <= lo or min(values) >= hi:
        total = sum(values)
        return total == total
    return False


def row_dots(x, y):
    """(P,) the dot products of rows ``x`` and ``y`` (P, 3), each as ``x[i] @ y[i]`` gives it
    (the same BLAS call per row, so the same bits as a loop of them)."""
    return np.matmul(x[:, None, :], y[:, :, None])[:, 0, 0]


def segment_hits(corners, order, start, group_of, segments, cutter_normals, plane_normals, sizes, tol_rel, eps,
                 chunk=1 << 16):
    """Which elements the contact segments part: the lines of :func:`.contact.cut_along_contacts`,
    S segments at once, each against every element of its group, ``chunk`` pairs at a time.

    ``corners`` (N, 4, 3) the elements' corners; ``order[start[g]:start[g + 1]]`` the elements of
    group g in order; per segment ``segments`` (S, 2, 3) its ends a, b (on its group's plane),
    ``group_of`` (S,) its group, ``cutter_normals`` (S, 3) its cutter's normal and
    ``plane_normals`` (S, 3) its group's; ``sizes`` (N,) each element's size (the square root of
    its area, world units). A segment has direction d, length L and in-plane normal m (the
    cutter's normal's part in the plane); it hits an element whose corners reach along d more
    than the element's tolerance t (``tol_rel`` x its size, at least ``eps``) past a and short
    of b, and lie on both sides of its line or within t of it. A segment whose hit elements all
    lie on one side of it with none across (a line along the face's own border) parts nothing.

    Returns the segments' (d (S, 3), L (S,), m (S, 3)) and the hits (segment (H,), element
    (H,), t (H,)) in segment order, each segment's in its group's order: every value the bit a
    loop over the segments gave (the same BLAS call per dot product, :func:`row_dots`)."""
    S = len(group_of)
    a = segments[:, 0]
    diff = segments[:, 1] - a
    length = np.sqrt(row_dots(diff, diff))
    d = diff / length[:, None]
    m = cutter_normals - row_dots(cutter_normals, plane_normals)[:, None] * plane_normals
    m = m / np.sqrt(row_dots(m, m))[:, None]
    cnt = (start[1:] - start[:-1])[group_of]
    ends = np.cumsum(cnt)
    hits = ([], [], [])
    s0 = 0
    while s0 < S:
        s1 = max(int(np.searchsorted(ends, (ends[s0 - 1] if s0 else 0) + chunk, "right")), s0 + 1)
        c = cnt[s0:s1]
        seg = np.repeat(np.arange(s0, s1), c)
        el = order[np.repeat(start[group_of[s0:s1]], c) + run_positions(c)]
        rel = corners[el] - a[seg][:, None, :]
        ext = np.matmul(rel, d[seg][:, :, None])[..., 0]                    # (P, 4) along the line
        h = np.matmul(rel, m[seg][:, :, None])[..., 0]                      # (P, 4) across it
        tol = np.maximum(tol_rel * sizes[el], eps)
        along = (ext.max(axis=1) > tol) & (ext.min(axis=1) < length[seg] - tol)
        both = (h.max(axis=1) > tol) & (h.min(axis=1) < -tol)
        near = np.abs(h) <= tol[:, None]
        hit = along & (near.any(axis=1) | both)
        side = np.sign(np.where(near, 0.0, h).sum(axis=1))
        # a segment parts its elements when one lies across it, or they lie on both sides
        across = np.bincount(seg - s0, hit & both, s1 - s0) > 0
        code = np.where(np.isnan(side), 3, side + 1).astype(np.int64)
        one = hit & ~both
        seen = np.zeros((s1 - s0, 4), bool)
        seen[seg[one] - s0, code[one]] = True
        keep = (across | (seen.sum(axis=1) >= 2))[seg - s0] & hit
        for out, x in zip(hits, (seg[keep], el[keep], tol[keep])):
            out.append(x)
        s0 = s1
    hits = tuple(np.concatenate(x) if x else np.zeros(0, t) for x, t in zip(hits, (np.int64, np.int64, float)))
    return (d, length, m), hits
