"""What the hemi-cube draws of grouped pieces: a planar cluster as its outline, not its pieces.

A wall modelled as 10,000 triangles and grouped into tens of clusters (:mod:`clusters`) covers
the same pixels whether its triangles are drawn or each cluster's outline is: the union of a
planar cluster's pieces *is* the polygon its boundary edges bound. So the hemi-cube's cost per
receiver follows the clusters' outlines, not the modelling:

* a cluster whose pieces lie in one plane, whose boundary (the directed piece edges whose
  reverse is not in the cluster) is one simple loop, is drawn as that loop triangulated
  (ear clipping, in its plane);
* vertices along a straight run of outline are left out where every outline through them agrees:
  a vertex is dropped when exactly two outline edges meet there (counted over all clusters, the
  vertices welded by position, so two clusters or two objects sharing the border drop it
  alike), the three points are collinear, and no piece drawn as-is uses it. Shared borders stay
  the same edges on both sides, so the drawing stays watertight (:mod:`hemicube`);
* everything else (curved clusters, clusters with holes or pinched outlines, single pieces,
  clusters whose outline cannot be clipped into ears) is drawn piece by piece, as before.

Coverage is exact (the same region, bounded by the same vertices); the depth of an outline
triangle is its cluster's plane (a representative piece's), within rounding of each piece's.
Which fragment wins a depth tie between coplanar surfaces may change; F does not otherwise.

Units: world units.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..mesh.clusters import Clusters
from ..mesh.patches import PatchSet, compact
from ..util.unique import run_positions, unique_ints, unique_rows

__all__ = ["DrawSet", "draw_set"]

#: Pieces of a cluster are coplanar when their normals differ by at most this (per component)
#: and their centres lie this fraction of the scene's diagonal off the representative's plane.
PLANAR_TOL = 1e-7
#: A vertex is on the straight line through its two outline neighbours when it is this fraction
#: of the scene's diagonal off it.
COLLINEAR_TOL = 1e-10


@dataclass
class DrawSet:
    """Convex polygons the hemi-cube draws, each with the cluster it is seen as.

    verts:   (V, 3) float64 positions, welded (one per distinct position).
    polys:   (M, 4) int64 indices into ``verts``; a triangle has -1 in column 3.
    normals: (M, 3) float64 unit normals; centers: (M, 3) float64 a point of each plane.
    item_of: (M,) int64 cluster of each polygon.
    outlined: (K,) bool clusters drawn as their outline.
    """

    verts: np.ndarray
    polys: np.ndarray
    normals: np.ndarray
    centers: np.ndarray
    item_of: np.ndarray
    outlined: np.ndarray

    def __len__(self) -> int:
        return int(len(self.polys))


def draw_set(pieces: PatchSet, clusters: Clusters) -> DrawSet:
    """The polygons that draw ``pieces`` grouped by ``clusters`` (see the module docstring)."""
    verts = np.asarray(pieces.verts, dtype=np.float64)
    polys = np.asarray(pieces.polys, dtype=np.int64)
    of = np.asarray(clusters.of, dtype=np.int64)
    K, P = len(clusters), len(pieces)
    diag = float(np.linalg.norm(verts.max(axis=0) - verts.min(axis=0))) or 1.0
    upos, weld = unique_rows(verts, return_inverse=True)
    weld = weld.reshape(-1)
    wpolys = np.where(polys < 0, -1, weld[np.maximum(polys, 0)])

    # a representative piece per cluster, and the clusters whose pieces share its plane
    order = np.argsort(of, kind="stable")
    starts = np.searchsorted(of[order], np.arange(K))
    rep = order[np.minimum(starts, P - 1)]
    n, c = np.asarray(pieces.normals), np.asarray(pieces.centers)
    bent = (np.abs(n - n[rep][of]).max(axis=1) > PLANAR_TOL) \
        | (np.abs(np.einsum("ij,ij->i", c - c[rep][of], n[rep][of])) > PLANAR_TOL * diag)
    ok = np.bincount(of, minlength=K) > 1
    areas = np.bincount(of, weights=np.asarray(pieces.areas, np.float64), minlength=K)
    ok[of[bent]] = False

    # every loop of the outlined clusters end to end: its vertices, its length, its cluster
    flat, lens, l_cl = _outline_loops(wpolys, of, ok, upos, n[rep])
    ok &= np.isin(np.arange(K), l_cl)
    loop_of = np.repeat(np.arange(lens.size), lens)
    succ = np.arange(1, flat.size + 1)                             # the next vertex in its loop
    succ[np.cumsum(lens) - 1] = np.cumsum(lens) - lens
    while True:
        # vertices every outline agrees to leave out: none that a piece drawn as-is uses
        used = wpolys[~ok[of]]
        pinned = np.zeros(len(upos), bool)
        pinned[used[used >= 0]] = True
        live = ok[l_cl][loop_of]
        drop = _droppable(upos, flat[live], flat[succ[live]], pinned, diag)
        keep = live & ~drop[flat]
        tris, tri_loop, bad = _ear_clip_loops(upos, flat[keep], np.bincount(loop_of[keep], minlength=lens.size),
                                              n[rep[l_cl]])
        bad |= ~ok[l_cl]
        failed = np.zeros(K, bool)
        failed[l_cl[bad]] = True
        ks = np.flatnonzero(ok & ~failed)
        kt = l_cl[tri_loop]
        good = ~failed[kt]
        tris, kt = tris[good], kt[good]
        wrong = _area_differs(upos, tris, kt, ks, areas[ks])
        failed = np.flatnonzero(failed & ok).tolist() + ks[wrong].tolist()
        if not failed:
            break
        ok[failed] = False            # drawn as pieces: decide the drop again around them
    as_is = np.flatnonzero(~ok[of])
    m_polys = np.concatenate([wpolys[as_is], np.concatenate([tris, np.full((len(tris), 1), -1)], axis=1)])
    item_of = np.concatenate([of[as_is], kt])
    normals = np.concatenate([n[as_is], n[rep][kt]])
    centers = np.concatenate([c[as_is], c[rep][kt]])
    drawn, m_polys = compact(upos, m_polys)                # only the vertices drawn
    return DrawSet(drawn, m_polys, normals, centers, item_of, ok)


def _outline_loops(wpolys, of, ok, pos, normals) -> tuple:
    """The loops of clusters ``ok`` whose boundary is loops without holes (the others are left
    out: a hole, an edge used twice the same way), each the welded vertex ids around one part of
    its cluster's boundary: (their vertices end to end, (L,) lengths, (L,) cluster of each),
    by cluster.

    Where the boundary touches itself at a vertex (two triangles meeting at a corner only), each
    edge arriving there goes on with the first edge leaving it clockwise in the cluster's plane
    (counter-clockwise from the outside): the loops part there, each simple. ``normals`` (K, 3)
    is each cluster's normal (the pieces wind counter-clockwise about it)."""
    found = _boundary_edges(wpolys, of, ok)
    if found is None:
        return (np.zeros(0, np.int64),) * 3
    a, b, cl, broken = found
    # each cluster's edges a run; a run of fewer than 3 (s = e = 0: no boundary edge at all, a
    # face doubled) or with a broken edge has no outline
    first = np.r_[0, np.flatnonzero(np.diff(cl)) + 1]
    run = np.repeat(np.arange(first.size), np.diff(np.r_[first, cl.size]))
    usable = (np.diff(np.r_[first, cl.size]) >= 3) & ~np.isin(cl[first] if cl.size else first, list(broken))
    # pinched (a vertex left twice): each through _loops; the others are cycles of one next edge
    twice = np.zeros(first.size, bool)
    twice[run[1:][(a[1:] == a[:-1]) & (cl[1:] == cl[:-1])]] = True
    V = np.int64(max(len(pos), 1))
    ek = cl * V + a                                                     # ascending
    want = cl * V + b
    nxt = np.minimum(np.searchsorted(ek, want), max(ek.size - 1, 0))
    closed = ek[nxt] == want if ek.size else np.zeros(0, bool)
    into = np.bincount(nxt[closed], minlength=ek.size)
    fails = np.zeros(first.size, bool)
    fails[run[~closed | (into != 1)]] = True
    cyc = usable & ~twice & ~fails
    lv, ll, lc = _cycles(np.flatnonzero(cyc[run]), nxt, a, cl)
    parts = [(lv, ll, lc)]
    stop = np.r_[first[1:], cl.size]
    for r in np.flatnonzero(usable & twice):
        s_, e_ = first[r], stop[r]
        k_ = int(cl[s_])
        found = _loops(a[s_:e_].tolist(), b[s_:e_].tolist(), pos, normals[k_])
        if found is not None:
            parts.append((np.array([v for L in found for v in L], dtype=np.int64),
                          np.array([len(L) for L in found], dtype=np.int64), np.full(len(found), k_, np.int64)))
    flat = np.concatenate([q[0] for q in parts])
    lens = np.concatenate([q[1] for q in parts])
    l_cl = np.concatenate([q[2] for q in parts])
    o = np.argsort(l_cl, kind="stable")                   # clusters ascending, each's loops in order
    start = np.cumsum(lens) - lens
    at = np.repeat(start[o], lens[o]) + run_positions(lens[o])
    return flat[at], lens[o], l_cl[o]


