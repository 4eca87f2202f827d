"""Rays over a point's hemisphere: how much of it is open sky, how much leaves into the open.

* :func:`cosine_lattice`: one cosine-distributed pattern of directions that every point shares
  (in its own normal's frame), so neighbouring points cast parallel rays;
* :func:`sky_fraction`: the cosine-weighted share of a point's hemisphere from which no surface
  is hit (the world's light arriving is the world's radiance times it);
* :func:`open_fraction` / :func:`closed_rays`: the share of rays that leave into the open (not
  onto a patch's back or a surface nearer than a reach).

The rays are cast by a back-end of :mod:`.rays` (Embree or the NumPy BVH).
"""
from __future__ import annotations

import numpy as np

from .mesh.patches import PatchSet
from .rays import ray_offsets
from .runtime.parallel import ordered_map, resolve_workers
from .util.geometry import in_frames, tangent_frames
from .util.sampling import cosine_directions, jittered_grid

__all__ = ["SKY_FIRST", "cosine_lattice", "sky_fraction", "open_fraction", "closed_rays"]

#: :func:`sky_fraction`'s ``first`` where the world's light is found at points one by one
#: (:meth:`.light.direct.DirectLight.world_at`): a quarter of the pattern first (64 of 256 rays).
#: Measured on every sky ray of the bench's zdm2 output vertices (152,134 points, 256 rays): 51%
#: of them had their first 64 all blocked (45%) or all open (5.5%), 38% of the rays; at those
#: points the fraction moved by 0.004 RMS (mean -0.0008, at most 0.078: a window that the
#: first 64 missed). A first eighth saved 52% at 0.017 RMS, a sixteenth 59% at 0.025.
SKY_FIRST = 4


