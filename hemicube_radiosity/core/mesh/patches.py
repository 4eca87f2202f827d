"""Patches: polygon meshes cut into radiosity patches, stored as plain arrays.

Contract
--------
A :class:`PatchSet` holds N patches, each a triangle or a quad, whose corners index a shared
vertex array. Two patches share a vertex exactly when their source faces share that source
vertex (and the source edge between them is cut into the same points), so vertex radiosities
can be formed by averaging over the patches around a vertex. Callers that want a hard edge
(different materials, sharp edges) split the source vertices there before calling
:func:`build_patches`.

Everything is world space, right-handed, counter-clockwise winding seen from the front.
Radiosity quantities (``emission``) are in Blender's radiance units: an emission strength of
1 in white is 1.0.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from ..runtime.cache import Memo
from ..runtime.errors import RadiosityError
from ..util.unique import unique_rows

__all__ = ["MeshInput", "PatchSet", "build_patches", "keeps_faces_whole", "PatchError"]


class PatchError(RadiosityError, ValueError):
    """Bad mesh input; the message names the object and the problem."""


@dataclass
class MeshInput:
    """One source mesh in world space.

    verts:        (V, 3) float positions.
    face_offsets: (F + 1,) int, face f uses ``face_indices[face_offsets[f]:face_offsets[f+1]]``.
    face_indices: (L,) int vertex indices, counter-clockwise seen from the front.
    face_rho:     (F, 3) diffuse reflectivity per face, each in [0, 1).
    face_emission:(F, 3) emitted radiance per face, >= 0.
    name:         object name, used in error messages and reports.
    corner_rho, corner_emission: (L, 3) or None, the same at every face corner (in
                  ``face_indices`` order) where they vary within a face (a texture); the output's
                  vertices take them, the solve the per-face values.
    """

    verts: np.ndarray
    face_offsets: np.ndarray
    face_indices: np.ndarray
    face_rho: np.ndarray
    face_emission: np.ndarray
    name: str = "mesh"
    corner_rho: np.ndarray | None = None
    corner_emission: np.ndarray | None = None

    @classmethod
    def from_faces(cls, verts, faces, rho=(0.5, 0.5, 0.5), emission=(0.0, 0.0, 0.0), name="mesh"):
        """Convenience: ``faces`` is a list of index sequences; rho/emission per face or one for all."""
        faces = [np.asarray(f, dtype=np.int64) for f in faces]
        offsets = np.zeros(len(faces) + 1, dtype=np.int64)
        offsets[1:] = np.cumsum([len(f) for f in faces])
        idx = np.concatenate(faces) if faces else np.zeros(0, np.int64)
        F = len(faces)
        rho = np.broadcast_to(np.asarray(rho, float), (F, 3)).copy()
        emission = np.broadcast_to(np.asarray(emission, float), (F, 3)).copy()
        return cls(np.asarray(verts, float), offsets, idx, rho, emission, name)


@dataclass
class PatchSet:
    """N patches (triangles or quads) as a structure of arrays.

    verts:       (V, 3) float64 patch corner positions.
    polys:       (N, 4) int64 indices into ``verts``; a triangle has -1 in column 3.
    centers:     (N, 3) float64 patch centres (mean of the corners).
    normals:     (N, 3) float64 unit normals (right-hand rule on the corner order).
    areas:       (N,)   float64 areas.
    rho:         (N, 3) float64 diffuse reflectivity, in [0, 1).
    emission:    (N, 3) float64 emitted radiance.
    owner:       (N,)   int32 index into ``object_names``.
    source_face: (N,)   int32 face index in the owner's source mesh.
    object_names: list of the source object names.
    """

    verts: np.ndarray
    polys: np.ndarray
    centers: np.ndarray
    normals: np.ndarray
    areas: np.ndarray
    rho: np.ndarray
    emission: np.ndarray
    owner: np.ndarray
    source_face: np.ndarray
    object_names: list = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.polys.shape[0])

    def emitting(self) -> np.ndarray:
        """(N,) bool: the patches that emit, ``emission.max(axis=1) > 0`` (the same values, NaN
        included), its bands compared a column at a time: the max over each short row took 0.2
        ms of the dense Cornell room's 7.5k patches, three times a relight."""
        e = np.asarray(self.emission)
        if e.ndim != 2 or e.shape[1] == 0:
            return e.max(axis=1) > 0
        m = e[:, 0]
        for k in range(1, e.shape[1]):
            m = np.maximum(m, e[:, k])
        return m > 0

    @property
    def nsides(self) -> np.ndarray:
        """(N,) 3 or 4."""
        return np.where(self.polys[:, 3] < 0, 3, 4)

    def corners(self, ids=None) -> np.ndarray:
        """(N, 4, 3) corner positions; a triangle repeats its last corner (a degenerate quad).
        ``ids`` (n,): only those patches' (n, 4, 3), as ``corners()[ids]`` (an emitter
        transport of a few lamps on a 54k-face mesh made every face's corners to keep its
        lamps'). Rows by ``take`` (indexing with an (N, 4) index array was 3-5x slower)."""
        p = self.polys if ids is None else self.polys.take(np.asarray(ids, dtype=np.int64).reshape(-1), axis=0)
        p = np.where(p[:, 3:] < 0, np.concatenate([p[:, :3], p[:, 2:3]], axis=1), p)
        return self.verts.take(p.reshape(-1), axis=0).reshape(len(p), 4, 3)

    def geometry_key(self) -> bytes:
        """Bytes that change exactly when the geometry (not materials) changes; for caching."""
        import hashlib

        h = hashlib.sha256()
        for a in (self.verts, self.polys):
            a = np.ascontiguousarray(a)
            h.update(str(a.dtype).encode() + str(a.shape).encode())
            h.update(a.tobytes())
        return h.digest()

    def with_mesh_materials(self, meshes) -> "PatchSet":
        """A copy whose reflectivity and emission are read again from the source ``meshes``
        (each patch its source face's), the geometry shared: what a relight needs.

        Each patch's face is read from the meshes' face arrays laid end to end, by one index per
        patch, kept for the patches' ``source_face`` and ``owner`` arrays and the meshes' face
        counts (:func:`_material_index`: a relight's cached patches and elements are the same
        arrays): the same values as a pass over the patches per mesh, which took 1.3 ms of
        the dense Cornell room's relight for each of its two element sets."""
        mats = [(np.asarray(m.face_rho, float), np.asarray(m.face_emission, float)) for m in meshes]
        index = _material_index(self, mats)
        if index is not None:
            # take: the rows 3x as fast as fancy indexing (25k elements: 0.22 -> 0.07 ms an array)
            return self.with_materials(np.concatenate([r for r, _ in mats]).take(index, axis=0),
                                       np.concatenate([e for _, e in mats]).take(index, axis=0))
        rho = np.empty((len(self), 3))
        em = np.empty((len(self), 3))
        for oi, m in enumerate(meshes):
            sel = self.owner == oi
            rho[sel] = np.asarray(m.face_rho, float)[self.source_face[sel]]
            em[sel] = np.asarray(m.face_emission, float)[self.source_face[sel]]
        return self.with_materials(rho, em)

    def with_materials(self, rho=None, emission=None) -> "PatchSet":
        """A copy with new reflectivity/emission and the same geometry (arrays shared)."""
        return PatchSet(
            self.verts, self.polys, self.centers, self.normals, self.areas,
            self.rho if rho is None else np.asarray(rho, float),
            self.emission if emission is None else np.asarray(emission, float),
            self.owner, self.source_face, list(self.object_names),
        )


