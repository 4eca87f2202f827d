"""Evaluate a bake anywhere on its surfaces: the paper's rendering step, bilinear inside a patch.

Given vertex radiosities on the patch mesh, a point on a surface takes the bilinear interpolation
of its patch's four corner values (a triangle patch is a quad with its last two corners equal,
which makes the same formula barycentric). Used to put a coarse patch solution on a finer mesh
(another mesh's vertices, a reference bake's vertices) without cutting more patches.
"""
from __future__ import annotations

import numpy as np

from ..mesh.patches import PatchSet
from ..runtime.parallel import ordered_map, resolve_workers
from ..util.geometry import bilinear
from ..util.spatial import MAX_PAIRS, Grid, sq_dist

__all__ = ["interpolate_located", "locate", "interpolate_at", "located_corners", "interpolate_corners",
           "interpolate_corner_values"]

_CELL = 2.0     # locate's grid cells, in median patch sizes: the 8 nearest centres mostly in the 27 cells around
_BRUTE = 512   # objects of at most so many patches: every centre for every point (cheaper than a grid)
_PRUNE = 8     # _pick fits every candidate up to so many, beyond only those that can win


def inverse_bilinear(c, p, iterations=8):
    """(u, v) with bilinear(c, u, v) closest to p (Gauss-Newton from the centre); c (..., 4, 3).

    Worked one coordinate at a time on contiguous (...,) arrays: the same operations as on the
    (..., 3) vectors, in the same order, so bit for bit the same (u, v), several times faster (a
    dot product over a short last axis, ``np.einsum("...i,...i")``, is slow; it sums x0 y0 +
    x2 y2 first, then x1 y1, without fused multiply-adds, as :func:`_dot` does). A dense mesh's
    gather hits on abrupt elements spend much of their time here."""
    shape = p.shape[:-1]
    c = np.asarray(c, dtype=np.float64)
    p = np.asarray(p, dtype=np.float64)
    cc = [[np.ascontiguousarray(np.broadcast_to(c[..., k, i], shape)) for i in range(3)] for k in range(4)]
    pp = [np.ascontiguousarray(np.broadcast_to(p[..., i], shape)) for i in range(3)]
    e10, e23, e30, e21 = ([cc[a][i] - cc[b][i] for i in range(3)] for a, b in ((1, 0), (2, 3), (3, 0), (2, 1)))
    u = np.full(shape, 0.5)
    v = np.full(shape, 0.5)
    for _ in range(iterations):
        mu, mv = 1 - u, 1 - v
        w = (mu * mv, u * mv, u * v, mu * v)             # as bilinear weighs the corners
        r = []
        for i in range(3):
            x = w[0] * cc[0][i]
            for k in (1, 2, 3):
                x += w[k] * cc[k][i]
            x -= pp[i]
            r.append(x)
        du = [mv * e10[i] + v * e23[i] for i in range(3)]
        dv = [mu * e30[i] + u * e21[i] for i in range(3)]
        a, b, d, gu, gv = _dot(du, du), _dot(du, dv), _dot(dv, dv), _dot(du, r), _dot(dv, r)
        det = a * d - b * b
        tiny = det <= 1e-30 * np.maximum(a * d, 1e-300)
        det = np.where(tiny, 1.0, det)
        step_u = np.where(tiny, 0.0, (d * gu - b * gv) / det)
        step_v = np.where(tiny, 0.0, (a * gv - b * gu) / det)
        u = np.clip(u - step_u, -0.5, 1.5)
        v = np.clip(v - step_v, -0.5, 1.5)
    return u, v


def _dot(x, y):
    """x . y for vectors given as three coordinate arrays, summed as ``np.einsum("...i,...i")``
    sums a last axis of 3 (x0 y0 + x2 y2, then + x1 y1; no fused multiply-add): bit for bit."""
    out = x[0] * y[0]
    out += x[2] * y[2]
    out += x[1] * y[1]
    return out


