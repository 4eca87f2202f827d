"""Where on a patch the direct light is evaluated: grids of points, stand-in points for a
cluster, the area average of a light field over a patch, patches turned around.

The exact direct light (:mod:`.stage`) is a function of points; a patch's value is its average
over a grid of ``n x n`` points (:func:`patch_average`, :func:`grid_of`), and a cluster's that of
a few stand-ins spread over its patches (:func:`stand_ins`). Grids and centres are kept per
geometry (a bake asks for the same ones in several stages). Shapes: points (M, 3) world units,
light values (M, 3) radiance.
"""
from __future__ import annotations

import numpy as np

from ..mesh.patches import PatchSet
from ..runtime.cache import Memo, frozen
from ..util.spatial import morton_order
from ..util.unique import unique_ints


def grid_points(patches: PatchSet, n: int, rng=None):
    """(N, n*n, 3) points at the centres of an n x n grid of each patch's bilinear map (a
    triangle is a quad with two corners equal) and (N, n*n) their area weights (summing to 1).
    ``rng`` (a NumPy Generator): each point jittered within its cell instead (a stratified
    sample, so a mean over them has no bias where the light changes within a cell)."""
    t = np.arange(n)
    i, j = [a.ravel()[None, :, None] for a in np.meshgrid(t, t, indexing="ij")]   # (1, n^2, 1)
    if rng is None:
        u, v = (i + 0.5) / n, (j + 0.5) / n
    else:
        N = len(patches)
        u, v = (i + rng.uniform(size=(N, n * n, 1))) / n, (j + rng.uniform(size=(N, n * n, 1))) / n
    c = patches.corners()[:, None]                                                  # (N, 1, 4, 3)
    c0, c1, c2, c3 = c[:, :, 0], c[:, :, 1], c[:, :, 2], c[:, :, 3]
    x = (1 - u) * (1 - v) * c0 + u * (1 - v) * c1 + u * v * c2 + (1 - u) * v * c3
    du = (1 - v) * (c1 - c0) + v * (c2 - c3)
    dv = (1 - u) * (c3 - c0) + u * (c2 - c1)
    w = np.linalg.norm(np.cross(du, dv), axis=-1)
    return x, w / np.maximum(w.sum(axis=1, keepdims=True), 1e-300)


def stand_ins(patches: PatchSet, clusters, k: int) -> np.ndarray:
    """(N,) int: the piece whose centre stands for each piece's light. A piece stands for
    itself, except in a cluster of more than ``k`` pieces: there the pieces are put in Morton
    order of their centres (in the cluster's bounding box), the order is cut into ``k`` runs of
    equal area, and each run's pieces take the light at the centre of the run's piece nearest
    the run's area centroid (a k-point midpoint rule over compact regions). So a cluster's light costs ``k`` points however
    finely it was modelled, and its area mean is a ``k``-point stratified estimate. The same
    array for the same patch and cluster arrays (a relight's points keep their keys)."""
    objs = (patches.centers, patches.areas, clusters.of)
    return _CENTRES.of(objs, lambda: _stand_ins(patches, clusters, k), ("stand", k))


def _stand_ins(patches: PatchSet, clusters, k: int) -> np.ndarray:
    """:func:`stand_ins`, made."""
    of, a, c = clusters.of, patches.areas, patches.centers
    stand = np.arange(len(of))
    big = np.flatnonzero(clusters.sizes[of] > k)
    if len(big):
        cl = of[big]
        order = morton_order(c[big], cl, len(clusters))
        rows, cl = big[order], cl[order]
        cum = np.cumsum(a[rows])
        first = np.r_[0, np.flatnonzero(np.diff(cl)) + 1]
        start = np.repeat(cum[first] - a[rows[first]], np.diff(np.r_[first, len(rows)]))
        total = np.bincount(cl, weights=a[rows], minlength=len(clusters))[cl]
        with np.errstate(divide="ignore", invalid="ignore"):      # a cluster of no area: one run
            frac = np.where(total > 0, (cum - 0.5 * a[rows] - start) / total, 0.0)
        run = np.clip((frac * k).astype(np.int64), 0, k - 1)
        # each run's stand-in: its piece nearest the run's area centroid
        rid = unique_ints(cl * k + run, return_inverse=True)[1]
        w = a[rows]
        mid = np.stack([np.bincount(rid, weights=w * c[rows, ax]) for ax in range(3)], 1)
        mid /= np.maximum(np.bincount(rid, weights=w), 1e-300)[:, None]
        d = np.einsum("ij,ij->i", c[rows] - mid[rid], c[rows] - mid[rid])
        near = np.lexsort((d, rid))
        best = near[np.r_[0, np.flatnonzero(np.diff(rid[near])) + 1]]
        stand[rows] = rows[best[rid]]
    return frozen(stand)


