"""The outlines of groups of polygons (an emitter's cells), for Lambert's contour integral over a
whole group at once (:func:`.polygon_ff.group_form_factors`).

:class:`GroupOutline` holds what that needs of the groups and does not depend on the receiving
points: each group's directed boundary edges (an edge shared by two polygons of a group
cancels, :func:`_boundary_edges`), runs of collinear edges merged into one
(:func:`_merge_collinear`: exact for the contour integral, which adds up over the pieces of a
straight edge), and, for groups with many edges, the jagged borders between coplanar groups
straightened (:func:`_straighten`, Douglas-Peucker: the same polyline for both groups, so their
sum is unchanged). Coordinates are the polygons' (the scene's units).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..util.unique import unique_rows

__all__ = ["GroupOutline", "STRAIGHTEN_ABOVE"]

#: A group with more boundary edges than this (after :func:`_merge_collinear`) has its borders
#: with coplanar groups straightened: a cell of a lamp modelled as thousands of triangles had
#: 62-82 edges along jagged triangle paths; the groups of coarse scenes have at most 10.
STRAIGHTEN_ABOVE = 16


def _boundary_edges(polys, groups, coplanar=None, plane_normals=None):
    """Directed boundary edges of each group of polygons: (E, 2, 3) endpoints and (E,) group,
    sorted by group. An edge shared by two polygons of a group (walked both ways) cancels.

    ``coplanar(g, h)``: (n,) bool, whether groups g and h (arrays) lie in one plane; with it the
    border between two coplanar groups, one of which has more than :data:`STRAIGHTEN_ABOVE`
    edges, is straightened (:func:`_straighten`) when that leaves fewer edges (a coarse scene's
    groups have fewer: their outlines are kept exactly, bit for bit); ``plane_normals`` (G, 3)
    the groups' planes."""
    M, K = polys.shape[:2]
    a = polys.reshape(M * K, 3)
    b = np.roll(polys, -1, axis=1).reshape(M * K, 3)
    g = np.repeat(groups, K)
    keep = np.any(a != b, axis=1)
    a, b, g = a[keep], b[keep], g[keep]
    # endpoints as exact coordinates (shared corners are the same vertex, bit for bit)
    pts = np.concatenate([a, b])
    _, ib = unique_rows(pts, return_inverse=True)
    ib = ib.reshape(-1)
    va, vb = ib[:len(a)], ib[len(a):]
    lo, hi = np.minimum(va, vb), np.maximum(va, vb)
    sign = np.where(va < vb, 1, -1)
    key = np.stack([g, lo, hi], axis=1)
    uk, inv = unique_rows(key, return_inverse=True)
    net = np.bincount(inv.reshape(-1), weights=sign, minlength=len(uk))
    first = np.full(len(uk), -1)
    first[inv.reshape(-1)[::-1]] = np.arange(len(inv))[::-1]
    out = np.flatnonzero(net != 0)
    e = first[out]
    fwd = (net[out] > 0) == (sign[e] > 0)
    ea = np.where(fwd[:, None], a[e], b[e])
    eb = np.where(fwd[:, None], b[e], a[e])
    order = np.argsort(uk[out, 0], kind="stable")
    edges, eg = np.stack([ea, eb], axis=1)[order], uk[out, 0][order]
    merged = _merge_collinear(edges, eg)
    if coplanar is None or len(merged[0]) < 2:
        return merged
    up = net[out][order] > 0                                   # walked from lo to hi
    lo, hi = uk[out, 1][order], uk[out, 2][order]
    start, end = np.where(up, lo, hi), np.where(up, hi, lo)
    busy = np.bincount(merged[1], minlength=int(eg.max()) + 1) > STRAIGHTEN_ABOVE
    if not busy.any():
        return merged
    straight = _straighten(edges, eg, start, end, np.abs(net[out][order]) == 1,
                           lambda g, h: (busy[g] | busy[h]) & coplanar(g, h), plane_normals)
    return straight if straight is not None and len(straight[0]) < len(merged[0]) else merged


