"""Light that a covered corner's near surfaces hand on to it (:mod:`.covered`).

A covered corner (:func:`.covered.covered_corners`) keeps its vertex's light reflected more than
once in proportion to the open scene it sees (:func:`.hemisphere.open_fraction`): its rays that
close within a reach of it lend nothing, which is right in a crack, whose walls are dark.
Cycles' rays from the corner read those near surfaces as they are lit, and in the apex of a
sunlit wedge the near wall is lit and bright (godot_zdm2's brushes meeting at 45 deg, the
corner 0.6 mm from the other wall: Cycles 1.21, ours 0.31 with a direct light of ~0.3).

Here the same rays (the open fraction's pattern, from the corner's start) that meet another
face's front within the reach find the direct light where they land
(:meth:`.light.direct.DirectLight.at`, :data:`PER_CORNER` landing points per corner, the world's
rays shared out among them): the corner receives c * mean(rho D) from them, c the share of its
rays that met such a front. In a crack the landing points lie in its shade: nothing is added.
Its vertex's light reflected more than once, of which the corner keeps a share, held what
the near fronts seen from the vertex's start hand on too: that much, found the same way there,
times the share, comes off (:func:`near_part`), so a corner no more covered than its vertex
gains nothing. Only the first bounce off the near fronts is taken: a wedge's walls light each
other over and over (an infinite one's radiosity is rho (D + ...) / (1 - rho F), F the view
factor between them), but a geometric series over c overshot the living room's sub-millimetre
bevels, whose near fronts Cycles reads dark (4.93% -> 5.04% RMS; godot_zdm2 12.34% -> 12.21%).
Faces of the corner's own source face are no near fronts: a warped face's other elements run a
hair off it (the living room's bevel corner 614 met its own face's other half 0.04 mm on, in
the sun where Cycles has the corner at 0.115). Geometry (the hits) is cached; their light is
found every bake.
"""
from __future__ import annotations

import numpy as np

from ..rays import embree_scene
from ..runtime.cache import array_key, cache_key, cached, geometry_key
from ..util.geometry import in_frames, tangent_frames
from ..util.sampling import cosine_directions, jittered_grid

__all__ = ["HIT_SAMPLES", "PER_CORNER", "face_keys", "near_hits", "near_light", "near_part"]

#: Landing points per corner whose direct light is found (the corner's near rays, evenly
#: picked, repeated where fewer met a near front). With 8 the living room's corner 704 read
#: 0.043 where Cycles has 0.022: one landing point of 8 fell on a sunlit face 2 cm off.
PER_CORNER = 32
#: Shadow rays per landing point toward each lamp (a sun's disc): the corner's mean is over
#: :data:`PER_CORNER` of them.
HIT_SAMPLES = 2


def face_keys(elements) -> np.ndarray:
    """(N,) int64 one key per (owner, source face) of the elements."""
    stride = int(elements.source_face.max(initial=0)) + 1
    return elements.owner.astype(np.int64) * stride + elements.source_face.astype(np.int64)


def near_hits(elements, scene, starts, normals, reach: float, rays: int, own=None, seed: int = 0):
    """(share (K,), points (K * PER_CORNER, 3), their normals, their elements (K * PER_CORNER,)):
    of ``rays`` cosine rays from each of ``starts`` (K, 3) (unit ``normals``; the pattern of
    :func:`.hemisphere.open_fraction` with ``seed``), the share that meet an element's front
    nearer than ``reach``, not of the start's own face (``own`` (K,) :func:`face_keys`, or
    None), and :data:`PER_CORNER` of their landing points per start (element -1 where none
    did). ``scene``: the Embree scene of ``elements``."""
    starts = np.asarray(starts, dtype=np.float64)
    u, v = jittered_grid(np.random.default_rng(seed), 1, rays)
    local = cosine_directions(np.stack([u[0], v[0]], -1))
    R, K = len(local), len(starts)
    d = in_frames(local, tangent_frames(np.asarray(normals, dtype=np.float64))).reshape(-1, 3)
    pid, t = scene.intersect(np.repeat(starts.astype(np.float32), R, axis=0), d)
    pid, t = np.asarray(pid, dtype=np.int64), np.asarray(t, dtype=np.float64)
    near = (pid >= 0) & (t < reach)
    near[near] = np.einsum("ij,ij->i", d[near], elements.normals[pid[near]]) < 0
    if own is not None:
        near[near] = face_keys(elements)[pid[near]] != np.repeat(np.asarray(own), R)[near]
    near = near.reshape(K, R)
    count = near.sum(axis=1)
    # PER_CORNER of each start's near rays, evenly over them (in the pattern's order)
    order = np.argsort(~near, axis=1, kind="stable")          # its near rays first
    j = (np.arange(PER_CORNER) + 0.5)[None, :] * np.maximum(count, 1)[:, None] / PER_CORNER
    ray = (np.take_along_axis(order, j.astype(np.int64), axis=1) + (np.arange(K) * R)[:, None]).ravel()
    hit = np.where(np.repeat(count > 0, PER_CORNER), pid[ray], -1)
    x = np.repeat(starts, PER_CORNER, axis=0) + t[ray, None] * d[ray]
    return count / R, np.where(hit[:, None] >= 0, x, 0.0), elements.normals[np.maximum(hit, 0)], hit