#: The points whose light is averaged (a patch's n x n grid, a cluster's stand-ins) share the
#: world's sky rays out in runs of this many (:func:`.hemisphere.sky_fraction`'s ``split``): each
#: casts this share of them, the run the whole pattern once, and the mean reads one full pattern
#: spread over the run's points, not one at each. The sky's rays at the grouped centres were
#: the direct stage's most (zdm2: 13.5 of 84 million sky rays, the truck town 6.1 of 23).
SKY_SHARE = 4


def patch_average(patches: PatchSet, n, light_at, centre_only=None, weight_at=None, rng=None,
                  stand=None, groups=None, share=False) -> np.ndarray:
    """(N, 3) area-weighted mean over n x n points of every patch of ``light_at(points, normals,
    where) -> (P, 3)`` (n = 1: at the centres). The points are the centres of an n x n grid of
    the patch's bilinear map (a triangle is a quad with two corners equal), weighted by the map's
    area there. ``centre_only`` (N,) bool: patches taken at their centre whatever n (the faces of
    a grouped cluster, whose mean over many faces already samples the light).
    ``weight_at(points, normals) -> (P,)`` in [0, 1]: how much each point counts besides its
    area (a point the rest of the scene cannot see, 0); a patch whose points all weigh 0 takes
    the plain area mean. ``rng``: jittered points (see :func:`grid_points`). ``stand`` (N,)
    int (:func:`stand_ins`): a centre-only piece takes the light at its stand-in's centre.
    ``share``: the points averaged share the sky's rays out (:data:`SKY_SHARE`): the n x n
    points of a patch's grid (n > 1), and with ``stand`` and ``groups`` (N,) int (the cluster of
    each piece) the stand-ins of a cluster of at least :data:`SKY_SHARE` of them
    (:func:`shared_parts`); ``light_at`` then takes ``split`` and ``part``
    (:meth:`.direct.DirectLight.at`'s) for those points."""
    some = centre_only is not None and centre_only.any()
    if (not some or stand is None) and (n <= 1 or some and centre_only.all()):
        return light_at(patches.centers, patches.normals, "centres")
    if some:
        lit = centre_only
        if stand is not None:
            lit = np.zeros(len(patches), bool)
            lit[stand[centre_only]] = True      # the centres that stand for the rest
        out = np.empty((len(patches), 3))
        if lit.all():
            out[:] = light_at(patches.centers, patches.normals, "centres")
        elif not share or groups is None or stand is None:
            out[lit] = light_at(*centres_of(patches, lit), "grouped-centres")
        else:
            out[lit] = _shared_centres(patches, lit, groups, light_at)
        if stand is not None:                   # every row at once (a masked scatter of rows: 4x slower)
            out = out.take(np.where(centre_only, stand, np.arange(len(patches))), axis=0)
        rest = np.flatnonzero(~centre_only)
        if len(rest):
            if n <= 1 or rng is not None:
                out[rest] = patch_average(patches.take(rest), n, light_at, weight_at=weight_at, rng=rng,
                                          share=share)
            else:
                out[rest] = _grid_average(grid_of(patches, rest, n), n, light_at, weight_at, share)
        return out
    if rng is None:
        return _grid_average(grid_of(patches, None, n), n, light_at, weight_at, share)
    x, w = grid_points(patches, n, rng)
    N, K = x.shape[:2]
    return _grid_average((x, x.reshape(N * K, 3), np.repeat(patches.normals, K, axis=0), w), n, light_at,
                         weight_at, share)


def _grid_average(grid, n, light_at, weight_at=None, share=False) -> np.ndarray:
    """:func:`patch_average` over the points of ``grid`` (:func:`grid_of`)."""
    _, x, nrm, w = grid
    N, K = w.shape
    if weight_at is not None:
        seen = w * np.asarray(weight_at(x, nrm), dtype=np.float64).reshape(N, K)
        total = seen.sum(axis=1, keepdims=True)
        w = np.where(total > 0, seen / np.where(total > 0, total, 1.0), w)
    kw = {"split": SKY_SHARE, "part": _grid_parts(N, K)} if share and K >= SKY_SHARE else {}
    D = light_at(x, nrm, f"patch-points-{n}", **kw).reshape(N, K, 3)
    return np.einsum("nk,nkc->nc", w, D)


def _grid_parts(N, K) -> np.ndarray:
    """(N K,) the share of the sky's rays each of N patches' K grid points casts (:data:`SKY_SHARE`):
    point k its k % SKY_SHARE-th, so a patch's points cast every ray at least once. Read-only
    and the same array for the same (N, K) (its hash keys the light's cache)."""
    return _PARTS.get(("grid", int(N), int(K)), lambda: frozen(np.tile(np.arange(K) % SKY_SHARE, N)))


