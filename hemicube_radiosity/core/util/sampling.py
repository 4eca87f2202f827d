"""Sampling the unit square [0, 1)^2 (dimensionless), and mapping it onto the hemisphere and disks
(pure NumPy, no radiosity knowledge).

Two stratified samplers, kept apart because their draws differ and saved bakes depend on them:

* :func:`stratified_unit_square` (count, k, 2): an m x (k // m) jittered grid, m = floor(sqrt k),
  the leftover points uniform (lamp shadow samples, stochastic form factors).
* :func:`jittered_grid` (count, g^2) u and v: a g x g jittered grid, g = ceil(sqrt samples)
  (emitter shadow samples, the final gather's ray pattern).

:func:`cosine_directions` maps the square to cosine-distributed unit directions in a local
frame (+Z the normal); :func:`disk_samples` to points on disks, uniform by area (lengths in the
scene's units).
"""
from __future__ import annotations

import numpy as np

from .geometry import orthonormal_basis

__all__ = ["stratified_unit_square", "jittered_grid", "cosine_directions", "disk_samples", "place_keys",
           "keyed_uniforms"]


def place_keys(points, origin, size) -> np.ndarray:
    """(P,) uint64 keys of ``points`` (P, 3): a hash of each one's position from ``origin`` (3,),
    to 2^-32 of ``size`` (the same point keys the same in any order)."""
    q = np.floor((np.asarray(points, dtype=np.float64) - origin) / size * 2.0 ** 32).astype(np.int64).astype(np.uint64)
    with np.errstate(over="ignore"):
        return (q[:, 0] * np.uint64(0x9E3779B97F4A7C15)) ^ (q[:, 1] * np.uint64(0xC2B2AE3D27D4EB4F)) \
            ^ (q[:, 2] * np.uint64(0x165667B19E3779F9))


def keyed_uniforms(keys, count) -> np.ndarray:
    """(P, count) uniforms in [0, 1), a stream of ``count`` for each of ``keys`` (P,) uint64
    (splitmix64 from the key): a key draws the same numbers whatever else is drawn."""
    with np.errstate(over="ignore"):
        z = np.asarray(keys, np.uint64)[:, None] \
            + (np.arange(1, count + 1, dtype=np.uint64) * np.uint64(0x9E3779B97F4A7C15))[None]
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)          # splitmix64's finaliser
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        z ^= z >> np.uint64(31)
    return (z >> np.uint64(11)).astype(np.float64) / 2.0 ** 53


def stratified_unit_square(rng, count, k):
    """(count, k, 2) points in [0,1)^2: a jittered m x (k // m) grid (m = floor(sqrt k)), the
    k - m * (k // m) left over drawn uniformly; a fresh jitter per row. ``rng``: a NumPy
    ``Generator`` (the jitter is drawn first, then the leftovers)."""
    m = max(1, int(np.floor(np.sqrt(k))))
    c = k // m
    gi, gj = np.meshgrid(np.arange(m), np.arange(c), indexing="ij")
    base = np.stack([gi.reshape(-1) / m, gj.reshape(-1) / c], -1)          # (m*c, 2)
    pts = base[None] + rng.random((count, m * c, 2)) * np.array([1.0 / m, 1.0 / c])
    if k > m * c:
        pts = np.concatenate([pts, rng.random((count, k - m * c, 2))], axis=1)
    return pts


def jittered_grid(rng, count, samples):
    """``u``, ``v`` (count, g*g) in [0,1): a g x g jittered grid, g = ceil(sqrt samples) (so at
    least ``samples`` points), cell (i, j) at index i * g + j. ``rng``: a NumPy ``Generator``
    (all u jitter is drawn, then all v)."""
    g = int(np.ceil(np.sqrt(samples)))
    i, j = np.meshgrid(np.arange(g), np.arange(g), indexing="ij")
    u = (i.ravel()[None] + rng.uniform(0, 1, (count, g * g))) / g
    v = (j.ravel()[None] + rng.uniform(0, 1, (count, g * g))) / g
    return u, v


def cosine_directions(u):
    """Map (..., 2) points of the unit square to cosine-distributed local unit directions
    (..., 3), +Z the normal (Malley: uniform on the disk by area, lifted to the hemisphere)."""
    r = np.sqrt(u[..., 0])
    phi = 2.0 * np.pi * u[..., 1]
    z = np.sqrt(np.maximum(0.0, 1.0 - u[..., 0]))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], -1)


def disk_samples(u, center, normal, radius):
    """Points (N,S,3) on the disks ``center`` (N,3), unit ``normal`` (N,3) (or (1, 3): one for
    every disk, its frame made once), ``radius`` (N,) from unit-square points ``u`` (N,S,2),
    uniform by area. One coordinate at a time (``center + a e1 + b e2`` summed in that order:
    the same values, bit for bit, without the (N, S, 3) temporaries of broadcasting)."""
    e1, e2 = orthonormal_basis(normal)
    r = np.sqrt(u[..., 0]) * radius[:, None]
    phi = 2 * np.pi * u[..., 1]
    a, b = r * np.cos(phi), r * np.sin(phi)
    out = np.empty(a.shape + (3,))
    for c in range(3):
        x = center[:, c, None] + a * e1[:, c, None]
        x += b * e2[:, c, None]
        out[..., c] = x
    return out
