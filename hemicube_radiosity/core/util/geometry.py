"""Geometry helpers with no radiosity knowledge (pure NumPy): frames around normals, the bilinear
map of a quad and regular polygons standing in for disks.

Frames
------
* :func:`orthonormal_basis` (N, 3) unit vectors -> two (N, 3) unit vectors spanning the plane
  perpendicular to them: the first is the vector crossed into the world axis least aligned
  with it, the second completes a right-handed frame.
* :func:`tangent_frames` (N, 3) unit normals -> (N, 3, 3) frames, rows (u, v, n), the same basis
  optionally turned about the normal; the hemi-cube, Embree and the final gather cast with it.
* :func:`in_frames` directions given in such frames -> world space.
* :func:`cross3` ``np.cross`` of (..., 3) vectors, the same values, without its overhead.

Patches
-------
* :func:`bilinear` (u, v) in [0, 1]^2 -> points on quads (a triangle repeats its third corner).

Disks
-----
* :func:`disk_polygons` (N, sides, 3): regular polygons standing in for disks (same area,
  :func:`equal_area_scale`), so a disk's form factor is a polygon's.

Lengths are in the scene's units (Blender metres); angles in radians.
"""
from __future__ import annotations

import numpy as np

__all__ = ["cross3", "orthonormal_basis", "tangent_frames", "in_frames", "bilinear", "barycentric", "equal_area_scale",
           "disk_polygons", "DISK_SIDES"]

#: Sides of the regular polygon standing in for disks and ellipses.
DISK_SIDES = 64


# --------------------------------------------------------------------------------------------
# Frames


def cross3(a, b) -> np.ndarray:
    """``np.cross(a, b)`` of float64 (..., 3) arrays (broadcast against each other): each
    component one product less another, as NumPy's (``numeric.cross``) computes it, so the
    same values bit for bit, without its axis moves and copies (most of its cost on the many
    small arrays of a contour integral: zdm2's output stage called it 13,000 times)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    for k, (i, j) in enumerate(((1, 2), (2, 0), (0, 1))):
        c = out[..., k]
        np.multiply(a[..., i], b[..., j], out=c)
        c -= a[..., j] * b[..., i]
    return out


def orthonormal_basis(m):
    """(N,3), (N,3): two unit vectors spanning the plane perpendicular to unit vectors ``m``
    (N,3): ``e1`` is ``m`` crossed into the world axis least aligned with it, ``e2 = m x e1``."""
    m = np.asarray(m, dtype=np.float64)
    helper = np.zeros_like(m)
    helper[np.arange(len(m)), np.argmin(np.abs(m), axis=1)] = 1.0
    e1 = cross3(helper, m)
    # a zero ``m`` (a face of no area's normal) gets the x axis, not NaN
    length = np.linalg.norm(e1, axis=1, keepdims=True)
    e1 = np.divide(e1, length, out=np.tile([1.0, 0.0, 0.0], (len(m), 1)), where=length > 0)
    return e1, cross3(m, e1)


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


def in_frames(local, frames, dtype=np.float64):
    """(M, R, 3) the directions ``local`` (R, 3), given in each frame's (u, v, n), in world
    space for every frame of ``frames`` (M, 3, 3) (from :func:`tangent_frames`): the sum over
    the three axes in order, as ``np.einsum("rj,mjc->mrc", local, frames)`` sums it (the same
    values, bit for bit). One world axis at a time, as outer products of contiguous (M, R)
    planes: about four times as fast as broadcasting the (M, R, 3) products (a vertex stage's
    sky and gather rays are tens of millions). ``dtype``: of the result, each sum rounded to it
    once (float32: what Embree is handed, without a float64 copy)."""
    frames = np.asarray(frames, dtype=np.float64)
    local = np.asarray(local, dtype=np.float64)
    d = np.empty((len(frames), len(local), 3), dtype=dtype)
    for c in range(3):
        x = np.multiply.outer(frames[:, 0, c], local[:, 0])
        x += np.multiply.outer(frames[:, 1, c], local[:, 1])
        x += np.multiply.outer(frames[:, 2, c], local[:, 2])
        d[..., c] = x
    return d


# --------------------------------------------------------------------------------------------
# Patches


def bilinear(c, u, v):
    """Points ``(u, v)`` in [0, 1]^2 mapped onto quads: ``c`` (..., 4, 3) corners in order, u and
    v broadcasting against ``c[..., 0, :]``; (..., 3). A triangle repeats its third corner."""
    return (1 - u) * (1 - v) * c[..., 0, :] + u * (1 - v) * c[..., 1, :] + u * v * c[..., 2, :] \
        + (1 - u) * v * c[..., 3, :]


# --------------------------------------------------------------------------------------------
# Disks


def barycentric(V, x) -> np.ndarray:
    """(m, 3) barycentric weights of points ``x`` (m, 3) in triangles ``V`` (m, 3, 3): of their
    projections onto the triangles' planes; outside a triangle some are negative."""
    a, b = V[:, 1] - V[:, 0], V[:, 2] - V[:, 0]
    d = x - V[:, 0]
    aa, ab, bb = (np.einsum("ij,ij->i", *q) for q in ((a, a), (a, b), (b, b)))
    da, db = np.einsum("ij,ij->i", d, a), np.einsum("ij,ij->i", d, b)
    det = aa * bb - ab * ab
    det = np.where(np.abs(det) > 0, det, 1.0)
    s, t = (bb * da - ab * db) / det, (aa * db - ab * da) / det
    return np.stack([1 - s - t, s, t], 1)


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
