"""Ray casting against the patches: Embree (through the optional ``embreex`` package) or a NumPy BVH.

Both back-ends see the same triangles: every patch as two triangles (a triangle patch as one),
zero-area halves left out, in the patches' world coordinates (scene units). They answer

* ``occluded(origins (M,3), directions (M,3), tfar (M,) | None) -> (M,) bool``: something lies on
  ``origin + t * direction`` for ``0 < t < tfar`` (t in units of the direction's length, so a
  direction ``target - origin`` with ``tfar = 1`` tests the segment; None: no limit);

and Embree also ``intersect(origins, directions, tfar) -> (patch id (M,) int64 or -1, t (M,))``,
the nearest hit. Any triangle blocks, front or back; what a back hit means is the caller's rule.

* :class:`EmbreeScene` / :func:`embree_scene`: Embree, float32 rays; the scene is built once per
  geometry (:meth:`PatchSet.geometry_key`) and cached (the two most recent), so form factors,
  shadow rays and the final gather of one bake share it. :func:`clear_ray_cache` empties it.
* :class:`NumpyOccluder`: a median-split BVH traversed breadth-first for a batch of rays, in
  float64 (slower, same answers up to float32 ties at edges).
* :func:`occluder`: the shadow-ray back-end by name ('auto', 'embree', 'numpy', 'none').

Rays over a point's hemisphere (the sky's share, the open share) are in :mod:`.hemisphere`.

A ray from a point on a surface starts a hair off it along the normal (:func:`ray_offsets`):
four times its object's back offset (:func:`.mesh.backs.offset`), so 1e-5 of that object's own
diagonal and at least 64 float32 steps of its largest coordinate. Of the object's, not the
scene's: a 2 km ground plane made every ray start 3 cm off its surface, above the ground for
grass a few millimetres under it, which then read the full sun.
"""
from __future__ import annotations

import numpy as np

from .runtime.cache import Memo
from .runtime.errors import RadiosityError
from .mesh.patches import PatchSet
from .light.transmit import SeeThroughScene

__all__ = ["mesh_offsets", "ray_offsets",
           "EmbreeUnavailable", "embree_available",
           "import_embreex", "EmbreeScene",
           "embree_scene", "clear_ray_cache", "NumpyOccluder", "occluder", "patch_triangles"]


# --------------------------------------------------------------------------------------------
# Embree


class EmbreeUnavailable(RadiosityError, RuntimeError):
    """``embreex`` cannot be imported (not installed, or its binary does not load here)."""

    def __init__(self, detail: str = ""):
        msg = "embreex is not installed; use method='hemicube' or install embreex"
        if detail:
            msg += f" ({detail})"
        super().__init__(msg)


def import_embreex():
    """(rtcore_scene, TriangleMesh) or raise :class:`EmbreeUnavailable`."""
    try:
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh
    except Exception as exc:  # ImportError, or OSError from a missing shared library
        raise EmbreeUnavailable(f"{type(exc).__name__}: {exc}") from exc
    return rtcore_scene, TriangleMesh


def embree_available() -> bool:
    """True when ``embreex`` imports and can build a scene."""
    try:
        import_embreex()
    except EmbreeUnavailable:
        return False
    return True


def patch_triangles(patches: PatchSet):
    """The patches as triangles: ``tris`` (T,3,3) float64, ``owner`` (T,) int64 patch id of each,
    and ``scale``, the length of the scene's bounding-box diagonal (1 for a point-like scene).

    Quads give the triangles (c0, c1, c2) then, after all of those, (c0, c2, c3); the second half
    of a triangle patch and halves with area below ``(1e-12 * scale)^2`` are left out."""
    N = len(patches)
    c = patches.corners()  # (N,4,3), triangles repeat corner 2
    tris = np.concatenate([c[:, [0, 1, 2]], c[:, [0, 2, 3]]], axis=0)  # (2N,3,3)
    owner = np.concatenate([np.arange(N), np.arange(N)])
    quad = np.concatenate([np.ones(N, bool), patches.polys[:, 3] >= 0])
    area2 = np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    lo, hi = patches.verts.min(axis=0), patches.verts.max(axis=0)
    scale = float(np.linalg.norm(hi - lo)) or 1.0
    keep = quad & (area2 > (1e-12 * scale) ** 2)
    return tris[keep], owner[keep].astype(np.int64), scale