def _pick(patches, corners, size, cand, p, normals):
    """The best of each point's candidate patches ``cand`` (m, k) for the points ``p`` (m, 3):
    (m,) position in ``cand`` (the first of equal scores), clamped (u, v) (m, k) each (read at
    the best only), and (m,) True where another candidate scores the same.

    With more than :data:`_PRUNE` candidates (the search farther out, 64), only those that can
    score as well as the best of the :data:`_PRUNE` likeliest are fitted: a candidate's score is
    at least its distance beyond its corners' sphere, over its size (the clamped point lies in
    the corners' hull), plus the facing penalty; one whose bound exceeds a score found cannot
    be the first of the best, nor tie with it. The scores fitted are the same numbers (each
    pair's fit is its own), so the choice is the same, bit for bit; a third of the fits."""
    m, k = cand.shape
    facing = None if normals is None else np.einsum("mkj,mj->mk", patches.normals[cand], normals)
    if k <= _PRUNE or not m:
        score, uc, vc = _scores(corners, size, cand, np.broadcast_to(p[:, None, :], cand.shape + (3,)), facing)
    else:
        centres = patches.centers[cand]                                # (m, k, 3)
        reach = np.sqrt(sq_dist(corners[cand], centres[:, :, None, :]).max(axis=2))
        bound = np.maximum(np.sqrt(sq_dist(p[:, None, :], centres)) - reach, 0.0) / size[cand] - 1e-6
        if facing is not None:
            bound = bound + 10.0 * (facing < 0.5)
        rows = np.repeat(np.arange(m), _PRUNE)
        likely = np.argpartition(bound, _PRUNE - 1, axis=1)[:, :_PRUNE].ravel()
        first = np.full((m, k), np.inf)
        first[rows, likely] = _scores(corners, size, cand[rows, likely], p[rows], _at(facing, rows, likely))[0]
        best = first.min(axis=1)
        need = (bound <= best[:, None]) | np.isfinite(first)
        need[~np.isfinite(best) | ~np.isfinite(bound).all(axis=1)] = True   # (NaN: every candidate, as before)
        r, j = np.nonzero(need)
        score, uc, vc = np.full((m, k), np.inf), np.zeros((m, k)), np.zeros((m, k))
        score[r, j], uc[r, j], vc[r, j] = _scores(corners, size, cand[r, j], p[r], _at(facing, r, j))
    best = np.argmin(score, axis=1)
    tied = (score == score[np.arange(len(cand)), best][:, None]).sum(1) > 1
    return best, uc, vc, tied


def _at(a, r, j):
    return None if a is None else a[r, j]


def _scores(corners, size, cand, pp, facing):
    """(score, u, v), each of ``cand``'s shape, of points ``pp`` (..., 3) in their candidate
    patches: how far outside the patch the fit lies plus the gap to it over the patch's size
    (+10 facing away); u, v clamped to the patch. Each pair's own arithmetic, whatever the shape."""
    c = corners[cand]                                            # (..., 4, 3)
    u, v = inverse_bilinear(c, pp)
    outside = np.maximum.reduce([np.zeros_like(u), -u, u - 1, -v, v - 1])
    uc, vc = np.clip(u, 0, 1), np.clip(v, 0, 1)
    gap = np.linalg.norm(bilinear(c, uc[..., None], vc[..., None]) - pp, axis=-1) / size[cand]
    score = outside + gap
    if facing is not None:
        score = score + 10.0 * (facing < 0.5)
    return score, uc, vc


