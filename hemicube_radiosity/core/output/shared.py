"""Final gather rays shared between the output vertices at one place (a flat-shaded mesh's corners).

A flat-shaded mesh splits every vertex into one output vertex per face normal around it (a
scanned bunny: 200,000 vertices at 35,000 places, about six at each). Each would cast the
gather's ``R`` cosine rays of its own (:func:`.gather.gather_matrix`), six times the rays of the
surface's shape. Here the vertices at one place whose normals are close (a *cluster*) share
one set of ``R`` rays instead: member ``a`` of a cluster of ``k`` casts the pattern's rays
``a, a + k, a + 2k, ...`` (``r_a`` of them, :func:`.hemisphere.cosine_lattice`) in its own normal's frame,
from its own point, and every member reads every ray of the cluster, weighted by the balance
heuristic of the mixture of the members' cosine lobes (multiple importance sampling with
``r_l`` samples from lobe ``l``):

    w_i(d) = cos_i+(d) / sum_l r_l cos_l+(d),    L_i ~ sum_d w_i(d) L(d) / sum_d w_i(d)

(``cos+``: the cosine with the member's normal, 0 below its plane: a ray under a member's face
counts nothing for it). The weights are normalised to sum to 1 per member (self-normalised
importance sampling: a uniform surrounding of radiance L gives exactly L, as the unshared
gather does; over the lattice's rotations the bias is of the order of 1/R). With one member,
or with every member's normal the same, each ray weighs 1 / R: the unshared estimate.

What a vertex reads is the light arriving at its cluster's points within a hair: each ray
starts from its own member's point (``xv``, moved a hundredth into its face,
:func:`..light.emitters.vertex_frames`) a hair off along its normal (:func:`.rays.ray_offsets`).
Vertices share only where that is the same light: at one position, of one object, both
on an open element (:func:`.sides.open_elements`), normals within :data:`SHARE_COSINE` of the
cluster's first, and nothing between their points (a partition standing on a floor's edge
parts the floor's corners). On the bench's bunny (``bench/real_scenes.py --scenes
stanford_bunny``: 201,570 vertices at 35,887 clusters) the vertex stage took half the CPU
time (20.5 s -> 10.7 s) at 1.07% RMS against Cycles instead of 1.03% (Cycles at 64 samples:
1.34%): each member's estimate is noisier than its own lattice's (the sky's share, 0.84%
against 0.47%: the members' sub-lattices in their own frames do not stratify as one lattice),
though the mixture wastes little (Kish's effective count 0.98 R on the median).

Units: directions unit vectors, points world units; weights are shares of a vertex's rays.
"""
from __future__ import annotations

import numpy as np

from ..rays import mesh_offsets, ray_offsets
from ..hemisphere import closed_rays
from ..runtime.cache import array_key, cache_key, cached, geometry_key
from ..runtime.parallel import ordered_map, resolve_workers
from ..util.geometry import in_frames, tangent_frames
from ..util.sampling import cosine_directions, jittered_grid
from ..util.sparse import summed_entries
from ..util.unique import unique_ints

__all__ = ["MIN_JOINED", "SHARE_COSINE", "Sharing", "share_corners", "corner_sharing", "cast_shared", "joined_ahead",
           "shared_open_fraction"]

#: Vertices at one place share their rays when their normals are within this cosine of their
#: cluster's first (45 degrees): on the bunny the members' effective sample counts (Kish's,
#: ``(sum w)^2 / sum w^2``) stay at 0.98 R on the median, 0.86 R at the 5th percentile.
SHARE_COSINE = np.sqrt(0.5)
#: ... and only where at least this share of the vertices would cast no rays of their own: the
#: gather then casts in cluster order and reorders G and its hits back (0.5 s of 13M entries on
#: the bunny, whose 82% of vertices join another's rays); the truck town, where 7.5% would,
#: took 4% more CPU in its vertex stage shared than not.
MIN_JOINED = 0.25