def _straighten(edges, eg, start, end, single, coplanar, normals):
    """The boundary edges of groups with each border between two coplanar groups (a chain of
    edges one group walks and the other walks back) replaced by a polyline within one of its
    edges' length of it (Douglas-Peucker), the same for both groups, walked both ways: (E', 2,
    3), (E',) merged as :func:`_merge_collinear`, or None when no border is straightened.

    A lamp modelled as thousands of triangles and split into cells has cell borders that follow
    the triangles' jagged paths (hundreds of edges per cell); straightened, a cell has a few
    edges. Each border is replaced in both groups by the same polyline, so the groups' sum (the
    whole region, whose own outline is kept) is unchanged; each group's region moves by at most
    one edge's length across its borders (a sliver of the triangles along it).
    ``start``, ``end`` (E,) vertex ids of the edges; ``single`` (E,) the edge is walked once;
    ``normals`` (G, 3) the groups' planes. A group whose straightened outline would cross
    itself, or enclose an area off by half or more, keeps its borders (and so do its neighbours
    along them): the groups' sum is exact only for outlines that bound their regions."""
    E = len(edges)
    partner = _partners(eg, start, end, single, coplanar)
    chains = _chains(edges, eg, start, end, partner)
    if not chains:
        return None
    # closed borders (an island in a group) and borders nothing shortens are kept as they are
    area = _signed_areas(edges, eg, normals)
    while chains:
        keep = np.ones(E, bool)
        new_e, new_g = [], []
        for g, h, chain, line in chains:
            keep[chain] = keep[partner[chain]] = False
            a, b = line[:-1], line[1:]
            new_e += [np.stack([a, b], axis=1), np.stack([b, a], axis=1)]
            new_g += [np.full(len(a), g), np.full(len(a), h)]
        out_e = np.concatenate([edges[keep]] + new_e)
        out_g = np.concatenate([eg[keep]] + new_g)
        order = np.argsort(out_g, kind="stable")
        out_e, out_g = out_e[order], out_g[order]
        # a group whose straightened outline crosses itself or lost much of its area (a few
        # scattered faces): its borders are kept as they were, on both sides
        touched = np.unique([c[0] for c in chains] + [c[1] for c in chains])
        new_area = _signed_areas(out_e, out_g, normals)
        bad = {g for g in touched if not (abs(new_area[g] - area[g]) <= 0.5 * abs(area[g])
                                          and np.sign(new_area[g]) == np.sign(area[g]))
               or _crosses(out_e[out_g == g], normals[g])}
        if not bad:
            return _merge_collinear(out_e, out_g)
        chains = [c for c in chains if c[0] not in bad and c[1] not in bad]
    return None


