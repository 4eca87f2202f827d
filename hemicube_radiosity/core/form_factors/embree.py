"""Form factors by ray casting with Embree (through the optional ``embreex`` package).

Two methods, both returning the same :class:`~.sparse.CSR` as the NumPy rasteriser
(``core/form_factors/hemicube.py``): F_ii = 0, float32 data, ``meta`` and ``sky`` filled.

* :func:`embree_hemicube_form_factors` casts one ray from each receiver's centre through the
  centre of every hemi-cube pixel and gives it that pixel's delta form factor. The item buffer
  of the rasteriser holds, per pixel, the nearest patch seen through the pixel centre, so the
  two methods produce the same rows up to ties at patch edges: this is the cross-check of the
  rasteriser (and of the ray caster).
* :func:`embree_stochastic_form_factors` casts ``rays_per_patch`` cosine-distributed rays
  (stratified in the unit square, a random rotation per receiver), each worth 1/rays.

Rules shared with the rasteriser: a ray that hits the back of a patch is blocked and counts
for nothing (neither F nor sky); a ray that hits nothing adds its weight to ``sky[i]``; a ray
that hits its own receiver is dropped (F_ii = 0). Rays leave from the receiver centre moved a
tiny distance along its normal, so a planar patch never sees itself and a neighbour sharing an
edge is seen as the rasteriser sees it.

All rays of a batch of receivers go to Embree in one ``scene.run`` call, on the cached scene of
:func:`.rays.embree_scene`; directions and frames come from :mod:`.geometry` and :mod:`.hemicube`.
"""
from __future__ import annotations

from contextlib import closing

import numpy as np

from ..util.geometry import tangent_frames
from ..util.sampling import cosine_directions, stratified_unit_square
from .hemicube import receiver_ids
from .pixels import pixel_directions, pixel_weights, receiver_frames
from ..mesh.patches import PatchSet
from ..runtime.parallel import ordered_map, resolve_workers
from ..runtime.progress import Ticker
from ..rays import embree_scene, import_embreex, ray_offsets
from ..util.sparse import CSR
from ..util.unique import unique_ints

__all__ = ["embree_hemicube_form_factors", "embree_stochastic_form_factors", "hemicube_directions"]

#: Rays per ``scene.run`` call (memory: ~60 bytes per ray for inputs and outputs).
RAYS_PER_BATCH = 1 << 18


# --------------------------------------------------------------------------------------------
# Hemi-cube pixel directions (local frame: +Z is the normal)


def hemicube_directions(resolution: int):
    """Unnormalised local directions through every hemi-cube pixel centre, and their weights.

    Returns (dirs (3R^2, 3), weights (3R^2,)): the rasteriser's own pixel order and delta form
    factors (:func:`.pixels.pixel_directions`, :func:`.pixels.pixel_weights`), so the two
    methods sample and weigh the same pixels alike.
    """
    R = int(resolution)
    if R < 2 or R % 2:
        raise ValueError(f"hemi-cube resolution must be an even number >= 2, got {resolution}")
    return pixel_directions(R), pixel_weights(R)


# --------------------------------------------------------------------------------------------
# Shared driver


def _receivers(patches, clusters):
    """(n, centres (n,3), normals (n,3), column of every patch (N,) or None) of the receivers:
    the patches themselves, or their clusters (then a hit on a patch counts for its cluster)."""
    if clusters is None:
        return len(patches), patches.centers, patches.normals, None
    return len(clusters), clusters.centers, clusters.normals, np.asarray(clusters.of, np.int64)


