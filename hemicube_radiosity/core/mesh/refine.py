"""Refinement where the light changes abruptly: patches and output elements split where it does.

A patch has one radiosity. Where the direct light changes abruptly across it (the edge of a
shadow, the foot of a block, a lamp hanging a few millimetres under a ceiling) that one value is
wrong twice: it is too dark on one side and too bright on the other, and the part the rest of the
scene cannot see (the ceiling above the lamp, the floor under a block) lends its light to the
part that it can. The paper's answer is smaller patches there; this module finds where, from the
exact direct light at a few points of every patch, and splits only those patches, level by level
(each level halves their size), so the cost follows how the light varies, not the modelling.

Units: world units for positions; the light values are radiance (any consistent units: only
ratios and a fraction of their mean are compared).
"""
from __future__ import annotations

import numpy as np

from ..runtime.cache import Memo, array_key, cache_key, cached, frozen, geometry_key
from .clusters import make_clusters
from ..light.points import grid_of
from ..light.direct import DirectLight
from .patches import PatchSet, poly_geometry
from .stage import form_factor_gb
from ..rays import embree_available, embree_scene
from ..util.unique import unique_ints

__all__ = ["split_patches", "abrupt", "refine", "refine_stage"]

_SPLIT = Memo(8)         # (patches' geometry arrays, selection) -> the split geometry
_REGROUP = Memo(8)       # (clusters' grouping, parents, refined geometry) -> the refined clusters



def abrupt(values, ratio: float, floor: float) -> np.ndarray:
    """(N,) bool from (N, K) luminances at K points of each of N patches: the brightest point is
    more than ``ratio`` times the darkest and brighter than it by more than ``floor`` (absolute,
    same units): a change a bilinear or constant value cannot carry. Dark patches and faint
    gradients are not abrupt."""
    hi, lo = values.max(axis=1), values.min(axis=1)
    return (hi > ratio * lo) & (hi - lo > floor)


def split_patches(patches: PatchSet, select) -> tuple[PatchSet, np.ndarray]:
    """Every selected patch replaced by four: a quad at its edge midpoints and centre, a
    triangle at its edge midpoints. Returns the new PatchSet (unselected patches first, in
    order, then the children) and ``parent`` (N',) the index in ``patches`` each came from.
    Midpoints are shared between neighbours split together; a neighbour left whole keeps its
    edge (a T-junction: the surface stays closed, only values may differ along the edge)."""
    select = np.asarray(select, bool)
    if not select.any():
        return patches, np.arange(len(patches))
    # the geometry kept for the patches' arrays and the selection: a relight splits the same
    # patches of the same (cached) arrays and gets the same arrays back, which every later
    # stage has hashed and keyed its products on already
    verts, polys, centers, normals, areas, owner, face, parent = _SPLIT.of(
        (patches.verts, patches.polys, patches.normals, patches.owner, patches.source_face),
        lambda: _split_geometry(patches, select), key=np.packbits(select).tobytes())
    out = PatchSet(verts, polys, centers, normals, areas, patches.rho[parent], patches.emission[parent],
                   owner, face, list(patches.object_names), patches.see_through)
    return out, parent


