"""Form factors by the hemi-cube (Cohen & Greenberg 1985), rasterised in NumPy: the driver.

For every receiver patch i a hemi-cube is put at the patch centre, moved a tiny distance along
the normal (as far as a ray from it starts, :func:`.rays.ray_offsets`: its object's, at least 64
float32 steps of the centred coordinates drawn) so that the patch and its coplanar neighbours lie
below the horizon. The scene's vertices are transformed into the
receiver frame (:mod:`.pixels`, normal = +Z) once per receiver, put on the faces, culled and
clipped (:mod:`.frustum`) and drawn into the receiver's item buffer (:mod:`.raster`). Each
fragment carries the reciprocal depth ``1/w`` of the patch plane at that pixel (exact for planar
patches, interpolated per pixel), and the item buffer keeps the nearest fragment per pixel.
Summing the delta form factors (:mod:`.deltaff`) per visible patch gives a row of F (eq. 7). A
patch seen from behind writes its depth (it occludes) but adds to neither F nor the sky; a pixel
that sees nothing adds its weight to ``sky[i]``.

All five faces share one item buffer of width R (the pixel order of
:func:`.pixels.pixel_weights`). Several receivers are processed per NumPy call (their buffers
stacked), which amortises the interpreter overhead; batches of receivers go to workers, come
back in receiver order (F is bit-identical for any worker count) and are assembled into a
:class:`~.sparse.CSR`.
Frames and pixel order are the ones :mod:`.embree` casts its rays with.

See-through patches (``PatchSet.see_through``: alpha cut-outs, transparent shaders) pass what
lies behind them: each receiver draws a second item buffer without them (:func:`_behind`), and
a pixel whose nearest item is a see-through patch (or cluster) of mean transmittance t gives
1 - t of its weight to that patch and t to the item of the second buffer there, or to the sky.
Rows then still sum to 1 at most. F so made reads the see-through patches' light over their
solid part (their colour, not their mean over the holes): ``meta['passes']`` (n,) holds each
receiver's t, and the solve (:mod:`..solve.stage`) solves for that light, its reflectance its
colour (the solve's reflectance over 1 - t), and takes each patch's mean back. One layer: a
second see-through surface behind the first passes all of it; a see-through patch seen from
behind (a closed mesh's, whose faces have no backs) still blocks.
"""
from __future__ import annotations

from contextlib import closing
from dataclasses import replace
from functools import partial
from time import perf_counter

import numpy as np

from .deltaff import delta_form_factors
from .drawn import draw_set
from .frustum import (
    FACE_V0, clip_to_faces, corner_tests, depth_planes, face_uvw, fans, hull_misses_centres,
    plane_distance, project, vertex_codes, vertex_faces, vertex_projection
)
from .pixels import pixel_weights, receiver_frames
from .raster import ID_MASK, can_cover, empty_key, rasterise
from ..mesh.patches import PatchSet
from ..runtime.parallel import ordered_map, resolve_workers
from ..runtime.progress import Cancelled, Ticker
from ..rays import ray_offsets
from ..util.sparse import CSR

__all__ = ["hemicube_form_factors", "receiver_ids"]

#: Near-plane distance, as a fraction of the scene's bounding-box diagonal.
NEAR = 1e-7
#: Draw a planar cluster of pieces as its outline (:mod:`.drawn`): the same pixels, drawn at a
#: cost that follows the clusters, not the modelling. False draws every piece (for comparison).
DRAW_OUTLINES = True
#: Leave out pieces crossing a face's frustum whose corners' projections, widened by
#: :data:`.frustum.CLIP_MARGIN` pixels, hold no candidate pixel, before clipping
#: (:func:`.frustum.hull_misses_centres`).
CLIP_CULL = True
#: Bound on receivers x patches transformed per batch (about 85 bytes each). Only a few passes
#: run over every pair (the culled ones are never listed), so what a small batch saves in cache
#: it loses in per-call overhead of the rasteriser's row and span classes (16 to 32 receivers a
#: batch did best on a 32k-piece mesh). With several workers each takes a share of it.
PATCHES_PER_BATCH = 1 << 20
#: Bound on receivers x hemi-cube pixels per batch (8-byte item-buffer keys): 85 receivers at
#: R = 32. Scenes of few polygons are bound by this; larger batches of them ran slower.
PIXELS_PER_BATCH = 1 << 18
#: The forecast's sample (``probe``): batches of receivers spread evenly through those asked for,
#: drawn first and timed, until this many seconds or this share of the receivers; not done
#: below ``PROBE_MIN_BATCHES`` batches' worth of receivers (the whole is as quick).
PROBE_SECONDS = 0.3
PROBE_SHARE = 0.02
PROBE_MIN_BATCHES = 16