class EmbreeScene:
    """An Embree scene of a PatchSet's patches (:func:`patch_triangles`, in float32).

    ``tri_patch[prim_id]`` is the patch a triangle belongs to; ``scale`` is the length of the
    scene's bounding-box diagonal (for ray offsets).
    """

    def __init__(self, patches: PatchSet):
        rtcs, TriangleMesh = import_embreex()
        tris, self.tri_patch, self.scale = patch_triangles(patches)
        self.n_patches = len(patches)
        self._scene = rtcs.EmbreeScene()
        self._mesh = TriangleMesh(self._scene, np.ascontiguousarray(tris, dtype=np.float32))

    def intersect(self, origins, directions, tfar=None):
        """Nearest hit per ray: (patch id or -1, distance along the direction's length units)."""
        o = np.ascontiguousarray(origins, dtype=np.float32)
        d = np.ascontiguousarray(directions, dtype=np.float32)
        kw = {} if tfar is None else {"dists": np.ascontiguousarray(tfar, dtype=np.float32)}
        res = self._scene.run(o, d, output=1, **kw)
        prim = res["primID"].astype(np.int64)
        pid = np.where(prim >= 0, self.tri_patch[np.maximum(prim, 0)], -1)
        return pid, res["tfar"]

    def occluded(self, origins, directions, tfar=None):
        """(M,) bool: something lies on the ray between 0 and ``tfar`` (default: infinity)."""
        o = np.ascontiguousarray(origins, dtype=np.float32)
        d = np.ascontiguousarray(directions, dtype=np.float32)
        kw = {} if tfar is None else {"dists": np.ascontiguousarray(tfar, dtype=np.float32)}
        return np.asarray(self._scene.run(o, d, query="OCCLUDED", **kw)) >= 0


_SCENE_CACHE = Memo(6)


def embree_scene(patches: PatchSet) -> EmbreeScene:
    """The Embree scene for ``patches``, built once per geometry (the six most recent are kept
    until :func:`clear_ray_cache`: with four, zdm2 built five of its ten twice)."""
    return _per_geometry(_SCENE_CACHE, patches, EmbreeScene)


def _per_geometry(cache: Memo, patches: PatchSet, make):
    """``make(patches)``, kept in ``cache`` by ``patches``' geometry."""
    return cache.get(patches.geometry_key(), lambda: make(patches))


def clear_ray_cache() -> None:
    """Forget every cached ray scene (frees Embree's memory once no caller holds a scene)."""
    _SCENE_CACHE.clear()
    _OCCLUDING_CACHE.clear()


# --------------------------------------------------------------------------------------------
# Ray start offsets

#: A ray starts this share of its object's diagonal off its surface ...
START_SHARE = 1e-5
#: ... and at least this many float32 steps (2**-23 of the object's largest coordinate) ...
START_ULPS = 64
#: ... which is this many times as far as the object's back lies behind it (:mod:`.mesh.backs`).
START_BACKS = 4
_OFFSETS = Memo(4)


def mesh_offsets(patches: PatchSet) -> np.ndarray:
    """(M,) per object (``patches.owner``): how far a ray from its surface starts off it,
    :data:`START_SHARE` of the diagonal of its patches' corners, at least :data:`START_ULPS`
    float32 steps of their largest coordinate (:data:`START_BACKS` times its back's
    :func:`.mesh.backs.offset`; 0 for an object without patches). Kept per patch set (by
    identity of its arrays)."""
    def make():
        owner = np.asarray(patches.owner, dtype=np.int64)
        M = int(owner.max(initial=-1)) + 1
        out = np.zeros(M)
        if not len(owner):
            return out
        c = patches.corners()
        order = np.argsort(owner, kind="stable")
        first = np.flatnonzero(np.r_[True, owner[order][1:] != owner[order][:-1]])
        lo = np.minimum.reduceat(c.min(axis=1)[order], first, axis=0)
        hi = np.maximum.reduceat(c.max(axis=1)[order], first, axis=0)
        big = np.maximum.reduceat(np.abs(c).max(axis=(1, 2))[order], first)
        out[owner[order][first]] = np.maximum(START_SHARE * np.linalg.norm(hi - lo, axis=1),
                                              START_ULPS * 2.0 ** -23 * big)
        return out
    return _OFFSETS.of((patches.verts, patches.polys, patches.owner), make)