class Sharing:
    """How the points of a gather share their rays: ``order`` (P,) the points cluster by
    cluster (each cluster's members in a run, the clusters by size, then in the order of their
    first point),
    and in that order ``member`` (P,) each point's place in its cluster, ``size`` (P,) its
    cluster's member count, ``first`` (P,) its cluster's first place in the order. ``clusters``
    (C + 1,) the places where the clusters start, and P at the end."""

    def __init__(self, order, cluster_of_sorted):
        self.order = np.asarray(order, np.int64)
        self.cluster_of = c = np.asarray(cluster_of_sorted, np.int64)
        P = len(c)
        new = np.ones(P, bool)
        new[1:] = c[1:] != c[:-1]
        self.clusters = np.append(np.flatnonzero(new), P)
        sizes = np.diff(self.clusters)
        self.first = np.repeat(self.clusters[:-1], sizes)
        self.size = np.repeat(sizes, sizes)
        self.member = np.arange(P) - self.first
        self.position = np.empty(P, np.int64)              # each point's place in the order
        self.position[self.order] = np.arange(P)

    def starts(self, step):
        """(starts list, ends dict): chunks of whole clusters of one size, of about ``step``
        clusters each (a chunk casts ``step`` x R rays)."""
        c = self.clusters[:-1]
        size = np.diff(self.clusters)
        new = np.ones(len(c), bool)
        new[1:] = size[1:] != size[:-1]
        run = np.cumsum(new) - 1                                     # each cluster's size run
        at = np.arange(len(c)) - np.flatnonzero(new)[run]           # its place in the run
        cuts = np.append(c[(at % max(1, int(step))) == 0], self.clusters[-1])
        return cuts[:-1].tolist(), dict(zip(cuts[:-1].tolist(), cuts[1:].tolist()))

    def restore(self, counts, cols, vals, sky, H=None):
        """G's rows (``counts`` (P,) entries per row, ``cols``, ``vals``), ``sky`` (P,) and the
        hits ``H`` (h, 6) or None, made in :attr:`order`, put back in the points' own order:
        (indptr (P + 1,), cols, vals, sky, H with its rows' point ids and order restored)."""
        counts = np.asarray(counts, np.int64)
        starts = np.concatenate([[0], np.cumsum(counts)])
        back = self.position                                # row r's source row in the order
        n_new = counts[back]
        indptr = np.concatenate([[0], np.cumsum(n_new)])
        take = _block_index(starts[back], n_new, int(indptr[-1]))
        cols, vals = np.asarray(cols).take(take), np.asarray(vals).take(take)
        sky = np.asarray(sky)[back]
        if H is None:
            return indptr, cols, vals, sky, None
        h_all = np.bincount(H[:, 0].astype(np.int64), minlength=len(back))    # per place in the order
        h_counts = h_all[back]
        H = H.take(_block_index(np.concatenate([[0], np.cumsum(h_all)])[back], h_counts, len(H)), axis=0)
        H[:, 0] = np.repeat(np.arange(len(back)), h_counts)         # each block's own point
        return indptr, cols, vals, sky, H


def _block_index(src_starts, lengths, total):
    """(total,) the index that lays blocks ``src_starts[i]:src_starts[i] + lengths[i]`` end to
    end, in the order of i: ones, each block's first the jump from where the one before ended,
    summed (one pass; a repeat and an arange over tens of millions of entries took twice as long)."""
    if total == 0:
        return np.zeros(0, np.int64)
    src = np.asarray(src_starts, np.int64)
    lengths = np.asarray(lengths, np.int64)
    full = lengths > 0
    src, lengths = src[full], lengths[full]
    dst = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    step = np.ones(total, np.int64)
    step[dst] = src - np.concatenate([[1], src[:-1] + lengths[:-1]]) + 1
    step[0] = src[0]
    return np.cumsum(step, out=step)


