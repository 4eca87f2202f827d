"""Receiver-frame geometry onto the hemi-cube's five faces: which face's frustum holds each vertex,
its pixel coordinates there, the per-pair culls, clipping to the frusta and the depth planes.

Coordinates: the receiver frame (+Z the normal, the eye at the origin, in the scene's units
centred on the scene), face coordinates (u, v, w) of face f (:data:`.pixels._FACE_AXES`: u
along the face, v up it, w the depth along its axis) and pixel coordinates (px, py) in [0, R]
x [0, R] on the top face, [0, R] x [0, R/2] on a side (:mod:`.pixels`), all float32.

Every vertex is transformed once per receiver and given the face whose 90-degree frustum holds
it (:func:`vertex_faces`) and its projection there (:func:`vertex_projection`); a patch is then
classified from its corners (:func:`vertex_codes`, one 32-bit word per corner, and
:func:`corner_tests`):

* a patch whose corners all fall in one face's frustum takes its corners' projections directly,
  unless its corners all lie in one pixel cell column or row: then it covers no pixel centre
  and is culled before it is listed (most pieces of a finely modelled mesh are that small
  seen from across the scene);
* a patch wholly below the horizon is culled;
* the others are clipped (Sutherland-Hodgman, vectorised over polygons, :func:`clip_to_faces`)
  against the frustum of every face they may touch (the near plane and the horizon
  included), each polygon only by the planes it crosses, and drawn as triangle fans
  (:func:`fans`); a polygon whose corners' projections on a face hold no candidate pixel is
  left out of that face before clipping (:func:`hull_misses_centres`).

Every cull takes only polygons the rasteriser's own candidate range
(:func:`.raster._pixel_range`) rejects, so the item buffers are those of drawing everything.
Patches sharing a corner share its projection, and a clipped edge is cut from its inside end,
so neighbours meet without a gap.
"""
from __future__ import annotations

import numpy as np

from .pixels import SAMPLE_X, SAMPLE_Y, subpixel
from .raster import SNAP, fold

__all__ = ["vertex_faces", "face_uvw", "vertex_projection", "vertex_codes", "corner_tests",
           "hull_misses_centres", "plane_distance", "clip_to_faces", "fans", "project",
           "depth_planes", "FACE_V0", "CLIP_MARGIN", "CLIP_SLOPE", "CLIP_DEPTH_RATIO"]

#: v of the face's bottom pixel edge: the top face spans v in [-1, 1], a side face v in [0, 1].
FACE_V0 = np.array([-1.0, 0.0, 0.0, 0.0, 0.0], dtype=np.float32)
#: :func:`hull_misses_centres` widens the corners' projections by CLIP_MARGIN pixels and
#: decides only corners within CLIP_SLOPE of the face's axis whose depths are within
#: CLIP_DEPTH_RATIO of each other (where float32 clipping moves a point far less than that).
CLIP_MARGIN = 1.0 / 64
CLIP_SLOPE = 8.0
CLIP_DEPTH_RATIO = 4.0


def vertex_faces(x, y, z, near):
    """Face (0..4) whose frustum holds each vertex, -1 below the horizon or at the eye, (B, V)
    int8; and ``max(|x|, |y|)`` (B, V) float32, a side face's depth ``w`` (:func:`face_uvw`:
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


def face_uvw(f, x, y, z):
    """Face coordinates (u, v, w) on face ``f`` of receiver-frame coordinates
    (:data:`.pixels._FACE_AXES`)."""
    if f == 0:
        return x, y, z
    if f == 1:
        return y, z, x
    if f == 2:
        return y, z, -x
    if f == 3:
        return x, z, y
    return x, z, -y


def vertex_projection(x, y, z, face, m, R):
    """Pixel coordinates (px, py) of vertices on their own face (see :func:`vertex_faces`,
    which gives ``m``, the depth on a side face).

    The same float32 values as :func:`project` on the vertex's :func:`face_uvw`, so a patch
    wholly inside one face gets bit-identical corners either way: ``w`` is ``m`` on a side face
    (the same value as +-x or +-y there), and ``v / w - v0`` is ``v / w + 1`` on top and
    ``v / w`` on a side (``v0`` of :data:`FACE_V0`). Vertices with face -1 get meaningless
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
    return subpixel(px) - np.float32(SAMPLE_X), subpixel(py) - np.float32(SAMPLE_Y)


