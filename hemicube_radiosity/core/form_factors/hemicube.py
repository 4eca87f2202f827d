"""Form factors by the hemi-cube (Cohen & Greenberg 1985), rasterised in NumPy.

For every receiver patch i a hemi-cube is put at the patch centre, moved a tiny distance along
the normal (``EYE_OFFSET`` times the scene's bounding-box diagonal) so that the patch and its
coplanar neighbours lie below the horizon.  The scene's vertices are transformed into the
receiver frame (normal = +Z) once per receiver, each is assigned the face whose 90-degree frustum
holds it and projected onto that face; a patch is then classified from its corners' faces
(packed into one 32-bit word per patch):

* a patch whose corners all fall in one face's frustum takes its corners' projections directly,
  unless its corners all lie in one pixel cell column or row (the word holds each corner's
  cell, :func:`_vertex_codes`): then it covers no pixel centre and is culled before it is
  listed (on Suzanne with a level-3 Subdivision Surface, 32.6k pieces, about 90% of the pieces
  a hemi-cube holds are too small to cover a centre; culled on the per-pair words rather
  than after projecting and setting up each, and with the larger batches that allows, the
  form-factor stage went from 26 s to about 5 s on one core);
* a patch wholly below the horizon is culled;
* the others are clipped (Sutherland-Hodgman, vectorised over polygons) against the frustum of
  every face they may touch (the near plane and the horizon included), each polygon only by
  the planes it crosses, and the clipped polygons are rasterised as triangle fans; a polygon
  whose corners' projections on a face hold no candidate pixel is left out of that face
  before clipping (:func:`_hull_misses_centres`).

Every cull takes only polygons the rasteriser's own candidate range (:func:`_pixel_range`)
rejects, so the item buffers are those of drawing everything.

The projected convex polygons are rasterised as pixel spans: per polygon and pixel row, the
edge functions bound the run of pixel centres inside.  Polygons are grouped by height and their
rows laid out (height, polygons), spans are grouped by length and expanded as (length, spans)
grids, so per-row and per-pixel work is broadcasting rather than gathers and ``np.repeat``.
The rasterisation is watertight: every vertex is
transformed once per receiver (patches sharing a corner share its projection), a clipped edge is
cut from its inside end, and an edge function is evaluated in one canonical direction and negated
for the polygon that runs the other way, so a pixel centre on a shared edge is covered by both
patches (the depth test picks one) and never by neither.  Each fragment carries the reciprocal depth ``1/w`` of
the patch plane at that pixel (exact for planar patches, interpolated per pixel), and the item
buffer keeps the nearest fragment per pixel (``np.minimum.at`` on int64 keys packing depth
and patch id).  Summing the delta form factors (:mod:`deltaff`) per visible patch gives a row
of F (eq. 7).  A patch seen from behind writes its depth (it occludes) but adds to neither F nor
the sky; a pixel that sees nothing adds its weight to ``sky[i]``.

All five faces share one item buffer of width R: the top face's R rows, then the R/2 rows of the
side faces +X, -X, +Y and -Y (the pixel order of :func:`pixel_weights`).  Several receivers are
processed per NumPy call (their buffers stacked), which amortises the interpreter overhead.

Frames (:func:`.geometry.tangent_frames`, :func:`receiver_frames`) and the pixel order
(:func:`pixel_directions`, :func:`pixel_weights`) are the ones :mod:`embree_ff` casts its rays
with: the tangent u is the normal crossed into the world axis least aligned with it, and
``rotate_seed`` turns each receiver's frame about its normal by an angle drawn for all patches
at once (so a row does not depend on which receivers are asked for).
"""
from __future__ import annotations

import sys
from contextlib import closing
from functools import partial

import numpy as np

from .deltaff import delta_form_factors
from .drawn import draw_set
from ..util.geometry import tangent_frames
from ..mesh.patches import PatchSet
from ..runtime.parallel import ordered_map, resolve_workers
from ..runtime.progress import Ticker
from ..util.sparse import CSR

__all__ = ["hemicube_form_factors", "receiver_frames", "receiver_ids", "pixel_weights",
           "pixel_directions"]

#: Eye offset along the receiver normal, as a fraction of the scene's bounding-box diagonal.
EYE_OFFSET = 1e-5
#: Near-plane distance, as a fraction of the scene's bounding-box diagonal.
NEAR = 1e-7
#: Span ends this close (in pixels) to a pixel centre are decided by the edge inequalities.
SNAP = 1e-3
#: Vertices are snapped to 1/SUBPIXEL of a pixel (as GPUs snap to a sub-pixel grid): the same
#: scene at another scale, which differs by float rounding, draws the same pixels (an edge
#: through a pixel centre stays exactly on it, and the fill rule of :func:`_covers` decides it).
#: 2^14 keeps ``R * SUBPIXEL`` within float32's exact integers up to R = 1024.
SUBPIXEL = 1 << 14
#: Every pixel is sampled at (SAMPLE_X, SAMPLE_Y) of a pixel off its centre (projections are
#: drawn that much the other way; multiples of 1/SUBPIXEL, so snapped vertices stay exact): a
#: generic point, not one on the lines a scene built on a grid projects through pixel centres.
#: Where surfaces meet on such a line (a single-plane partition against a side wall, a block's
#: foot on a floor that runs on under it) the ray through a centre hit both at one depth, the
#: edge went by the fill rule or float rounding to one side and the depth tie to the lower
#: patch id: the lit half's side wall seen past a partition's edge (a dark-half patch's row
#: held up to 0.8% of lit patches). Off the line, coverage and depth agree on what is in
#: front. The ratio is near the golden ratio's: a line through a centre whose slope is a ratio
#: of integers up to 8 passes 5e-5 pixels or more from the sample (snapping moves a vertex
#: 3e-5 at most). Against sampling the centres, F moves where edges ran through them: the
#: reference Cornell bakes by up to 1.2e-3 of their maximum (ties broken anew, not a bias).
SAMPLE_X = 128 / SUBPIXEL
SAMPLE_Y = 79 / SUBPIXEL
#: Draw a planar cluster of pieces as its outline (:mod:`drawn`): the same pixels, drawn at a
#: cost that follows the clusters, not the modelling. False draws every piece (for comparison).
DRAW_OUTLINES = True
#: Leave out pieces crossing a face's frustum whose corners' projections, widened by
#: CLIP_MARGIN pixels, hold no candidate pixel (:func:`_hull_misses_centres`), before clipping.
CLIP_CULL = True
CLIP_MARGIN = 1.0 / 64
CLIP_SLOPE = 8.0
CLIP_DEPTH_RATIO = 4.0
#: Bound on the fragments expanded at once in the rasteriser (about 40 bytes each).
FRAGMENTS_PER_CHUNK = 1 << 21
#: Bound on receivers x patches transformed per batch (about 85 bytes each: 1<<20 pairs peaked
#: 85 MB above 2^17's on Suzanne level 3).  Only a few passes run over every pair (the culled
#: ones are never listed), so what a small batch saves in cache it loses in per-call overhead
#: of the rasteriser's row and span classes: on Suzanne level 3 (32.6k pieces, 1 worker) 4
#: receivers a batch took 9.4 s of CPU, 8 7.6 s, 16 6.8-7.1 s, 32 7.1-7.4 s; level 2 (9k pieces)
#: 14 receivers 3.0-3.3 s, 32 2.7-2.9 s, 58 2.7 s. Workers halve the batch.
PATCHES_PER_BATCH = 1 << 20
#: Bound on receivers x hemi-cube pixels per batch (8-byte item-buffer keys): 85 receivers at
#: R = 32. The Cornell box tessellated 16 (1,059 drawn polygons, bound by this) took 0.34-0.36 s
#: at 64 receivers a batch, 0.39-0.40 s at 131 and 0.42 s at 341 (2^20 pixels).
PIXELS_PER_BATCH = 1 << 18