def share_corners(mesh, points, normals, scene, opened=None, min_cos=SHARE_COSINE):
    """The :class:`Sharing` of a gather at the vertices of ``mesh`` (a PatchSet: ``points``
    (V, 3) and unit ``normals`` (V, 3) its vertices' evaluation points), or None where fewer
    than :data:`MIN_JOINED` of them would join another's rays (a smooth mesh: every vertex
    casts its own rays, as before). ``scene``:
    Embree scene of ``mesh`` (``occluded``); ``opened`` (N,) or None:
    :func:`.sides.open_elements` (a vertex of a buried element shares nothing)."""
    polys = mesh.polys
    V = len(mesh.verts)
    p, c = np.nonzero(polys >= 0)
    v = polys[p, c]
    ok = np.ones(V, bool)
    if opened is not None:
        ok[v[np.asarray(opened)[p] <= 0]] = False
    owner = np.full(V, -1, np.int64)
    owner[v] = mesh.owner[p]
    ok &= (owner >= 0) & np.all(np.isfinite(normals), axis=1) & (np.linalg.norm(normals, axis=1) > 0.5)
    cand = np.flatnonzero(ok)
    if len(cand) < 2:
        return None
    _, place, counts = unique_ints(_place_keys(mesh.verts[cand], owner[cand]), return_inverse=True,
                                   return_counts=True)
    shared = counts[place] > 1
    if shared.sum() - np.count_nonzero(counts > 1) < MIN_JOINED * V:
        return None                        # too few could join (at most all at a place but one)
    cand, place = cand[shared], place[shared]
    order = np.lexsort((cand, place))
    cand, place = cand[order], place[order]                # candidates by place, then vertex id
    cluster = np.arange(V)                                 # each vertex its own, unless joined
    free = np.ones(len(cand), bool)
    x = np.asarray(points, np.float64)
    n = np.asarray(normals, np.float64)
    lifted = x + mesh_offsets(mesh)[np.maximum(owner, 0)][:, None] * n      # the rays' starts
    while free.any():
        idx = np.flatnonzero(free)
        grp = place[idx]
        head = np.ones(len(idx), bool)
        head[1:] = grp[1:] != grp[:-1]
        lead = idx[np.maximum.accumulate(np.where(head, np.arange(len(idx)), 0))]
        a, b = cand[lead], cand[idx]
        join = (np.einsum("ij,ij->i", n[a], n[b]) >= min_cos) & np.all(mesh.verts[a] == mesh.verts[b], axis=1)
        test = np.flatnonzero(join & ~head)
        if test.size:
            join[test] &= ~_parted(scene, x[a[test]], x[b[test]], lifted[a[test]], lifted[b[test]],
                                   n[a[test]] + n[b[test]])
        join |= head
        cluster[b[join]] = a[join]
        free[idx[join]] = False
    sizes = np.bincount(cluster, minlength=V)
    if V - np.count_nonzero(sizes) < MIN_JOINED * V:
        return None                        # too few rays saved for the reordering
    # clusters by size (a chunk casts clusters of one size), then in the order of their first
    # vertex (their lead: the smallest id at its place not joined before); members by vertex id
    order = np.lexsort((np.arange(V), cluster, sizes[cluster]))
    return Sharing(order, cluster[order])


def _place_keys(verts, owner):
    """(V,) int64: one key per (object, position), from the coordinates' bits (equal positions,
    equal keys; two places on one key, about one in 2^64, are told apart where they are read)."""
    bits = np.ascontiguousarray(np.asarray(verts, np.float64) + 0.0).view(np.int64)   # -0.0 as 0.0
    k = np.asarray(owner, np.int64) * np.int64(-7046029254386353131)
    for c, m in enumerate((-4658895280553007687, 2685821657736338717, -8796714831421723037)):
        k = (k ^ bits[:, c]) * np.int64(m)
    return k


def joined_ahead(mesh) -> int:
    """About how many vertices of ``mesh`` cast no gather rays of their own (:func:`share_corners`,
    counted before the output stage: the forecast's, :mod:`..runtime.forecast`): those at the
    place of another vertex of their object whose face normal is within :data:`SHARE_COSINE`
    of the first's there (by vertex id; neither buried elements nor partitions are looked for),
    0 where fewer than :data:`MIN_JOINED` of them would."""
    p, c = np.nonzero(mesh.polys >= 0)
    v = mesh.polys[p, c]
    V = len(mesh.verts)
    owner = np.full(V, -1, np.int64)
    owner[v] = mesh.owner[p]
    n = np.zeros((V, 3))
    n[v] = mesh.normals[p]
    _, first, place = unique_ints(_place_keys(mesh.verts, owner), return_index=True, return_inverse=True)
    lead = first[place]
    joined = int(((lead != np.arange(V)) & (np.einsum("ij,ij->i", n, n[lead]) >= SHARE_COSINE) & (owner >= 0)).sum())
    return joined if joined >= MIN_JOINED * V else 0


