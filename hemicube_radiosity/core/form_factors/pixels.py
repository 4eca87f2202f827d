"""The hemi-cube's faces and pixels: their order, the point each pixel samples, the snapping grid
and the receiver frames, shared by the rasteriser (:mod:`.hemicube`) and Embree (:mod:`.embree`).

Five faces in one item-buffer row per receiver: the top face's R rows of R pixels (``x``, ``y``
in [-1, 1] on the plane ``z = 1``), then the R/2 rows of the side faces +X, -X, +Y and -Y (the
upper half of the unit-distance face), the layout of :mod:`.deltaff`'s tables; so 3 R^2
pixels. Coordinates are in the receiver frame (+Z the normal, dimensionless).

Frames: :func:`.geometry.tangent_frames` (the tangent u is the normal crossed into the world
axis least aligned with it), turned about the normal by an angle drawn for all patches at once
when ``rotate_seed`` is given (so a row does not depend on which receivers are asked for).
"""
from __future__ import annotations

import numpy as np

from .deltaff import delta_form_factors
from ..util.geometry import tangent_frames

__all__ = ["pixel_weights", "pixel_directions", "receiver_frames", "subpixel", "SUBPIXEL",
           "SAMPLE_X", "SAMPLE_Y"]

#: Vertices are snapped to 1/SUBPIXEL of a pixel (as GPUs snap to a sub-pixel grid): the same
#: scene at another scale, which differs by float rounding, draws the same pixels (an edge
#: through a pixel centre stays exactly on it, and the fill rule of :func:`.raster._covers`
#: decides it). 2^14 keeps ``R * SUBPIXEL`` within float32's exact integers up to R = 1024.
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


def subpixel(p):
    """Pixel coordinates ``p`` (float32) rounded to :data:`SUBPIXEL` of a pixel, as GPUs do."""
    with np.errstate(invalid="ignore", over="ignore"):
        return np.rint(p * np.float32(SUBPIXEL)) / np.float32(SUBPIXEL)