# Per-vertex code bits (:func:`vertex_codes`): face + 1 in bits 0-2, above the horizon in bit 3,
# then whether no candidate column (row) boundary lies at the vertex, and the pixel cell's
# column and row + 1 (12 bits each: 0..R for R <= 2048, the settings' maximum; a larger R
# is drawn without the cull by cell).
_ABOVE = np.int32(1 << 3)
_CLEAR_X = np.int32(1 << 4)
_CLEAR_Y = np.int32(1 << 5)
_CELL_X = np.int32(0xFFF << 6)
_CELL_Y = np.int32(0xFFF << 18)


def vertex_codes(vface, z, vpx, vpy):
    """(B, V) int32 codes of vertices on their own face, for the per-pair tests of
    :func:`corner_tests`.

    Face + 1 and "above the horizon" say which patches lie wholly in one face's frustum (equal
    low bits at every corner). The cell bits say which of those cover no candidate pixel of
    :func:`.raster._pixel_range` without projecting them: that range's first column is the least
    of the corners' ``ceil(px - (1/2 + SNAP))``, its last the greatest ``floor(px - (1/2 -
    SNAP))`` (float32 rounding is monotonic, so taking the extreme before or after it is the
    same), and rows alike with 1/2. A vertex is x-clear when its two column values differ by one
    (no centre column within SNAP of it); a patch whose corners are all x-clear in the same cell
    column has its first candidate column past its last: it covers nothing, and neither does one
    whose corners are all y-clear in the same cell row. The cell is ``floor(px - (1/2 -
    SNAP))``, in [-1, R - 1] for a vertex in its face (:func:`vertex_projection`), so cell + 1
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


def corner_tests(code):
    """Per-pair tests from the corners' :func:`vertex_codes` ``code`` (B, 4, N) int32.

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


def hull_misses_centres(u, v, w, f, R):
    """(S,) bool: polygons (face coordinates ``u``, ``v``, ``w`` on face ``f``, each (4, S)
    float32) whose part inside the face's frustum surely has no candidate pixel of
    :func:`.raster._pixel_range`, so clipping and drawing them is left out.

    Clipping keeps a polygon inside its corners' convex hull, and the hull's projection lies
    within its corners' projections' bounding box; when that box, widened by :data:`CLIP_MARGIN`
    pixels (R / 2048 at larger R), holds no candidate column or row of the face, neither do the
    clipped fan triangles :func:`.raster.rasterise` would be given. Decided only where every
    corner lies in front of the face (``w > 0``), within ``CLIP_SLOPE`` of its axis (``max(|u|,
    |v|) <= CLIP_SLOPE w``) and the corners' depths within ``CLIP_DEPTH_RATIO`` of each other:
    there a clipped point's float32 rounding (a few units in the last place of coordinates up to
    ``sqrt(1 + 2 CLIP_SLOPE^2) w_max``, through five planes) moves its projection by at most
    about ``2e-5 R`` pixels, under 1e-3 at R = 32 (the margin is 1/64), plus the 3e-5 of
    snapping.
    """
    half = np.float32(R / 2)
    w_lo, w_hi = w.min(axis=0), w.max(axis=0)
    ok = (w_lo > 0) & (w_hi <= np.float32(CLIP_DEPTH_RATIO) * w_lo)
    for k in range(u.shape[0]):
        ok &= np.maximum(np.abs(u[k]), np.abs(v[k])) <= np.float32(CLIP_SLOPE) * w[k]
    with np.errstate(divide="ignore", invalid="ignore"):
        px = (u / w + 1) * half - np.float32(SAMPLE_X)
        py = (v / w - FACE_V0[f]) * half - np.float32(SAMPLE_Y)
    m = np.float32(max(CLIP_MARGIN, R / 2048))
    rows = R if f == 0 else R // 2
    j0 = np.maximum(np.ceil(py.min(axis=0) - m - np.float32(0.5)), 0)
    j1 = np.minimum(np.floor(py.max(axis=0) + m - np.float32(0.5)), rows - 1)
    i0 = np.maximum(np.ceil(px.min(axis=0) - m - np.float32(0.5 + SNAP)), 0)
    i1 = np.minimum(np.floor(px.max(axis=0) + m - np.float32(0.5 - SNAP)), R - 1)
    return ok & ((j1 < j0) | (i1 < i0))


