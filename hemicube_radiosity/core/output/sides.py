"""What the scene sees of the output mesh: open elements, the two sides of a partition, and
the open side of buried vertices.

A floor runs on under a block standing on it or under a partition; an output vertex on such
an outline is shared by elements the scene sees and elements it does not, or by elements on
the two sides of a surface. Here: which elements are open (:func:`open_elements`), the mesh
with such vertices split per side (:func:`sided_mesh`), how much of the scene sees a point
(:func:`seen_fraction`, :func:`seen_vertices`) and the :class:`.contact.OpenSide` of the
vertices it does not see (:func:`buried_side`). Geometry only (rays into :mod:`.rays`' Embree
scenes), cached: a relight casts no ray. Without Embree every element counts as open.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..light.emitters import vertex_frames
from ..mesh.contact import OpenSide, open_side
from ..mesh.patches import PatchSet
from ..rays import embree_available, embree_scene, ray_offsets
from ..hemisphere import open_fraction
from ..runtime.cache import Memo, array_key, cache_key, cached, frozen, geometry_key
from ..runtime.stored import storable
from ..util.unique import linked_labels, unique_rows
from .shared import corner_sharing, shared_open_fraction

_SIDED = Memo(8)            # (verts, polys, split code) -> the sided mesh's (verts, polys)
storable(OpenSide)          # cached on disk: a relight in a new process finds it (:func:`buried_side`)

__all__ = ["open_elements", "sided_mesh", "seen_fraction", "seen_vertices", "buried_side"]


def open_elements(ctx, elements):
    """(N,) 1 for an element the scene can see, 0 for one buried in a solid (its centre's rays
    all end on back faces or within a twentieth of the patch size: :func:`.hemisphere.open_fraction`),
    so output vertices on a block's outline are evaluated on the open side. None without
    Embree (every element counts). Read-only, kept beside the fractions: the same array at
    every call (a relight's frames and fits key on it, hashing it once)."""
    if not embree_available():
        return None
    reach = 0.05 * float(ctx.settings.patch_size or ctx.settings.element_size or 1.0)
    key = cache_key(geometry_key(elements), ("open-centres", reach))
    f = cached(ctx.cache, key, lambda: open_fraction(elements, elements.centers, elements.normals,
                                                     embree_scene(elements), reach,
                                                     workers=ctx.settings.workers, eps=ray_offsets(elements)))
    return cached(ctx.cache, key + "-weights", lambda: frozen((f > 0.05).astype(np.float64)), disk=False)


def sided_mesh(ctx, mesh: PatchSet) -> PatchSet:
    """``mesh`` (patches or elements) with a vertex split where elements that share it, both
    seen by the scene (:func:`open_elements`), lie on the two sides of another surface: a floor
    running on under a single-plane partition, the side walls and ceiling it stands against.
    Each side's copy of the vertex is evaluated on its side (:func:`.emitters.vertex_frames`
    moves it toward its own elements), averages and extrapolates its own side's patches, and
    the gather's rays read it on its side: shared, the vertices on the partition's line took
    half the lit side's light into the dark half (2.7% of the lit floor next to the line). A
    floor under a block standing on it is not split (the side under the block is not seen:
    its vertices on the outline are evaluated on the open side already). The same object when
    nothing is split, as in a scene without such contacts. Cached (geometry only)."""
    if not embree_available() or len(mesh) == 0:
        return mesh
    def split():                              # one array, so the cache keeps it on disk too
        out = _split_sides(ctx, mesh)
        if out is None:
            return np.zeros(0, np.int64)      # nothing split: remembered as well (a relight casts no ray)
        return np.concatenate([[out[0].size], out[0].reshape(-1), out[1]]).astype(np.int64)

    code = cached(ctx.cache, cache_key(geometry_key(mesh), ("sides",)), split)
    if code.size == 0:
        return mesh

    def geometry():                           # the same arrays every relight: memos keyed on them hit
        n = int(code[0])
        return mesh.verts[code[1 + n:]], code[1:1 + n].reshape(mesh.polys.shape)
    verts, polys = _SIDED.of((mesh.verts, mesh.polys, code), geometry)
    out = PatchSet(verts, polys, mesh.centers, mesh.normals, mesh.areas, mesh.rho,
                   mesh.emission, mesh.owner, mesh.source_face, list(mesh.object_names), mesh.see_through)
    # the elements are the same: what is known of them carries over (no second ray cast)
    reach = 0.05 * float(ctx.settings.patch_size or ctx.settings.element_size or 1.0)
    if ctx.cache is not None:
        mine = cache_key(geometry_key(out), ("open-centres", reach))
        seen = None if ctx.cache.get(mine) is not None else \
            ctx.cache.get(cache_key(geometry_key(mesh), ("open-centres", reach)))
        if seen is not None:
            ctx.cache.put(mine, seen)
    return out


def _split_sides(ctx, mesh: PatchSet, inset=1e-2):
    """(polys (N, 4), origin (V',)) of :func:`sided_mesh`, or None when no vertex is split:
    the elements' corners renumbered, and the vertex of ``mesh`` each of the V' is a copy of.

    Two elements seen by the scene that share a vertex are parted there when the segment
    between points a hair inside each (``inset`` of the way from the vertex to their centres,
    as the vertices are evaluated), lifted off the surface along their mean normal (by the two
    insets' length times a hundredth plus the sine of half the angle between their normals),
    crosses another surface (:class:`_Parting`). Each element is tested against the first at its
    vertex; where one is parted, every pair there (elements refined on one side meet the other
    side's at a corner, not an edge), and the corners are grouped by the pairs not parted, one
    vertex a group (a buried element's corner is a group of its own)."""
    opened = open_elements(ctx, mesh)
    if opened is None:
        return None
    N, V = len(mesh.polys), len(mesh.verts)
    p, c, v, first = _seen_corners(mesh.polys, opened)
    head = p[np.maximum.accumulate(np.where(first, np.arange(len(v)), 0))]
    reach = 0.05 * float(ctx.settings.patch_size or ctx.settings.element_size or 1.0)
    parted = _Parting(mesh, embree_scene(mesh), reach, ctx.settings.workers, inset)
    rest = ~first
    cut = parted(head[rest], p[rest], v[rest])
    if not cut.any():
        return None
    split_v = np.zeros(V, bool)
    split_v[v[rest][cut]] = True
    label, split_v = _corner_groups(parted, p, c, v, split_v, N)
    if not split_v.any():
        return None
    return _renumbered(mesh.polys, split_v, label, V)


def _seen_corners(polys, opened):
    """(element, corner, vertex, first) (C,) of every corner of the elements the scene sees
    (``opened`` (N,) > 0), sorted by vertex then element; ``first``: the first corner at its
    vertex."""
    p, c = np.nonzero(polys >= 0)
    v = polys[p, c]
    on = opened[p] > 0
    p, c, v = p[on], c[on], v[on]
    order = np.lexsort((p, v))
    p, c, v = p[order], c[order], v[order]
    first = np.ones(len(v), bool)
    first[1:] = v[1:] != v[:-1]
    return p, c, v, first


@dataclass
class _Parting:
    """Whether elements meeting at a vertex lie on two sides of another surface: called with
    elements ``e1``, ``e2`` and their shared vertex ``at`` (K,), (K,) bool parted.

    ``mesh``'s Embree ``scene`` is cast between points ``inset`` (a fraction) of the way from
    the vertex to each element's centre, lifted off the surface; a pair counts as parted only
    where the scene sees both points (:func:`.hemisphere.open_fraction` over 0.05, its rays
    reaching ``reach`` world units, cast on ``workers``)."""

    mesh: PatchSet
    scene: object
    reach: float
    workers: int
    inset: float

    def __call__(self, e1, e2, at) -> np.ndarray:
        mesh = self.mesh
        x = mesh.verts[at]
        d1, d2 = self.inset * (mesh.centers[e1] - x), self.inset * (mesh.centers[e2] - x)
        p1, p2 = self._lifted(e1, e2, x, d1, d2)
        out = self.scene.occluded(p1, p2 - p1, np.ones(len(p1))) if len(p1) else np.zeros(0, bool)
        # only between points the scene sees: two floor patches whose corners meet under a
        # block standing on them are parted by the block, but nothing sees either corner
        k = np.flatnonzero(out)
        if k.size:
            x2 = np.concatenate([x[k] + d1[k], x[k] + d2[k]])
            n2 = np.concatenate([mesh.normals[e1[k]], mesh.normals[e2[k]]])
            f = open_fraction(mesh, x2, n2, self.scene, self.reach, workers=self.workers,
                              eps=ray_offsets(mesh, owner=mesh.owner[np.concatenate([e1[k], e2[k]])])).reshape(2, -1)
            out[k] = (f > 0.05).all(axis=0)
        return out

    def _lifted(self, e1, e2, x, d1, d2):
        """(p1, p2) (K, 3): the vertices ``x`` (K, 3) moved by ``d1``, ``d2`` (K, 3) toward the
        two elements' centres and lifted off the surface along their mean normal."""
        mesh = self.mesh
        n = mesh.normals[e1] + mesh.normals[e2]
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        # over a convex crease the segment dips below the edge by about an inset times
        # sin(half the angle between the normals): lifted twice that, plus a hundredth of the
        # insets (at least a ray's start offset) where the two lie in one plane, so that a
        # surface crossing that plane at a grazing angle (a terrain sloping into a house's base)
        # parts them too, where a lift of the insets' whole length passed under it
        half = np.sqrt(np.clip((1.0 - np.einsum("ij,ij->i", mesh.normals[e1], mesh.normals[e2])) / 2, 0.0, 1.0))
        lift = np.maximum((0.01 + half) * (np.linalg.norm(d1, axis=1) + np.linalg.norm(d2, axis=1)),
                          ray_offsets(mesh, owner=mesh.owner[e1]))[:, None] * n
        return x + d1 + lift, x + d2 + lift


def _corner_groups(parted, p, c, v, split_v, N):
    """(label (4 N,), split (V,) bool): at the vertices ``split_v`` (V,) bool, every pair of the
    seen corners there (element ``p``, corner ``c``, vertex ``v`` (C,), sorted by vertex) tested
    by ``parted``; the corner slots (element * 4 + corner) linked by the pairs not parted, and
    the vertices whose corners fall into more than one group. A vertex whose seen elements all
    join up (a floor around a block's corner, whose edge grazes the segment across the corner)
    is not split: not even its buried corners."""
    at = np.flatnonzero(split_v[v])
    sv, sp, sc = v[at], p[at], c[at]
    i, j = _pairs_within_runs(sv)
    joined = ~parted(sp[i], sp[j], sv[i])
    slot = sp * 4 + sc
    sa, sb = slot[i[joined]], slot[j[joined]]
    label = linked_labels(4 * N, sa, sb)      # label propagation over the joined corner slots
    pairs = unique_rows(np.column_stack([sv, label[slot]]))
    split = np.zeros(len(split_v), bool)
    split[pairs[1:, 0][pairs[1:, 0] == pairs[:-1, 0]]] = True
    return label, split


def _pairs_within_runs(keys):
    """(i, j) (K,): every pair of positions i < j in one run of equal ``keys`` (sorted)."""
    start = np.flatnonzero(np.r_[True, keys[1:] != keys[:-1]])
    size = np.diff(np.r_[start, len(keys)])
    i_l, j_l = [], []
    for k in np.unique(size):
        base = start[size == k]
        i, j = np.triu_indices(k, 1)
        i_l.append((base[:, None] + i[None]).ravel())
        j_l.append((base[:, None] + j[None]).ravel())
    return np.concatenate(i_l), np.concatenate(j_l)


def _renumbered(polys, split_v, label, V):
    """(polys (N, 4), origin (V',)): the corners at the vertices ``split_v`` (V,) bool given one
    vertex per group ``label`` (4 N,) of corner slots, the first group keeping the vertex's id,
    each other a new one from V on; ``origin``: the vertex each of the V' copies."""
    flat = polys.reshape(-1).copy()
    at = np.flatnonzero((flat >= 0) & split_v[np.maximum(flat, 0)])
    groups, inv = unique_rows(np.column_stack([flat[at], label[at]]), return_inverse=True)
    inv = inv.reshape(-1)
    lead = np.ones(len(groups), bool)
    lead[1:] = groups[1:, 0] != groups[:-1, 0]
    ids = np.where(lead, groups[:, 0], 0)
    extra = np.flatnonzero(~lead)
    ids[extra] = V + np.arange(extra.size)
    flat[at] = ids[inv]
    return flat.reshape(polys.shape), np.concatenate([np.arange(V), groups[extra, 0]])


def seen_fraction(ctx, elements, x, nrm, share=None):
    """(P,) in [0, 1]: how much of the scene sees the points ``x`` (P, 3) on ``elements`` with
    normals ``nrm``: :func:`.hemisphere.open_fraction` (reach a twentieth of the patch size) over a
    half, so a point with half its hemisphere open (in a corner) counts fully, one a few
    millimetres above a lamp's back or inside a block not at all. ``share``: a
    :class:`.shared.Sharing` of the points (``x`` the vertices' points): the vertices at one
    place cast the rays once between them (:func:`.shared.shared_open_fraction`). Cached
    (geometry only)."""
    reach = 0.05 * float(ctx.settings.patch_size or ctx.settings.element_size or 1.0)
    key = cache_key(geometry_key(elements) + array_key(x) + (b"" if share is None else b"shared"),
                    ("exposure", reach))                                       # x hashed once per array

    def make():
        if share is None:
            return open_fraction(elements, x, nrm, embree_scene(elements), reach, workers=ctx.settings.workers)
        return shared_open_fraction(elements, x, nrm, embree_scene(elements), reach, share,
                                    workers=ctx.settings.workers)
    f = cached(ctx.cache, key, make)
    return np.minimum(1.0, f / 0.5)


def seen_vertices(ctx, elements) -> np.ndarray:
    """(V,) bool: output vertices the scene sees (:func:`seen_fraction` at their evaluation points of
    the vertex stage, at least a half), not those buried under what stands on their surface;
    all of them without Embree."""
    if not embree_available():
        return np.ones(len(elements.verts), bool)
    xv, nv, _ = vertex_frames(elements, weights=open_elements(ctx, elements))
    return seen_fraction(ctx, elements, xv, nv) >= 0.5


def buried_side(ctx, elements, xv, nv):
    """The :class:`.contact.OpenSide` of the output vertices buried under what stands on their
    surface (:func:`seen_fraction` below a half: less than a quarter of their rays leave into the
    open), or None without Embree. Geometry only, cached: a relight casts no ray."""
    if ctx.direct is None or not embree_available():
        return None
    # a flat-shaded mesh's corners at one place cast the rays once (as the gather's)
    share = corner_sharing(ctx.cache, elements, xv, nv, open_elements(ctx, elements))
    buried = seen_fraction(ctx, elements, xv, nv, share) < 0.5
    if not buried.any():
        return None
    key = cache_key(geometry_key(elements) + array_key(xv), ("open-side",))
    return cached(ctx.cache, key, lambda: open_side(elements, buried, embree_scene(elements),
                                                    open_elements(ctx, elements)))
