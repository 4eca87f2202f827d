"""Final gather rays through see-through faces: alpha cut-outs and transparent shaders.

A gather ray (:func:`.gather.gather_matrix`) that lands on a see-through patch (cut from a face
of ``PatchSet.see_through``, :mod:`..light.transmit`) reads (1 - t) of that surface and goes on,
from just past it in the same direction, with t of its weight for what lies behind, up to
:data:`..light.transmit.LAYERS` surfaces (as Cycles' rays pass a Transparent BSDF; past the last,
the rest is lost). t is the transmittance where the ray crosses the face, read as the shadow
rays read it (:meth:`..light.transmit.SeeThrough.at`: uniform per face, or an image's alpha
through the face's UVs). G stays a linear map: a row has an entry per surface its rays read, at
the weight that reached it, and the sky fraction is the weight that escaped.

The surface's light is the solve's, whose reflectance carries the face's mean opacity o (as
Cycles' albedo carries the alpha, :mod:`...blender.read.transparency`), so a hit reads it times
(1 - t) / o: the full colour where the face is solid, nothing in its holes, and over the face on
average what the solve gave it. A hit on a see-through face's back, where it has none, reads
nothing (as on an opaque one) and passes t.

A see-through face is one surface however many sides it has: an open surface's back lies a hair
behind its front (:mod:`..mesh.backs`), so a ray goes on from past both (its object's ray start
offset, four times the back's distance, over the cosine at which it crosses: the distance along
the ray) and reads t once, on the face's own triangles (``SeeThrough.tris``, the fronts), found
by a ray over that stretch. Where none is found (a warped face whose patches stray from its
triangles by more than that), the ray reads the surface as an opaque one and stops.

Units: world units; weights and transmittances are shares (0..1).
"""
from __future__ import annotations

import numpy as np

from ..light.transmit import LAYERS
from ..rays import mesh_offsets
from ..util.geometry import in_frames, tangent_frames
from ..util.unique import unique_ints

__all__ = ["Through", "cast_through", "through_key"]

#: A ray crossing a see-through face at a cosine below this goes on from as far past it as at
#: this cosine (past its back for any crossing at 1/4 of it): a grazing ray would otherwise jump
#: far along the face.
MIN_COSINE = 1e-3


def through_key(patches) -> bytes:
    """Bytes that change with what the gather rays of ``patches`` pass (empty when none is
    see-through: an opaque scene's cache keys are what they were)."""
    st = getattr(patches, "see_through", None)
    return b"" if st is None else b"gather-through" + st.key()


class Through:
    """What the gather rays of ``patches`` need to pass their see-through faces: which patches
    are see-through (``mask`` (N,) bool), how far past a crossing a ray goes on (``reach`` (N,)
    world units, the patch's object's ray start offset), and an Embree scene of the faces' own
    triangles, where the transmittance is read. Built (committed) before threads or forked
    workers share it. Make it with :meth:`of`."""

    def __init__(self, patches, st):
        from ..rays import import_embreex

        rtcs, TriangleMesh = import_embreex()
        self.st, self.normals = st, patches.normals
        self.mask = st.patch_mask(patches)
        self.reach = mesh_offsets(patches)[np.asarray(patches.owner, np.int64)]
        self.opacity = np.ones(len(st.tris)) if st.opacity is None else np.asarray(st.opacity, float)
        self._scene = rtcs.EmbreeScene()
        self._mesh = TriangleMesh(self._scene, np.ascontiguousarray(st.tris, dtype=np.float32))
        self._scene.run(np.zeros((1, 3), np.float32), np.array([[0.0, 0.0, 1.0]], np.float32), output=1)

    @classmethod
    def of(cls, patches):
        """A :class:`Through` for ``patches``, or None when no patch is see-through (the gather
        then casts its rays as it always did)."""
        st = getattr(patches, "see_through", None)
        if st is None or not len(st.tris) or not st.patch_mask(patches).any():
            return None
        return cls(patches, st)

    def crossing(self, o, d, t, pid):
        """Rays ``o + s d`` (h, 3) float64 that hit see-through patches ``pid`` (h,) at s = ``t``
        (h,): (transmittance (h,), what the surface is read times (h,), the s (h,) past the face
        and its back to go on from)."""
        cos = np.abs(np.einsum("ij,ij->i", d, self.normals.take(pid, axis=0)))
        cos /= np.maximum(np.linalg.norm(d, axis=1), 1e-300)
        past = t + self.reach.take(pid) / np.maximum(cos, MIN_COSINE)
        res = self._scene.run(np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32),
                              output=1, dists=np.ascontiguousarray(past, np.float32))
        prim = np.asarray(res["primID"], np.int64)
        found = prim >= 0
        tau, scale = np.zeros(len(pid)), np.ones(len(pid))
        if found.any():
            p = prim[found]
            tau[found] = self.st.at(p, np.asarray(res["u"])[found], np.asarray(res["v"])[found])
            op = self.opacity[p]
            scale[found] = np.where(op > 0, (1.0 - tau[found]) / np.where(op > 0, op, 1.0), 0.0)
        return tau, scale, past