def ray_offsets(patches: PatchSet, points=None, normals=None, owner=None, scene=None) -> np.ndarray:
    """(P,) how far a ray from each point (P, 3) with unit ``normals`` on the surfaces of
    ``patches`` starts off it: its object's :func:`mesh_offsets`. The object is ``owner`` (P,)
    when known (``points`` None: the patch centres); else the one whose surface a probe ray
    finds first within a hair either side of the point (64 float32 steps of its coordinates,
    at least the smallest object's offset), down its normal, and facing the way it does (not
    its back); ``scene``: the Embree scene of ``patches``, made when not given. Where the probe
    finds none (no Embree, a point off every surface), the largest object's offset."""
    off = mesh_offsets(patches)
    if owner is None and points is None:
        owner = patches.owner
    if owner is not None:
        return off[np.asarray(owner, dtype=np.int64)]
    x = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    out = np.full(len(x), off.max(initial=0.0))
    if not len(x) or not embree_available():
        return out
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    a = np.maximum(64 * 2.0 ** -23 * np.abs(x).max(axis=1), off[off > 0].min(initial=0.0))
    scene = embree_scene(patches) if scene is None else scene
    pid = np.asarray(scene.intersect(x + a[:, None] * n, -n, 2 * a)[0])
    hit = np.flatnonzero(pid >= 0)
    hit = hit[np.einsum("ij,ij->i", patches.normals[pid[hit]], n[hit]) > 0]
    out[hit] = off[patches.owner[pid[hit]]]
    return out


# --------------------------------------------------------------------------------------------
# NumPy BVH


class NumpyOccluder:
    """Shadow-ray queries against the patches in plain NumPy: a median-split BVH over the
    patch triangles (:func:`patch_triangles`), traversed breadth-first for a whole batch of
    rays at once."""

    LEAF = 4
    RAYS_PER_CHUNK = 1 << 14

    def __init__(self, patches: PatchSet):
        tris, _, self.scale = patch_triangles(patches)
        self._build(tris)

    def _build(self, tris):
        T = len(tris)
        cent = tris.mean(axis=1)
        tlo, thi = tris.min(axis=1), tris.max(axis=1)
        order = np.arange(T)
        starts, counts, lefts, los, his = [], [], [], [], []
        f_start, f_count = np.array([0]), np.array([T])
        n_nodes = 0
        while f_start.size:
            n_nodes += f_start.size
            seg = np.repeat(np.arange(f_start.size), f_count)
            pos = np.repeat(f_start - np.concatenate([[0], np.cumsum(f_count)[:-1]]), f_count) + np.arange(seg.size)
            tri = order[pos]
            bnd = np.concatenate([[0], np.cumsum(f_count)[:-1]])
            lo = np.minimum.reduceat(tlo[tri], bnd, axis=0)
            hi = np.maximum.reduceat(thi[tri], bnd, axis=0)
            split = f_count > self.LEAF
            left = np.full(f_start.size, -1, np.int64)
            # children of this level's split nodes get consecutive ids after all current nodes
            left[split] = n_nodes + 2 * np.arange(split.sum())
            starts.append(f_start), counts.append(f_count), lefts.append(left)
            los.append(lo), his.append(hi)
            if not split.any():
                break
            clo = np.minimum.reduceat(cent[tri], bnd, axis=0)
            chi = np.maximum.reduceat(cent[tri], bnd, axis=0)
            axis = np.argmax(chi - clo, axis=1)
            sel = split[seg]
            key = cent[tri, axis[seg]]
            perm = np.lexsort((key[sel], seg[sel]))
            order[pos[sel]] = tri[sel][perm]
            s_start, s_count = f_start[split], f_count[split]
            half = s_count // 2
            f_start = np.stack([s_start, s_start + half], 1).reshape(-1)
            f_count = np.stack([half, s_count - half], 1).reshape(-1)
        self.start = np.concatenate(starts)
        self.count = np.concatenate(counts)
        self.left = np.concatenate(lefts)
        self.lo = np.concatenate(los)
        self.hi = np.concatenate(his)
        self.order = order
        t = tris[order]
        self.v0, self.e1, self.e2 = t[:, 0], t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]

    def occluded(self, origins, directions, tfar=None):
        """(M,) bool: a triangle crosses the segment origin + t * direction, 0 < t < tfar
        (tfar None: infinite)."""
        o = np.asarray(origins, np.float64)
        d = np.asarray(directions, np.float64)
        tf = np.full(len(o), np.inf) if tfar is None else np.asarray(tfar, np.float64)
        out = np.zeros(len(o), bool)
        for s in range(0, len(o), self.RAYS_PER_CHUNK):
            sl = slice(s, s + self.RAYS_PER_CHUNK)
            out[sl] = self._occluded_chunk(o[sl], d[sl], tf[sl])
        return out

    def _occluded_chunk(self, o, d, tf):
        M = len(o)
        occ = np.zeros(M, bool)
        if M == 0 or len(self.order) == 0:
            return occ
        ds = np.where(np.abs(d) < 1e-30, np.where(d < 0, -1e-30, 1e-30), d)
        inv = 1.0 / ds
        ray = np.arange(M)
        node = np.zeros(M, np.int64)
        while ray.size:
            oo, ii = o[ray], inv[ray]
            t0 = (self.lo[node] - oo) * ii
            t1 = (self.hi[node] - oo) * ii
            tmin = np.minimum(t0, t1).max(axis=1)
            tmax = np.maximum(t0, t1).min(axis=1)
            hit = (tmin <= tmax) & (tmax >= 0) & (tmin <= tf[ray])
            ray, node = ray[hit], node[hit]
            leaf = self.left[node] < 0
            lr, ln = ray[leaf], node[leaf]
            if lr.size:
                cnt = self.count[ln]
                rr = np.repeat(lr, cnt)
                first = np.repeat(self.start[ln] - np.concatenate([[0], np.cumsum(cnt)[:-1]]), cnt)
                tri = first + np.arange(rr.size)
                occ[rr[self._hits(o[rr], d[rr], tf[rr], tri)]] = True
            ir, inn = ray[~leaf], node[~leaf]
            ray = np.concatenate([ir, ir])
            node = np.concatenate([self.left[inn], self.left[inn] + 1])
            keep = ~occ[ray]
            ray, node = ray[keep], node[keep]
        return occ

    def _hits(self, o, d, tf, tri):
        e1, e2 = self.e1[tri], self.e2[tri]
        p = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, p)
        ok = np.abs(det) > 1e-300
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = o - self.v0[tri]
        u = np.einsum("ij,ij->i", s, p) * inv
        q = np.cross(s, e1)
        v = np.einsum("ij,ij->i", d, q) * inv
        t = np.einsum("ij,ij->i", e2, q) * inv
        return ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & (t < tf)


