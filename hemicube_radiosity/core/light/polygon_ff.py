"""Unoccluded form factors from differential areas to polygons and groups of polygons, in closed
form (Lambert's contour integral), for the direct light of emitters and lamps.

* :func:`polygon_form_factor` (N,): differential area -> convex polygon, over the part above the
  receiver's horizon; :func:`distant_form_factor` the same where every receiver sees the polygon
  at the same offsets (the sun's disk), in closed form where it is wholly above the horizon.
* :func:`polygon_form_factors` (P, M): every point to every polygon, optionally one-sided;
  :func:`front_polygon_sum` (P,) their sum over the polygons in front of each point.
* :func:`group_form_factors` (P, G): every point to every group of front-facing polygons, by the
  group's outline (:class:`.outline.GroupOutline`) where that stands for it, face by face where
  not.

Form factors are dimensionless; points in the scene's units, normals unit length.
"""
from __future__ import annotations

import numpy as np

from ..util.geometry import cross3
from ..util.unique import run_positions
from .outline import GroupOutline

__all__ = ["polygon_form_factor", "distant_form_factor", "polygon_form_factors", "front_polygon_sum",
           "group_form_factors", "in_front", "GROUP_LOOP", "BLOCK_PAIRS"]


def polygon_form_factor(x, n, poly):
    """Form factor (N,) from differential areas at ``x`` (N,3) with unit normals ``n`` (N,3) to
    the part of a planar convex polygon above their tangent planes (either side of the polygon).

    ``poly``: (K,3) shared, or (N,K,3) one per receiver. Lambert's contour integral,
    ``F = |sum_k angle(a_k, a_k+1) n . unit(a_k x a_k+1)| / (2 pi)`` over the polygon clipped to
    ``n . (p - x) > 0`` (Sutherland-Hodgman, vectorised: missing slots repeat the previous
    vertex, and zero-length edges contribute nothing).
    """
    x = np.asarray(x, np.float64)
    n = np.asarray(n, np.float64)
    N = len(x)
    poly = np.asarray(poly, np.float64)
    if poly.ndim == 2:
        poly = np.broadcast_to(poly, (N,) + poly.shape)
    K = poly.shape[1]
    rel = poly - x[:, None, :]
    h = np.einsum("nkc,nc->nk", rel, n)
    up = (h > 0).any(axis=1)
    if not up.all():
        # wholly below the horizon (the sun or a lamp behind a surface: half the receivers of
        # a scene): no corner kept, F is 0 exactly, as the contour of those rows would make it
        F = np.zeros(N)
        if up.any():
            F[up] = polygon_form_factor(x[up], n[up], poly[up])
        return F
    rel_n, h_n = np.roll(rel, -1, axis=1), np.roll(h, -1, axis=1)
    inside = h > 0
    crosses = inside != (h_n > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(crosses, h / (h - h_n), 0.0)
    cut = rel + t[..., None] * (rel_n - rel)
    pts = np.stack([rel, cut], axis=2).reshape(N, 2 * K, 3)
    valid = np.stack([inside, crosses], axis=2).reshape(N, 2 * K)
    idx = np.maximum.accumulate(np.where(valid, np.arange(2 * K), -1), axis=1)
    last = idx[:, -1:]
    idx = np.maximum(np.where(idx < 0, last, idx), 0)
    q = np.take_along_axis(pts, idx[..., None], axis=1)
    a, b = q, np.roll(q, -1, axis=1)
    c = cross3(a, b)
    cn = np.linalg.norm(c, axis=-1)
    theta = np.arctan2(cn, np.einsum("nkc,nkc->nk", a, b))
    with np.errstate(divide="ignore", invalid="ignore"):
        g = np.where(cn > 0, np.einsum("nkc,nc->nk", c, n) / cn, 0.0)
    F = np.abs((theta * g).sum(axis=1)) / (2 * np.pi)
    F[last[:, 0] < 0] = 0.0
    return F


def distant_form_factor(n, rel, margin=1e-9):
    """((N,), (N,) bool): :func:`polygon_form_factor` of a planar convex polygon at the same
    offsets ``rel`` (K, 3) from each of N receivers with unit normals ``n`` (N, 3) (a light at
    infinity: the sun's disk at unit distance), and where that holds. Where every corner lies
    above a receiver's tangent plane by more than ``margin`` (of the offsets' length: 1 for
    the sun's disk) nothing is clipped, and Lambert's contour integral is linear in the normal:
    ``F = |n . V| / (2 pi)`` with ``V = sum_k angle(a_k, a_k+1) unit(a_k x a_k+1)``, one vector
    for every receiver, instead of a (N, 2K, 3) contour each. The same sum as
    :func:`polygon_form_factor` to round-off (its per-receiver offsets ``poly - x`` carry
    the receivers' coordinates' rounding, which this does not). Where every corner lies as far
    below it, F is 0, as the clipped contour gives it (the receivers facing away from the sun:
    about half of a scene's), and the mask True too; elsewhere (the polygon crosses the
    horizon) F is 0 and the mask False: the caller clips those."""
    n = np.asarray(n, np.float64)
    rel = np.asarray(rel, np.float64)
    nxt = np.roll(rel, -1, axis=0)
    c = cross3(rel, nxt)
    cn = np.linalg.norm(c, axis=1)
    theta = np.arctan2(cn, np.einsum("kc,kc->k", rel, nxt))
    V = (theta * np.where(cn > 0, 1.0 / np.where(cn > 0, cn, 1.0), 0.0)) @ c
    scale = float(np.sqrt(np.einsum("kc,kc->k", rel, rel).max(initial=0.0)))
    h = n @ rel.T
    whole = h.min(axis=1, initial=np.inf) > margin * scale
    below = h.max(axis=1, initial=-np.inf) < -margin * scale
    return np.where(whole, np.abs(n @ V) / (2 * np.pi), 0.0), whole | below


def polygon_form_factors(points, normals, polys, poly_normals=None):
    """(P, M) unoccluded form factors from differential areas at ``points`` (P, 3) with unit
    ``normals`` to every polygon of ``polys`` (M, K, 3) (any winding; a triangle may repeat a
    corner), over the part of each polygon above the point's horizon
    (:func:`polygon_form_factor`). With ``poly_normals`` (M, 3) an emitter only shines from its
    front: F = 0 for points behind or in its plane.
    """
    points = np.asarray(points, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    polys = np.asarray(polys, dtype=np.float64)
    P, M = len(points), len(polys)
    F = polygon_form_factor(np.repeat(points, M, axis=0), np.repeat(normals, M, axis=0),
                            np.broadcast_to(polys[None], (P,) + polys.shape).reshape((P * M,) + polys.shape[1:]))
    F = F.reshape(P, M)
    if poly_normals is not None:
        # in front of the plane by more than round-off: a point on the emitter's own plane (a
        # neighbour on the same wall) must get 0, not Lambert's in-plane 1/2 or 1
        centre = polys.mean(axis=1)
        size = np.linalg.norm(polys.max(axis=1) - polys.min(axis=1), axis=1)
        h = np.einsum("pmj,mj->pm", points[:, None, :] - centre[None], np.asarray(poly_normals, float))
        F = np.where(h > 1e-9 * np.maximum(size, 1e-300)[None, :], F, 0.0)
    return F


def group_form_factors(points, normals, polys, groups, poly_normals, outline: GroupOutline | None = None,
                       pairs=None, front=None):
    """(P, G) unoccluded form factors from differential areas at ``points`` (P, 3) with unit
    ``normals`` to groups of front-facing polygons (``polys`` (M, K, 3), ``groups`` (M,) in
    0..G-1, ``poly_normals`` (M, 3)): the sum of :func:`polygon_form_factors` over each group.
    ``outline``: :meth:`GroupOutline.of` the same polygons, when the caller asks for many
    chunks of points (else computed here). ``pairs`` (P, G) bool or None (all): the pairs to
    compute, 0 elsewhere (each pair's value is the same whichever others are asked for);
    ``front``: :func:`in_front` of the points, when the caller has it.

    A group in front of a point is one surface to Lambert's contour integral: only its boundary
    edges count (shared edges cancel), clipped to the point's horizon and closed along it where
    the group crosses the horizon, so the cost follows the group's outline, not how many faces
    it was modelled with. Pairs where the point is in front of part of the group only (a curved
    group), or whose crossings do not pair up, are summed face by face.
    """
    points = np.asarray(points, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    o = outline if outline is not None else GroupOutline.of(polys, groups, poly_normals)
    P, G = len(points), len(o.count)
    F = np.zeros((P, G))
    below = np.zeros((P, G), bool)
    n_front, count = in_front(points, o) if front is None else front
    if pairs is not None:
        n_front = np.where(pairs, n_front, 0)
    # the contour only for the pairs whose point is in front of the group (a lamp's back is in
    # front of the ceiling above it alone)
    front = n_front > 0
    live = np.flatnonzero(front.any(axis=0))
    if live.size > GROUP_LOOP:
        _contours_flat(points, normals, o, front, F, below)
    else:
        _contours_by_group(points, normals, o, front, live, F, below)
    _not_by_outline(points, normals, o, n_front, count, below, F)
    return F


def _contours_by_group(points, normals, o, front, live, F, below):
    """:func:`group_form_factors`' contour terms for a few groups (a scene's lamps): each group
    of ``live`` (g,) int against the ``points`` (P, 3, scene units) with unit ``normals`` (P, 3)
    in front of it (``front`` (P, G) bool) as a (points x edges) block of at most
    :data:`BLOCK_PAIRS` pairs, no index arrays; fills ``F`` (P, G) float64, the dimensionless
    form factor of the group's outline, and ``below`` (P, G) bool, where some outline corner is
    at or below the point's horizon. The terms are summed edge after edge, as
    :func:`_contours_flat`'s bincount sums them: the same values, bit for bit."""
    cols = [np.ascontiguousarray(points[:, c]) for c in range(3)]
    ncols = [np.ascontiguousarray(normals[:, c]) for c in range(3)]
    for g in live.tolist():
        s0, k = int(o.edge_start[g]), int(o.edge_count[g])
        ea = [o.edge_columns[0][c][None, s0:s0 + k] for c in range(3)]
        eb = [o.edge_columns[1][c][None, s0:s0 + k] for c in range(3)]
        pg = np.flatnonzero(front[:, g])
        for lo in range(0, pg.size, max(1, BLOCK_PAIRS // max(k, 1))):
            p = pg[lo:lo + max(1, BLOCK_PAIRS // max(k, 1))]
            x = [cols[c].take(p)[:, None] for c in range(3)]
            n = [ncols[c].take(p)[:, None] for c in range(3)]
            a = [ea[c] - x[c] for c in range(3)]
            term = _edge_terms_xyz(a, [eb[c] - x[c] for c in range(3)], n)
            total = np.zeros(p.size)
            for j in range(k):
                total += term[:, j]
            F[p, g] = np.abs(total) / (2 * np.pi)
            # where the contour does not stand for the group: some corner at or below the
            # horizon, or the point not in front of every polygon of the group
            below[p, g] = (a[0] * n[0] + a[1] * n[1] + a[2] * n[2] <= 0).any(axis=1)


def _not_by_outline(points, normals, o, n_front, count, below, F):
    """Set ``F`` (P, G) float64, dimensionless, anew where a group's outline does not stand for
    it. A pair in front of every polygon of its group but with an outline corner ``below``
    (P, G) bool the point's horizon gets the outline clipped to the horizon
    (:func:`_clipped_contour`); a pair in front of only some of the group's polygons
    (``n_front`` (P, G) int of ``count`` (G,)), or whose clipped crossings do not pair up, gets
    the sum face by face (:func:`front_polygon_sum`). ``points`` (P, 3) in the scene's units,
    unit ``normals`` (P, 3); ``o``: the :class:`.outline.GroupOutline`."""
    partial = (n_front > 0) & (n_front < count[None])
    for g in np.flatnonzero((below & ~partial & (n_front > 0)).any(axis=0)):
        p = np.flatnonzero(below[:, g] & ~partial[:, g] & (n_front[:, g] > 0))
        F[p, g], ok = _clipped_contour(points[p], normals[p], o.edges[o.edge_group == g],
                                       o.normals[o.groups == g].mean(axis=0))
        partial[p[~ok], g] = True
    for g in np.flatnonzero(partial.any(axis=0)):
        p = np.flatnonzero(partial[:, g])
        m = np.flatnonzero(o.groups == g)
        F[p, g] = front_polygon_sum(points[p], normals[p], o.polys[m], o.normals[m], o.centre[m], o.size[m])


#: :func:`group_form_factors` takes the groups one by one (a block of points x edges each) up to
#: this many groups in front of some point, else every (point, group) pair's edges flat.
GROUP_LOOP = 64
#: Point-edge pairs per block in :func:`group_form_factors`' group-by-group path (memory).
BLOCK_PAIRS = 1 << 18


def _contours_flat(points, normals, o, front, F, below):
    """:func:`group_form_factors`' contour terms for many groups: each (point, group) pair in
    front, its group's edges, all flat; fills ``F`` and ``below`` (P, G) where ``front``."""
    pi, gi = np.nonzero(front)
    if not pi.size:
        return
    k = o.edge_count[gi]
    pair = np.repeat(np.arange(pi.size), k)
    e = run_positions(k) + np.repeat(o.edge_start[gi], k)
    # by components (3 arrays of the pairs' edges): NumPy's cross and norm of (N, 3) rows
    # cost more than the arithmetic; each a contiguous column read with ``take`` (indexing the
    # (.., 3) arrays with index arrays cost twice as much)
    p_of = pi[pair]
    x = [np.ascontiguousarray(points[:, c]).take(p_of) for c in range(3)]
    a = [o.edge_columns[0][c].take(e) - x[c] for c in range(3)]
    b = [o.edge_columns[1][c].take(e) - x[c] for c in range(3)]
    n = [np.ascontiguousarray(normals[:, c]).take(p_of) for c in range(3)]
    term = _edge_terms_xyz(a, b, n)
    F[pi, gi] = np.abs(np.bincount(pair, weights=term, minlength=pi.size)) / (2 * np.pi)
    h = a[0] * n[0] + a[1] * n[1] + a[2] * n[2]
    below[pi, gi] = np.bincount(pair, weights=h <= 0, minlength=pi.size) > 0


def front_polygon_sum(points, normals, polys, poly_normals, centre=None, size=None, pairs=1 << 18):
    """(P,) ``polygon_form_factors(points, normals, polys, poly_normals).sum(axis=1)``, computed
    for the pairs whose point is in front of the polygon only, and for a polygon wholly above
    the point's horizon by its edges alone (no clipping, the arithmetic by components): a curved
    group seen from the side, half its faces turned away, costs the faces that face the point.
    ``centre`` (M, 3) and ``size`` (M,): the polygons' corner means and bounding-box diagonals
    (computed when None); ``pairs``: point-polygon pairs per chunk (memory)."""
    points = np.asarray(points, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    polys = np.asarray(polys, dtype=np.float64)
    pn = np.asarray(poly_normals, dtype=np.float64)
    if centre is None:
        centre = polys.mean(axis=1)
    if size is None:
        size = np.linalg.norm(polys.max(axis=1) - polys.min(axis=1), axis=1)
    P, M = len(points), len(polys)
    out = np.zeros(P)
    step = max(1, pairs // max(M, 1))
    tol = 1e-9 * np.maximum(size, 1e-300)
    for lo in range(0, P, step):
        x, nx = points[lo:lo + step], normals[lo:lo + step]
        front = np.einsum("pmj,mj->pm", x[:, None, :] - centre[None], pn) > tol[None]
        pi, mi = np.nonzero(front)
        if not pi.size:
            continue
        rel = [polys[mi, :, c] - x[pi, c][:, None] for c in range(3)]           # 3 x (S, K)
        n = [nx[pi, c][:, None] for c in range(3)]
        h = rel[0] * n[0] + rel[1] * n[1] + rel[2] * n[2]                        # (S, K)
        above = (h > 0).all(axis=1)
        f = np.zeros(pi.size)
        s = np.flatnonzero(above)
        if s.size:
            a = [r[s] for r in rel]
            b = [np.roll(r, -1, axis=1) for r in a]
            nn = [c[s] for c in n]
            f[s] = np.abs(_edge_terms_xyz(a, b, nn).sum(axis=1)) / (2 * np.pi)
        s = np.flatnonzero(~above & (h > 0).any(axis=1))                         # crossing the horizon
        if s.size:
            f[s] = polygon_form_factor(x[pi[s]], nx[pi[s]], polys[mi[s]])
        out[lo:lo + step] = np.bincount(pi, weights=f, minlength=len(x))
    return out


def in_front(points, o: GroupOutline):
    """(P, G) how many polygons of each group have the point in front of their plane (by more
    than round-off), and (G,) how many polygons each group has. A planar group (one plane for
    all its polygons) is tested once, a curved one polygon by polygon."""
    centre, size, count, rep, planar, groups, pn = o.centre, o.size, o.count, o.rep, o.planar, o.groups, o.normals
    n_front = np.zeros((len(points), len(count)))
    h = np.einsum("pj,gj->pg", points, pn[rep]) - np.einsum("gj,gj->g", centre[rep], pn[rep])
    n_front[:, planar] = (h[:, planar] > 1e-9 * size[rep][planar]) * count[planar]
    bent = np.flatnonzero(~planar)
    if bent.size:
        # a curved group's normal cone and bounding sphere decide most points at once: in front
        # of every polygon's plane, or of none (a margin of 1e-6 radians for round-off); the
        # points left undecided are tested polygon by polygon
        cone, ball, mid = o.cones
        u = points[:, None, :] - mid[bent][None]                                   # (P, C, 3)
        d = np.linalg.norm(u, axis=2)
        with np.errstate(divide="ignore", invalid="ignore"):
            phi = np.arccos(np.clip(np.einsum("pcj,cj->pc", u, pn[rep][bent]) / d, -1.0, 1.0))
            reach = np.where(d > ball[bent][None], np.arcsin(np.minimum(ball[bent][None] / d, 1.0)), np.inf)
        spread = cone[bent][None] + reach + 1e-6
        n_front[:, bent] = np.where(phi + spread < 0.5 * np.pi, count[bent][None], 0.0)
        for j, g in enumerate(bent):
            p = np.flatnonzero(~(phi[:, j] + spread[:, j] < 0.5 * np.pi) & ~(phi[:, j] - spread[:, j] > 0.5 * np.pi))
            if not p.size:
                continue
            m = np.flatnonzero(groups == g)
            f = np.einsum("pmj,mj->pm", points[p][:, None, :] - centre[m][None], pn[m]) > 1e-9 * size[m][None]
            n_front[p, g] = f.sum(axis=1)
    return n_front, count


def _clipped_contour(x, n, edges, plane_normal):
    """Form factors (P,) from points ``x`` with normals ``n`` to the part above their horizons
    of the planar region bounded by the directed ``edges`` (E, 2, 3), by the contour integral
    over its boundary clipped to the horizon, closed along the horizon: the crossings are sorted
    along the line where the horizon meets the region's plane and paired (exit -> entry).
    Returns (F, ok): ok False where the crossings do not pair up (then F is not valid).

    Points that see the whole region at or below their horizon see nothing of it (F = 0, ok):
    they are answered from the edges' heights alone. They were most of the points clipped on
    a dense mesh (a group in front of a point but wholly behind its tangent plane)."""
    x, n = np.asarray(x, dtype=np.float64), np.asarray(n, dtype=np.float64)
    F, ok = np.zeros(len(x)), np.ones(len(x), bool)
    # the corners' heights over each horizon, with a margin for round-off (the exact heights
    # in :func:`_clipped_rows` decide the points kept)
    corners = np.concatenate([edges[:, 0], edges[:, 1]])
    h = np.einsum("ec,pc->pe", corners, n) - np.einsum("pc,pc->p", x, n)[:, None]
    seen = np.flatnonzero((h > -1e-9 * _reach(edges, x)).any(axis=1))
    if seen.size:
        F[seen], ok[seen] = _clipped_rows(x[seen], n[seen], edges, plane_normal)
    return F, ok


def _reach(edges, x):
    """(P, 1): a length at the scale of the points' distances to the edges (round-off margins)."""
    lo, hi = edges.reshape(-1, 3).min(axis=0), edges.reshape(-1, 3).max(axis=0)
    return (np.abs(x - 0.5 * (lo + hi)).max(axis=1) + np.abs(hi - lo).max())[:, None]


def _clipped_rows(x, n, edges, plane_normal):
    """:func:`_clipped_contour` of points that may see part of the region."""
    a = edges[None, :, 0] - x[:, None]
    b = edges[None, :, 1] - x[:, None]
    ha = np.einsum("pec,pc->pe", a, n)
    hb = np.einsum("pec,pc->pe", b, n)
    ia, ib = ha > 0, hb > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(ia != ib, ha / (ha - hb), 0.0)
    q = a + t[..., None] * (b - a)                                        # the crossing, if any
    ca = np.where((ia & ib)[..., None] | (ia & ~ib)[..., None], a, q)    # clipped edge start
    cb = np.where((ia & ib)[..., None] | (~ia & ib)[..., None], b, q)    # clipped edge end
    keep = ia | ib
    total = np.where(keep, _edge_terms(ca, cb, n), 0.0).sum(axis=1)
    exits, entries = ia & ~ib, ~ia & ib
    crossing = exits | entries
    d = cross3(n, plane_normal)
    key = np.where(crossing, np.einsum("pec,pc->pe", q, d), np.inf)
    order = np.argsort(key, axis=1)
    k = crossing.sum(axis=1)
    qs = np.take_along_axis(q, order[..., None], axis=1)
    out = np.take_along_axis(exits, order, axis=1)
    E = edges.shape[0]
    first, second = np.arange(0, E - 1, 2), np.arange(1, E, 2)
    pair = second[None] < k[:, None]                                      # (P, E//2)
    ex, ey = out[:, first], out[:, second]
    ok = (k % 2 == 0) & np.all(~pair | (ex != ey), axis=1)
    qa, qb = qs[:, first], qs[:, second]
    start = np.where(ex[..., None], qa, qb)                               # from the exit ...
    end = np.where(ex[..., None], qb, qa)                                 # ... to the entry
    total += np.where(pair, _edge_terms(start, end, n), 0.0).sum(axis=1)
    return np.abs(total) / (2 * np.pi), ok


def _edge_terms_xyz(a, b, n):
    """:func:`_edge_terms` of edges a -> b, each with its receiver's normal n, all given as
    their three components (lists of 3 arrays (N,))."""
    ax, ay, az = a
    bx, by, bz = b
    cx = ay * bz - az * by
    cy = az * bx - ax * bz
    cz = ax * by - ay * bx
    cn = np.sqrt(cx * cx + cy * cy + cz * cz)
    theta = np.arctan2(cn, ax * bx + ay * by + az * bz)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(cn > 0, theta * (cx * n[0] + cy * n[1] + cz * n[2]) / cn, 0.0)


def _edge_terms(a, b, n):
    """Lambert's contour terms angle(a, b) * n . unit(a x b) of edges a -> b (.., E, 3) seen
    from the origin, with the receivers' normals ``n`` (P, 3)."""
    c = cross3(a, b)
    cn = np.linalg.norm(c, axis=-1)
    theta = np.arctan2(cn, np.einsum("pec,pec->pe", a, b))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(cn > 0, theta * np.einsum("pec,pc->pe", c, n) / cn, 0.0)