def plane_distance(u, v, w, v0, p, near):
    """Signed distance of points in face coordinates to clip plane ``p`` of their face; inside
    is >= 0.  Planes: w - u, w + u, w - v, v - v0 w (``v0`` of :data:`FACE_V0`: -w on top,
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


def clip_to_faces(uvw, faces, near):
    """Clip polygons (M, 4, 3) in face coordinates to their face's frustum.

    A polygon is clipped only by the planes it crosses.  Returns the clipped polygons (M', K, 3)
    padded by repeating their last vertex, their vertex counts (>= 3) and the index (M',) of
    the input polygon of each; polygons clipped away entirely are left out.  Successive planes
    can leave vertices a rounding error apart, which makes a clipped polygon slightly
    non-convex; its fan triangles (:func:`fans`) are convex whatever the noise, so they are
    what is rasterised.
    """
    poly = uvw
    count = np.full(len(uvw), uvw.shape[1])
    alive = np.arange(len(uvw))
    for p in range(5):
        dist = plane_distance(poly[..., 0], poly[..., 1], poly[..., 2], FACE_V0[faces[alive]][:, None],
                               p, near)
        out = dist < 0
        cut = np.flatnonzero(fold(np.logical_or, list(out.T)))
        if not cut.size:
            continue
        gone = fold(np.logical_and, list(out[cut].T))
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


def fans(px, py, count):
    """Fan triangles (v0, vk, vk+1) of polygons (M, K) with ``count`` vertices each.

    Returns px, py as lists of 3 arrays (T,) and the polygon (T,) of each triangle.
    """
    W = px.shape[1]
    m, k = np.nonzero(np.arange(1, W - 1) < (count[:, None] - 1))
    i0 = m * W
    i1 = i0 + k + 1
    px, py = px.ravel(), py.ravel()
    return [px[i0], px[i1], px[i1 + 1]], [py[i0], py[i1], py[i1 + 1]], m


def project(uvw, faces, R):
    """Pixel coordinates (px, py) of face-coordinate vertices (M, K, 3) on their face."""
    half = np.float32(R / 2)
    w = uvw[..., 2]
    px = (uvw[..., 0] / w + 1) * half
    py = (uvw[..., 1] / w - FACE_V0[faces][:, None]) * half
    # moved so that pixel centres sample SAMPLE_X, SAMPLE_Y off the centres (exact: both are
    # multiples of 1 / SUBPIXEL)
    return subpixel(px.astype(np.float32)) - np.float32(SAMPLE_X), \
        subpixel(py.astype(np.float32)) - np.float32(SAMPLE_Y)


def depth_planes(R, nl, dist, faces):
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
    # pixel coordinates are drawn SAMPLE_X, SAMPLE_Y less (:func:`project`)
    c = ((nw - nu + FACE_V0[faces] * nv) / dist + nu * s * SAMPLE_X + nv * s * SAMPLE_Y).astype(np.float32)
    return a, b, c
