"""Geometry and sampling helpers shared by the form-factor, light and gather modules (pure NumPy).

Frames
------
* :func:`orthonormal_basis` (N, 3) unit vectors -> two (N, 3) unit vectors spanning the plane
  perpendicular to them: the first is the vector crossed into the world axis least aligned
  with it, the second completes a right-handed frame.
* :func:`tangent_frames` (N, 3) unit normals -> (N, 3, 3) frames, rows (u, v, n), the same basis
  optionally turned about the normal; the hemi-cube, Embree and the final gather cast with it.

Sampling (points in the unit square [0, 1)^2, dimensionless)
------------------------------------------------------------
Two stratified samplers, kept apart because their draws differ and saved bakes depend on them:

* :func:`stratified_unit_square` (count, k, 2): an m x (k // m) jittered grid, m = floor(sqrt k),
  the leftover points uniform (lamp shadow samples, stochastic form factors).
* :func:`jittered_grid` (count, g^2) u and v: a g x g jittered grid, g = ceil(sqrt samples)
  (emitter shadow samples, the final gather's ray pattern).

:func:`cosine_directions` maps the square to cosine-distributed unit directions in a local
frame (+Z the normal); :func:`disk_samples` to points on disks, uniform by area.

Form factors (dimensionless)
----------------------------
* :func:`polygon_form_factor` (N,): differential area -> convex polygon, Lambert's contour
  integral over the part above the receiver's horizon.
* :func:`polygon_form_factors` (P, M): every point to every polygon, optionally one-sided.
* :func:`disk_polygons` (N, sides, 3): regular polygons standing in for disks (same area), so
  a disk's form factor is a polygon's.

Lengths are in the scene's units (Blender metres); angles in radians.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .unique import unique_rows

__all__ = ["orthonormal_basis", "tangent_frames", "stratified_unit_square", "jittered_grid",
           "cosine_directions", "polygon_form_factor", "polygon_form_factors",
           "equal_area_scale", "disk_polygons", "disk_samples", "DISK_SIDES", "GroupOutline",
           "group_form_factors"]

#: Sides of the regular polygon standing in for disks and ellipses.
DISK_SIDES = 64


# --------------------------------------------------------------------------------------------
# Frames


def orthonormal_basis(m):
    """(N,3), (N,3): two unit vectors spanning the plane perpendicular to unit vectors ``m``
    (N,3): ``e1`` is ``m`` crossed into the world axis least aligned with it, ``e2 = m x e1``."""
    m = np.asarray(m, dtype=np.float64)
    helper = np.zeros_like(m)
    helper[np.arange(len(m)), np.argmin(np.abs(m), axis=1)] = 1.0
    e1 = np.cross(helper, m)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return e1, np.cross(m, e1)


def tangent_frames(normals, angles=None):
    """Orthonormal frames (N, 3, 3), rows (u, v, n), around unit normals (N, 3).

    ``u``, ``v``: :func:`orthonormal_basis` of the normals, turned by ``angles`` (N,) radians
    about the normal when given.  Right-handed; ``frames[i] @ d`` expresses a world vector in
    frame i.
    """
    n = np.asarray(normals, dtype=np.float64)
    u, v = orthonormal_basis(n)
    if angles is not None:
        ca, sa = np.cos(angles)[:, None], np.sin(angles)[:, None]
        u, v = ca * u + sa * v, -sa * u + ca * v
    return np.stack([u, v, n], axis=1)


def in_frames(local, frames):
    """(M, R, 3) the directions ``local`` (R, 3), given in each frame's (u, v, n), in world
    space for every frame of ``frames`` (M, 3, 3) (from :func:`tangent_frames`): the sum over
    the three axes in order, as ``np.einsum("rj,mjc->mrc", local, frames)`` sums it (the same
    values, bit for bit, in half its time on a gather's quarter million rays)."""
    d = local[None, :, 0, None] * frames[:, None, 0, :]
    d += local[None, :, 1, None] * frames[:, None, 1, :]
    d += local[None, :, 2, None] * frames[:, None, 2, :]
    return d


# --------------------------------------------------------------------------------------------
# Sampling the unit square


def stratified_unit_square(rng, count, k):
    """(count, k, 2) points in [0,1)^2: a jittered m x (k // m) grid (m = floor(sqrt k)), the
    k - m * (k // m) left over drawn uniformly; a fresh jitter per row. ``rng``: a NumPy
    ``Generator`` (the jitter is drawn first, then the leftovers)."""
    m = max(1, int(np.floor(np.sqrt(k))))
    c = k // m
    gi, gj = np.meshgrid(np.arange(m), np.arange(c), indexing="ij")
    base = np.stack([gi.reshape(-1) / m, gj.reshape(-1) / c], -1)          # (m*c, 2)
    pts = base[None] + rng.random((count, m * c, 2)) * np.array([1.0 / m, 1.0 / c])
    if k > m * c:
        pts = np.concatenate([pts, rng.random((count, k - m * c, 2))], axis=1)
    return pts


def jittered_grid(rng, count, samples):
    """``u``, ``v`` (count, g*g) in [0,1): a g x g jittered grid, g = ceil(sqrt samples) (so at
    least ``samples`` points), cell (i, j) at index i * g + j. ``rng``: a NumPy ``Generator``
    (all u jitter is drawn, then all v)."""
    g = int(np.ceil(np.sqrt(samples)))
    i, j = np.meshgrid(np.arange(g), np.arange(g), indexing="ij")
    u = (i.ravel()[None] + rng.uniform(0, 1, (count, g * g))) / g
    v = (j.ravel()[None] + rng.uniform(0, 1, (count, g * g))) / g
    return u, v


def cosine_directions(u):
    """Map (..., 2) points of the unit square to cosine-distributed local unit directions
    (..., 3), +Z the normal (Malley: uniform on the disk by area, lifted to the hemisphere)."""
    r = np.sqrt(u[..., 0])
    phi = 2.0 * np.pi * u[..., 1]
    z = np.sqrt(np.maximum(0.0, 1.0 - u[..., 0]))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], -1)