def _parted(scene, xa, xb, la, lb, nsum):
    """(m,) bool: another surface lies between the points ``xa`` and ``xb`` (m, 3) of a place,
    tested from their ray starts ``la``, ``lb`` lifted along their mean normal (``nsum``
    normalised) by their distance times a hundredth plus the sine of half the angle between
    their normals (over a convex edge the straight segment would pass under the faces)."""
    m = nsum / np.maximum(np.linalg.norm(nsum, axis=1, keepdims=True), 1e-300)
    half = np.sqrt(np.clip(1.0 - np.einsum("ij,ij->i", nsum, nsum) / 4.0, 0.0, 1.0))
    h = np.linalg.norm(xb - xa, axis=1) * (0.01 + half)
    a, b = la + h[:, None] * m, lb + h[:, None] * m
    return np.asarray(scene.occluded(a, b - a, np.ones(len(a))), bool)


def corner_sharing(cache, mesh, points, normals, opened=None):
    """:func:`share_corners` of the vertices of ``mesh`` at ``points`` with ``normals``, kept in
    ``cache`` (geometry only: the gather and the vertices' open fractions ask for the same; a
    smooth mesh's None is kept too, as an empty array)."""
    def make():
        from ..rays import embree_scene
        sh = share_corners(mesh, points, normals, embree_scene(mesh), opened)
        return np.zeros(0, np.int64) if sh is None else np.stack([sh.order, sh.cluster_of])
    key = cache_key(geometry_key(mesh) + array_key(np.asarray(points, np.float64))
                    + array_key(np.asarray(normals, np.float64))
                    + (b"" if opened is None else array_key(np.asarray(opened, np.float64))),
                    ("corner-sharing", float(SHARE_COSINE)))
    code = cached(cache, key, make)
    return None if code.size == 0 else Sharing(code[0], code[1])


def _cluster_rays(share, s, e, local, points, normals, eps):
    """The rays of the clusters of one size k at places ``s:e`` of ``share``'s order (``points``,
    ``normals``, ``eps`` (P, 1) in that order): member a casts the pattern's rays a, a + k, ...
    (``local`` (R, 3)) in its normal's frame from its point ``eps`` off along its normal. Returns
    (k, C clusters, directions (C R, 3), origins (C R, 3), weights (C, R, k)): each ray's weight
    for each member of its cluster (module docstring; 1 / R where k is 1)."""
    R = len(local)
    k = int(share.size[s])
    C = (e - s) // k
    n = normals[s:e].reshape(C, k, 3)
    lifted = (points[s:e] + eps[s:e] * normals[s:e]).reshape(C, k, 3)
    f = tangent_frames(normals[s:e]).reshape(C, k, 3, 3)
    d = np.empty((C, R, 3))
    o = np.empty((C, R, 3))
    for a in range(k):                     # member a casts the pattern's rays a, a + k, ...
        d[:, a::k] = in_frames(local[a::k], f[:, a])
        o[:, a::k] = lifted[:, a, None]
    if k == 1:                             # alone: each ray weighs 1 / R, as unshared
        w = np.full((C, R, 1), 1.0 / R)
    else:
        w = np.matmul(d, n.transpose(0, 2, 1))                       # (C, R, k) cosines
        np.maximum(w, 0.0, out=w)
        r = np.bincount(np.arange(R) % k, minlength=k).astype(np.float64)    # rays per lobe
        w /= (w @ r)[..., None]                        # the balance heuristic (its own lobe's > 0)
        w /= w.sum(axis=1, keepdims=True)
    return k, C, d.reshape(-1, 3), o.reshape(-1, 3), w