class _Scene:
    """What every batch needs: patch geometry centred on the scene, in float32, and the constants.

    verts (V, 3) float32, centred; corner_ids (N, 4) int64 (triangles repeat corner 2) and
    its transpose corners_t (4, N);
    normals (N, 3) float64; plane (N,) float64 ``n . c`` (centred); eyes (K, 3) float64 (centred,
    offset along the receivers' normals); near (float32); weights (3 R^2,) pixel delta form
    factors; item_of (N,) the receiver (cluster) each drawn patch belongs to, or None when every
    patch is its own receiver (K = N).
    """

    def __init__(self, patches, resolution, clusters=None, eyes=None):
        verts = np.asarray(patches.verts, dtype=np.float64)
        lo, hi = verts.min(axis=0), verts.max(axis=0)
        origin = 0.5 * (lo + hi)
        scale = float(np.linalg.norm(hi - lo)) or 1.0
        self.item_of = None
        drawn = patches
        if clusters is not None:
            drawn = draw_set(patches, clusters) if DRAW_OUTLINES else patches
            self.item_of = np.asarray(drawn.item_of if DRAW_OUTLINES else clusters.of, dtype=np.int64)
        self.n = len(drawn)
        self.resolution = resolution
        self.verts = (np.asarray(drawn.verts, dtype=np.float64) - origin).astype(np.float32)
        polys = np.asarray(drawn.polys)
        self.corner_ids = np.where(polys < 0, polys[:, 2:3], polys)
        self.corners_t = np.ascontiguousarray(self.corner_ids.T)         # (4, N)
        self.normals = np.asarray(drawn.normals, dtype=np.float64)
        self.plane = np.einsum("ij,ij->i", self.normals, drawn.centers - origin)
        self.eyes = eyes
        if eyes is None:
            rc, rn = (patches.centers, patches.normals) if clusters is None else (clusters.centers, clusters.normals)
            lift = ray_offsets(patches, owner=patches.owner if clusters is None else clusters.owner)
            lift = np.maximum(lift, 64 * 2.0 ** -23 * np.abs(rc - origin).max(axis=1, initial=0.0))
            self.eyes = rc - origin + lift[:, None] * np.asarray(rn, dtype=np.float64)
        self.near = np.float32(NEAR * scale)
        self.weights = pixel_weights(resolution)
        self.behind = self.passes = None          # see-through patches: :func:`_behind`


def _behind(scene, patches, clusters):
    """Give ``scene`` (a :class:`_Scene` of ``patches``) what its see-through patches pass:
    ``passes`` (n,) the mean transmittance of each receiver (patch, or cluster: its pieces'
    area-weighted mean), and ``behind``, a :class:`_Scene` of the other patches (every piece of a
    cluster that passes any light left out) seen from the same eyes, its items numbered as the
    receivers. Nothing when no patch passes light."""
    st = getattr(patches, "see_through", None)
    if st is None:
        return
    t = st.patch_transmit(patches)
    if clusters is not None:
        t = clusters.mean(t, patches.areas)
    keep = ~(t > 0) if clusters is None else ~(t > 0)[np.asarray(clusters.of, np.int64)]
    if keep.all() or not keep.any():           # (every patch see-through: they block, as before)
        return
    behind = _Scene(patches.take(keep), scene.resolution, None if clusters is None else replace(clusters, of=clusters.of[keep]),
                    eyes=scene.eyes)
    if clusters is None:
        behind.item_of = np.flatnonzero(keep)
    scene.behind, scene.passes = behind, t