_MATERIAL_INDEX = Memo(8)      # (source_face, owner), face counts -> index or None


def _material_index(patches: PatchSet, mats):
    """(N,) each patch's face in the meshes' face arrays ``mats`` ([(rho (F, 3), emission
    (F, 3))] per mesh) laid end to end, or None when they cannot be read so (a face array not
    (F, 3), an owner or face out of range: :meth:`PatchSet.with_mesh_materials` reads them mesh
    by mesh). Kept for the last few ``source_face`` arrays (the same objects and face counts)."""
    counts = tuple(len(r) for r, _ in mats)
    if not mats or any(r.ndim != 2 or r.shape[1] != 3 or e.shape != r.shape for r, e in mats):
        return None
    sf, owner = patches.source_face, patches.owner
    hit = _MATERIAL_INDEX.lookup((sf, owner), counts)
    if hit is not _MATERIAL_INDEX.MISSING:
        return hit
    index = None
    o = np.asarray(owner, dtype=np.int64)
    f = np.asarray(sf, dtype=np.int64)
    if o.size == 0 or (o.min() >= 0 and o.max() < len(mats)):
        size = np.asarray(counts, dtype=np.int64)
        if o.size == 0 or (f.min() >= 0 and (f < size[o]).all()):
            index = np.concatenate([[0], np.cumsum(size)]).astype(np.int64)[o] + f
    return _MATERIAL_INDEX.store((sf, owner), index, counts)


