"""Delta form factors of the hemi-cube pixels, integrated exactly.

Cohen & Greenberg (1985, eq. 3) weight each hemi-cube pixel by the differential form factor at
its centre, ``dA / (pi (x^2 + y^2 + 1)^2)``.  Here each pixel's weight is the exact form factor
from a differential area at the origin (normal +Z) to the pixel's square, so the weights of a
table sum to 1 to round-off at every resolution.  The closed forms come from the contour
integral ``F = 1/(2 pi) sum_edges angle_k * n . unit(r_k x r_k+1)`` evaluated on a rectangle
with one corner at the foot of the face (the "corner function"); a pixel is the usual
inclusion-exclusion of four corners.

Layout (shared with :mod:`hemicube`)
------------------------------------
* Top face: the square ``x, y in [-1, 1]`` on the plane ``z = 1``; ``top[row, col]`` is the
  pixel with ``y`` in row ``row`` and ``x`` in column ``col``, both counted from -1 upwards.
* Side faces: the upper half (``z in [0, 1]``) of the unit-distance face, e.g. the plane
  ``x = 1``; ``side[row, col]`` has ``z`` in row ``row`` counted from the horizon and the
  coordinate along the face in column ``col`` counted from -1.  All four side faces share it.

Pixel edges sit at ``-1 + 2 k / R``; a side face has ``R // 2`` rows of the same pixel size.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

__all__ = ["delta_form_factors", "top_corner", "side_corner"]


def top_corner(x, y):
    """Form factor from the origin (normal +Z) to the rectangle ``[0, x] x [0, y]`` on ``z = 1``.

    Parameters
    ----------
    x, y : array_like
        Signed extents; the result is odd in each of them, so inclusion-exclusion over any
        rectangle ``[x0, x1] x [y0, y1]`` works across the axes.

    Returns
    -------
    ndarray
        ``(x/sqrt(1+x^2) atan(y/sqrt(1+x^2)) + y/sqrt(1+y^2) atan(x/sqrt(1+y^2))) / (2 pi)``.
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    hx = np.sqrt(1.0 + x * x)
    hy = np.sqrt(1.0 + y * y)
    return (x / hx * np.arctan(y / hx) + y / hy * np.arctan(x / hy)) / (2.0 * np.pi)


def side_corner(s, z):
    """Form factor from the origin (normal +Z) to the rectangle ``y in [0, s], z' in [0, z]`` on ``x = 1``.

    Parameters
    ----------
    s : array_like
        Signed extent along the face (the result is odd in ``s``).
    z : array_like
        Height above the horizon, ``z >= 0``.

    Returns
    -------
    ndarray
        ``(atan(s) - atan(s / sqrt(1+z^2)) / sqrt(1+z^2)) / (2 pi)``.
    """
    s = np.asarray(s, dtype=np.float64)
    hz = np.sqrt(1.0 + np.asarray(z, dtype=np.float64) ** 2)
    return (np.arctan(s) - np.arctan(s / hz) / hz) / (2.0 * np.pi)


def _rect_sum(corner, a0, a1, b0, b1):
    """Inclusion-exclusion of a corner function over rectangles ``[a0, a1] x [b0, b1]``."""
    return corner(a1, b1) - corner(a0, b1) - corner(a1, b0) + corner(a0, b0)


def _pixel_edges(resolution):
    """(R + 1,) pixel edge coordinates ``-1 + 2 k / R``."""
    return -1.0 + 2.0 * np.arange(resolution + 1) / resolution


def _top_octant(resolution):
    """Top-face weights on one octant, mirrored to the full (R, R) table.

    Only pixels with ``0 <= x`` and ``0 <= y <= x`` (their index pairs ``j <= i`` in the upper
    quadrant) are integrated; the quadrant is completed by transposition and the face by
    mirroring in x and y.
    """
    h = resolution // 2
    e = _pixel_edges(resolution)[h:]  # edges of the upper half: 0 .. 1
    i, j = np.nonzero(np.tril(np.ones((h, h), dtype=bool)))  # i = x index, j = y index, j <= i
    quadrant = np.zeros((h, h))
    quadrant[j, i] = _rect_sum(top_corner, e[i], e[i + 1], e[j], e[j + 1])
    quadrant = quadrant + np.triu(quadrant, 1).T  # rows y, cols x; fill y > x from symmetry
    upper = np.concatenate([quadrant[:, ::-1], quadrant], axis=1)
    return np.concatenate([upper[::-1], upper], axis=0)


def _side_half(resolution):
    """Side-face weights on the half ``s >= 0``, mirrored to the full (R // 2, R) table."""
    h = resolution // 2
    e = _pixel_edges(resolution)[h:]  # 0 .. 1, used both along the face and in height
    half = _rect_sum(side_corner, e[None, :-1], e[None, 1:], e[:-1, None], e[1:, None])
    return np.concatenate([half[:, ::-1], half], axis=1)


@lru_cache(maxsize=None)
def _tables(resolution):
    top = _top_octant(resolution)
    side = _side_half(resolution)
    top.setflags(write=False)
    side.setflags(write=False)
    return top, side


def delta_form_factors(resolution):
    """Exact per-pixel delta form factors of a hemi-cube of ``resolution`` pixels across the top.

    Parameters
    ----------
    resolution : int
        Pixels across the top face (R); even and >= 2 so that side faces have ``R // 2`` rows.

    Returns
    -------
    top : ndarray, shape (R, R), float64
        ``top[row, col]``: form factor to the top-face pixel in row ``row`` (y) and column
        ``col`` (x).
    side : ndarray, shape (R // 2, R), float64
        ``side[row, col]``: form factor to the side-face pixel ``row`` pixels above the horizon
        and ``col`` pixels along the face; the same table serves all four side faces.

    ``top.sum() + 4 * side.sum() == 1`` to round-off.  The arrays are cached per resolution and
    read-only.

    Raises
    ------
    ValueError
        If ``resolution`` is not an even integer >= 2.
    """
    r = int(resolution)
    if r != resolution or r < 2 or r % 2:
        raise ValueError(f"hemi-cube resolution must be an even integer >= 2, got {resolution!r}")
    return _tables(r)