def _partners(eg, start, end, single, coplanar):
    """(E,) for each boundary edge the same edge walked back by another, coplanar group (an edge
    in exactly two groups' boundaries, walked once each way), -1 for none."""
    und = np.stack([np.minimum(start, end), np.maximum(start, end)], axis=1)
    _, inv, cnt = unique_rows(und, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    order = np.argsort(inv, kind="stable")
    two = np.flatnonzero(cnt[inv[order]] == 2)
    i, j = order[two[0::2]], order[two[1::2]]
    ok = (eg[i] != eg[j]) & single[i] & single[j] & (start[i] == end[j])
    i, j = i[ok], j[ok]
    if i.size:
        ok = coplanar(eg[i], eg[j])
        i, j = i[ok], j[ok]
    partner = np.full(len(eg), -1)
    partner[i], partner[j] = j, i
    return partner


def _chains(edges, eg, start, end, partner):
    """The borders between two groups that Douglas-Peucker shortens, each once (walked by its
    lower group): a list of (group, other group, its edges (k,), polyline (m, 3)); None where no
    edge is shared."""
    shared = partner >= 0
    mine = np.flatnonzero(shared & (eg < eg[np.maximum(partner, 0)]))  # each border once, from its lower group
    if mine.size == 0:
        return None
    nb = eg[partner[mine]]
    # chains: an edge continues into the edge of the same border starting where it ends
    starts = {}
    for k, h in zip(mine, nb):
        starts.setdefault((eg[k], h, start[k]), []).append(k)
    nxt = {}
    for k, h in zip(mine, nb):
        c = starts.get((eg[k], h, end[k]), [])
        if len(c) == 1:
            nxt[k] = c[0]
    has_prev = set(nxt.values())
    chains = []                                                # (group, other group, its edges, polyline)
    walked = set()
    for k, h in zip(mine, nb):
        if k in has_prev:
            continue
        chain = [k]
        walked.add(k)
        while chain[-1] in nxt and nxt[chain[-1]] not in walked:   # (a border that runs into a
            chain.append(nxt[chain[-1]])                            # loop stops where it closes)
            walked.add(chain[-1])
        pts = np.concatenate([edges[chain, 0], edges[chain[-1:], 1]])
        tol = np.linalg.norm(edges[chain, 1] - edges[chain, 0], axis=1).max()
        idx = _douglas_peucker(pts, tol)
        if len(idx) < len(pts):
            chains.append((eg[k], h, np.array(chain), pts[idx]))
    return chains


def _signed_areas(edges, eg, normals):
    """(G,) the area each group's directed boundary ``edges`` (E, 2, 3) encloses, signed along
    its plane's normal (``normals`` (G, 3)): positive for a counter-clockwise outline."""
    c = np.cross(edges[:, 0], edges[:, 1])
    return np.bincount(eg, weights=np.einsum("ej,ej->e", c, normals[eg]), minlength=len(normals)) / 2


def _crosses(edges, normal):
    """Whether two of the segments ``edges`` (E, 2, 3) in a plane with ``normal`` meet anywhere
    but at an endpoint they share (crossing, or one touching the other: a straightened border
    through a vertex of the grid)."""
    axis = int(np.abs(normal).argmax())
    p = np.delete(edges, axis, axis=2)                                  # (E, 2, 2)
    a, b = p[:, None, 0], p[:, None, 1]
    c, d = p[None, :, 0], p[None, :, 1]
    eps = 1e-12 * float(np.ptp(p.reshape(-1, 2), axis=0).max()) ** 2

    def orient(u, v, w):
        o = (v[..., 0] - u[..., 0]) * (w[..., 1] - u[..., 1]) - (v[..., 1] - u[..., 1]) * (w[..., 0] - u[..., 0])
        return np.where(np.abs(o) <= eps, 0.0, np.sign(o))

    o1, o2 = orient(a, b, c), orient(a, b, d)
    o3, o4 = orient(c, d, a), orient(c, d, b)
    meet = (o1 * o2 <= 0) & (o3 * o4 <= 0)
    # all four on one line: they meet where their spans overlap
    line = (o1 == 0) & (o2 == 0)
    lo1, hi1 = np.minimum(a, b), np.maximum(a, b)
    lo2, hi2 = np.minimum(c, d), np.maximum(c, d)
    overlap = np.all(np.minimum(hi1, hi2) - np.maximum(lo1, lo2) > 1e-6 * np.sqrt(eps), axis=-1)
    meet &= ~line | overlap
    share = (np.all(a == c, -1) | np.all(a == d, -1) | np.all(b == c, -1) | np.all(b == d, -1))
    meet &= ~share | (line & overlap)
    np.fill_diagonal(meet, False)
    return bool(meet.any())


def _douglas_peucker(pts, tol):
    """Indices (ascending, first and last always) of the points of the polyline ``pts`` (n, 3)
    kept by Douglas-Peucker: every point dropped is within ``tol`` of the segment that spans it."""
    keep = np.zeros(len(pts), bool)
    keep[[0, -1]] = True
    stack = [(0, len(pts) - 1)]
    while stack:
        s, e = stack.pop()
        if e - s < 2:
            continue
        seg = pts[e] - pts[s]
        rel = pts[s + 1:e] - pts[s]
        L = float(seg @ seg)
        if L > 0:
            t = np.clip(rel @ seg / L, 0.0, 1.0)
            d = np.linalg.norm(rel - t[:, None] * seg, axis=1)
        else:
            d = np.linalg.norm(rel, axis=1)
        m = int(d.argmax())
        if d[m] > tol or L == 0:
            keep[s + 1 + m] = True
            stack += [(s, s + 1 + m), (s + 1 + m, e)]
    return np.flatnonzero(keep)


def _merge_collinear(edges, groups, tol=1e-9):
    """The same boundary with each run of collinear edges (a modeller's grid along a lamp's
    side) as one edge: (E', 2, 3), (E',). Exact for Lambert's contour integral, which adds up
    over the pieces of a straight edge; an edge whose end starts no single next edge is kept."""
    E = len(edges)
    if E < 2:
        return edges, groups
    # each end point as an id (group and the coordinates' exact bits): edge i runs on into the
    # edge that starts where it ends, when exactly one does (all at once, not a Python loop with
    # a cross product per edge)
    g = np.asarray(groups, np.int64)
    ends = np.concatenate([edges[:, 0], edges[:, 1]])
    bits = np.ascontiguousarray(ends, dtype=np.float64).view(np.int64).reshape(-1, 3)
    pid = unique_rows(np.column_stack([np.tile(g, 2), bits]), return_inverse=True)[1]
    start, end = pid[:E], pid[E:]
    order = np.argsort(start, kind="stable")
    lo = np.searchsorted(start[order], end, side="left")
    hi = np.searchsorted(start[order], end, side="right")
    d = edges[:, 1] - edges[:, 0]
    n = np.linalg.norm(d, axis=1, keepdims=True)
    u = d / np.where(n > 0, n, 1.0)
    nxt = np.full(E, -1)
    one = np.flatnonzero(hi - lo == 1)
    c = order[lo[one]]
    straight = (np.linalg.norm(np.cross(u[one], u[c]), axis=1) < tol) & ((u[one] * u[c]).sum(axis=1) > 0)
    nxt[one[straight]] = c[straight]
    has_prev = np.zeros(E, bool)
    has_prev[nxt[nxt >= 0]] = True
    seen = [False] * E
    nxt = nxt.tolist()
    first, last = [], []
    for i in np.flatnonzero(~has_prev).tolist() + list(range(E)):
        if seen[i]:
            continue
        j = i
        seen[j] = True
        while nxt[j] >= 0 and not seen[nxt[j]]:
            j = nxt[j]
            seen[j] = True
        first.append(i)
        last.append(j)
    return np.stack([edges[first, 0], edges[last, 1]], axis=1), np.asarray(groups)[first]


@dataclass(frozen=True)
class GroupOutline:
    """What :func:`.polygon_ff.group_form_factors` needs of groups of polygons that does not
    depend on the points: computed once per emitter set, not per chunk of points.

    The edges bound each group's region for Lambert's contour integral, not exactly its
    polygons: where a lamp modelled as thousands of triangles is split into cells, the borders
    between coplanar cells (jagged triangle paths, 62-82 edges per cell) are straightened, the
    same polyline for both cells (:func:`_straighten`), so the sum over the groups is exactly
    the whole lamp's and each group's region is its polygons give or take a sliver of
    triangles along its borders (its shadow rays still go to its own polygons).

    ``polys`` (M, K, 3), ``groups`` (M,) int64 in 0..G-1, ``normals`` (M, 3) float64;
    ``edges`` (E, 2, 3) the groups' directed boundary edges and ``edge_group`` (E,)
    (:func:`_boundary_edges`, straightened), sorted by group; per group ``edge_start``, ``edge_count`` (G,)
    its run of edges, ``rep`` (G,) a polygon of it, ``planar`` (G,) bool
    (one plane for all its polygons), ``count`` (G,) its polygons; per polygon ``centre``
    (M, 3) and ``size`` (M,) its bounding-box diagonal.
    """

    polys: np.ndarray
    groups: np.ndarray
    normals: np.ndarray
    edges: np.ndarray
    edge_group: np.ndarray
    edge_start: np.ndarray
    edge_count: np.ndarray
    rep: np.ndarray
    planar: np.ndarray
    count: np.ndarray
    centre: np.ndarray
    size: np.ndarray

    @property
    def cones(self):
        """Per group (G,): the largest angle (radians) between a polygon's normal and the
        representative's, the radius of a ball about ``mid`` (G, 3) holding every polygon's
        centre, and ``mid`` (the mean of the centres); computed once."""
        if getattr(self, "_cones", None) is None:
            G = len(self.count)
            ref = self.normals[self.rep][self.groups]
            cos = np.clip(np.einsum("mj,mj->m", self.normals, ref), -1.0, 1.0)
            cone = np.zeros(G)
            np.maximum.at(cone, self.groups, np.arccos(cos))
            mid = np.stack([np.bincount(self.groups, weights=self.centre[:, c], minlength=G) for c in range(3)], 1) \
                / np.maximum(self.count, 1)[:, None]
            ball = np.zeros(G)
            np.maximum.at(ball, self.groups, np.linalg.norm(self.centre - mid[self.groups], axis=1))
            object.__setattr__(self, "_cones", (cone, ball * (1 + 1e-9) + 1e-300, mid))
        return self._cones

    @property
    def edge_columns(self):
        """``edges`` by component: ((x, y, z) of the edges' starts, (x, y, z) of their ends),
        contiguous (E,) arrays; computed once."""
        if getattr(self, "_columns", None) is None:
            cols = tuple(tuple(np.ascontiguousarray(self.edges[:, k, c]) for c in range(3)) for k in range(2))
            object.__setattr__(self, "_columns", cols)
        return self._columns

    @classmethod
    def of(cls, polys, groups, poly_normals) -> "GroupOutline":
        polys = np.asarray(polys, dtype=np.float64)
        groups = np.asarray(groups, dtype=np.int64)
        pn = np.asarray(poly_normals, dtype=np.float64)
        G = int(groups.max()) + 1
        centre = polys.mean(axis=1)
        size = np.maximum(np.linalg.norm(polys.max(axis=1) - polys.min(axis=1), axis=1), 1e-300)
        count = np.bincount(groups, minlength=G)
        first = np.searchsorted(np.sort(groups), np.arange(G))
        rep = np.argsort(groups, kind="stable")[first]                    # a polygon of each group
        planar = np.ones(G, bool)
        off = np.abs(np.einsum("mj,mj->m", centre - centre[rep][groups], pn[rep][groups]))
        bent = (np.abs(pn - pn[rep][groups]).max(axis=1) > 1e-9) | (off > 1e-9 * size)
        planar[groups[bent]] = False

        def coplanar(g, h):
            """Whether groups g and h (arrays) lie in one plane, as :attr:`planar` tests a group."""
            a, b = rep[g], rep[h]
            gap = np.abs(np.einsum("nj,nj->n", centre[b] - centre[a], pn[a]))
            return planar[g] & planar[h] & (np.abs(pn[a] - pn[b]).max(axis=1) <= 1e-9) \
                & (gap <= 1e-9 * np.maximum(size[a], size[b]))

        edges, eg = _boundary_edges(polys, groups, coplanar, pn[rep])
        order = np.argsort(eg, kind="stable")
        edges, eg = edges[order], eg[order]
        edge_count = np.bincount(eg, minlength=G)
        return cls(polys, groups, pn, edges, eg, np.cumsum(edge_count) - edge_count, edge_count, rep,
                   planar, count, centre, size)