def shared_open_fraction(patches, points, normals, scene, reach, share, rays=16, seed=0, workers=1):
    """:func:`.hemisphere.open_fraction` (the same jittered pattern, seeded; start offsets
    :func:`.rays.ray_offsets`) at the vertices of ``share`` (a :class:`Sharing` of ``points``),
    each cluster casting the pattern once between its members, each member's fraction its
    weighted share of its cluster's rays that leave into the open (neither a back face nor
    a surface closer than ``reach``). The same for any ``workers``."""
    points = np.asarray(points, np.float64)[share.order]
    normals = np.asarray(normals, np.float64)[share.order]
    eps = ray_offsets(patches, points, normals, scene=scene)[:, None]
    u, v = jittered_grid(np.random.default_rng(seed), 1, rays)
    local = cosine_directions(np.stack([u[0], v[0]], -1))                       # (R, 3)
    out = np.empty(len(points))
    workers = resolve_workers(workers)
    C = len(share.clusters) - 1
    starts, ends = share.starts(max(1, min((1 << 20) // len(local), -(-C // (2 * workers)))))
    if workers > 1 and len(starts) > 1:
        scene.intersect(points[:1], normals[:1])      # commit the scene before threads share it

    def chunk(s):
        k, C, d, o, w = _cluster_rays(share, s, ends[s], local, points, normals, eps)
        closed = closed_rays(patches, d, *scene.intersect(o, d), reach)
        out[s:ends[s]] = np.einsum("cr,crk->ck", (~closed).reshape(C, -1).astype(np.float64), w).reshape(-1)
    for _ in ordered_map(chunk, starts, workers if len(starts) > 1 else 1):
        pass
    return out[share.position]


def cast_shared(share, ends, weights, hit_dtype, patches, params, scene, points, normals, eps, local, hits, out, s):
    """:func:`.gather._cast` for points in the order of ``share`` (a :class:`Sharing`; ``points``,
    ``normals``, ``eps`` (P, 1) already in it): the clusters of the chunk ``s:ends[s]`` (all of
    one size k) each cast the pattern ``local`` (R, 3) once between their members, and each
    member reads every ray of its cluster by its weight (module docstring). ``weights``:
    :func:`.gather.surface_weights`; ``hit_dtype`` the hits' dtype; ``out``: the forked
    workers' shared rows (``write(s, cols, vals, H)``) or None. Returns (s, m, sky (m,),
    entries per row (m,), columns (e,) int32, values (e,) float32, hits (h, 6) or None): each
    hit once per member that reads it, rows ``(point id, patch id, x, y, z, weight x R)`` in
    point order (a member's rays in the pattern's order); with ``out``, the entry and hit
    counts in place of the columns and hits."""
    e = ends[s]
    R = len(local)
    m = e - s
    k, C, d, o, w = _cluster_rays(share, s, e, local, points, normals, eps)
    pid, tfar = scene.intersect(o, d)
    pid = np.asarray(pid)
    hit = pid >= 0
    sky_s = np.einsum("cr,crk->ck", (~hit).reshape(C, R).astype(np.float64), w).reshape(m)
    fr = np.flatnonzero(hit)
    pf = pid[fr]
    df = d.take(fr, axis=0)
    front = np.einsum("ij,ij->i", df, patches.normals.take(pf, axis=0)) < 0
    fr, pf, df = fr[front], pf[front], df[front]
    y = o.take(fr, axis=0) + np.asarray(tfar, np.float64)[fr, None] * df
    ids, wt = weights(params, patches.polys, pf, y)
    # each front hit for each member that reads it, by member, rays in the pattern's order
    at = np.full(C * R, -1, np.int64)                                 # each ray's front hit
    at[fr] = np.arange(len(fr))
    W = np.ascontiguousarray(w.transpose(0, 2, 1))                    # (C, k, R)
    read = (W > 0) & (at >= 0).reshape(C, 1, R)
    c, a, j = np.nonzero(read)
    pp, ph, pw = c * k + a, at[c * R + j], W[read]
    H = None
    if hits:
        H = np.column_stack([s + pp, pf[ph], y[ph], pw * R]).astype(hit_dtype)
    counts, cols, vals = summed_entries(pp, ids[ph], wt[ph] * pw[:, None], len(patches.verts), m)
    if out is not None:
        ne, nh = out.write(s, cols, vals, H)
        return s, m, sky_s, counts, ne, None, nh
    return s, m, sky_s, counts, cols, vals, H