def cast_through(through, weights, hit_dtype, patches, params, scene, points, normals, eps, local, step, hits, s):
    """:func:`.gather._cast` for a scene with see-through patches (``through``, a
    :class:`Through`): the rays of the points ``s:s + step`` go on past each see-through surface
    they hit (module docstring). ``weights``: :func:`.gather.surface_weights`; ``hit_dtype``: the
    hits' dtype. Returns (s, m, sky (m,), entries per row (m,), columns (e,)
    int32, values (e,) float32, hits (h, 6) or None): the hits are rows ``(point id, patch id,
    x, y, z, weight)``, each hit carrying ``weight / rays`` in G, in point order and, within a
    ray, in the order it met them. A ray that meets no see-through patch gives exactly what
    :func:`.gather._cast` gives (the same entries, summed in the same order)."""
    R = len(local)
    x, n = points[s:s + step], normals[s:s + step]
    m = len(x)
    d = in_frames(local, tangent_frames(n)).reshape(-1, 3)
    o = np.repeat(x + eps[s:s + step] * n, R, axis=0)            # each ray's origin, moved on
    w = np.ones(m * R)                                           # the weight still going on
    sky = np.zeros(m * R)
    live, parts = np.arange(m * R), []
    for _ in range(LAYERS + 1):                                  # past the last, the rest is lost
        pid, tfar = scene.intersect(o.take(live, axis=0), d.take(live, axis=0))
        pid = np.asarray(pid)
        hit = pid >= 0
        sky[live[~hit]] += w[live[~hit]]
        f, pf = live[hit], pid[hit]
        t, df = np.asarray(tfar, np.float64)[hit], d.take(f, axis=0)
        y = o.take(f, axis=0) + t[:, None] * df
        seen, passed = w[f], np.zeros(len(f))
        see = np.flatnonzero(through.mask[pf])
        if see.size:
            tau, scale, past = through.crossing(o.take(f[see], axis=0), df[see], t[see], pf[see])
            seen[see] *= scale
            passed[see] = tau
            o[f[see]] += past[:, None] * df[see]
        front = np.flatnonzero((np.einsum("ij,ij->i", df, patches.normals.take(pf, axis=0)) < 0) & (seen != 0))
        parts.append((f[front], pf[front], y[front], seen[front]))
        w[f] *= passed
        live = f[w[f] > 0]
        if not live.size:
            break
    ray, pf, y, seen = (np.concatenate([p[k] for p in parts]) for k in range(4))
    if len(parts) > 1:                                           # a ray's hits together, in order
        order = np.argsort(ray, kind="stable")
        ray, pf, y, seen = ray[order], pf[order], y[order], seen[order]
    ids, wts = weights(params, patches.polys, pf, y)
    H = None
    if hits:
        H = np.column_stack([s + ray // R, pf, y, seen]).astype(hit_dtype)
    V = len(patches.verts)
    key, inv = unique_ints(np.repeat(ray // R, 4) * V + ids.ravel(), return_inverse=True, grouped=True)
    summed = np.bincount(inv.reshape(-1), weights=(wts * seen[:, None]).ravel() / R, minlength=key.size)
    keep = summed != 0
    key, summed = key[keep], summed[keep]
    sky_s = sky.reshape(m, R).sum(axis=1) / R
    return s, m, sky_s, np.bincount(key // V, minlength=m), (key % V).astype(np.int32), summed.astype(np.float32), H