def poly_geometry(verts, polys):
    """Centres, unit normals and areas of triangles/quads (quads may be slightly non-planar)."""
    c = verts[np.where(polys < 0, polys[:, 2:3], polys)]  # (N,4,3), triangle repeats corner 2
    tri = polys[:, 3] < 0
    centers = np.where(tri[:, None], c[:, :3].mean(axis=1), c.mean(axis=1))
    # Quad: half the cross product of the diagonals; triangle: same formula with d = c2 - c0.
    cross = np.cross(c[:, 2] - c[:, 0], c[:, 3] - c[:, 1])
    cross_tri = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    cross = np.where(tri[:, None], cross_tri, cross)
    norm = np.linalg.norm(cross, axis=1)
    areas = 0.5 * norm
    with np.errstate(invalid="ignore", divide="ignore"):
        normals = cross / norm[:, None]
    return centers, normals, areas


def _is_convex(p: np.ndarray) -> bool:
    """True when polygon p (k,3) is convex and planar enough to fan from its centre."""
    n = np.zeros(3)
    for i in range(len(p)):  # Newell normal
        a, b = p[i], p[(i + 1) % len(p)]
        n += np.array([(a[1] - b[1]) * (a[2] + b[2]), (a[2] - b[2]) * (a[0] + b[0]), (a[0] - b[0]) * (a[1] + b[1])])
    e = np.roll(p, -1, axis=0) - p
    turn = np.cross(e, np.roll(e, -1, axis=0)) @ n
    # relative to the largest turn (a length^4): an absolute floor would call a concave
    # millimetre-sized polygon convex
    return bool(np.all(turn >= -1e-12 * float(np.abs(turn).max(initial=0))))


def _ear_clip(p: np.ndarray) -> list:
    """Triangulate a simple (possibly concave) polygon p (k,3); returns local index triples."""
    n = np.zeros(3)
    for i in range(len(p)):
        a, b = p[i], p[(i + 1) % len(p)]
        n += np.cross(a, b)
    idx = list(range(len(p)))
    tris = []
    guard = 0
    while len(idx) > 3 and guard < 10 * len(p) ** 2:
        guard += 1
        for k in range(len(idx)):
            i0, i1, i2 = idx[k - 1], idx[k], idx[(k + 1) % len(idx)]
            a, b, c = p[i0], p[i1], p[i2]
            if np.dot(np.cross(b - a, c - b), n) <= 0:
                continue  # reflex corner
            inside = False
            for j in idx:
                if j in (i0, i1, i2):
                    continue
                q = p[j]
                if (np.dot(np.cross(b - a, q - a), n) >= 0 and np.dot(np.cross(c - b, q - b), n) >= 0
                        and np.dot(np.cross(a - c, q - c), n) >= 0):
                    inside = True
                    break
            if not inside:
                tris.append((i0, i1, i2))
                idx.pop(k)
                break
        else:
            break
    if len(idx) == 3:
        tris.append(tuple(idx))
    return tris


def _check_faces(mesh: MeshInput, verts, idx, sizes):
    """Raise :class:`PatchError` naming the object when the faces are unusable.

    verts (V, 3) float64, idx (L,) int64 ``face_indices``, sizes (F,) int64 corners per face.
    """
    if len(sizes) == 0:
        raise PatchError(f"{mesh.name!r}: the mesh has no faces")
    if np.any(sizes < 3):
        f = int(np.flatnonzero(sizes < 3)[0])
        raise PatchError(f"{mesh.name!r}: face {f} has fewer than 3 vertices")
    if idx.size and (idx.min() < 0 or idx.max() >= len(verts)):
        raise PatchError(f"{mesh.name!r}: a face refers to a vertex that does not exist")
    if not np.all(np.isfinite(verts)):
        raise PatchError(f"{mesh.name!r}: vertex positions are not finite (NaN or infinity)")


def _small_faces(off, idx, sizes):
    """The triangles and quads among the faces, as (M, 4) int64 polys (-1 in column 3 for a
    triangle) and their (M,) int64 face indices; off (F + 1,), idx (L,), sizes (F,) as in
    :class:`MeshInput`."""
    polys = np.full((len(sizes), 4), -1, dtype=np.int64)
    for k in (3, 4):
        sel = np.flatnonzero(sizes == k)
        if sel.size:
            polys[sel, :k] = idx[off[sel][:, None] + np.arange(k)]
    small = sizes <= 4
    return polys[small], np.flatnonzero(small)