# --------------------------------------------------------------------------------------------
# Choice


def occluder(patches, shadows="auto"):
    """Something with ``occluded(origins, directions, tfar)`` for shadow rays: Embree's scene
    ('embree', or 'auto' when embreex is there), the NumPy BVH ('numpy'), or None ('none')."""
    if shadows == "none":
        return None
    if shadows not in ("auto", "embree", "numpy"):
        raise ValueError(f"shadows must be 'auto', 'embree', 'numpy' or 'none', got {shadows!r}")
    if shadows in ("auto", "embree"):
        if embree_available():
            if getattr(patches, "see_through", None) is not None:
                return _see_through_scene(patches)
            return embree_scene(_occluding(patches))
        if shadows == "embree":
            raise EmbreeUnavailable()
    return NumpyOccluder(_occluding(patches))


#: The patches' outlines and the front faces' (:func:`.output.crease`) stay while the output's
#: elements are drawn too: with two kept, zdm2's patch outlines (1.1 s) were drawn a second time.
_OCCLUDING_CACHE = Memo(3)


def _see_through_scene(patches: PatchSet):
    """A :class:`.light.transmit.SeeThroughScene` for ``patches`` whose ``see_through`` is set:
    the outlines of the other patches block, the see-through faces pass their share. Kept with
    the geometry and the see-through faces (the last two)."""
    st = patches.see_through
    key = patches.geometry_key() + b"see-through" + st.key()

    def make():
        opaque = patches.take(~st.patch_mask(patches))
        lo, hi = patches.verts.min(axis=0), patches.verts.max(axis=0)
        return SeeThroughScene(embree_scene(_occluding(opaque)), st, float(np.linalg.norm(hi - lo)))
    return _OCCLUDING_CACHE.get(key, make)


def _occluding(patches: PatchSet) -> PatchSet:
    """The surfaces shadow rays test against: ``patches`` with each planar region as its
    outline (:func:`.drawn.plane_outlines`; a wall modelled as 10,000 triangles is 2 for a shadow
    ray), built once per geometry (the three most recent are kept)."""
    from .form_factors.drawn import plane_outlines

    return _per_geometry(_OCCLUDING_CACHE, patches, plane_outlines)