def shared_parts(groups) -> tuple:
    """(full (M,) bool, part (M,) int) for M points of clusters ``groups`` (M,) int: the points of
    clusters of at least :data:`SKY_SHARE` points, and each one's share of the sky's rays, its
    rank among its cluster's points (in the given order) modulo :data:`SKY_SHARE`: every such
    cluster casts each ray of the pattern at least once (smaller clusters, each point all)."""
    groups = np.asarray(groups, dtype=np.int64)
    order = np.argsort(groups, kind="stable")
    g = groups[order]
    first = np.r_[0, np.flatnonzero(np.diff(g)) + 1] if len(g) else np.zeros(0, np.int64)
    size = np.diff(np.r_[first, len(g)])
    rank = np.empty(len(g), np.int64)
    rank[order] = np.arange(len(g)) - np.repeat(first, size)
    full = np.empty(len(g), bool)
    full[order] = np.repeat(size >= SKY_SHARE, size)
    return full, rank % SKY_SHARE


def _shared_centres(patches: PatchSet, lit, groups, light_at) -> np.ndarray:
    """(M, 3) ``light_at`` the centres of the patches ``lit`` (N,) bool: those of clusters
    (``groups``) with at least :data:`SKY_SHARE` of them sharing the sky's rays out
    (:func:`shared_parts`), the rest each casting all of them."""
    x, nrm = centres_of(patches, lit)

    def make():
        full, part = shared_parts(np.asarray(groups)[lit])
        rows = [np.flatnonzero(full), np.flatnonzero(~full)]
        return [(r, *frozen(np.ascontiguousarray(x[r]), np.ascontiguousarray(nrm[r]), part[r])) for r in rows]
    sets = _PARTS.of((x, groups), make, "grouped")
    out = np.empty((len(x), 3))
    if not len(sets[0][0]):                   # no cluster shares: the centres as they are
        return light_at(x, nrm, "grouped-centres")
    if not len(sets[1][0]):                   # every cluster shares
        return light_at(x, nrm, "grouped-centres", split=SKY_SHARE, part=sets[0][3])
    for (r, xs, ns, part), share in zip(sets, (True, False)):
        if len(r):
            kw = {"split": SKY_SHARE, "part": part} if share else {}
            out[r] = light_at(xs, ns, "grouped-centres" if share else "grouped-few", **kw)
    return out


_PARTS = Memo(8)                   # (N, K) or (centres, groups) -> the sky's shares (SKY_SHARE)
_GRIDS = Memo(8, refresh=True)     # (verts, polys), (n, N, rows) -> grid: the most recently used kept


def grid_of(patches: PatchSet, rows, n: int):
    """:func:`grid_points` (n x n, not jittered) of the patches ``rows`` (int array; None: all)
    as (points (R, K, 3), the same as (R K, 3), their normals (R K, 3), weights (R, K)),
    read-only, kept for the last few patch arrays and rows: the same arrays for the same
    geometry, so the point sets a relight lights again (the keys of their transports, exposure
    and crossings) are hashed once, and the points are not made again (a relight's patch grids,
    asked for twice, and its refine grids)."""
    rk = b"" if rows is None else np.ascontiguousarray(rows, dtype=np.int64).tobytes()

    def make():
        sub = patches if rows is None else patches.take(rows)
        x, w = grid_points(sub, n)
        N, K = x.shape[:2]
        return frozen(x, x.reshape(N * K, 3), np.repeat(sub.normals, K, axis=0), w)
    return _GRIDS.of((patches.verts, patches.polys), make, (int(n), len(patches), rk))


#: A cluster's light from at most this many x patch_light_points^2 centres (:func:`stand_ins`).
#: At 4 (16 centres) one stand-in of a densely tessellated box's ceiling fell beside the lamp, whose
#: back lights the ceiling through a 2 mm gap in a band a few millimetres wide, and its light stood
#: for a sixteenth of the cluster: the ceiling's reflected light came out 42% too high. From 8 on the
#: means agree with lighting every face centre, for little more time in the direct stage.
STAND_INS = 8


#: (centers, normals), mask bytes -> their rows (:func:`centres_of`); (centers, areas, cluster
#: of), k -> stand-ins (:func:`stand_ins`): the last eight of either
_CENTRES = Memo(8)


def centres_of(patches: PatchSet, select) -> tuple:
    """(centres (M, 3), normals (M, 3)) of the patches ``select`` (N,) bool, the same arrays for
    the same patch arrays and selection (a relight's: its transports' keys hash them once,
    :func:`.cache.array_key`). The arrays are read-only."""
    c, n = patches.centers, patches.normals
    return _CENTRES.of((c, n), lambda: frozen(c[select], n[select]), (np.packbits(select).tobytes(), len(select)))


def turned_around(patches: PatchSet) -> PatchSet:
    """The same patches facing the other way: corners in reverse order, normals negated."""
    polys = patches.polys.copy()
    tri = polys[:, 3] < 0
    polys[~tri] = polys[~tri][:, ::-1]
    polys[tri, :3] = polys[tri, 2::-1]
    return PatchSet(patches.verts, polys, patches.centers, -patches.normals, patches.areas,
                    patches.rho, patches.emission, patches.owner, patches.source_face,
                    list(patches.object_names))