def _fan_convex_ngon(verts, ring, new_verts, midpoint) -> list:
    """Quads around the centre of the convex n-gon ``ring`` (n,) int64 indices into verts (V, 3).

    The centre and edge midpoints not yet in ``midpoint`` (a dict: sorted source edge (a, b) ->
    vertex index) are appended to ``new_verts`` (list of (3,) positions, numbered from V on).
    Returns n quads (centre, midpoint before corner, corner, midpoint after corner) as 4-tuples.
    """
    c = len(verts) + len(new_verts)
    new_verts.append(verts[ring].mean(axis=0))
    mids = []
    for i in range(len(ring)):
        a, b = int(ring[i]), int(ring[(i + 1) % len(ring)])
        key = (min(a, b), max(a, b))
        if key not in midpoint:
            midpoint[key] = len(verts) + len(new_verts)
            new_verts.append(0.5 * (verts[a] + verts[b]))
        mids.append(midpoint[key])
    return [(c, mids[i - 1], int(ring[i]), mids[i]) for i in range(len(ring))]


def _split_ngons(verts, off, idx, big, new_verts, midpoint):
    """Split the faces ``big`` (B,) of more than 4 corners: convex ones with
    :func:`_fan_convex_ngon` (which fills ``new_verts`` and ``midpoint``), concave ones by ear
    clipping. Returns the pieces, a list of 4-tuples (-1 last for a triangle), and a list of
    their source faces."""
    pieces, src = [], []
    for f in big:
        ring = idx[off[f]:off[f + 1]]
        p = verts[ring]
        if _is_convex(p):
            new = _fan_convex_ngon(verts, ring, new_verts, midpoint)
        else:
            new = [(int(ring[t[0]]), int(ring[t[1]]), int(ring[t[2]]), -1) for t in _ear_clip(p)]
        pieces += new
        src += [f] * len(new)
    return pieces, src


def _ring_with_midpoints(ring, midpoint):
    """The corner list ``ring`` (k ints) with every n-gon edge midpoint in ``midpoint`` inserted
    on its edge, or None when no edge of the ring was split."""
    k = len(ring)
    split = [midpoint.get((min(ring[i], ring[(i + 1) % k]), max(ring[i], ring[(i + 1) % k])))
             for i in range(k)]
    if all(s is None for s in split):
        return None
    ring2 = []
    for i in range(k):
        ring2.append(ring[i])
        if split[i] is not None:
            ring2.append(split[i])
    return ring2


def _recut_ring(verts, ring2, new_verts) -> list:
    """Cut the polygon ``ring2`` (m ints, into verts (V, 3) then ``new_verts``) without
    T-junctions: when convex, fan around its centre (appended to ``new_verts``) pairing
    consecutive ring vertices into quads (a triangle closes an odd ring); else ear clipping.
    Returns 4-tuples, -1 last for a triangle."""
    rp = np.concatenate([verts, np.array(new_verts)])[ring2]
    if not _is_convex(rp):
        return [(ring2[t[0]], ring2[t[1]], ring2[t[2]], -1) for t in _ear_clip(rp)]
    c = len(verts) + len(new_verts)
    new_verts.append(rp.mean(axis=0))
    m = len(ring2)
    pieces = [(c, ring2[i], ring2[i + 1], ring2[(i + 2) % m]) for i in range(0, m - 1, 2)]
    if m % 2:
        pieces.append((c, ring2[m - 1], ring2[0], -1))
    return pieces


def _mend_t_junctions(verts, polys, src, new_verts, midpoint, pieces, pieces_src):
    """Re-cut the triangles/quads ``polys`` (M, 4) (source faces ``src`` (M,)) that have an
    n-gon's edge midpoint on an edge, with :func:`_recut_ring`; their pieces are appended to
    ``pieces`` and ``pieces_src``. Returns the polys left whole, (M', 4) int64, and their
    (M',) int64 source faces."""
    whole = []
    for poly, s in zip(polys, src):
        k = 3 if poly[3] < 0 else 4
        ring2 = _ring_with_midpoints([int(v) for v in poly[:k]], midpoint)
        if ring2 is None:
            whole.append((poly, s))
            continue
        new = _recut_ring(verts, ring2, new_verts)
        pieces += new
        pieces_src += [s] * len(new)
    return (np.array([p for p, _ in whole], dtype=np.int64).reshape(-1, 4),
            np.array([s for _, s in whole], dtype=np.int64))