def _cast_rows(patches, recv, local_dirs_fn, rays_per_receiver, progress, cancelled, clusters=None,
               workers=1):
    """Cast every receiver's rays (built by ``local_dirs_fn(batch) -> (B, K, 3) world dirs,
    (B, K) weights``) and accumulate F rows and sky. Returns the CSR arrays (indptr, indices
    int32, data float32) and sky: batches come in receiver order and each is reduced to sorted
    unique (row, column) entries, so the rows are assembled as they come, without a global sort
    (whose temporaries peaked at several times the size of F). ``workers`` threads cast batches
    at once (:func:`.parallel.ordered_map`: still assembled in receiver order, so bit-identical).
    Threads, not the rasteriser's worker processes: Embree traverses without the GIL, so threads
    already scale, and processes gain nothing (their rows are pickled back;
    bench/bench_parallel.py, docs/performance.md 'Both cores')."""
    scene = embree_scene(patches)
    n, centres, normals, column = _receivers(patches, clusters)
    eps = ray_offsets(patches, owner=patches.owner if clusters is None else clusters.owner)[:, None]
    per_batch = max(1, RAYS_PER_BATCH // max(1, rays_per_receiver))
    ticker = Ticker(progress, cancelled)
    sky = np.zeros(n, dtype=np.float64)
    counts = np.zeros(n, dtype=np.int64)
    cols_l, vals_l = [], []
    ticker.tick(0, len(recv), force=True)

    def cast(batch):
        B = len(batch)
        dirs, w = local_dirs_fn(batch)                                   # (B,K,3), (B,K)
        K = dirs.shape[1]
        origin = centres[batch] + eps[batch] * normals[batch]
        o = np.repeat(origin, K, axis=0)
        pid, _ = scene.intersect(o, dirs.reshape(-1, 3))
        w = w.reshape(-1)
        rid = np.repeat(np.arange(B), K)
        miss = pid < 0
        sky_b = np.bincount(rid[miss], weights=w[miss], minlength=B)
        hit = ~miss
        pid_h, rid_h, w_h = pid[hit], rid[hit], w[hit]
        front = np.einsum("ij,ij->i", dirs.reshape(-1, 3)[hit], patches.normals[pid_h]) < 0
        if column is not None:
            pid_h = column[pid_h]
        ok = front & (pid_h != batch[rid_h])
        key = rid_h[ok] * n + pid_h[ok]
        uk, inv = unique_ints(key, return_inverse=True)
        vals = np.bincount(inv.reshape(-1), weights=w_h[ok], minlength=uk.size)
        return (batch, sky_b, np.bincount(uk // n, minlength=B), (uk % n).astype(np.int32),
                vals.astype(np.float32))

    if len(recv):
        scene.intersect(centres[recv[:1]], normals[recv[:1]])  # commit the scene before threads share it
    done = 0
    batches = (recv[start:start + per_batch] for start in range(0, len(recv), per_batch))
    with closing(ordered_map(cast, batches, resolve_workers(workers))) as results:
        for batch, sky_b, cnt, cols, vals in results:
            sky[batch] += sky_b
            counts[batch] = cnt
            cols_l.append(cols)
            vals_l.append(vals)
            done += len(batch)
            ticker.tick(done, len(recv))
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    cat = (lambda l, dt: np.concatenate(l) if l else np.zeros(0, dt))
    return indptr, cat(cols_l, np.int32), cat(vals_l, np.float32), sky


# --------------------------------------------------------------------------------------------
# (a) rays through the hemi-cube pixels


def embree_hemicube_form_factors(patches: PatchSet, resolution=64, *, rotate_seed=None,
                                 receivers=None, progress=None, cancelled=None, clusters=None,
                                 workers=1) -> CSR:
    """Form factors from rays through the hemi-cube pixel centres, weighted by the same delta
    form factors as the rasteriser (``core/form_factors/hemicube.py``), in the same hemi-cube orientation
    (``rotate_seed``: None keeps the fixed frame, an int turns each receiver's hemi-cube about
    its normal by a random angle drawn for all patches).

    ``receivers``: patch ids whose rows are computed (others stay empty). ``progress(f)`` is
    called now and then; ``cancelled()`` is polled between batches (raises ``Cancelled``).
    ``clusters``: receivers are these clusters of the patches, and F is over clusters (see
    :func:`.hemicube.hemicube_form_factors`). ``workers``: threads casting batches of receivers
    (0 = every core, 1 = serial); rows are bit-identical for any count.
    Raises :class:`.rays.EmbreeUnavailable` when embreex cannot be imported.
    """
    import_embreex()
    n, _, normals, _ = _receivers(patches, clusters)
    recv = receiver_ids(n, receivers)
    local, weights = hemicube_directions(resolution)
    frames = receiver_frames(normals, rotate_seed)

    def dirs_fn(batch):
        d = np.einsum("kc,bcj->bkj", local, frames[batch])  # local (x,y,z) -> x u + y v + z n
        return d, np.broadcast_to(weights, (len(batch), weights.size))

    indptr, cols, vals, sky = _cast_rows(patches, recv, dirs_fn, weights.size, progress, cancelled,
                                         clusters, workers)
    meta = {"method": "embree", "resolution": int(resolution), "rotate_seed": rotate_seed,
            "n_patches": n, "n_receivers": int(recv.size), "rays_per_receiver": int(weights.size)}
    F = CSR(indptr, cols, vals, (n, n), meta)
    F.sky = sky.astype(np.float32)
    return F


# --------------------------------------------------------------------------------------------
# (b) stochastic cosine-weighted rays


def embree_stochastic_form_factors(patches: PatchSet, rays_per_patch=512, *, seed=0,
                                   receivers=None, progress=None, cancelled=None, clusters=None,
                                 workers=1) -> CSR:
    """Form factors from ``rays_per_patch`` cosine-distributed rays per receiver, each worth
    1/rays_per_patch (F_ij is the fraction of them whose first hit is the front of patch j).

    Stratified: a jittered grid on the unit square mapped by Malley's method, in a frame turned
    by a random angle per receiver. The standard error of one entry is at most
    sqrt(F (1 - F) / rays_per_patch) (less with stratification). Deterministic for a ``seed``
    whatever ``receivers`` is (each receiver has its own random stream).
    """
    import_embreex()
    k = int(rays_per_patch)
    if k < 1:
        raise ValueError(f"rays_per_patch must be >= 1, got {rays_per_patch}")
    n, _, normals, _ = _receivers(patches, clusters)
    recv = receiver_ids(n, receivers)
    angles = np.random.default_rng([seed, 0x5eed]).uniform(0, 2 * np.pi, n)
    frames = tangent_frames(normals, angles)

    def dirs_fn(batch):
        # one stream per receiver id, so rows do not depend on the batch or receiver set
        u = np.concatenate([stratified_unit_square(np.random.default_rng([seed, int(i)]), 1, k)
                            for i in batch])
        local = cosine_directions(u)                                        # (B,k,3)
        d = np.einsum("bkc,bcj->bkj", local, frames[batch])
        return d, np.full((len(batch), k), 1.0 / k)

    indptr, cols, vals, sky = _cast_rows(patches, recv, dirs_fn, k, progress, cancelled, clusters,
                                         workers)
    meta = {"method": "embree_stochastic", "rays_per_patch": k, "seed": seed,
            "n_patches": n, "n_receivers": int(recv.size)}
    F = CSR(indptr, cols, vals, (n, n), meta)
    F.sky = sky.astype(np.float32)
    return F