# Face f maps receiver-frame (x, y, z) to face coordinates (u, v, w) = _FACE_AXES[f] @ (x, y, z):
# u runs along the face (table column), v up the face (table row), w is the depth along the
# face axis.  Order: top (+Z), +X, -X, +Y, -Y.
_FACE_AXES = np.array([
    [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
    [[0, 1, 0], [0, 0, 1], [1, 0, 0]],
    [[0, 1, 0], [0, 0, 1], [-1, 0, 0]],
    [[1, 0, 0], [0, 0, 1], [0, 1, 0]],
    [[1, 0, 0], [0, 0, 1], [0, -1, 0]],
], dtype=np.float32)
# the same maps as a permutation and signs: (u, v, w) = sign * (x, y, z)[perm]
_FACE_PERM = np.abs(_FACE_AXES).argmax(axis=2)
_FACE_SIGN = np.take_along_axis(_FACE_AXES, _FACE_PERM[..., None], axis=2)[..., 0]
# v of the face's bottom pixel edge: the top face spans v in [-1, 1], a side face v in [0, 1].
_FACE_V0 = np.array([-1.0, 0.0, 0.0, 0.0, 0.0], dtype=np.float32)
_ID_MASK = np.int64(0xFFFFFFFF)
# index of the high 32-bit half of an int64 viewed as two int32
_HIGH = 1 if sys.byteorder == "little" else 0


def pixel_weights(resolution):
    """Delta form factors of all hemi-cube pixels in item-buffer order.

    Parameters
    ----------
    resolution : int
        Pixels across the top face (even).

    Returns
    -------
    ndarray, shape (3 R^2,), float64
        The top table row by row, then the side table four times (faces +X, -X, +Y, -Y).
    """
    top, side = delta_form_factors(resolution)
    return np.concatenate([top.ravel()] + [side.ravel()] * 4)


def pixel_directions(resolution):
    """Directions through every hemi-cube pixel centre, in item-buffer order.

    Parameters
    ----------
    resolution : int
        Pixels across the top face (even).

    Returns
    -------
    ndarray, shape (3 R^2, 3), float64
        Unnormalised receiver-frame directions (+Z is the normal), in the order of
        :func:`pixel_weights`: the top face ``(x, y, 1)`` row by row (row = y, column = x,
        ``-1 + (k + 1/2 + SAMPLE_Y) 2/R`` and ``-1 + (k + 1/2 + SAMPLE_X) 2/R``), then the side
        faces +X, -X, +Y, -Y at unit distance, row r at height ``z = (r + 1/2 + SAMPLE_Y) 2/R``,
        column c at ``-1 + (c + 1/2 + SAMPLE_X) 2/R`` along the face (y on the +-X faces, x on
        the +-Y faces): the points the rasteriser samples, a hair off the centres
        (:data:`SAMPLE_X`).
    """
    R = int(resolution)
    step = 2.0 / R
    along = -1.0 + (np.arange(R) + 0.5 + SAMPLE_X) * step
    rows = -1.0 + (np.arange(R) + 0.5 + SAMPLE_Y) * step
    height = (np.arange(R // 2) + 0.5 + SAMPLE_Y) * step
    out = []
    for f in range(5):
        v, u = np.meshgrid(rows if f == 0 else height, along, indexing="ij")
        uvw = np.stack([u.ravel(), v.ravel(), np.ones(u.size)], axis=1)
        xyz = np.empty_like(uvw)
        xyz[:, _FACE_PERM[f]] = uvw * _FACE_SIGN[f]                   # (u, v, w) -> (x, y, z)
        out.append(xyz)
    return np.concatenate(out)


def receiver_frames(normals, rotate_seed=None):
    """Orthonormal hemi-cube frames, one per patch.

    Parameters
    ----------
    normals : (N, 3) array_like
        Unit patch normals.
    rotate_seed : int or None
        None keeps the fixed frame; an int turns every frame about its normal by an angle drawn
        uniformly from ``numpy.random.default_rng(rotate_seed)`` (N angles, patch order).

    Returns
    -------
    ndarray, shape (N, 3, 3), float64
        :func:`.geometry.tangent_frames` of the normals, turned by those angles.
    """
    angles = None
    if rotate_seed is not None:
        angles = np.random.default_rng(rotate_seed).uniform(0.0, 2.0 * np.pi, len(normals))
    return tangent_frames(normals, angles)


class _Scene:
    """What every batch needs: patch geometry centred on the scene, in float32, and the constants.

    verts (V, 3) float32, centred; corner_ids (N, 4) int64 (triangles repeat corner 2) and
    its transpose corners_t (4, N);
    normals (N, 3) float64; plane (N,) float64 ``n . c`` (centred); eyes (K, 3) float64 (centred,
    offset along the receivers' normals); near (float32); weights (3 R^2,) pixel delta form
    factors; item_of (N,) the receiver (cluster) each drawn patch belongs to, or None when every
    patch is its own receiver (K = N).
    """

    def __init__(self, patches, resolution, clusters=None):
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
        rc, rn = (patches.centers, patches.normals) if clusters is None else (clusters.centers, clusters.normals)
        self.eyes = rc - origin + EYE_OFFSET * scale * np.asarray(rn, dtype=np.float64)
        self.near = np.float32(NEAR * scale)
        self.weights = pixel_weights(resolution)


def _vertex_faces(x, y, z, near):
    """Face (0..4) whose frustum holds each vertex, -1 below the horizon or at the eye, (B, V)
    int8; and ``max(|x|, |y|)`` (B, V) float32, a side face's depth ``w`` (:func:`_face_uvw`:
    the coordinate along its axis, which is that maximum on the face it holds).

    In int8 and in place: side 1, 2, 3, 4 (+x, -x, +y, -y) is 2 - [on the positive side] + 2
    [not x-major]; the (B, V) passes cost as much as the projection.
    """
    ax, ay = np.abs(x), np.abs(y)
    xs = ax >= ay
    m = np.maximum(ax, ay)
    face = np.where(xs, x >= 0, y >= 0).view(np.int8)
    np.subtract(np.int8(2), face, out=face)
    face += (~xs).view(np.int8) << 1
    face[z >= m] = 0
    face[(z < 0) | (np.maximum(z, m) < near)] = -1
    return face, m

def _plane_distance(u, v, w, v0, p, near):
    """Signed distance of points in face coordinates to clip plane ``p`` of their face; inside
    is >= 0.  Planes: w - u, w + u, w - v, v - v0 w (``v0`` of :data:`_FACE_V0`: -w on top,
    the horizon on a side face), w - near."""
    if p == 0:
        return w - u
    if p == 1:
        return w + u
    if p == 2:
        return w - v
    if p == 3:
        return v - v0 * w
    return w - near


def _clip_convex(poly, count, dist):
    """Clip convex polygons against one plane each (Sutherland-Hodgman, all polygons at once).

    Parameters
    ----------
    poly : (M, K, 3) float
        Vertices in order; a polygon with fewer than K vertices repeats its last one.
    count : (M,) int
        Vertices of each polygon (>= 1).
    dist : (M, K) float
        Signed distance of every vertex to the plane; inside is >= 0.

    Returns
    -------
    poly : (M, K', 3)
        Clipped polygons, padded by repeating the last vertex (K' <= K + 1 for convex input).
    count : (M,) int
        Vertices kept (0 when the polygon lies wholly outside).
    """
    M, K = dist.shape
    nxt = np.roll(poly, -1, axis=1)
    dn = np.roll(dist, -1, axis=1)
    inside = dist >= 0
    cross = inside != (dn >= 0)
    # cut every edge from its inside end, so neighbours sharing the edge get the same point
    p_in = np.where(inside[..., None], poly, nxt)
    p_out = np.where(inside[..., None], nxt, poly)
    d_in = np.where(inside, dist, dn)
    d_out = np.where(inside, dn, dist)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(cross, d_in / (d_in - d_out), 0)
    hit = p_in + t[..., None] * (p_out - p_in)
    out = np.stack([poly, hit], axis=2).reshape(M, -1, 3)
    # the padding repeats the last vertex: slots count-1 .. K-2 hold copies of it joined by
    # zero-length edges; only the last slot (whose edge closes the polygon) is kept
    copy = (np.arange(K) >= count[:, None] - 1) & (np.arange(K) < K - 1)
    keep = np.stack([inside & ~copy, cross], axis=2).reshape(-1)
    kept = np.flatnonzero(keep)
    vals = out.reshape(-1, 3)[kept]
    count = np.bincount(kept // (2 * K), minlength=M)
    first = np.cumsum(count) - count
    width = max(int(count.max(initial=0)), 1)
    # slot k of polygon m holds its kept vertex min(k, count - 1): padded by the last one
    src = first[:, None] + np.minimum(np.arange(width), np.maximum(count, 1)[:, None] - 1)
    res = vals[np.minimum(src, max(kept.size - 1, 0))] if kept.size else np.zeros((M, width, 3), poly.dtype)
    return res, count


def _clip_to_faces(uvw, faces, near):
    """Clip polygons (M, 4, 3) in face coordinates to their face's frustum.

    A polygon is clipped only by the planes it crosses.  Returns the clipped polygons (M', K, 3)
    padded by repeating their last vertex, their vertex counts (>= 3) and the index (M',) of
    the input polygon of each; polygons clipped away entirely are left out.  Successive planes
    can leave vertices a rounding error apart, which makes a clipped polygon slightly
    non-convex; its fan triangles (:func:`_fans`) are convex whatever the noise, so they are
    what is rasterised.
    """
    poly = uvw
    count = np.full(len(uvw), uvw.shape[1])
    alive = np.arange(len(uvw))
    for p in range(5):
        dist = _plane_distance(poly[..., 0], poly[..., 1], poly[..., 2], _FACE_V0[faces[alive]][:, None],
                               p, near)
        out = dist < 0
        cut = np.flatnonzero(_reduce(np.logical_or, list(out.T)))
        if not cut.size:
            continue
        gone = _reduce(np.logical_and, list(out[cut].T))
        if gone.any():
            ok = np.ones(len(poly), bool)
            ok[cut[gone]] = False
            cut = cut[~gone]
            shift = np.cumsum(ok) - 1
            poly, count, alive, dist = poly[ok], count[ok], alive[ok], dist[ok]
            cut = shift[cut]
        if not cut.size:
            continue
        cp, cc = _clip_convex(poly[cut], count[cut], dist[cut])
        W = max(poly.shape[1], cp.shape[1])
        if W > poly.shape[1]:
            poly = np.concatenate([poly, np.repeat(poly[:, -1:], W - poly.shape[1], axis=1)], axis=1)
        if cp.shape[1] < W:
            cp = np.concatenate([cp, np.repeat(cp[:, -1:], W - cp.shape[1], axis=1)], axis=1)
        poly[cut] = cp
        count[cut] = cc
        ok = count >= 3
        if not ok.all():
            poly, count, alive = poly[ok], count[ok], alive[ok]
    return poly, count, alive


def _fans(px, py, count):
    """Fan triangles (v0, vk, vk+1) of polygons (M, K) with ``count`` vertices each.

    Returns px, py as lists of 3 arrays (T,) and the polygon (T,) of each triangle.
    """
    W = px.shape[1]
    m, k = np.nonzero(np.arange(1, W - 1) < (count[:, None] - 1))
    i0 = m * W
    i1 = i0 + k + 1
    px, py = px.ravel(), py.ravel()
    return [px[i0], px[i1], px[i1 + 1]], [py[i0], py[i1], py[i1 + 1]], m


def _depth_planes(scene, R, nl, dist, faces):
    """Reciprocal depth ``1/w`` of patch planes as affine functions of pixel coordinates.

    For pixel coordinates (px, py) on face f (the face spans [0, R] x [0, R or R/2]),
    ``1/w = a px + b py + c``.  ``nl`` (3, M) are the patch normals in the receiver frame,
    ``dist`` (M,) is ``n . (c - eye)`` (nonzero: the eye is not in the patch plane).
    Returns a, b, c, each (M,) float32.
    """
    nx, ny, nz = nl
    nu = np.where((faces == 1) | (faces == 2), ny, nx)
    nv = np.where(faces == 0, ny, nz)
    nw = np.where(faces == 0, nz, np.where(faces <= 2, nx, ny))
    nw = np.where((faces == 2) | (faces == 4), -nw, nw)
    s = 2.0 / (R * dist)
    a = (nu * s).astype(np.float32)
    b = (nv * s).astype(np.float32)
    # pixel coordinates are drawn SAMPLE_X, SAMPLE_Y less (:func:`_project`)
    c = ((nw - nu + _FACE_V0[faces] * nv) / dist + nu * s * SAMPLE_X + nv * s * SAMPLE_Y).astype(np.float32)
    return a, b, c


def _project(uvw, faces, R):
    """Pixel coordinates (px, py) of face-coordinate vertices (M, K, 3) on their face."""
    half = np.float32(R / 2)
    w = uvw[..., 2]
    px = (uvw[..., 0] / w + 1) * half
    py = (uvw[..., 1] / w - _FACE_V0[faces][:, None]) * half
    # moved so that pixel centres sample SAMPLE_X, SAMPLE_Y off the centres (exact: both are
    # multiples of 1 / SUBPIXEL)
    return _subpixel(px.astype(np.float32)) - np.float32(SAMPLE_X), \
        _subpixel(py.astype(np.float32)) - np.float32(SAMPLE_Y)


def _subpixel(p):
    """Pixel coordinates ``p`` (float32) rounded to :data:`SUBPIXEL` of a pixel, as GPUs do."""
    with np.errstate(invalid="ignore", over="ignore"):
        return np.rint(p * np.float32(SUBPIXEL)) / np.float32(SUBPIXEL)


def _covers(A, B, X, rhs):
    """Edge test with a fill rule: ``A X > rhs``, or on the edge (``A X == rhs``) when the edge
    is this polygon's to own (``A > 0``, or ``A == 0`` and ``B >= 0``: a padding edge of zero
    length, 0 >= 0 everywhere, never excludes).  A polygon sharing the edge
    has ``-A``, ``-B``, ``-rhs``: a pixel centre exactly on it goes to one of the two, decided by
    the geometry, not by which depth rounds nearer."""
    ax = A * X
    return (ax > rhs) | ((ax == rhs) & ((A > 0) | ((A == 0) & (B >= 0))))


def _edge_functions(px, py):
    """Edge functions of convex polygons in either winding.

    ``px``, ``py`` are lists of K arrays (M,) float32, the vertices in order.  Returns lists
    (a, b, c) of K arrays (M,) float32 and ``flat`` (M,) bool: ``a X + b Y + c >= 0`` for a
    point (X, Y) on the inner side of edge k (or on it).  ``c`` is computed from the edge's
    lexicographically first endpoint and its direction away from it, then negated as the
    polygon's winding needs, so two polygons sharing an edge evaluate exactly opposite values.
    ``flat`` marks polygons of zero area (they cover nothing; their coefficients are
    meaningless).  ``a`` is never -0.
    """
    K = len(px)
    area2 = None
    for k in range(K):  # summed left to right, as numpy sums a short row
        t = px[k] * py[(k + 1) % K] - px[(k + 1) % K] * py[k]
        area2 = t if area2 is None else area2 + t
    sgn = np.sign(area2).astype(np.float32)
    a_l, b_l, c_l = [], [], []
    for k in range(K):
        x0, y0, x1, y1 = px[k], py[k], px[(k + 1) % K], py[(k + 1) % K]
        dx, dy = x1 - x0, y1 - y0
        # first endpoint in (x, y) order: its x is the smaller one, its y that of the same end
        swap = (x1 < x0) | ((x1 == x0) & (y1 < y0))
        sx, sy = np.minimum(x0, x1), np.where(swap, y1, y0)
        a = (y0 - y1) * sgn
        a += np.float32(0)                                           # -0 -> +0
        a_l.append(a)
        b_l.append(dx * sgn)
        c_l.append((dy * sx - dx * sy) * sgn)
    return a_l, b_l, c_l, area2 == 0


#: Row-count classes of the rasteriser: polygons are rasterised in groups of similar height.
_ROW_CLASSES = (1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192, 256)
#: Span-length classes of the fragment stage: spans up to 8 pixels long are expanded by exact
#: length, longer ones padded up to the next class.
_SPAN_CLASSES = (1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192, 256, 384, 512)
_EXACT_SPANS = 8


def _classes(bounds, top):
    """Class bounds up to ``top`` and a table: class of every size 0..top."""
    b = [x for x in bounds if x < top] + [top]
    return b, np.searchsorted(np.array(b), np.arange(top + 1)).astype(np.int8)


def _rasterise(px, py, face_rows, pixel_base, depth, item, keys, R):
    """Write polygons into the item buffer (see :func:`_rasterise_quiet`); infinities and nans
    of edges parallel to the rows or of unbounded spans are expected, their warnings are off."""
    with np.errstate(divide="ignore", invalid="ignore"):
        _rasterise_quiet(px, py, face_rows, pixel_base, depth, item, keys, R)


def _rasterise_quiet(px, py, face_rows, pixel_base, depth, item, keys, R):
    """Write polygons into the item buffer, keeping the nearest fragment per pixel.

    Parameters
    ----------
    px, py : lists of K arrays (M,) float32
        Convex polygons in pixel coordinates of their face, padded by repeating a vertex.
    face_rows : (M,) int
        Rows of each polygon's face (R or R/2); columns are R for every face.
    pixel_base : (M,) int64
        Index in ``keys`` of pixel (0, 0) of the polygon's face for its receiver.
    depth : 3 arrays (M,) float32
        Reciprocal depth ``a px + b py + c`` per polygon.
    item : (M,) int32
        Id written to the item buffer.
    keys : (P,) int64
        Item buffer, updated in place: ``(depth bits << 32) | item``, smaller is nearer.
    R : int
        Pixels across a face.
    """
    j0, rows, i0, i1 = _pixel_range(px, py, face_rows, R)
    bounds, table = _classes(_ROW_CLASSES, R)
    cls = table[np.clip(rows, 0, R)]
    cls[(rows <= 0) | (i1 < i0)] = -1
    # one candidate pixel (one row, one column within SNAP of the x-range): a point test
    single = np.flatnonzero((rows == 1) & (i1 == i0))
    if single.size:
        cls[single] = -1
        _draw_points(i0[single], j0[single], [p[single] for p in px], [p[single] for p in py],
                     pixel_base[single], [d[single] for d in depth], item[single], keys, R)
    order = np.argsort(cls, kind="stable")                            # radix sort
    ends = np.cumsum(np.bincount(cls + 1, minlength=len(bounds) + 1))
    spans = []
    for ci in np.flatnonzero(np.diff(ends)):
        sel = order[ends[ci]:ends[ci + 1]]
        spans.append(_spans(bounds[ci], rows[sel], j0[sel], [p[sel] for p in px],
                            [p[sel] for p in py], pixel_base[sel], [d[sel] for d in depth],
                            item[sel], R))
    if not spans:
        return
    q0, dq, start, ids, n = (np.concatenate(s) for s in zip(*spans))
    if n.sum() <= FRAGMENTS_PER_CHUNK:
        _draw_spans(q0, dq, start, ids, n, keys, R)
        return
    ends = np.cumsum(n)
    lo = 0
    while lo < n.size:
        hi = int(np.searchsorted(ends, (ends[lo - 1] if lo else 0) + FRAGMENTS_PER_CHUNK, "right"))
        hi = max(hi, lo + 1)
        sl = slice(lo, hi)
        _draw_spans(q0[sl], dq[sl], start[sl], ids[sl], n[sl], keys, R)
        lo = hi


def _pixel_range(px, py, face_rows, R):
    """Candidate pixels of polygons: first row j0 (M,) int64, rows (M,) int64 (<= 0: none),
    first and last column i0, i1 (M,) float32 (i1 < i0: none).

    Rows are those whose centres lie in the polygon's y-range; columns those whose centres lie
    within ``SNAP`` of its x-range (rounding in the edge inequalities moves a boundary by far
    less than SNAP), both clamped to the face.
    """
    lo_y, hi_y = _reduce(np.minimum, py), _reduce(np.maximum, py)
    j0 = np.maximum(np.ceil(lo_y - np.float32(0.5)), 0).astype(np.int64)
    j1 = np.minimum(np.floor(hi_y - np.float32(0.5)), face_rows - 1).astype(np.int64)
    lo_x, hi_x = _reduce(np.minimum, px), _reduce(np.maximum, px)
    i0 = np.maximum(np.ceil(lo_x - np.float32(0.5 + SNAP)), 0)
    i1 = np.minimum(np.floor(hi_x - np.float32(0.5 - SNAP)), R - 1)
    return j0, j1 - j0 + 1, i0, i1


def _can_cover(px, py, face_rows, R):
    """(M,) bool: polygons with a candidate pixel (:func:`_pixel_range`); the others are left
    out by :func:`_rasterise` anyway."""
    with np.errstate(invalid="ignore"):
        _, rows, i0, i1 = _pixel_range(px, py, face_rows, R)
        return (rows > 0) & (i1 >= i0)


def _reduce(op, arrays):
    """``op`` folded over a list of arrays (faster than a reduction along a short axis)."""
    out = arrays[0]
    for a in arrays[1:]:
        out = op(out, a)
    return out


def _spans(height, rows, j0, px, py, pixel_base, depth, item, R):
    """Pixel spans covered by polygons of at most ``height`` rows, one per (polygon, pixel row).

    Pixel (i, j) is covered when its centre satisfies every edge function.  On row j each edge
    ``a X + b Y + c >= 0`` bounds X from one side at ``-(b Y + c) / a``; a polygon sharing the
    edge computes the same bound with both signs flipped, so the two spans meet without a gap.
    When a bound falls within ``SNAP`` of a pixel centre, that pixel is decided by the edge
    inequalities themselves (``a X >= -(b Y + c)``, exactly complementary between neighbours),
    not by the rounded quotient, so a centre lying on an edge is covered as a point test would.
    An edge parallel to the rows (``a = 0``) empties the rows outside it.

    The rows are laid out (height, S): row r of every polygon at once, no gathers.
    Returns (q0, dq, start, item, n) per span: reciprocal depth at the first pixel and its step
    along the row (float32), index of the first pixel in the item buffer, id, and length (> 0).
    """
    a, b, c, flat = _edge_functions(px, py)
    S = rows.size
    r = np.arange(height)[:, None]
    j = j0 + r
    Y = j.astype(np.float32) + np.float32(0.5)                         # (height, S)
    lo = hi = None
    rhs_l = []
    inf = np.float32(np.inf)
    zero = np.float32(0)
    # (called with division and invalid-value warnings off: see _rasterise)
    for k in range(len(a)):
        A = a[k]
        rhs = (-b[k]) * Y + (-c[k])                                  # need A X >= rhs
        bound = rhs / A
        # a left edge (A > 0) bounds from below, a right edge (A < 0) from above; a level
        # edge (A = +0) gives +inf (row outside: empty), -inf or nan (no bound) from below
        # and nothing from above (nan and inf are ignored by fmax / fmin)
        l = bound + np.where(A < 0, -inf, zero)
        # a level edge through the row's centres (0 / 0): the row is inside when the edge is ours
        l = np.where((A == 0) & (rhs == 0) & (b[k] < 0), inf, l)
        h = bound + np.where(A >= 0, inf, zero)
        lo = l if lo is None else np.fmax(lo, l)
        hi = h if hi is None else np.fmin(hi, h)
        rhs_l.append(rhs)
    i_lo = np.maximum(_snap_to_pixels(lo, a, b, rhs_l, first=True), zero)
    i_hi = np.minimum(_snap_to_pixels(hi, a, b, rhs_l, first=False), np.float32(R - 1))
    n = i_hi - i_lo + 1
    ok = (n > 0) & (r < rows) & ~flat
    da, db, dc = depth
    idx = np.flatnonzero(ok)
    s = idx % S
    i_lo = i_lo.ravel()[idx]
    Yk = Y.ravel()[idx]
    dq = da[s]
    q0 = dq * (i_lo + np.float32(0.5)) + db[s] * Yk + dc[s]
    start = pixel_base[s] + j.ravel()[idx] * R + i_lo.astype(np.int64)
    return q0, dq, start, item[s], n.ravel()[idx].astype(np.int64)


def _snap_to_pixels(bound, A, B, rhs, first):
    """First (or last) pixel column whose centre lies inside, given the span bound on X.

    ``bound`` and ``rhs[k]`` are (height, S), ``A[k]``, ``B[k]`` (S,).  Columns whose centres
    are within ``SNAP`` of the bound are tested with the edge inequalities (all edges, with the
    fill rule of :func:`_covers`) instead of trusting the quotient's rounding.
    """
    t = bound - np.float32(0.5)
    col = np.ceil(t) if first else np.floor(t)
    near = np.round(t)
    check = np.flatnonzero(np.abs(t - near) < SNAP)                 # nan on an unbounded side
    if check.size:
        S = bound.shape[1]
        s = check % S
        nr = near.ravel()[check]
        X = nr + np.float32(0.5)
        inside = None
        for Ak, Bk, rk in zip(A, B, rhs):
            t_k = _covers(Ak[s], Bk[s], X, rk.ravel()[check])
            inside = t_k if inside is None else inside & t_k
        col.ravel()[check] = np.where(inside, nr, nr + (1 if first else -1))
    return col


def _fragment_keys(q, ids):
    """Item-buffer keys of fragments: reciprocal depths ``q`` (...) float32 and ids broadcasting
    against them (int32) packed as int64 ``((0x7F800000 - bits(q)) << 32) | id``, so the nearer
    fragment (the larger 1/w) has the smaller key; q is clamped to 1e-30 (positive bits)."""
    qbits = np.maximum(q, np.float32(1e-30)).view(np.int32)
    frag = np.empty(q.shape + (2,), dtype=np.int32)                   # (high, low) int64 halves
    np.subtract(np.int32(0x7F800000), qbits, out=frag[..., _HIGH])
    frag[..., 1 - _HIGH] = ids
    return frag.view(np.int64)[..., 0]


def _draw_points(i, j, px, py, pixel_base, depth, item, keys, R):
    """Depth-test polygons that can cover one pixel centre only, (i, j), into ``keys``.

    The pixel is covered when its centre satisfies every edge inequality ``a X >= -(b Y + c)``
    (on an edge: by the fill rule of :func:`_covers`)
    (as computed in :func:`_spans`, which decides a single candidate the same way), and its
    fragment carries the same depth and key as there.
    """
    a, b, c, flat = _edge_functions(px, py)
    X = i.astype(np.float32) + np.float32(0.5)
    Y = j.astype(np.float32) + np.float32(0.5)
    inside = ~flat
    for k in range(len(a)):
        inside &= _covers(a[k], b[k], X, (-b[k]) * Y + (-c[k]))
    sel = np.flatnonzero(inside)
    if not sel.size:
        return
    da, db, dc = depth
    X, Y = X[sel], Y[sel]
    q = da[sel] * X + db[sel] * Y + dc[sel]
    np.minimum.at(keys, pixel_base[sel] + j[sel] * R + i[sel].astype(np.int64), _fragment_keys(q, item[sel]))


def _draw_spans(q0, dq, start, ids, n, keys, R):
    """Depth-test the pixels of the spans into the item buffer ``keys`` (see :func:`_rasterise`).

    Spans are grouped by length and expanded as (length, spans) grids, so the per-pixel work is
    broadcasting, not repeating.  The reciprocal depth of pixel ``start + o`` is ``q0 + dq o``
    in float32.
    """
    bounds, table = _classes(_SPAN_CLASSES, R)
    cls = table[n]
    order = np.argsort(cls, kind="stable")                            # radix sort
    counts = np.bincount(cls, minlength=len(bounds))
    q0, dq, start, ids = q0[order], dq[order], start[order], ids[order]
    lo = 0
    for ci in np.flatnonzero(counts):
        hi = lo + int(counts[ci])
        L = bounds[ci]
        o = np.arange(L)[:, None]
        q = q0[lo:hi] + dq[lo:hi] * o.astype(np.float32)             # (L, S)
        frag = _fragment_keys(q, ids[lo:hi])
        pix = start[lo:hi] + o
        if L > _EXACT_SPANS:  # padded class: keep the pixels inside the spans
            inside = o < n[order[lo:hi]]
            frag, pix = frag[inside], pix[inside]
        np.minimum.at(keys, pix.ravel(), frag.ravel())
        lo = hi


def _vertex_projection(x, y, z, face, m, R):
    """Pixel coordinates (px, py) of vertices on their own face (see :func:`_vertex_faces`,
    which gives ``m``, the depth on a side face).

    The same float32 values as :func:`_project` on the vertex's :func:`_face_uvw`, so a patch
    wholly inside one face gets bit-identical corners either way: ``w`` is ``m`` on a side face
    (the same value as +-x or +-y there), and ``v / w - v0`` is ``v / w + 1`` on top and
    ``v / w`` on a side (``v0`` of :data:`_FACE_V0`). Vertices with face -1 get meaningless
    values. A vertex inside its face's frustum has ``|u| <= w`` and ``0 <= v <= w`` on a side,
    so px lies in [-SAMPLE_X, R - SAMPLE_X], py in [-SAMPLE_Y, R - SAMPLE_Y] (R / 2 on a side).
    """
    half = np.float32(R / 2)
    top = face == 0
    u = np.where((face == 1) | (face == 2), y, x)
    v = np.where(top, y, z)
    w = np.where(top, z, m)
    with np.errstate(divide="ignore", invalid="ignore"):
        px = u / w
        px += np.float32(1)
        px *= half
        py = v / w
        np.add(py, np.float32(1), out=py, where=top)
        py *= half
    return _subpixel(px) - np.float32(SAMPLE_X), _subpixel(py) - np.float32(SAMPLE_Y)

def _face_uvw(f, x, y, z):
    """Face coordinates (u, v, w) on face ``f`` of receiver-frame coordinates (:data:`_FACE_AXES`)."""
    if f == 0:
        return x, y, z
    if f == 1:
        return y, z, x
    if f == 2:
        return y, z, -x
    if f == 3:
        return x, z, y
    return x, z, -y


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
    plane = _depth_planes(scene, R, nl, d, faces)
    item = np.where(d < 0, ni, N).astype(np.int32)
    _rasterise(px, py, face_rows[faces], bi * (3 * R * R) + face_base[faces], plane, item, keys, R)


# Per-vertex code bits (:func:`_vertex_codes`): face + 1 in bits 0-2, above the horizon in bit 3,
# then whether no candidate column (row) boundary lies at the vertex, and the pixel cell's
# column and row + 1 (12 bits each: 0..R for R <= 2048, the settings' maximum; a larger R
# is drawn without the cull by cell).
_ABOVE = np.int32(1 << 3)
_CLEAR_X = np.int32(1 << 4)
_CLEAR_Y = np.int32(1 << 5)
_CELL_X = np.int32(0xFFF << 6)
_CELL_Y = np.int32(0xFFF << 18)


def _vertex_codes(vface, z, vpx, vpy):
    """(B, V) int32 codes of vertices on their own face, for the per-pair tests of
    :func:`_corner_tests`.

    Face + 1 and "above the horizon" say which patches lie wholly in one face's frustum (equal
    low bits at every corner). The cell bits say which of those cover no candidate pixel of
    :func:`_pixel_range` without projecting them: that range's first column is the least of
    the corners' ``ceil(px - (1/2 + SNAP))``, its last the greatest ``floor(px - (1/2 - SNAP))``
    (float32 rounding is monotonic, so taking the extreme before or after it is the same), and
    rows alike with 1/2. A vertex is x-clear when its two column values differ by one (no
    centre column within SNAP of it); a patch whose corners are all x-clear in the same cell
    column has its first candidate column past its last: it covers nothing, and neither does
    one whose corners are all y-clear in the same cell row. The cell is ``floor(px - (1/2 -
    SNAP))``, in [-1, R - 1] for a vertex in its face (:func:`_vertex_projection`), so cell + 1
    fills its 12 bits exactly; a vertex with face -1 may write anything above bit 5 (its pairs
    are never whole).
    """
    with np.errstate(invalid="ignore"):
        gx = np.floor(vpx - np.float32(0.5 - SNAP))
        cx = np.ceil(vpx - np.float32(0.5 + SNAP))
        cx -= gx
        gy = np.floor(vpy - np.float32(0.5))
        cy = np.ceil(vpy - np.float32(0.5))
        cy -= gy
        gx += np.float32(1)
        gy += np.float32(1)
        code = gx.astype(np.int32)
        code <<= 6
        cell_y = gy.astype(np.int32)
    cell_y <<= 18
    code |= cell_y
    code |= np.where(cx == 1, _CLEAR_X, np.int32(0))
    code |= np.where(cy == 1, _CLEAR_Y, np.int32(0))
    code |= (vface + 1).astype(np.int32)
    code |= np.where(z >= 0, _ABOVE, np.int32(0))
    return code

def _hull_misses_centres(u, v, w, f, R):
    """(S,) bool: polygons (face coordinates ``u``, ``v``, ``w`` on face ``f``, each (4, S)
    float32) whose part inside the face's frustum surely has no candidate pixel of
    :func:`_pixel_range`, so clipping and drawing them is left out.

    Clipping keeps a polygon inside its corners' convex hull, and the hull's projection lies
    within its corners' projections' bounding box; when that box, widened by
    :data:`CLIP_MARGIN` pixels (R / 2048 at larger R), holds no candidate column or row of the
    face, neither do the clipped fan triangles :func:`_rasterise` would be given. Decided only
    where every corner lies in front of the face (``w > 0``), within ``CLIP_SLOPE`` of its axis
    (``max(|u|, |v|) <= CLIP_SLOPE w``) and the corners' depths within ``CLIP_DEPTH_RATIO`` of
    each other: there a clipped point's float32 rounding (a few units in the last place of
    coordinates up to ``sqrt(1 + 2 CLIP_SLOPE^2) w_max``, through five planes) moves its
    projection by at most about ``2e-5 R`` pixels, under 1e-3 at R = 32 (the margin is 1/64),
    plus the 3e-5 of snapping.
    """
    half = np.float32(R / 2)
    w_lo, w_hi = w.min(axis=0), w.max(axis=0)
    ok = (w_lo > 0) & (w_hi <= np.float32(CLIP_DEPTH_RATIO) * w_lo)
    for k in range(u.shape[0]):
        ok &= np.maximum(np.abs(u[k]), np.abs(v[k])) <= np.float32(CLIP_SLOPE) * w[k]
    with np.errstate(divide="ignore", invalid="ignore"):
        px = (u / w + 1) * half - np.float32(SAMPLE_X)
        py = (v / w - _FACE_V0[f]) * half - np.float32(SAMPLE_Y)
    m = np.float32(max(CLIP_MARGIN, R / 2048))
    rows = R if f == 0 else R // 2
    j0 = np.maximum(np.ceil(py.min(axis=0) - m - np.float32(0.5)), 0)
    j1 = np.minimum(np.floor(py.max(axis=0) + m - np.float32(0.5)), rows - 1)
    i0 = np.maximum(np.ceil(px.min(axis=0) - m - np.float32(0.5 + SNAP)), 0)
    i1 = np.minimum(np.floor(px.max(axis=0) + m - np.float32(0.5 - SNAP)), R - 1)
    return ok & ((j1 < j0) | (i1 < i0))


def _corner_tests(code):
    """Per-pair tests from the corners' :func:`_vertex_codes` ``code`` (B, 4, N) int32.

    Returns (B, N) arrays: ``visible`` (a corner above the horizon), ``whole`` (every corner in
    one face's frustum, above the horizon), ``empty`` (meaningful where whole: every corner
    x-clear in one cell column, or y-clear in one cell row, so no candidate pixel) and ``low``
    (int32, face + 1 + 8 where whole).
    """
    c0 = code[:, 0]
    diff = (c0 ^ code[:, 1]) | (c0 ^ code[:, 2]) | (c0 ^ code[:, 3])
    visible = ((c0 | code[:, 1] | code[:, 2] | code[:, 3]) & _ABOVE) != 0
    low = c0 & np.int32(0xF)
    whole = ((diff & np.int32(0xF)) == 0) & (low >= 9)
    empty = (((diff & (_CLEAR_X | _CELL_X)) == 0) & ((c0 & _CLEAR_X) != 0)) \
        | (((diff & (_CLEAR_Y | _CELL_Y)) == 0) & ((c0 & _CLEAR_Y) != 0))
    return visible, whole, empty, low


def _batch_item_buffer(scene, recv, frames, eyes):
    """Item buffers of a batch of receivers: keys (B, 3 R^2) int64 (see :func:`_empty_key`)."""
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
    vface, m = _vertex_faces(x, y, z, scene.near)                    # (B, V)
    vpx, vpy = _vertex_projection(x, y, z, vface, m, R)
    visible, whole, empty, low = _corner_tests(
        np.take(_vertex_codes(vface, z, vpx, vpy), scene.corners_t, axis=1))
    if R > 0xFFF - 1:                         # cells past 12 bits: no cull by cell
        empty[:] = False
    if scene.item_of is None:
        visible[np.arange(B), recv] = False
    else:                                     # a cluster does not see its own pieces
        visible &= scene.item_of[None, :] != recv[:, None]
    face_rows = np.array([R, R // 2, R // 2, R // 2, R // 2])
    face_base = np.array([0, R * R, 3 * R * R // 2, 2 * R * R, 5 * R * R // 2])
    keys = np.full(B * P, _empty_key(N), dtype=np.int64)
    ctx = (scene, keys, fr, eyes[recv], face_rows, face_base)

    # patches wholly inside one face's frustum: their corners' own projections
    bi, ni = np.nonzero(whole & visible & ~empty)
    vpx, vpy = vpx.ravel(), vpy.ravel()
    faces = (low[bi, ni] - 9).astype(np.intp)
    corner = np.take(scene.corners_t, ni, axis=1) + bi * V            # (4, M)
    px, py = [vpx[c] for c in corner], [vpy[c] for c in corner]
    keep = np.flatnonzero(_can_cover(px, py, face_rows[faces], R))
    d = _pair_dist(ctx, bi[keep], ni[keep])
    seen = np.abs(d) > scene.near                                     # not edge-on
    keep = keep[seen]
    # drawn in one pass with the clipped ones below (fewer, larger rasteriser calls)
    todo = [(bi[keep], ni[keep], d[seen], faces[keep], [p[keep] for p in px], [p[keep] for p in py])]
    # the rest: clip against every face whose frustum they may reach
    bi, ni = np.nonzero(visible & ~whole)
    if bi.size:
        corner = np.take(scene.corners_t, ni, axis=1) + bi * V
        xyz = [c.ravel()[corner] for c in (x, y, z)]                 # each (4, S)
        polys, faces, pairs = [], [], []
        for f in range(5):
            u, v, w = _face_uvw(f, *xyz)
            # wholly outside one of the face's clip planes: clipping would leave nothing
            out = None
            for p in range(5):
                d = _plane_distance(u, v, w, _FACE_V0[f], p, scene.near) < 0
                d = d[0] & d[1] & d[2] & d[3]
                out = d if out is None else out | d
            if CLIP_CULL:
                out |= _hull_misses_centres(u, v, w, f, R)
            s = np.flatnonzero(~out)
            polys.append(np.stack([u[:, s], v[:, s], w[:, s]], axis=-1).transpose(1, 0, 2))
            faces.append(np.full(s.size, f))
            pairs.append(s)
        fi = np.concatenate(faces)
        si = np.concatenate(pairs)
        poly, count, src = _clip_to_faces(np.concatenate(polys), fi, scene.near)
        bi, ni, fi = bi[si[src]], ni[si[src]], fi[src]
        d = _pair_dist(ctx, bi, ni)
        seen = np.flatnonzero(np.abs(d) > scene.near)                # not edge-on
        bi, ni, d, fi, poly, count = bi[seen], ni[seen], d[seen], fi[seen], poly[seen], count[seen]
        px, py, m = _fans(*_project(poly, fi, R), count)
        keep = np.flatnonzero(_can_cover(px, py, face_rows[fi[m]], R))
        m = m[keep]
        # fan triangles as quads repeating their last corner (as triangle patches are): a
        # zero-length edge excludes nothing and adds 0 to the area, so they cover as before
        px, py = [p[keep] for p in px], [p[keep] for p in py]
        todo.append((bi[m], ni[m], d[m], fi[m], px + px[2:], py + py[2:]))
    bi, ni, d, faces = (np.concatenate([t[k] for t in todo]) for k in range(4))
    px = [np.concatenate(c) for c in zip(*(t[4] for t in todo))]
    py = [np.concatenate(c) for c in zip(*(t[5] for t in todo))]
    _draw(ctx, bi, ni, d, faces, px, py)
    return keys.reshape(B, P)


def _empty_key(n):
    """Item-buffer key of a pixel that sees nothing: farther than any fragment, id ``n + 1``
    (fragments carry a patch id, or ``n`` for a back face)."""
    return (np.int64(0x7F800000) << 32) | np.int64(n + 1)


def _resolve(keys, weights, n, item_of=None):
    """Sum pixel weights per visible front-facing patch (or its receiver ``item_of``, of n).

    Returns F rows (B, n) float64 and sky (B,) float64.
    """
    B = len(keys)
    bins = keys & _ID_MASK
    if item_of is not None:                   # drawn piece -> its cluster; back face, sky stay last
        bins = np.concatenate([item_of, [n, n + 1]])[bins]
    bins += (np.arange(B) * (n + 2))[:, None]
    rows = np.bincount(bins.ravel(), weights=np.tile(weights, B), minlength=B * (n + 2))
    rows = rows.reshape(B, n + 2)
    return rows[:, :n], rows[:, n + 1]


def receiver_ids(n, receivers):
    """Sorted unique receiver ids (all patches when None); ValueError when out of range."""
    if receivers is None:
        return np.arange(n, dtype=np.int64)
    r = np.unique(np.asarray(receivers, dtype=np.int64).reshape(-1))
    if r.size and (r[0] < 0 or r[-1] >= n):
        raise ValueError(f"receiver ids must be in [0, {n}), got {r[0]}..{r[-1]}")
    return r


def _batch_size(n, resolution, requested):
    if requested is not None:
        if int(requested) < 1:
            raise ValueError(f"batch must be >= 1, got {requested}")
        return int(requested)
    return max(1, min(PATCHES_PER_BATCH // max(n, 1), PIXELS_PER_BATCH // (3 * resolution ** 2)))


def hemicube_form_factors(patches: PatchSet, resolution=64, *, rotate_seed=None, receivers=None,
                          progress=None, cancelled=None, batch=None, clusters=None, workers=1) -> CSR:
    """Form-factor matrix F by the hemi-cube, one rasterised hemi-cube per receiver.

    Parameters
    ----------
    patches : PatchSet
        Convex planar quads and triangles (as :func:`patches.build_patches` makes them).
    resolution : int
        Pixels across the top face (even); side faces have ``resolution // 2`` rows.
    rotate_seed : int or None
        None: fixed frames; an int turns each receiver's hemi-cube about its normal by a random
        angle (reproducible, see :func:`receiver_frames`).
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
    scene = _Scene(patches, R, clusters)
    frames = receiver_frames(patches.normals if clusters is None else clusters.normals, rotate_seed)
    workers = resolve_workers(workers)
    # with several batches drawn at once, smaller ones: the peak memory stays that of one worker
    B = _batch_size(scene.n, R, batch) if batch is not None else max(1, _batch_size(scene.n, R, None) // workers)
    ticker = Ticker(progress, cancelled)
    ticker.tick(0, recv.size, force=True)
    batches = (recv[lo:lo + B] for lo in range(0, recv.size, B))
    # batches in receiver order whatever the worker count: F is bit-identical
    rows_of = partial(_batch_rows, scene, frames, n)
    with closing(ordered_map(rows_of, batches, workers, processes=True)) as results:
        indptr, indices, data, sky = _collect_rows(results, n, recv.size, ticker)
    meta = {"method": "hemicube", "resolution": R, "rotate_seed": rotate_seed}
    return CSR(indptr, indices, data, (n, n), meta, sky)


def _batch_rows(scene, frames, n, ids):
    """Rows of F for the receivers ``ids`` (B,) int64, sparse.

    ``frames`` (K, 3, 3) receiver frames; ``n`` receivers in all (K). Returns ids, the entries
    per row (B,) int64, their columns (E,) int32 and form factors (E,) float32 (row by row,
    columns ascending), and sky (B,) float64.
    """
    keys = _batch_item_buffer(scene, ids, frames, scene.eyes)
    rows, sky_b = _resolve(keys, scene.weights, n, scene.item_of)
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