def _to_tris_and_quads(mesh: MeshInput):
    """Split n-gons: convex ones into n quads around their centre, concave ones by ear clipping.

    Returns verts (V', 3), polys (F', 4) with -1 for triangles, and the source face per poly.
    New vertices on a source edge (edge midpoints) are shared by the faces on both sides.
    """
    verts = np.asarray(mesh.verts, dtype=np.float64)
    off = np.asarray(mesh.face_offsets, dtype=np.int64)
    idx = np.asarray(mesh.face_indices, dtype=np.int64)
    sizes = np.diff(off)
    _check_faces(mesh, verts, idx, sizes)
    polys, src = _small_faces(off, idx, sizes)
    big = np.flatnonzero(sizes > 4)
    if big.size == 0:
        return verts, polys, src
    new_verts, midpoint = [], {}
    pieces, pieces_src = _split_ngons(verts, off, idx, big, new_verts, midpoint)
    # A convex n-gon's edge midpoint splits the edge for a neighbour that is a triangle or quad too:
    # re-express such neighbours so that no T-junction remains.
    if midpoint:
        polys, src = _mend_t_junctions(verts, polys, src, new_verts, midpoint, pieces, pieces_src)
    verts = np.concatenate([verts, np.array(new_verts).reshape(-1, 3)])
    polys = np.concatenate([polys, np.array(pieces, dtype=np.int64).reshape(-1, 4)])
    src = np.concatenate([src, np.array(pieces_src, dtype=np.int64)])
    return verts, polys, src


def _edge_segments(verts, polys, patch_size):
    """Number of segments per unique edge, equalised so every face can be cut as a regular grid.

    Quads need equal counts on opposite edges, triangles on all three edges; the maximum is
    propagated until it is stable, so neighbouring faces cut their shared edge at the same points.
    Returns (edges (E,2) sorted pairs, face_edges (F,4) edge ids with -1, flipped (F,4) bool, n (E,)).
    """
    F = len(polys)
    tri = polys[:, 3] < 0
    a, b, valid, ea, eb = _poly_sides(polys)
    key = np.stack([ea, eb], axis=1)
    edges, inv = unique_rows(key, return_inverse=True)
    inv = inv.reshape(-1)
    face_edges = np.full((F, 4), -1, dtype=np.int64)
    face_edges[valid] = inv
    flipped = np.zeros((F, 4), bool)
    flipped[valid] = (a > b)[valid]
    n = _segment_counts(verts[edges[:, 0]], verts[edges[:, 1]], patch_size)
    q = np.flatnonzero(~tri)
    t = np.flatnonzero(tri)
    for _ in range(len(edges) + 1):
        before = n.copy()
        if q.size:
            for i, j in ((0, 2), (1, 3)):
                m = np.maximum(n[face_edges[q, i]], n[face_edges[q, j]])
                np.maximum.at(n, face_edges[q, i], m)
                np.maximum.at(n, face_edges[q, j], m)
        if t.size:
            m = n[face_edges[t, :3]].max(axis=1)
            for i in range(3):
                np.maximum.at(n, face_edges[t, i], m)
        if np.array_equal(before, n):
            break
    return edges, face_edges, flipped, n


def _poly_sides(polys):
    """The sides of polys (F, 4) (-1 in column 3 for a triangle): ``a``, ``b`` (F, 4) each side's
    first and last vertex (side i runs corner i -> i + 1), ``valid`` (F, 4) False for a
    triangle's fourth, and the valid sides' vertices ``lo``, ``hi`` (S,), the lower id first."""
    tri = polys[:, 3] < 0
    b = np.where(tri[:, None], polys[:, [1, 2, 0, 0]], polys[:, [1, 2, 3, 0]])
    valid = np.ones(polys.shape, bool)
    valid[tri, 3] = False
    return polys, b, valid, np.minimum(polys, b)[valid], np.maximum(polys, b)[valid]


def _segment_counts(va, vb, patch_size):
    """(E,) int64 segments of the edges ``va`` -> ``vb`` (E, 3) at ``patch_size`` (1 each with no
    size), before they are equalised over faces."""
    if patch_size is None or patch_size <= 0:
        return np.ones(len(va), dtype=np.int64)
    length = np.linalg.norm(vb - va, axis=1)
    # An edge a whisker longer than k patches gets k segments, not k + 1. The whisker is
    # relative: coordinates often come in float32 (Blender), whose rounding is ~6e-8 of the
    # coordinates' magnitude, so a 1 mm edge cut at 0.125 mm measures 8.0000004 patches.
    # Scaling the scene or moving it away from the origin must not change the count.
    mag = np.maximum(np.abs(va).max(axis=1), np.abs(vb).max(axis=1))
    slack = 1e-6 * np.maximum(length, mag)
    return np.maximum(1, np.ceil((length - slack) / patch_size)).astype(np.int64)