def locate(patches: PatchSet, points, owner=None, normals=None, candidates=8, chunk=2048, workers=1):
    """Patch index (P,) and bilinear (u, v) (P, 2) in [0, 1] for points on the patch surfaces.

    ``owner`` (P,) restricts each point to patches of that object; ``normals`` (P, 3) rejects
    patches facing another way (for corners shared by differently oriented faces). Each point is
    tried against its ``candidates`` nearest patch centres; the one it lies in (or is closest to
    lying in) wins. Points off every surface get the nearest patch, clamped.

    The result is the brute-force search's to the bit: every centre of the object for every
    point (``np.argpartition`` of the squared distances), the candidates tried in the order that
    gives. The nearest centres come from a grid over the object's centres instead
    (``spatial.Grid``, cells twice the median patch size), at a cost of about
    P * candidates, not P * patches; only where the grid's candidates leave the choice open is the
    point compared with every centre as before: when two candidates fit equally well (a point on
    an edge two patches share, at a cost of its object's patches: ``argpartition``'s order picks
    one, and at a T-junction they give other values) or the last candidate's distance is tied with
    the next centre's. Objects of at most 512 patches take the brute force for every point.

    ``workers`` (0 = every core): threads that take the grid's chunks of points (NumPy lets go
    of the GIL in their searches and fits; each chunk writes its own points' rows), the same
    result, bit for bit, for any count. Why: zdm2's 150,000 output vertices in one object's
    7,000 patches took 5 s on one core while the other idled.
    """
    points = np.asarray(points, dtype=np.float64)
    P = len(points)
    by_owner = owner is not None
    owner = np.asarray(owner, np.int64) if by_owner else np.zeros(P, np.int64)
    powner = patches.owner if by_owner else np.zeros(len(patches), np.int64)
    loc = _Located(patches, points, None if normals is None else np.asarray(normals, dtype=np.float64))
    # objects of at most ``candidates`` patches (a face's few elements, when keyed by face): every
    # patch a candidate, in index order, for all the objects of one count at once
    groups, count = np.unique(powner, return_counts=True)
    order = np.argsort(powner, kind="stable")                  # each object's patches, ascending
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    g = np.searchsorted(groups, owner)
    g = np.minimum(g, max(len(groups) - 1, 0))
    known = (g < len(groups)) & (groups[g] == owner) if len(groups) else np.zeros(P, bool)
    if not known.all():
        raise ValueError(f"no patches belong to object {int(owner[~known][0])}")
    few = count[g] <= candidates
    for N in np.unique(count[g[few]]):
        pts_ids = np.flatnonzero(few & (count[g] == N))
        cand = order[start[g[pts_ids]][:, None] + np.arange(N)[None]]
        for s in range(0, pts_ids.size, chunk):
            loc.settle(pts_ids[s:s + chunk], cand[s:s + chunk])
    for o in np.unique(owner[~few]):
        loc.in_object(np.flatnonzero(owner == o), np.flatnonzero(powner == o), candidates, chunk, workers)
    return loc.idx, loc.uv