def _split_geometry(patches: PatchSet, select):
    """The geometry of :func:`split_patches` (read only): verts, polys, centres, normals, areas,
    owner, source face and parent of the new patches."""
    keep = np.flatnonzero(~select)
    sel = np.flatnonzero(select)
    P = patches.polys[sel]
    tri = P[:, 3] < 0
    k = np.where(tri, 3, 4)
    # edges (a, b) of every selected patch, in corner order
    nxt = np.where(tri[:, None], np.array([1, 2, 0, 0]), np.array([1, 2, 3, 0]))
    a = P
    b = np.take_along_axis(np.where(P < 0, P[:, :1], P), nxt, axis=1)
    valid = np.arange(4)[None, :] < k[:, None]
    lo, hi = np.minimum(a, b)[valid], np.maximum(a, b)[valid]
    V = len(patches.verts)
    uniq, inv = unique_ints(lo * V + hi, return_inverse=True)
    mids = 0.5 * (patches.verts[uniq // V] + patches.verts[uniq % V])
    mid = np.full(P.shape, -1, np.int64)
    mid[valid] = V + inv.reshape(-1)
    quads = np.flatnonzero(~tri)
    centres = patches.verts[P[quads]].mean(axis=1)
    ctr = np.full(len(P), -1, np.int64)
    ctr[quads] = V + len(uniq) + np.arange(quads.size)
    verts = np.concatenate([patches.verts, mids, centres])
    c0, c1, c2, c3 = P.T
    m0, m1, m2, m3 = mid.T             # m0 on edge c0-c1, m1 on c1-c2, m2 on c2-c3 (c2-c0 for a triangle)
    neg = np.full(len(P), -1, np.int64)
    q = [np.stack(s, 1) for s in ((c0, m0, ctr, m3), (m0, c1, m1, ctr), (ctr, m1, c2, m2), (m3, ctr, m2, c3))]
    t = [np.stack(s, 1) for s in ((c0, m0, m2, neg), (m0, c1, m1, neg), (m2, m1, c2, neg), (m0, m1, m2, neg))]
    children = np.stack([np.where(tri[:, None], ti, qi) for qi, ti in zip(q, t)], 1).reshape(-1, 4)
    parent = np.concatenate([keep, np.repeat(sel, 4)])
    polys = np.concatenate([patches.polys[keep], children])
    centers, normals, areas = poly_geometry(verts, polys)
    normals = patches.normals[parent]            # children lie in their parent's plane
    return frozen(verts, polys, centers, normals, areas, patches.owner[parent], patches.source_face[parent], parent)


def refine(patches: PatchSet, light_at, levels: int, *, ratio=8.0, floor=0.05, n=3, min_area=0.0,
           frozen=None, say=None, crossed=None) -> tuple[PatchSet, np.ndarray]:
    """Split patches where the direct light changes abruptly, up to ``levels`` times.

    ``light_at(points (P, 3), normals (P, 3)) -> (P, S)``: the luminance arriving directly from
    each of S sources apart (:meth:`.light.direct.DirectLight.sources_at`). A patch is split
    when the light of one source is :func:`abrupt` over an ``n`` x ``n`` grid of its points,
    ``floor`` a fraction of that source's area-weighted mean over the scene (taken once, from
    the patches as given). Each source is judged on its own and only by ratios, so a relight
    (new strengths, colours, reflectivities) splits the same patches and reuses the form
    factors. A patch smaller than ``min_area`` or ``frozen`` (N,) bool (emitters, grouped faces)
    stays. Returns the refined PatchSet and ``parent`` (N',) into the patches given."""
    parent = None                         # (the identity) kept as the same array for the same splits
    frozen = np.zeros(len(patches), bool) if frozen is None else np.asarray(frozen, bool)
    check = ~frozen & (patches.areas > min_area)
    absolute = None
    for level in range(levels):
        ids = np.flatnonzero(check)
        if ids.size == 0:
            break
        sub = patches.take(ids, see_through=True)
        x, flat, nrm, w = grid_of(patches, ids, n)      # kept for the geometry: a relight's are hashed once
        K = x.shape[1]
        Y = np.asarray(light_at(flat, nrm))
        Y = Y.reshape(len(ids), K, -1)                                            # (n, K, S)
        if absolute is None:
            mean = np.einsum("nk,nks,n->s", w, Y, sub.areas) / max(sub.areas.sum(), 1e-300)
            absolute = floor * mean
        split = np.zeros(len(ids), bool)
        for s in range(Y.shape[2]):
            split |= abrupt(Y[:, :, s], ratio, absolute[s])
        if crossed is not None:
            split |= crossed(x, sub)
        hit = np.zeros(len(patches), bool)
        hit[ids[split]] = True
        if say is not None:
            say(level, int(hit.sum()))
        if not hit.any():
            break
        patches, p = split_patches(patches, hit)
        parent = p if parent is None else _SPLIT.of((parent, p), lambda: parent[p])
        check = hit[p] & (patches.areas > min_area)
    return patches, np.arange(len(patches)) if parent is None else parent


def _crossing(patches, cache=None):
    """``crossed(points (n, K, 3), sub) -> (n,) bool`` for :func:`refine`: a patch another
    surface passes through (a block's side sunk into a floor, the floor across that side):
    segments between neighbouring points of its grid, lifted a hair off it, hit a surface both
    in front of it and behind it. A block resting on the floor, a wall standing on it, touch
    the floor from one side only: nothing to split for (the light splits the floor there, and
    the output's vertices take the open side). None without Embree.

    Patch by patch the hemi-cube sees from the centre: a side patch of a block sunk 10 cm into
    the floor had its centre on the floor's plane and saw the room above and the void below
    (B 0.047 against 0.099 for the patch above it); the floor beside the block, which gathers
    that side within millimetres of the floor, read 17% too little on the block's outline. Geometry only: cached in
    ``cache`` (a relight casts no ray)."""
    if not embree_available():
        return None

    def crossed(x, sub):
        key = cache_key(geometry_key(patches) + array_key(x), ("crossed",))    # each hashed once
        return cached(cache, key, lambda: test(x, sub).astype(np.uint8)).astype(bool)

    def test(x, sub):
        N, K = x.shape[:2]
        n = int(round(np.sqrt(K)))
        k = np.arange(K).reshape(n, n)
        a = np.concatenate([k[:, :-1].ravel(), k[:-1, :].ravel()])
        b = np.concatenate([k[:, 1:].ravel(), k[1:, :].ravel()])
        lift = 1e-3 * np.sqrt(sub.areas)[:, None, None] * sub.normals[:, None, :]
        out = np.ones(N, bool)
        for side in (1, -1):
            p, q = (x + side * lift)[:, a], (x + side * lift)[:, b]
            hit = embree_scene(patches).occluded(p.reshape(-1, 3), (q - p).reshape(-1, 3),
                                                 np.ones(p.shape[0] * p.shape[1]))
            out &= hit.reshape(N, -1).any(axis=1)
        return out
    return crossed


def _regrouped(of, parent, refined: PatchSet, before: int):
    """The clusters of the ``refined`` patches: each piece in its parent's cluster (``of``), each
    child of a split patch a cluster of its own. Their grouping and geometry are kept for the
    arrays they are made from (a relight splits the same patches: the same arrays, which later
    stages key their products on), their materials read from ``refined``."""
    def make():
        out = of[parent]
        child = np.flatnonzero(np.bincount(parent, minlength=before)[parent] > 1)
        out[child] = out.max() + 1 + np.arange(child.size)
        grouped = make_clusters(refined, unique_ints(out, return_inverse=True)[1].reshape(-1))
        frozen(grouped.of, grouped.centers, grouped.normals, grouped.areas, grouped.owner)
        return grouped
    return _REGROUP.of((of, parent, refined.verts, refined.areas), make).with_materials(refined)


def refine_stage(ctx) -> None:
    """Split ``ctx.patches`` (and regroup ``ctx.clusters``) where the exact direct light changes
    abruptly, ``settings.refine_levels`` times at most. Emitters and faces grouped into clusters
    stay whole. Nothing to do without exact direct light, with 0 levels, or when the patches are
    the output mesh (no detail size: the user's faces are not cut)."""
    s = ctx.settings
    if s.refine_levels <= 0 or not s.uses_elements() or ctx.given:
        return                                # without elements the patches are the output mesh
    plan = DirectLight.plan(ctx.patches, s, ctx.lights, ctx.cancelled, ctx.cache, ctx.clusters, ctx.world)
    if plan is None:
        return
    p = ctx.patches
    frozen = p.emitting()
    if ctx.clusters is not None:
        frozen |= ctx.clusters.sizes[ctx.clusters.of] > 1
    min_area = (float(s.patch_size) / 16) ** 2 if s.patch_size else 0.0
    ctx.say(0.0, "finding where the light changes abruptly")

    def say(level, count):
        ctx.say((level + 1) / (s.refine_levels + 1), f"level {level + 1}: {count} patches split")
        ctx.check()

    refined, parent = refine(p, lambda x, n: plan.sources_at(x, n, "refine"), s.refine_levels, frozen=frozen,
                             min_area=min_area, say=say, crossed=_crossing(p, ctx.cache))
    if len(refined) == len(p):
        return
    clusters = None
    if ctx.clusters is not None:
        clusters = _regrouped(ctx.clusters.of, parent, refined, len(p))
    before = len(ctx.unknowns)
    after = len(refined if clusters is None else clusters)
    if after > s.max_patches or form_factor_gb(after, s) > s.max_memory_gb:
        # the limits the patch stage checked hold after refinement too: the patches stay as cut
        ctx.notes.append(
            f"refining where the light changes abruptly would make {after} patches, past the "
            f"limit of {s.max_patches} patches or {s.max_memory_gb:g} GB of form factors: the "
            f"{before} patches are kept unrefined (shadow edges only as sharp as the detail size "
            "allows); raise Max Patches or the memory budget to refine them")
        return
    if clusters is not None:
        ctx.clusters = clusters
    ctx.say(1.0, f"refined {len(p)} patches into {len(refined)} where the direct light changes abruptly")
    ctx.patches = refined