def keeps_faces_whole(meshes, patch_size) -> bool:
    """True when :func:`build_patches` at ``patch_size`` cuts no face (every edge one segment):
    then it makes the same PatchSet, array for array, as with no size (the same steps, with every
    count 1), and a mesh finer than the size is its own patches or output elements. It measures
    the faces' edges and builds nothing (the 54k-triangle Cornell box: 25 ms, against 0.2 s to
    build its faces twice to find them equal). Raises :class:`PatchError` as :func:`build_patches`
    does for faces that are unusable."""
    if patch_size is None or patch_size <= 0:
        return True
    for mesh in [meshes] if isinstance(meshes, MeshInput) else meshes:
        verts = np.asarray(mesh.verts, dtype=np.float64)
        off = np.asarray(mesh.face_offsets, dtype=np.int64)
        idx = np.asarray(mesh.face_indices, dtype=np.int64)
        sizes = np.diff(off)
        _check_faces(mesh, verts, idx, sizes)
        # the faces' own edges, each from its lower vertex id to its higher, as _edge_segments
        # measures them; an n-gon's are halved at most when it is split (edge midpoints)
        nxt = np.arange(1, idx.size + 1)
        nxt[off[1:] - 1] = off[:-1]
        a, b = idx, idx[nxt]
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        if np.any(_segment_counts(verts[lo], verts[hi], (2.5 if np.any(sizes > 4) else 1.0) * patch_size) > 1):
            return False
        if np.any(sizes > 4):                  # the split's own edges, measured exactly
            verts, polys, _ = _to_tris_and_quads(mesh)
            lo, hi = _poly_sides(polys)[3:]
            if np.any(_segment_counts(verts[lo], verts[hi], patch_size) > 1):
                return False
    return True


class _EdgeCuts(NamedTuple):
    """Every unique edge cut into segments, and the vertices on the cuts.

    edges:      (E, 2) int64 sorted vertex pairs.
    face_edges: (F, 4) int64 edge id of each poly side (side i runs corner i -> i + 1), -1 for a
                triangle's fourth.
    flipped:    (F, 4) bool, the side walks its edge from ``edges[e, 1]`` to ``edges[e, 0]``.
    n:          (E,) int64 segments per edge (from :func:`_edge_segments`).
    e_off:      (E + 1,) int64: edge e owns the vertices ``e_off[e] .. e_off[e] + n[e] - 2``, at
                t = k / n[e], k = 1 .. n[e] - 1, from ``edges[e, 0]``; ``e_off[-1]`` is the next free.
    """

    edges: np.ndarray
    face_edges: np.ndarray
    flipped: np.ndarray
    n: np.ndarray
    e_off: np.ndarray

    def vertex(self, face_ids, side, k):
        """(G,) global index of the k-th vertex (k (G,) in 0..n) walking along side ``side`` of
        the polys ``face_ids`` (G,) in face order."""
        e = self.face_edges[face_ids, side]
        m = self.n[e]
        flip = self.flipped[face_ids, side]
        first = np.where(flip, self.edges[e, 1], self.edges[e, 0])
        last = np.where(flip, self.edges[e, 0], self.edges[e, 1])
        inner = self.e_off[e] + np.where(flip, m - k, k) - 1
        return np.where(k == 0, first, np.where(k == m, last, inner))


def _cut_edges(verts, polys, patch_size):
    """Cut the edges of polys (F, 4) over verts (V, 3) for ``patch_size``.

    Returns the :class:`_EdgeCuts` and the positions (e_off[-1] - V, 3) of the vertices inside
    edges, numbered from V on.
    """
    edges, face_edges, flipped, n = _edge_segments(verts, polys, patch_size)
    V = len(verts)
    e_off = V + np.concatenate([[0], np.cumsum(n - 1)])
    e_rep = np.repeat(np.arange(len(edges)), n - 1)
    k_in = np.arange(e_rep.size) - (e_off[e_rep] - V) + 1
    t = (k_in / n[e_rep])[:, None]
    edge_pos = (1 - t) * verts[edges[e_rep, 0]] + t * verts[edges[e_rep, 1]]
    return _EdgeCuts(edges, face_edges, flipped, n, e_off), edge_pos


def _quad_boundary(cuts, fid, gu, gv):
    """(G, gu + 1, gv + 1) int64 grid of the quads ``fid`` (G,) with the edge vertices filled in
    (the inside is left uninitialised); u along side 0 (c0 -> c1), v along side 3 reversed."""
    G = fid.size
    grid = np.empty((G, gu + 1, gv + 1), dtype=np.int64)
    for i in range(gu + 1):
        grid[:, i, 0] = cuts.vertex(fid, 0, np.full(G, i))          # c0 -> c1
        grid[:, i, gv] = cuts.vertex(fid, 2, np.full(G, gu - i))    # c2 -> c3 reversed
    for j in range(gv + 1):
        grid[:, gu, j] = cuts.vertex(fid, 1, np.full(G, j))         # c1 -> c2
        grid[:, 0, j] = cuts.vertex(fid, 3, np.full(G, gv - j))     # c3 -> c0 reversed
    return grid