# --------------------------------------------------------------------------------------------
# Disks


def equal_area_scale(sides=DISK_SIDES):
    """Circumradius of the regular ``sides``-gon with the area of the unit circle."""
    return np.sqrt(np.pi / (0.5 * sides * np.sin(2 * np.pi / sides)))


def disk_polygons(center, normal, radius, sides=DISK_SIDES):
    """(N, sides, 3) regular polygons with the area of the disks ``center`` (N,3), unit
    ``normal`` (N,3), ``radius`` (N,), in the plane of :func:`orthonormal_basis` of the normal."""
    e1, e2 = orthonormal_basis(normal)
    phi = 2 * np.pi * np.arange(sides) / sides
    r = (equal_area_scale(sides) * radius)[:, None, None]
    return center[:, None] + r * (np.cos(phi)[None, :, None] * e1[:, None] + np.sin(phi)[None, :, None] * e2[:, None])


def disk_samples(u, center, normal, radius):
    """Points (N,S,3) on the disks ``center`` (N,3), unit ``normal`` (N,3), ``radius`` (N,) from
    unit-square points ``u`` (N,S,2), uniform by area."""
    e1, e2 = orthonormal_basis(normal)
    r = np.sqrt(u[..., 0]) * radius[:, None]
    phi = 2 * np.pi * u[..., 1]
    return center[:, None] + (r * np.cos(phi))[..., None] * e1[:, None] + (r * np.sin(phi))[..., None] * e2[:, None]