def _batch_item_buffer(scene, recv, frames, eyes):
    """Item buffers of a batch of receivers: keys (B, 3 R^2) int64 (see :func:`empty_key`)."""
    R = scene.resolution
    B, N = len(recv), scene.n
    V = len(scene.verts)
    P = 3 * R * R
    fr = frames[recv]
    rows = fr.reshape(B * 3, 3).astype(np.float32)
    local = rows @ scene.verts.T                                     # (3B, V)
    local -= np.einsum("bij,bj->bi", fr, eyes[recv]).reshape(B * 3, 1).astype(np.float32)
    local = local.reshape(B, 3, V)
    x, y, z = local[:, 0], local[:, 1], local[:, 2]
    vface, m = vertex_faces(x, y, z, scene.near)                    # (B, V)
    vpx, vpy = vertex_projection(x, y, z, vface, m, R)
    visible, whole, empty, low = corner_tests(
        np.take(vertex_codes(vface, z, vpx, vpy), scene.corners_t, axis=1))
    if R > 0xFFF - 1:                         # cells past 12 bits: no cull by cell
        empty[:] = False
    if scene.item_of is None:
        visible[np.arange(B), recv] = False
    else:                                     # a cluster does not see its own pieces
        visible &= scene.item_of[None, :] != recv[:, None]
    face_rows = np.array([R, R // 2, R // 2, R // 2, R // 2])
    face_base = np.array([0, R * R, 3 * R * R // 2, 2 * R * R, 5 * R * R // 2])
    keys = np.full(B * P, empty_key(N), dtype=np.int64)
    ctx = (scene, keys, fr, eyes[recv], face_rows, face_base)

    # patches wholly inside one face's frustum, drawn in one pass with the clipped ones
    # (fewer, larger rasteriser calls)
    todo = [_whole_pairs(ctx, whole & visible & ~empty, low, vpx, vpy, V)]
    bi, ni = np.nonzero(visible & ~whole)
    if bi.size:
        todo.append(_clipped_pairs(ctx, bi, ni, x, y, z, V))
    bi, ni, d, faces = (np.concatenate([t[k] for t in todo]) for k in range(4))
    px = [np.concatenate(c) for c in zip(*(t[4] for t in todo))]
    py = [np.concatenate(c) for c in zip(*(t[5] for t in todo))]
    _draw(ctx, bi, ni, d, faces, px, py)
    return keys.reshape(B, P)


def _whole_pairs(ctx, inside, low, vpx, vpy, V):
    """The (receiver, patch) pairs ``inside`` (B, N) bool, each wholly inside the frustum of one
    hemi-cube face (``low`` - 9), drawn from their corners' own projections ``vpx``, ``vpy``
    (B, V): (receivers, patches, plane distances, faces, [4 x px], [4 x py]), each (M,), of those
    that can cover a pixel centre and are not edge-on."""
    scene, face_rows = ctx[0], ctx[4]
    R = scene.resolution
    bi, ni = np.nonzero(inside)
    vpx, vpy = vpx.ravel(), vpy.ravel()
    faces = (low[bi, ni] - 9).astype(np.intp)
    corner = np.take(scene.corners_t, ni, axis=1) + bi * V            # (4, M)
    px, py = [vpx[c] for c in corner], [vpy[c] for c in corner]
    keep = np.flatnonzero(can_cover(px, py, face_rows[faces], R))
    d = _pair_dist(ctx, bi[keep], ni[keep])
    seen = np.abs(d) > scene.near                                     # not edge-on
    keep = keep[seen]
    return bi[keep], ni[keep], d[seen], faces[keep], [p[keep] for p in px], [p[keep] for p in py]


def _clipped_pairs(ctx, bi, ni, x, y, z, V):
    """The pairs (receiver ``bi``, patch ``ni``) (S,) not wholly inside one face's frustum,
    clipped against every face whose frustum they may reach (receiver-local corners ``x``, ``y``,
    ``z`` (B, V)): (receivers, patches, plane distances, faces, [4 x px], [4 x py]) of the clipped
    pieces as fans of triangles, each a quad repeating its last corner."""
    scene, face_rows = ctx[0], ctx[4]
    R = scene.resolution
    corner = np.take(scene.corners_t, ni, axis=1) + bi * V
    xyz = [c.ravel()[corner] for c in (x, y, z)]                     # each (4, S)
    polys, faces, pairs = [], [], []
    for f in range(5):
        u, v, w = face_uvw(f, *xyz)
        # wholly outside one of the face's clip planes: clipping would leave nothing
        out = None
        for p in range(5):
            d = plane_distance(u, v, w, FACE_V0[f], p, scene.near) < 0
            d = d[0] & d[1] & d[2] & d[3]
            out = d if out is None else out | d
        if CLIP_CULL:
            out |= hull_misses_centres(u, v, w, f, R)
        s = np.flatnonzero(~out)
        polys.append(np.stack([u[:, s], v[:, s], w[:, s]], axis=-1).transpose(1, 0, 2))
        faces.append(np.full(s.size, f))
        pairs.append(s)
    fi = np.concatenate(faces)
    si = np.concatenate(pairs)
    poly, count, src = clip_to_faces(np.concatenate(polys), fi, scene.near)
    bi, ni, fi = bi[si[src]], ni[si[src]], fi[src]
    d = _pair_dist(ctx, bi, ni)
    seen = np.flatnonzero(np.abs(d) > scene.near)                    # not edge-on
    bi, ni, d, fi, poly, count = bi[seen], ni[seen], d[seen], fi[seen], poly[seen], count[seen]
    px, py, m = fans(*project(poly, fi, R), count)
    keep = np.flatnonzero(can_cover(px, py, face_rows[fi[m]], R))
    m = m[keep]
    # fan triangles as quads repeating their last corner (as triangle patches are): a
    # zero-length edge excludes nothing and adds 0 to the area, so they cover as before
    px, py = [p[keep] for p in px], [p[keep] for p in py]
    return bi[m], ni[m], d[m], fi[m], px + px[2:], py + py[2:]


def _pair_dist(ctx, bi, ni):
    """``n . (c - eye)`` (M,) float64 of patches ``ni`` seen from batch receivers ``bi``: < 0
    when the front is seen, within ``near`` of 0 when the eye is in the patch plane (edge-on).
    Per pair, the same products and sums as over every pair of the batch (einsum)."""
    scene, eyes = ctx[0], ctx[3]
    return scene.plane[ni] - np.einsum("mj,mj->m", scene.normals[ni], eyes[bi])


def _draw(ctx, bi, ni, d, faces, px, py):
    """Rasterise polygons (pixel coordinates ``px``, ``py`` on ``faces``) of patches ``ni``
    into the item buffers of batch receivers ``bi``; ``d`` is their :func:`_pair_dist`."""
    scene, keys, fr, _, face_rows, face_base = ctx
    N, R = scene.n, scene.resolution
    nl = np.einsum("mjk,mk->jm", fr[bi], scene.normals[ni])          # normals in the frames
    plane = depth_planes(R, nl, d, faces)
    item = np.where(d < 0, ni, N).astype(np.int32)
    rasterise(px, py, face_rows[faces], bi * (3 * R * R) + face_base[faces], plane, item, keys, R)


def _resolve(keys, weights, n, item_of=None):
    """Sum pixel weights per visible front-facing patch (or its receiver ``item_of``, of n).

    Returns F rows (B, n) float64 and sky (B,) float64.
    """
    B = len(keys)
    bins = keys & ID_MASK
    if item_of is not None:                   # drawn piece -> its cluster; back face, sky stay last
        bins = np.concatenate([item_of, [n, n + 1]])[bins]
    bins += (np.arange(B) * (n + 2))[:, None]
    rows = np.bincount(bins.ravel(), weights=np.tile(weights, B), minlength=B * (n + 2))
    rows = rows.reshape(B, n + 2)
    return rows[:, :n], rows[:, n + 1]


def _pass_through(scene, keys, ids, frames, n, rows, sky):
    """Move in ``rows`` (B, n) and ``sky`` (B,) of receivers ``ids`` (B,) what the see-through
    items of their item buffers ``keys`` (B, 3 R^2) pass: at each pixel whose item passes t of
    the light (``scene.passes``), t times its weight from that item to the item there in an item
    buffer of ``scene.behind``, drawn only for the receivers that see such an item."""
    front = _receiver_items(keys, scene.n, n, scene.item_of)
    t = np.concatenate([scene.passes, [0.0, 0.0]])[front]
    see = np.flatnonzero((t > 0).any(axis=1))
    if not see.size:
        return
    behind = _batch_item_buffer(scene.behind, ids[see], frames, scene.eyes)
    t = t[see]
    b, p = np.nonzero(t > 0)
    back = _receiver_items(behind[b, p], scene.behind.n, n, scene.behind.item_of)
    w = t[b, p] * scene.weights[p]
    got = np.bincount(b * (n + 2) + back, weights=w, minlength=see.size * (n + 2)) \
        - np.bincount(b * (n + 2) + front[see][b, p], weights=w, minlength=see.size * (n + 2))
    got = got.reshape(see.size, n + 2)
    moved = rows[see] + got[:, :n]
    moved[np.abs(moved) < 1e-12] = 0.0               # an item wholly passed: no entry left
    rows[see] = moved
    sky[see] += got[:, n + 1]


def _receiver_items(keys, N, n, item_of):
    """The receivers (of n; n: a back face, n + 1: the sky) that item-buffer ``keys`` of a
    scene of N drawn items show."""
    ids = keys & ID_MASK
    if item_of is None:
        return ids
    return np.concatenate([item_of, [n, n + 1]])[ids]


def receiver_ids(n, receivers):
    """Sorted unique receiver ids (all patches when None); ValueError when out of range."""
    if receivers is None:
        return np.arange(n, dtype=np.int64)
    r = np.unique(np.asarray(receivers, dtype=np.int64).reshape(-1))
    if r.size and (r[0] < 0 or r[-1] >= n):
        raise ValueError(f"receiver ids must be in [0, {n}), got {r[0]}..{r[-1]}")
    return r


def _batch_size(n, resolution, requested, workers=1):
    """Receivers per batch over ``n`` drawn items at ``resolution``: ``requested`` (>= 1) or,
    when None, as many as :data:`PATCHES_PER_BATCH` and :data:`PIXELS_PER_BATCH` allow, shared
    among ``workers`` (with several batches drawn at once the peak memory stays one worker's)."""
    if requested is not None:
        if int(requested) < 1:
            raise ValueError(f"batch must be >= 1, got {requested}")
        return int(requested)
    return max(1, max(1, min(PATCHES_PER_BATCH // max(n, 1), PIXELS_PER_BATCH // (3 * resolution ** 2))) // workers)


def hemicube_form_factors(patches: PatchSet, resolution=64, *, rotate_seed=None, receivers=None,
                          progress=None, cancelled=None, batch=None, clusters=None, workers=1,
                          probe=None) -> CSR:
    """Form-factor matrix F by the hemi-cube, one rasterised hemi-cube per receiver.

    Parameters
    ----------
    patches : PatchSet
        Convex planar quads and triangles (as :func:`.subdivide.build_patches` makes them).
    resolution : int
        Pixels across the top face (even); side faces have ``resolution // 2`` rows.
    rotate_seed : int or None
        None: fixed frames; an int turns each receiver's hemi-cube about its normal by a random
        angle (reproducible, see :func:`.pixels.receiver_frames`).
    receivers : array_like of int or None
        Patch ids whose rows are computed; the other rows stay empty and their sky is 0.
    progress : callable(float) or None
        Called now and then with the fraction done.
    cancelled : callable() -> bool or None
        Polled between batches; when it returns True, :class:`progress.Cancelled` is raised.
    batch : int or None
        Receivers per NumPy pass; None picks one whose arrays stay small (tens of MB) and
        mostly in cache.
    clusters : core.mesh.clusters.Clusters or None
        Receivers are these K clusters of the patches (their eye points and normals), and every
        patch is drawn with its cluster's id: F is (K, K) over clusters while visibility sees
        every patch. None: every patch is its own receiver.
    workers : int
        Workers drawing batches of receivers at once (:func:`.parallel.resolve_workers`: 0 = every
        core, 1 = in the calling thread): forked processes on Linux, threads elsewhere
        (:func:`.parallel.ordered_map`). Batches are assembled in receiver order, so F is
        bit-identical for any count; ``progress`` and ``cancelled`` stay on the calling thread.
    probe : callable(float or None) or None
        Called once before the hemi-cubes are drawn with the seconds one receiver took on one
        worker in a sample drawn first (:func:`_probe`: up to ``PROBE_SECONDS``, its rows thrown
        away, F unchanged), or None where there are too few receivers to sample: the forecast's
        measure of this scene (:mod:`..runtime.forecast`).

    Returns
    -------
    CSR
        (N, N) float32 with ``F_ii = 0``, ``meta = {'method': 'hemicube', 'resolution': R,
        'rotate_seed': rotate_seed}`` and ``sky`` (N,) float32, the fraction of each receiver's
        hemisphere (cosine-weighted) that sees no surface.
    """
    R = int(resolution)
    delta_form_factors(R)  # validates the resolution
    n = len(patches) if clusters is None else len(clusters)
    recv = receiver_ids(n, receivers)
    scene, frames = _scene_and_frames(patches, R, clusters, rotate_seed)
    workers = resolve_workers(workers)
    B = _batch_size(scene.n, R, batch, workers)
    rows_of = partial(_batch_rows, scene, frames, n)
    if probe is not None:
        probe(_probe(rows_of, recv, B, cancelled))
    indptr, indices, data, sky = _draw_batches(rows_of, recv, B, n, workers, Ticker(progress, cancelled))
    meta = {"method": "hemicube", "resolution": R, "rotate_seed": rotate_seed,
            **({} if scene.passes is None else {"passes": scene.passes})}
    return CSR(indptr, indices, data, (n, n), meta, sky)


def _scene_and_frames(patches, R, clusters, rotate_seed):
    """The :class:`_Scene` of ``patches`` drawn at resolution ``R`` (with what its see-through
    patches pass, :func:`_behind`) and the receivers' frames (K, 3, 3) float64, orthonormal
    (:func:`.pixels.receiver_frames`: rows the hemi-cube's x, y and the normal; K receivers,
    the patches or their ``clusters``)."""
    scene = _Scene(patches, R, clusters)
    _behind(scene, patches, clusters)
    return scene, receiver_frames(patches.normals if clusters is None else clusters.normals, rotate_seed)


def _draw_batches(rows_of, recv, B, n, workers, ticker):
    """The CSR arrays (:func:`_collect_rows`: indptr (n + 1,) int64, indices (E,) int32, data
    (E,) float32 form factors, sky (n,) float32) of the receivers ``recv`` (r,) int64, sorted,
    of ``n``: their rows made ``B`` receivers a batch by ``rows_of`` (:func:`_batch_rows`) on
    ``workers`` (forked processes where the platform has them), assembled in receiver order
    whatever the count, so F is bit-identical; ``ticker`` is told the receivers done and polls
    for cancellation."""
    ticker.tick(0, recv.size, force=True)
    batches = (recv[lo:lo + B] for lo in range(0, recv.size, B))
    with closing(ordered_map(rows_of, batches, workers, processes=True)) as results:
        return _collect_rows(results, n, recv.size, ticker)


def _probe(rows_of, recv, B, cancelled):
    """Seconds per receiver of ``rows_of`` on this thread, over batches of ``B`` of ``recv``
    spread evenly through it (one receiver of every ``recv.size / (PROBE_MIN_BATCHES B)``),
    until ``PROBE_SECONDS`` or ``PROBE_SHARE`` of them; None below ``PROBE_MIN_BATCHES`` batches'
    worth. ``cancelled``: polled between batches."""
    if recv.size < PROBE_MIN_BATCHES * B:
        return None
    sample = recv[::recv.size // (PROBE_MIN_BATCHES * B)]
    most = max(B, int(PROBE_SHARE * recv.size))
    start, done = perf_counter(), 0
    while done < min(most, sample.size) and (done == 0 or perf_counter() - start < PROBE_SECONDS):
        if cancelled is not None and cancelled():
            raise Cancelled("cancelled")
        batch = sample[done:done + B]
        rows_of(batch)
        done += batch.size
    return (perf_counter() - start) / done


def _batch_rows(scene, frames, n, ids):
    """Rows of F for the receivers ``ids`` (B,) int64, sparse.

    ``frames`` (K, 3, 3) receiver frames; ``n`` receivers in all (K). Returns ids, the entries
    per row (B,) int64, their columns (E,) int32 and form factors (E,) float32 (row by row,
    columns ascending), and sky (B,) float64.
    """
    keys = _batch_item_buffer(scene, ids, frames, scene.eyes)
    rows, sky_b = _resolve(keys, scene.weights, n, scene.item_of)
    if scene.behind is not None:
        _pass_through(scene, keys, ids, frames, n, rows, sky_b)
    r, c = np.nonzero(rows)
    return ids, np.bincount(r, minlength=ids.size), c.astype(np.int32), \
        rows[r, c].astype(np.float32), sky_b


def _collect_rows(results, n, total, ticker):
    """Assemble the :func:`_batch_rows` of batches in ascending receiver order into CSR arrays.

    ``total`` receivers are asked for (``ticker`` is ticked with the count done after every
    batch). Returns indptr (n + 1,) int64, indices (E,) int32, data (E,) float32 and sky (n,)
    float32; rows not asked for stay empty with sky 0.
    """
    sky = np.zeros(n, dtype=np.float32)
    counts = np.zeros(n + 1, dtype=np.int64)
    cols_l, vals_l = [], []
    done = 0
    for ids, cnt, cols, vals, sky_b in results:
        counts[ids + 1] = cnt
        cols_l.append(cols)
        vals_l.append(vals)
        sky[ids] = sky_b
        done += ids.size
        ticker.tick(done, total)
    indices = np.concatenate(cols_l) if cols_l else np.zeros(0, np.int32)
    data = np.concatenate(vals_l) if vals_l else np.zeros(0, np.float32)
    return np.cumsum(counts), indices, data, sky