def _cut_quads(verts, polys, cuts, fid, gu, gv, next_v):
    """Cut the quads ``fid`` (G,), gu segments along sides 0 and 2 and gv along 1 and 3, into
    gu x gv grids. Returns the bilinear positions (G * (gu-1) * (gv-1), 3) of the new inner
    vertices, numbered from ``next_v`` quad by quad, and the patches (G * gu * gv, 4)."""
    G = fid.size
    grid = _quad_boundary(cuts, fid, gu, gv)
    ni = (gu - 1) * (gv - 1)
    pos = np.zeros((0, 3))
    if ni > 0:
        c = verts[polys[fid]]  # (G,4,3)
        uu, vv = np.meshgrid(np.arange(1, gu) / gu, np.arange(1, gv) / gv, indexing="ij")
        uu = uu.reshape(-1)[None, :, None]
        vv = vv.reshape(-1)[None, :, None]
        pos = ((1 - uu) * (1 - vv) * c[:, None, 0] + uu * (1 - vv) * c[:, None, 1]
               + uu * vv * c[:, None, 2] + (1 - uu) * vv * c[:, None, 3]).reshape(-1, 3)
        grid[:, 1:gu, 1:gv] = next_v + np.arange(G * ni).reshape(G, gu - 1, gv - 1)
    p = np.stack([grid[:, :-1, :-1], grid[:, 1:, :-1], grid[:, 1:, 1:], grid[:, :-1, 1:]], axis=-1)
    return pos, p.reshape(-1, 4)


def _triangle_boundary(cuts, fid, g):
    """(G, g + 1, g + 1) int64 grid of the triangles ``fid`` (G,), vertex (i, j) at
    c0 + i/g (c1-c0) + j/g (c2-c0), with the edge vertices filled in and -1 elsewhere."""
    G = fid.size
    grid = np.full((G, g + 1, g + 1), -1, dtype=np.int64)
    for i in range(g + 1):
        grid[:, i, 0] = cuts.vertex(fid, 0, np.full(G, i))              # c0 -> c1
    for j in range(g + 1):
        grid[:, g - j, j] = cuts.vertex(fid, 1, np.full(G, j))          # c1 -> c2
        grid[:, 0, j] = cuts.vertex(fid, 2, np.full(G, g - j))          # c2 -> c0 reversed
    return grid


def _triangle_cells(grid, g):
    """(G, g * g, 4) the triangles of barycentric grids ``grid`` (G, g + 1, g + 1), -1 last:
    for each (i, j) the upright cell, then the inverted one beside it where there is one."""
    G = grid.shape[0]
    tris = []
    for i in range(g):
        for j in range(g - i):
            tris.append(np.stack([grid[:, i, j], grid[:, i + 1, j], grid[:, i, j + 1],
                                  np.full(G, -1)], axis=1))
            if i + j < g - 1:
                tris.append(np.stack([grid[:, i + 1, j], grid[:, i + 1, j + 1], grid[:, i, j + 1],
                                      np.full(G, -1)], axis=1))
    return np.stack(tris, axis=1)


def _cut_triangles(verts, polys, cuts, fid, g, next_v):
    """Cut the triangles ``fid`` (G,), g segments on every side, into g * g triangles each.
    Returns the positions (G * I, 3) of the I new inner vertices per triangle, numbered from
    ``next_v`` triangle by triangle, and the patches (G * g * g, 4)."""
    G = fid.size
    grid = _triangle_boundary(cuts, fid, g)
    ii, jj = np.nonzero((np.add.outer(np.arange(g + 1), np.arange(g + 1)) < g)
                        & (np.arange(g + 1)[:, None] > 0) & (np.arange(g + 1)[None, :] > 0))
    pos = np.zeros((0, 3))
    if ii.size:
        c = verts[polys[fid, :3]]
        a = (ii / g)[None, :, None]
        b = (jj / g)[None, :, None]
        pos = (c[:, None, 0] + a * (c[:, None, 1] - c[:, None, 0])
               + b * (c[:, None, 2] - c[:, None, 0])).reshape(-1, 3)
        grid[:, ii, jj] = next_v + np.arange(G * ii.size).reshape(G, ii.size)
    return pos, _triangle_cells(grid, g).reshape(-1, 4)