# --------------------------------------------------------------------------------------------
# Point-to-polygon form factors


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
    c = np.cross(a, b)
    cn = np.linalg.norm(c, axis=-1)
    theta = np.arctan2(cn, np.einsum("nkc,nkc->nk", a, b))
    with np.errstate(divide="ignore", invalid="ignore"):
        g = np.where(cn > 0, np.einsum("nkc,nc->nk", c, n) / cn, 0.0)
    F = np.abs((theta * g).sum(axis=1)) / (2 * np.pi)
    F[last[:, 0] < 0] = 0.0
    return F


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
    und = np.stack([np.minimum(start, end), np.maximum(start, end)], axis=1)
    _, inv, cnt = unique_rows(und, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    # the other group along each edge: an edge in exactly two groups' boundaries, walked once
    # each way
    order = np.argsort(inv, kind="stable")
    two = np.flatnonzero(cnt[inv[order]] == 2)
    i, j = order[two[0::2]], order[two[1::2]]
    ok = (eg[i] != eg[j]) & single[i] & single[j] & (start[i] == end[j])
    i, j = i[ok], j[ok]
    if i.size:
        ok = coplanar(eg[i], eg[j])
        i, j = i[ok], j[ok]
    partner = np.full(E, -1)
    partner[i], partner[j] = j, i
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
    # edge that starts where it ends, when exactly one does (all at once: this ran a Python loop
    # with a cross product per edge, 0.25 s for the 5,500 outline edges of a 54k-triangle box)
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
    """What :func:`group_form_factors` needs of groups of polygons that does not depend on the
    points: computed once per emitter set, not per chunk of points.

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


def group_form_factors(points, normals, polys, groups, poly_normals, outline: GroupOutline | None = None):
    """(P, G) unoccluded form factors from differential areas at ``points`` (P, 3) with unit
    ``normals`` to groups of front-facing polygons (``polys`` (M, K, 3), ``groups`` (M,) in
    0..G-1, ``poly_normals`` (M, 3)): the sum of :func:`polygon_form_factors` over each group.
    ``outline``: :meth:`GroupOutline.of` the same polygons, when the caller asks for many
    chunks of points (else computed here).

    A group in front of a point is one surface to Lambert's contour integral: only its boundary
    edges count (shared edges cancel), clipped to the point's horizon and closed along it where
    the group crosses the horizon, so the cost follows the group's outline, not how many faces
    it was modelled with. Pairs where the point is in front of part of the group only (a curved
    group), or whose crossings do not pair up, are summed face by face.
    """
    points = np.asarray(points, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    o = outline if outline is not None else GroupOutline.of(polys, groups, poly_normals)
    polys, groups, pn, edges, eg = o.polys, o.groups, o.normals, o.edges, o.edge_group
    P, G = len(points), len(o.count)
    F = np.zeros((P, G))
    below = np.zeros((P, G), bool)
    n_front, count = _in_front(points, o)
    # the contour only for the pairs whose point is in front of the group (a lamp's back is in
    # front of the ceiling above it alone)
    front = n_front > 0
    live = np.flatnonzero(front.any(axis=0))
    if live.size > GROUP_LOOP:
        _contours_flat(points, normals, o, front, F, below)
    else:
        # a few groups (a scene's lamps): each group's edges against the points in front of it
        # as a (points x edges) block, no index arrays; the terms summed edge after edge, as
        # the flat path's bincount sums them (the same values, bit for bit)
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
    partial = (n_front > 0) & (n_front < count[None])
    for g in np.flatnonzero((below & ~partial & (n_front > 0)).any(axis=0)):
        p = np.flatnonzero(below[:, g] & ~partial[:, g] & (n_front[:, g] > 0))
        F[p, g], ok = _clipped_contour(points[p], normals[p], edges[eg == g], pn[groups == g].mean(axis=0))
        partial[p[~ok], g] = True
    for g in np.flatnonzero(partial.any(axis=0)):
        p = np.flatnonzero(partial[:, g])
        m = np.flatnonzero(groups == g)
        F[p, g] = front_polygon_sum(points[p], normals[p], polys[m], pn[m], o.centre[m], o.size[m])
    return F


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
    e = np.arange(int(k.sum())) - np.repeat(np.cumsum(k) - k, k) + np.repeat(o.edge_start[gi], k)
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
    P, M, K = len(points), len(polys), polys.shape[1]
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


def _in_front(points, o: GroupOutline):
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
    they are answered from the edges' heights alone. They were 88% of the points clipped on
    the 54k-triangle box (a group in front of a point but wholly behind its tangent plane)."""
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
    d = np.cross(n, plane_normal)
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
    c = np.cross(a, b)
    cn = np.linalg.norm(c, axis=-1)
    theta = np.arctan2(cn, np.einsum("pec,pec->pe", a, b))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(cn > 0, theta * np.einsum("pec,pc->pe", c, n) / cn, 0.0)


def bilinear(c, u, v):
    """Points ``(u, v)`` in [0, 1]^2 mapped onto quads: ``c`` (..., 4, 3) corners in order, u and
    v broadcasting against ``c[..., 0, :]``; (..., 3). A triangle repeats its third corner."""
    return (1 - u) * (1 - v) * c[..., 0, :] + u * (1 - v) * c[..., 1, :] + u * v * c[..., 2, :] \
        + (1 - u) * v * c[..., 3, :]