def open_fraction(patches: PatchSet, points, normals, scene, reach: float, rays: int = 16, seed: int = 0,
                  chunk_rays: int = 1 << 20, workers: int = 1, eps=None) -> np.ndarray:
    """(P,) fraction of ``rays`` cosine rays from each point (P, 3) with unit ``normals`` that
    leave it into the open (:func:`closed_rays`, ``reach`` in world units): a point a few
    millimetres above a lamp's back, or on a floor buried inside a block, has none; one in the
    open all, one in a corner about half. ``scene``: :func:`.rays.embree_scene` of ``patches``.
    One jittered pattern (seeded) for every point, in its normal's frame. Geometry only.
    ``workers`` (0 = every core): threads casting a few chunks of points each (Embree lets go of
    the GIL while it casts); each point's value does not depend on the chunks, so the result is
    the same for any count. ``eps`` (P,): the rays' start offsets (default :func:`ray_offsets`)."""
    points = np.asarray(points, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    u, v = jittered_grid(np.random.default_rng(seed), 1, rays)
    local = cosine_directions(np.stack([u[0], v[0]], -1))                         # (R, 3)
    R = len(local)
    eps = (ray_offsets(patches, points, normals, scene=scene) if eps is None else np.asarray(eps, np.float64))[:, None]
    out = np.empty(len(points))
    step = max(1, chunk_rays // R)
    workers = resolve_workers(workers)
    if workers > 1:                  # two chunks a worker, of at least 4,096 points
        step = max(1, min(step, max(4096, -(-len(points) // (2 * workers)))))
    if len(points) and (workers > 1 and len(points) > step):
        scene.intersect(points[:1], normals[:1])      # commit the scene before threads share it

    def chunk(s):
        x, n = points[s:s + step], normals[s:s + step]
        d = in_frames(local, tangent_frames(n)).reshape(-1, 3)
        # Embree's float32 starts rounded before they are repeated (the same values)
        pid, t = scene.intersect(np.repeat((x + eps[s:s + step] * n).astype(np.float32), R, axis=0), d)
        out[s:s + step] = 1.0 - closed_rays(patches, d, pid, t, reach).reshape(len(x), R).mean(axis=1)
    for _ in ordered_map(chunk, range(0, len(points), step), workers if len(points) > step else 1):
        pass
    return out


def closed_rays(patches: PatchSet, directions, pid, t, reach: float) -> np.ndarray:
    """(M,) bool: the rays (``directions`` (M, 3), hits ``pid``, ``t`` of :meth:`EmbreeScene.intersect`)
    that hit a patch's back, or any surface nearer than ``reach``: those not leaving into the open."""
    hit = np.asarray(pid) >= 0
    back = np.zeros_like(hit)
    back[hit] = np.einsum("ij,ij->i", directions[hit], patches.normals[np.asarray(pid)[hit]]) > 0
    return back | (hit & (np.asarray(t) < reach))


def cosine_lattice(rays: int, seed: int = 0) -> np.ndarray:
    """(rays, 3) cosine-distributed local directions (+Z the normal) from a Fibonacci lattice of
    the unit square, (u, v) = ((i + 1/2) / n, i / golden ratio) mod 1, shifted by a seeded
    random offset (a Cranley-Patterson rotation: over seeds its mean is the exact integral),
    mapped as :func:`.sampling.cosine_directions` does (u the squared radius on the disk, v the
    angle: Vogel's sunflower, lifted to the hemisphere).

    For a pattern every point shares, what matters is how evenly it covers any sliver of the
    hemisphere: as a point moves, the rays that cross an object's outline switch from sky to
    object one at a time, and an uneven pattern makes uneven steps between neighbouring
    points. The lattice covers slivers more evenly than a jittered grid: on the open yard's
    ground and walls the sky's roughness at 256 rays is what a jittered grid reaches at 1,024."""
    n = int(rays)
    shift = np.random.default_rng(seed).uniform(size=2)
    i = np.arange(n)
    u = ((i + 0.5) / n + shift[0]) % 1.0
    v = (i * (np.sqrt(5.0) - 1.0) / 2.0 + shift[1]) % 1.0
    return cosine_directions(np.stack([u, v], -1))


def sky_fraction(scene, points, normals, rays: int = 256, seed: int = 0, chunk_rays: int = 1 << 16, *,
                 eps, facing=None, workers: int = 1, split: int = 1, part=None, first: int = 1) -> np.ndarray:
    """(P,) cosine-weighted fraction of each point's hemisphere (unit ``normals``) from which no
    surface is hit: the world's radiance times it is the world's light arriving. ``scene``:
    anything with ``occluded(origins, directions)`` (:func:`occluder`); ``eps`` (P,) the rays'
    start offsets (:func:`ray_offsets` of the points on the scene's patches). One pattern of ``rays``
    (:func:`cosine_lattice`, seeded) for every point, in its normal's frame: neighbouring points
    cast parallel rays, so the estimate varies smoothly over a surface. ``facing`` (P, 3) or
    None: rays with a negative or zero component along it count as hitting a surface (below a
    point's own triangle, :func:`.light.lamps.direct_irradiance`). ``split``: the points share
    the pattern out, point p casting rays ``part[p]``, ``part[p] + split``, ... (``rays / split``
    each); ``part`` (P,) in [0, split), default runs of ``split`` points (a cell's, whose mean
    is what is read: it casts every ray of the pattern once).

    ``first`` > 1 (with ``split`` 1, no ``facing``, an opaque scene): every point casts rays 0,
    ``first``, 2 ``first``, ... of the pattern first (an even share of it: a lattice of its own);
    where all of them meet a surface the point's fraction is 0, where none does 1, and only
    the others cast the rest (their fraction from every ray, as with ``first`` 1). A point deep
    in a closed room or out in the open casts a ``first``-th of the rays; what it misses is a
    sliver of sky (or of wall) that no ray of the first share found (:data:`SKY_FIRST`).

    ``chunk_rays``: rays cast at once (65,536: their temporaries stay in the caches); ``workers``
    (0 = every core): threads casting chunks of points (Embree lets go of the GIL while it
    casts, and so do the large NumPy steps). Each point's value depends on neither, so the
    result is the same, bit for bit, for any chunking and any count."""
    points = np.asarray(points, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    local = cosine_lattice(rays, seed)                                             # (R, 3)
    R = len(local) // split
    eps = np.broadcast_to(np.asarray(eps, dtype=np.float64), (len(points),))[:, None]
    out = np.empty(len(points))
    step = max(1, chunk_rays // R)
    part = np.arange(len(points)) % split if part is None else np.asarray(part, dtype=np.int64)
    workers = resolve_workers(workers) if len(points) > step else 1
    see_through = getattr(scene, "see_through", False)
    if workers > 1 and not see_through:
        scene.occluded(points[:1], normals[:1])       # commit the scene before threads share it
    # Embree takes float32: the directions rounded once from the same float64 sums, the
    # origins before they are repeated (the same values as a float64 array cast whole); with
    # ``facing``, float64 directions only for the points whose unit normal is not within half
    # the pattern's lowest ray's height of their ``facing``: no ray of the others lies below it
    # (d . facing >= z - |facing - n| > z / 2, far beyond rounding; seed 0's lowest is 0.04
    # above the plane at 256 rays, 0.01 at 4,096), so they are cast as without one
    facing = None if facing is None else np.asarray(facing, dtype=np.float64)
    clear = (0.5 * max(float(local[:, 2].min()), 0.0)) ** 2
    dt = np.float64 if see_through else np.float32
    early = first > 1 and split == 1 and facing is None and not see_through and R % first == 0
    first = first if early else 1

    def chunk(s):
        x, n = points[s:s + step], normals[s:s + step]
        f, p = tangent_frames(n), part[s:s + step]
        d = _directions(local, split, f, p, dt).reshape(-1, 3)
        o = x + eps[s:s + step] * n
        o = np.repeat(o if see_through else o.astype(np.float32), R, axis=0)
        below = None if facing is None else _below(local, split, f, p, n, facing[s:s + step], clear)
        out[s:s + step] = _fraction(scene, o, d, below, len(x), R, see_through, first)
    for _ in ordered_map(chunk, range(0, len(points), step), 1 if see_through else workers):
        pass
    return out


def _fraction(scene, o, d, below, P, R, see_through, first) -> np.ndarray:
    """(P,) :func:`sky_fraction` of P points from their R rays each, ``o``, ``d`` (P R, 3):
    what passes a see-through scene (``below`` (P R,) bool or None: rays counted blocked), a
    ``first`` share first (:func:`_early_fraction`), or every ray's hit."""
    if see_through:
        passed = scene.transmitted(o, d)
        if below is not None:
            passed = np.where(below, 0.0, passed)
        return passed.reshape(P, R).mean(axis=1)
    if first > 1:
        return _early_fraction(scene, o, d, P, R, first)
    return 1.0 - _hits(scene, o, d, below).reshape(P, R).mean(axis=1)


def _early_fraction(scene, o, d, P, R, first) -> np.ndarray:
    """(P,) :func:`sky_fraction` of P points whose R rays each are ``o``, ``d`` (P R, 3): rays 0,
    ``first``, ... of every point first; the rest only where those are neither all hits nor
    all misses. The fraction of a point that casts them all is the mean of its R hits, in the
    pattern's order (as without ``first``)."""
    o, d = o.reshape(P, R, 3), d.reshape(P, R, 3)
    head = np.asarray(scene.occluded(o[:, ::first].reshape(-1, 3), d[:, ::first].reshape(-1, 3))).reshape(P, -1)
    n = head.sum(axis=1)
    out = np.where(n == 0, 1.0, 0.0)
    mixed = np.flatnonzero((n > 0) & (n < head.shape[1]))
    if mixed.size:
        hit = np.empty((mixed.size, R), bool)
        hit[:, ::first] = head[mixed]
        rest = np.ones(R, bool)
        rest[::first] = False
        hit[:, rest] = np.asarray(scene.occluded(o[mixed][:, rest].reshape(-1, 3),
                                                 d[mixed][:, rest].reshape(-1, 3))).reshape(mixed.size, -1)
        out[mixed] = 1.0 - hit.mean(axis=1)
    return out


def _directions(local, split, frames, part, dtype) -> np.ndarray:
    """(P, R, 3) world directions of :func:`sky_fraction`'s pattern ``local`` (R * split, 3) in
    each point's ``frames``: all of it, or with ``split`` > 1 rays ``part[p]``, ``part[p] + split``,
    ... of it at point p; float64 sums rounded once to ``dtype``."""
    if split == 1:
        return in_frames(local, frames, dtype)
    d = np.empty((len(frames), len(local) // split, 3), dtype)
    for k in range(split):
        m = part == k
        d[m] = in_frames(local[k::split], frames[m], dtype)
    return d


def _below(local, split, frames, part, normals, facing, clear):
    """(P * R,) bool or None: the rays of :func:`_directions` at or below each point's ``facing``
    plane, found in float64 for the points whose unit normal lies ``clear`` (a squared distance)
    or further from their facing; None where no point does (no ray lies below)."""
    off = facing - normals
    near = (np.abs(np.einsum("ij,ij->i", normals, normals) - 1.0) < 1e-6) & (np.einsum("ij,ij->i", off, off) < clear)
    tilt = np.flatnonzero(~near)
    if not tilt.size:
        return None
    R = len(local) // split
    # the same float64 directions and products as for the whole chunk
    dd = _directions(local, split, frames[tilt], part[tilt], np.float64).reshape(-1, 3)
    below = np.zeros((len(frames), R), bool)
    below[tilt] = (np.einsum("ij,ij->i", dd, np.repeat(facing[tilt], R, axis=0)) <= 0).reshape(-1, R)
    return below.reshape(-1)


def _hits(scene, o, d, below):
    """(M,) bool: the rays ``o`` + t ``d`` (M, 3) that meet a surface; those ``below`` (M,) bool
    (or None) a point's ``facing`` plane count as hits and are not cast."""
    if below is None:
        return np.asarray(scene.occluded(o, d))
    hit = below.copy()
    up = np.flatnonzero(~below)
    if up.size:
        hit[up] = np.asarray(scene.occluded(o[up], d[up]))
    return hit