def _subdivide(verts, polys, patch_size):
    """Cut triangles/quads into regular grids of patches with shared vertices.

    verts (V, 3), polys (F, 4) with -1 for triangles. Returns new verts (V', 3), patch polys
    (P, 4), and the parent poly index per patch (P,). Polys are cut in groups of the same grid
    size, quads first; the new vertices follow in the same order.
    """
    cuts, edge_pos = _cut_edges(verts, polys, patch_size)
    next_v = int(cuts.e_off[-1])
    all_pos = [verts, edge_pos]
    out_polys, out_parent = [], []
    tri = polys[:, 3] < 0
    q = np.flatnonzero(~tri)
    if q.size:
        nu = cuts.n[cuts.face_edges[q, 0]]
        nv = cuts.n[cuts.face_edges[q, 1]]
        for (gu, gv) in unique_rows(np.stack([nu, nv], 1)):
            fid = q[(nu == gu) & (nv == gv)]
            pos, cells = _cut_quads(verts, polys, cuts, fid, gu, gv, next_v)
            next_v += len(pos)
            all_pos.append(pos)
            out_polys.append(cells)
            out_parent.append(np.repeat(fid, gu * gv))
    t_ids = np.flatnonzero(tri)
    if t_ids.size:
        nt = cuts.n[cuts.face_edges[t_ids, 0]]
        for g in np.unique(nt):
            fid = t_ids[nt == g]
            pos, cells = _cut_triangles(verts, polys, cuts, fid, g, next_v)
            next_v += len(pos)
            all_pos.append(pos)
            out_polys.append(cells)
            out_parent.append(np.repeat(fid, g * g))
    return np.concatenate(all_pos), np.concatenate(out_polys), np.concatenate(out_parent)


def _compact(verts, polys):
    """Drop vertices no poly uses; renumber."""
    used = np.unique(polys[polys >= 0])
    remap = np.full(len(verts), -1, dtype=np.int64)
    remap[used] = np.arange(used.size)
    return verts[used], np.where(polys >= 0, remap[np.maximum(polys, 0)], -1)


def build_patches(meshes, patch_size=None, min_area=None) -> PatchSet:
    """Cut source meshes into patches of edge length about ``patch_size`` (world units).

    ``patch_size`` None or <= 0 keeps every triangle/quad as one patch (n-gons are still split).
    Triangles become n*n triangles, quads an nu*nv grid; n-gons are split first (convex: quads
    around the centre; concave: ear clipping). Faces with area below ``min_area`` are dropped;
    None (default) means 1e-12 of the squared size (bounding-box diagonal) of each mesh, so the
    same scene in millimetres or kilometres keeps the same patches.
    Raises :class:`PatchError` naming the object when the input is unusable.
    """
    if isinstance(meshes, MeshInput):
        meshes = [meshes]
    if not meshes:
        raise PatchError("no meshes were given")
    parts = []
    v_base = 0
    for oi, mesh in enumerate(meshes):
        rho = np.asarray(mesh.face_rho, float)
        em = np.asarray(mesh.face_emission, float)
        F = len(mesh.face_offsets) - 1
        if rho.shape != (F, 3) or em.shape != (F, 3):
            raise PatchError(f"{mesh.name!r}: face_rho and face_emission must have shape ({F}, 3)")
        if not (np.all(np.isfinite(rho)) and np.all(np.isfinite(em))):
            raise PatchError(f"{mesh.name!r}: reflectivity or emission is not finite")
        if np.any(rho < 0) or np.any(rho >= 1):
            f = int(np.flatnonzero(np.any((rho < 0) | (rho >= 1), axis=1))[0])
            raise PatchError(f"{mesh.name!r}: face {f} has reflectivity {tuple(rho[f])}; "
                             "each band must be in [0, 1)")
        if np.any(em < 0):
            f = int(np.flatnonzero(np.any(em < 0, axis=1))[0])
            raise PatchError(f"{mesh.name!r}: face {f} has negative emission {tuple(em[f])}")
        v, p, src = _to_tris_and_quads(mesh)
        v, p, parent = _subdivide(v, p, patch_size)
        src = src[parent]
        v, p = _compact(v, p)
        c, nrm, a = poly_geometry(v, p)
        if min_area is None:
            span = np.ptp(np.asarray(mesh.verts, float), axis=0) if len(mesh.verts) else np.zeros(3)
            keep = a > 1e-12 * float(span @ span)
        else:
            keep = a > min_area
        if not np.any(keep):
            raise PatchError(f"{mesh.name!r}: every face has zero area")
        p, c, nrm, a, src = p[keep], c[keep], nrm[keep], a[keep], src[keep]
        v, p = _compact(v, p)
        parts.append((v, p + v_base * (p >= 0), c, nrm, a, rho[src], em[src],
                      np.full(len(p), oi, np.int32), src.astype(np.int32)))
        v_base += len(v)
    cat = [np.concatenate([part[i] for part in parts]) for i in range(9)]
    return PatchSet(*cat, object_names=[m.name for m in meshes])