def _boundary_edges(wpolys, of, ok):
    """The boundary edges of the clusters ``ok`` (``wpolys`` the pieces' welded corners, ``of``
    their clusters): (a, b, cluster), each an edge only one piece of its cluster has, directed as
    that piece winds, sorted by cluster then a; and the set of clusters with a broken edge (used
    more than twice, or twice the same way). None when no cluster is ``ok``."""
    sel = np.flatnonzero(ok[of])
    if not sel.size:
        return None
    p = wpolys[sel]
    k = np.where(p[:, 3] < 0, 3, 4)
    nxt = np.where(np.arange(4)[None, :] + 1 < k[:, None], np.roll(p, -1, axis=1), p[:, :1])
    live = np.arange(4)[None, :] < k[:, None]
    a, b = p[live], nxt[live]
    cl = np.repeat(of[sel], k)
    keep = a != b
    a, b, cl = a[keep], b[keep], cl[keep]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = np.stack([cl, lo, hi], axis=1)
    _, inv, cnt = unique_rows(key, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    fwd = np.bincount(inv, weights=(a < b).astype(np.float64), minlength=cnt.size)
    bad = (cnt > 2) | ((cnt == 2) & (fwd != 1))
    broken = set(np.unique(cl[bad[inv]]).tolist())
    edge = cnt[inv] == 1
    a, b, cl = a[edge], b[edge], cl[edge]
    o = np.lexsort((a, cl))
    return a[o], b[o], cl[o], broken


def _cycles(edges, nxt, a, cl):
    """The loops of ``edges`` (ids into ``a``, ``cl``: whole clusters whose every edge has one
    next edge ``nxt`` and one before it): each loop from its lowest edge (the lowest vertex of
    its cluster's loop: edges by cluster, then ``a``), the loops by that edge, as :func:`_loops`
    walks them. Returns (vertices end to end, (L,) lengths, (L,) cluster)."""
    if not edges.size:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
    pos = np.full(len(a), -1, np.int64)
    pos[edges] = np.arange(edges.size)
    nx = pos[nxt[edges]]                          # within ``edges``
    # the lowest edge of each loop, and how far each edge is from the loop's last one: doubling
    low, jump = np.arange(edges.size), nx.copy()
    n = 1
    while n < edges.size:
        low = np.minimum(low, low[jump])
        jump = jump[jump]
        n *= 2
    last = nx == low                              # the edge back to the loop's start
    dist = np.where(last, 0, 1)
    step = np.where(last, np.arange(edges.size), nx)
    n = 1
    while n < edges.size:
        dist = dist + dist[step]
        step = step[step]
        n *= 2
    length = dist[low] + 1
    order = np.lexsort((length - 1 - dist, low))     # by loop (its lowest edge), then along it
    heads = low[order][np.r_[True, low[order][1:] != low[order][:-1]]]
    return a[edges[order]], length[heads], cl[edges[heads]]


def _loops(a, b, pos, normal):
    """Directed boundary edges a[i] -> b[i] of one cluster cut into loops (lists of vertex ids),
    or None when they do not close."""
    out = {}
    for x, y in zip(a, b):
        out.setdefault(x, []).append(y)
    pinched = any(len(v) > 1 for v in out.values())
    if pinched:
        ax = int(np.argmax(np.abs(normal)))
        i, j = [(1, 2), (2, 0), (0, 1)][ax]
        sgn = 1.0 if normal[ax] > 0 else -1.0

        def angle(frm, to):
            d = pos[to] - pos[frm]
            return float(np.arctan2(sgn * d[j], d[i]))
    used = set()
    loops = []
    for x0, y0 in zip(a, b):
        if (x0, y0) in used:
            continue
        loop, x, y = [x0], x0, y0
        used.add((x0, y0))
        while y != x0:
            if len(loop) > len(a):
                return None
            nxt = [z for z in out.get(y, ()) if (y, z) not in used]
            if not nxt:
                return None
            if len(nxt) > 1 or len(out[y]) > 1:
                if not pinched:
                    return None
                back = angle(y, x)
                # first edge leaving y clockwise from the way back (interior on the left)
                nxt = [min(out[y], key=lambda z: (back - angle(y, z)) % (2 * np.pi) or 2 * np.pi)]
                if (y, nxt[0]) in used:
                    return None
            loop.append(y)
            x, y = y, nxt[0]
            used.add((x, y))
        loops.append(loop)
    return loops


def _droppable(pos, a, b, pinned, diag) -> np.ndarray:
    """(V,) bool welded vertices every outline may leave out: two outline edges (``a`` -> ``b``,
    over all loops, undirected) meet there, collinear, and no piece drawn as-is uses the vertex."""
    drop = np.zeros(len(pos), bool)
    if not a.size:
        return drop
    und = unique_rows(np.stack([np.minimum(a, b), np.maximum(a, b)], axis=1))
    ends = und.ravel()
    deg = np.bincount(ends, minlength=len(pos))
    cand = np.flatnonzero((deg == 2) & ~pinned)
    if not cand.size:
        return drop
    # the two neighbours of each candidate
    other = np.concatenate([und[:, 1], und[:, 0]])
    at = np.concatenate([und[:, 0], und[:, 1]])
    o = np.argsort(at, kind="stable")
    at, other = at[o], other[o]
    first = np.searchsorted(at, cand)
    u, w = other[first], other[first + 1]
    x, pu, pw = pos[cand], pos[u], pos[w]
    d = pw - pu
    L2 = np.einsum("ij,ij->i", d, d)
    off = np.linalg.norm(np.cross(x - pu, d), axis=1) / np.sqrt(np.maximum(L2, 1e-300))
    t = np.einsum("ij,ij->i", x - pu, d) / np.maximum(L2, 1e-300)
    drop[cand[(off <= COLLINEAR_TOL * diag) & (t > 0) & (t < 1)]] = True
    return drop


def _area_differs(pos, tris, kt, ks, areas, tol=1e-9) -> np.ndarray:
    """(K,) bool: where the triangles ``tris`` (T, 3) of clusters ``ks`` (K,) (``kt`` (T,) the
    cluster of each, ascending) do not cover its pieces' area ``areas`` (K,) (to ``tol``
    relative): a loop that is a hole, or loops that overlap. Every cluster's triangles at once,
    their areas summed a row per cluster of clusters with as many triangles (the sums of the
    cluster-by-cluster check, bit for bit: NumPy sums a row of a 2-D array as it sums the row
    alone; a dense level's 30,000 clusters took 4 s in tiny NumPy calls)."""
    K = len(ks)
    out = np.zeros(K, bool)
    if not K:
        return out
    count = np.bincount(np.searchsorted(ks, kt), minlength=K)
    p = pos[tris]
    norms = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    first = np.cumsum(count) - count
    got = np.empty(K)
    for T in np.unique(count):
        k = np.flatnonzero(count == T)
        got[k] = 0.5 * norms[first[k, None] + np.arange(T)[None]].sum(axis=1)
    return np.abs(got - areas) > tol * areas


def _ear_clip_loops(pos, flat, count, normals):
    """Every loop's triangles (:func:`_ear_clip`): the loops end to end, ``flat`` their vertex ids,
    ``count`` (L,) their lengths, ``normals`` (L, 3) their planes. Returns (T, 3) int64
    triangles, (T,) the loop of each (ascending, each loop's in :func:`_ear_clip`'s order), and
    (L,) bool the loops that cannot be clipped (or have fewer than 3 vertices).

    Where :func:`_ear_clip` takes the fan from a loop's last vertex (every step an ear: a convex
    outline, the usual case), the same tests decide it here for all loops of one length at once,
    the same numbers compared the same way (:func:`_fan`); the others go through :func:`_ear_clip`."""
    start = np.cumsum(count) - count
    bad = count < 3
    parts, owners = [], []
    slow = np.flatnonzero((count > _FAN_MAX) & ~bad).tolist()
    for m in np.unique(count[(count >= 3) & (count <= _FAN_MAX)]):
        rows = np.flatnonzero(count == m)
        for sel in np.array_split(rows, -(-rows.size * m * m // (1 << 20))):
            t, tl, none, rest = _fan(pos, flat[start[sel, None] + np.arange(m)], normals[sel])
            bad[sel[none]] = True
            parts.append(t)
            owners.append(sel[tl])
            slow += sel[rest].tolist()
    for l in slow:
        t = _ear_clip(pos, flat[start[l]:start[l] + count[l]], normals[l])
        if t is None:
            bad[l] = True
        else:
            parts.append(t)
            owners.append(np.full(len(t), l, np.int64))
    if not parts:
        return np.zeros((0, 3), np.int64), np.zeros(0, np.int64), bad
    tris, tri_loop = np.concatenate(parts), np.concatenate(owners)
    o = np.argsort(tri_loop, kind="stable")
    return tris[o], tri_loop[o], bad


_FAN_MAX = 48    # loops of up to so many vertices: :func:`_fan` first


def _fan(pos, ids, normals):
    """:func:`_ear_clip` for the loops ``ids`` (n, m) whose every step is an ear: it clips the fan
    from the last vertex, (m-1, j, j+1) for j < m - 3, then (m-3, m-2, m-1). Returns their
    triangles (T, 3), the row of each (T,), the rows :func:`_ear_clip` gives None for, and the
    rows whose clipping is not the fan (left to :func:`_ear_clip`)."""
    n, m = ids.shape
    ax = np.argmax(np.abs(normals), axis=1)
    pts = pos[ids]                                                    # (n, m, 3)
    x = np.take_along_axis(pts, np.array([1, 2, 0])[ax][:, None, None], axis=2)[..., 0]
    y = np.take_along_axis(pts, np.array([2, 0, 1])[ax][:, None, None], axis=2)[..., 0]
    xn, yn = np.roll(x, -1, axis=1), np.roll(y, -1, axis=1)
    area2 = np.cumsum(x * yn - xn * y, axis=1)[:, -1]       # Python's sum: in order, one by one
    s = np.where(area2 > 0, 1.0, -1.0)[:, None]
    r = np.arange(n)[:, None]

    def cross(p, q, t):        # (n, k) positions in each row, as _ear_clip's cross
        xp, yp = x[r, p], y[r, p]
        return s * ((x[r, q] - xp) * (y[r, t] - yp) - (y[r, q] - yp) * (x[r, t] - xp))

    fan = np.ones(n, bool)
    if m > 3:
        q = np.broadcast_to(np.arange(m - 3), (n, m - 3))
        p = np.full((n, m - 3), m - 1)
        fan = (cross(p, q, q + 1) > 0).all(axis=1)
        # at step j the other vertices j + 2 .. m - 2: none inside the ear, its border included
        # (those at the place of one of its corners left out)
        tt = np.broadcast_to(np.arange(m), (n, m - 3, m)).reshape(n, -1)
        pj, qj = np.repeat(p, m, axis=1), np.repeat(q, m, axis=1)
        rj = qj + 1
        other = (tt >= qj + 2) & (tt <= m - 2)
        for c in (pj, qj, rj):
            other &= ~((x[r, tt] == x[r, c]) & (y[r, tt] == y[r, c]))
        inside = (cross(pj, qj, tt) >= 0) & (cross(qj, rj, tt) >= 0) & (cross(rj, pj, tt) >= 0)
        fan &= ~(other & inside).any(axis=1)
    last = cross(np.full((n, 1), m - 3), np.full((n, 1), m - 2), np.full((n, 1), m - 1))[:, 0]
    none = (area2 == 0) | (fan & (last < 0))
    fan &= ~none
    rows = np.flatnonzero(fan)
    tail = rows[last[rows] > 0]
    k = np.repeat(rows, m - 3)
    j = np.tile(np.arange(m - 3), rows.size)
    tri = np.concatenate([np.stack([ids[k, m - 1], ids[k, j], ids[k, j + 1]], axis=1), ids[tail][:, m - 3:]])
    row = np.concatenate([k, tail])
    order = np.argsort(row, kind="stable")
    return tri[order], row[order], none, np.flatnonzero(~fan & ~none)


def _ear_clip(pos, loop, normal):
    """(T, 3) int64 triangles of the simple polygon ``loop`` (welded vertex ids) in the plane of
    ``normal``; None when no ear can be clipped (a polygon that is not simple in its plane).

    An ear is a convex corner whose triangle holds no other vertex, on its border included (a
    vertex on the cut would leave a T-junction inside the cluster)."""
    ax = int(np.argmax(np.abs(normal)))
    i, j = [(1, 2), (2, 0), (0, 1)][ax]
    pts = pos[np.asarray(loop)]
    x, y = pts[:, i].tolist(), pts[:, j].tolist()
    m = len(loop)
    area2 = sum(x[k] * y[(k + 1) % m] - x[(k + 1) % m] * y[k] for k in range(m))
    if area2 == 0:
        return None
    s = 1.0 if area2 > 0 else -1.0
    idx = list(range(m))
    out = []

    def cross(p, q, r):
        return s * ((x[q] - x[p]) * (y[r] - y[p]) - (y[q] - y[p]) * (x[r] - x[p]))

    guard = 0
    k = 0
    while len(idx) > 3:
        if guard > len(idx):
            return None
        n_ = len(idx)
        p, q, r = idx[(k - 1) % n_], idx[k % n_], idx[(k + 1) % n_]
        ear = cross(p, q, r) > 0
        if ear:
            for t in idx:
                if t in (p, q, r) or (x[t], y[t]) in ((x[p], y[p]), (x[q], y[q]), (x[r], y[r])):
                    continue
                if cross(p, q, t) >= 0 and cross(q, r, t) >= 0 and cross(r, p, t) >= 0:
                    ear = False
                    break
        if ear:
            out.append((loop[p], loop[q], loop[r]))
            idx.pop(k % n_)
            guard = 0
            k = k % len(idx)
        else:
            guard += 1
            k = (k + 1) % n_
    p, q, r = idx
    if cross(p, q, r) > 0:
        out.append((loop[p], loop[q], loop[r]))
    elif cross(p, q, r) < 0:
        return None
    return np.asarray(out, dtype=np.int64).reshape(-1, 3)


def plane_outlines(patches: PatchSet) -> PatchSet:
    """The same surfaces as ``patches`` in fewer triangles, for shadow rays (which ask whether
    something is in the way, not what): connected patches in one plane (welded by position) are
    one region, drawn as its outline triangulated like a cluster (:func:`draw_set`); a region
    with a hole, or a patch alone, stays as it is. Only the geometry is meaningful in the
    result (reflectivity and emission 0, owner and source face -1)."""
    from ..mesh.clusters import connected_components, make_clusters

    P = len(patches)
    verts = np.asarray(patches.verts, dtype=np.float64)
    if P < 2:
        return patches
    diag = float(np.linalg.norm(verts.max(axis=0) - verts.min(axis=0))) or 1.0
    n = np.asarray(patches.normals, dtype=np.float64)
    d = np.einsum("ij,ij->i", n, np.asarray(patches.centers)) / diag
    key = unique_rows(np.round(np.column_stack([n, d]), 7) + 0.0, return_inverse=True)[1].reshape(-1)
    key = np.where(np.all(np.isfinite(n), axis=1), key, -1 - np.arange(P))
    weld = unique_rows(verts, return_inverse=True)[1].reshape(-1)
    polys = np.asarray(patches.polys)
    wpolys = np.where(polys < 0, -1, weld[np.maximum(polys, 0)])
    of = unique_ints(connected_components(key, wpolys), return_inverse=True)[1].reshape(-1).astype(np.int64)
    if of.max() + 1 == P:
        return patches
    d_set = draw_set(patches, make_clusters(patches, of))
    V = d_set.verts
    c = np.where(d_set.polys < 0, d_set.polys[:, 2:3], d_set.polys)
    corners = V[c]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 2] - corners[:, 0], corners[:, 1] - corners[:, 0])
                                + np.cross(corners[:, 3] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    M = len(d_set)
    return PatchSet(V, d_set.polys, corners.mean(axis=1), d_set.normals, area, np.zeros((M, 3)),
                    np.zeros((M, 3)), np.full(M, -1, np.int32), np.full(M, -1, np.int32), [])