class _Located:
    """:func:`locate`'s points and what it has found for them: ``idx`` (P,) patch, ``uv`` (P, 2)."""

    def __init__(self, patches, points, normals):
        self.patches, self.points, self.normals = patches, points, normals
        self.corners = patches.corners()
        self.size = np.sqrt(patches.areas)
        self.idx = np.full(len(points), -1, np.int64)
        self.uv = np.zeros((len(points), 2))

    def settle(self, ids, cand):
        """Place the points ``ids`` (n,) in the best of their candidate patches ``cand`` (n, k);
        (n,) bool: where two candidates fitted equally well."""
        best, uc, vc, tied = _pick(self.patches, self.corners, self.size, cand, self.points[ids],
                                   None if self.normals is None else self.normals[ids])
        r = np.arange(ids.size)
        self.idx[ids] = cand[r, best]
        self.uv[ids] = np.stack([uc[r, best], vc[r, best]], 1)
        return tied

    def in_object(self, pts_ids, cand_all, candidates, chunk, workers):
        """Place the points ``pts_ids`` among one object's patches ``cand_all`` (ascending): the
        grid's nearest centres first where the object is large, the brute force where it is small
        or where the grid's choice is open (:func:`locate`)."""
        N = cand_all.size
        k = min(candidates, N)
        cc = self.patches.centers[cand_all]
        if N <= _BRUTE:
            redo = pts_ids
        else:
            # the median patch's size: where most centres are, the 27 cells around a point hold a
            # few dozen (the area-weighted size, led by a level's few large floors, made cells
            # 35 times zdm2's median patch and 5 M pairs a chunk); points among larger patches
            # settle on the grid's coarser levels. The k nearest are exact for any cell.
            grid = Grid(cc, _CELL * float(np.median(self.size[cand_all])))

            def nearest(s):
                ids = pts_ids[s:s + chunk]
                near, d2 = grid.k_nearest(self.points[ids], k + 1)
                tied = self.settle(ids, cand_all[np.sort(near[:, :k], axis=1)])
                return ids[tied | (d2[:, k - 1] == d2[:, k])]
            w = min(resolve_workers(workers), -(-pts_ids.size // chunk))
            if w > 1:
                grid.build_levels()                # threads must not build them at once
            redo = np.concatenate(list(ordered_map(nearest, range(0, pts_ids.size, chunk), w)))
        # the brute force, where the order of the candidates decides (or the object has few patches)
        rows = max(1, MAX_PAIRS // N)
        for s in range(0, redo.size, rows):
            ids = redo[s:s + rows]
            d2 = sq_dist(self.points[ids][:, None, :], cc[None, :, :])     # as ((p - cc) ** 2).sum(-1), to the bit
            self.settle(ids, cand_all[np.argpartition(d2, k - 1, axis=1)[:, :k]])


def interpolate_at(patches: PatchSet, vertex_values, points, owner=None, normals=None) -> np.ndarray:
    """Bilinear interpolation of per-vertex values (V, k) at points on the surfaces -> (P, k)."""
    return interpolate_located(patches, vertex_values, *locate(patches, points, owner, normals))


def interpolate_located(patches: PatchSet, vertex_values, idx, uv) -> np.ndarray:
    """(P, k) per-vertex values (V, k) at points already located (``idx``, ``uv`` of
    :func:`locate`: geometry only, so a relight can keep them)."""
    return interpolate_corners(vertex_values, located_corners(patches, idx, uv))


def interpolate_corner_values(corner_values, idx, uv) -> np.ndarray:
    """(P, k) per-corner values (N, 4, k) (``BakeResult.corner_values``: each element corner its
    own) at points already located (``idx``, ``uv`` of :func:`locate`), bilinear in the element."""
    return bilinear(np.asarray(corner_values, dtype=np.float64)[idx], uv[:, :1], uv[:, 1:])


def located_corners(patches: PatchSet, idx, uv):
    """(corner vertex ids (4, P) intp, bilinear weights (4, P)) of points located at ``idx``,
    ``uv`` (:func:`locate`): what :func:`interpolate_corners` reads, geometry only (a relight
    keeps it and only reads its new values through it)."""
    polys = patches.polys[idx].copy()
    tri = polys[:, 3] < 0
    polys[tri, 3] = polys[tri, 2]
    u, v = uv[:, 0], uv[:, 1]
    w = np.stack([(1 - u) * (1 - v), u * (1 - v), u * v, (1 - u) * v])
    return np.ascontiguousarray(polys.T, dtype=np.intp), w


def interpolate_corners(vertex_values, corners) -> np.ndarray:
    """(P, k) the bilinear interpolation of per-vertex values (V, k) through ``corners``
    (:func:`located_corners`): the same arithmetic as :func:`..util.geometry.bilinear` on the corners' values,
    bit for bit, a band's corners taken and weighted as contiguous rows (weighing the (P, 1)
    weights into (P, k) corner values, broadcast along the short axis, was most of it)."""
    cols, w = corners
    vt = np.ascontiguousarray(np.asarray(vertex_values, dtype=np.float64).T)      # (k, V)
    total = vt.take(cols[0], axis=1) * w[0]
    for c in range(1, 4):
        total += vt.take(cols[c], axis=1) * w[c]
    return np.ascontiguousarray(total.T)