def near_light(ctx, elements, scene, starts, normals, reach: float, rays: int, where: str, own=None,
               seed: int = 0) -> np.ndarray:
    """(K, 3) radiance that reaches each of ``starts`` (K, 3) (unit ``normals``) from the fronts
    of :func:`near_hits`, lit by the direct light (``where``: the name of the points in the
    direct light's cache keys)."""
    key = cache_key(geometry_key(elements) + array_key(starts) + array_key(normals)
                    + (b"" if own is None else np.asarray(own, np.int64).tobytes()),
                    ("near-hits", reach, rays, seed, PER_CORNER))
    share, x, n, hit = cached(ctx.cache, key, lambda: near_hits(elements, scene, starts, normals, reach, rays, own,
                                                                 seed))
    out = np.zeros((len(starts), 3))
    some = np.flatnonzero(hit >= 0)             # whole runs of PER_CORNER: a start's or none
    if not some.size:
        return out
    # a few float32 steps off the landing point, toward where the ray came from
    lift = 8 * 2.0 ** -23 * np.maximum(np.abs(x[some]).max(axis=1), 1.0)
    D = ctx.direct.at(x[some], n[some], where, samples=HIT_SAMPLES, eps=lift, facing=n[some], split=PER_CORNER)
    np.add.at(out, some // PER_CORNER, np.asarray(elements.rho, dtype=np.float64)[hit[some]] * D / PER_CORNER)
    return share[:, None] * out


def near_part(ctx, elements, starts, normals, vstarts, vnormals, grouped, reach: float, rays: int, keep, rows,
              arriving=None, own=None) -> np.ndarray:
    """(K, 3) what to add to the direct light of covered corners at ``starts`` (K, 3) (unit
    ``normals``; rays within ``reach``, ``rays`` of them): their :func:`near_light`, less that
    at their vertices' starts ``vstarts`` (normals ``vnormals``) times ``keep`` (K,), the share
    of the vertex's light reflected more than once (``arriving`` (K, 3), per rho, or None) the
    corner keeps, and at most all of that. Only at ``rows`` (K,) bool; ``own`` (K,): each
    corner's :func:`face_keys` (its own face is no near front of the corner; the vertex's
    start, whose gather read every face, counts them all). ``grouped``: (one, of) the corners
    grouped by vertex start (:func:`.covered._start_groups`): the rays of each are cast once."""
    out = np.zeros((len(starts), 3))
    rows = np.flatnonzero(rows)
    if not rows.size:
        return out
    scene = embree_scene(elements)
    own = None if own is None else np.asarray(own)[rows]
    here = near_light(ctx, elements, scene, starts[rows], normals[rows], reach, rays, "covered-near", own)
    # once per vertex start (its corners share it), all its rays meet: what its gather read
    one, of = grouped
    used, of = np.unique(of[rows], return_inverse=True)         # the starts of ``rows``, in its order
    there = near_light(ctx, elements, scene, vstarts[one[used]], vnormals[one[used]], reach, rays,
                       "covered-near-vertex")[of.ravel()]
    less = keep[rows, None] * there
    if arriving is not None:
        less = np.minimum(less, keep[rows, None] * arriving[rows])
    out[rows] = here - less
    return out
