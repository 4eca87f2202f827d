"""The patch data model: the source meshes given to a bake and the patches they are cut into,
as plain arrays.

Contract
--------
A :class:`PatchSet` holds N patches, each a triangle or a quad, whose corners index a shared
vertex array. Two patches share a vertex exactly when their source faces share that source
vertex (and the source edge between them is cut into the same points), so vertex radiosities
can be formed by averaging over the patches around a vertex. Callers that want a hard edge
(different materials, sharp edges) split the source vertices there before calling
:func:`.subdivide.build_patches` (which splits n-gons with :mod:`.ngons`, then cuts the faces to
the patch size).

Everything is world space, right-handed, counter-clockwise winding seen from the front.
Radiosity quantities (``emission``) are in Blender's radiance units: an emission strength of
1 in white is 1.0.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np
from ..runtime.cache import PER_MESH, Memo, frozen
from ..runtime.stored import storable
from ..runtime.errors import RadiosityError
from ..light.transmit import see_through

__all__ = ["MeshInput", "negated_rows", "PatchSet", "PatchError", "poly_geometry", "compact", "check_faces", "meshes_key", "RHO_MAX",
           "ZERO_AREA", "covering_faces"]

RHO_MAX = 0.999          # the solve needs every band's reflectivity below 1: the most a face takes
#: A face of an area below this share of its mesh's squared size (bounding-box diagonal) covers
#: nothing: :func:`.subdivide.build_patches` drops it, and refuses a mesh of nothing else.
ZERO_AREA = 1e-12


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
    face_material:(F,) int or None, which material each face has (any ids, equal for one
                  material across meshes): faces of one material may be grouped into one patch
                  although a texture varies their reflectivity (:func:`.clusters.piece_materials`);
                  None: faces group only where reflectivity and emission are equal.
    size_scale:   this mesh is cut at the patch and detail sizes times this (an object far
                  larger than the rest of the scene: :mod:`.sizes`).
    corner_normal:(L, 3) or None, the unit shading normal at every face corner (``face_indices``
                  order): smooth shading and custom normals, as Cycles shades with them at the
                  output vertices (:mod:`..output.normals`); None: the faces' own normals.
    face_triangles:(T, 4) int or None, rows (face, i, j, k): these faces are split into exactly
                  these triangles, ``i, j, k`` positions in the face's ring (0 .. corners - 1),
                  counter-clockwise seen from the front (:mod:`.ngons`). What a non-planar n-gon
                  needs to be the surface Cycles renders (Blender's own loop triangles); faces
                  not listed are split by :mod:`.ngons`' own rule; None: no face is listed.
    face_glossy:  (F, 3) or None, the reflectance of the faces' specular and metallic layers
                  (Cycles' glossy albedo at normal incidence), in [0, 1): with
                  ``specular_bounce`` a face mirrors it onto the rest (:mod:`..form_factors.glossy`)
                  or, a weak layer or without Embree, it is added to what the solve bounces,
                  spread as diffuse light (:func:`.specular.with_specular_bounce`); ``face_rho``
                  stays the diffuse colour the output shows. None: no such layer.
    back_of:      -1, or this mesh is the back of mesh ``back_of`` (its open faces turned
                  around, a hair behind: :mod:`.backs`) ...
    back_faces:   ... (F,) int, and its faces are the back of these faces of that mesh.
    transmit:     a :class:`..light.transmit.Transmit` or None: what light passes through its
                  faces (alpha cut-outs, transparent shaders); None: opaque.
    """

    verts: np.ndarray
    face_offsets: np.ndarray
    face_indices: np.ndarray
    face_rho: np.ndarray
    face_emission: np.ndarray
    name: str = "mesh"
    corner_rho: np.ndarray | None = None
    corner_emission: np.ndarray | None = None
    face_material: np.ndarray | None = None
    size_scale: float = 1.0
    corner_normal: np.ndarray | None = None
    back_of: int = -1
    back_faces: np.ndarray | None = None
    face_triangles: np.ndarray | None = None
    face_glossy: np.ndarray | None = None
    transmit: object = None

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


def meshes_key(meshes) -> bytes:
    """Bytes that change exactly when the source meshes' geometry changes (not materials).
    Hashed once per set of read-only arrays (a relight's meshes, read again, are the same
    arrays: ``blender/read/scene.py``); arrays that may change in place, every time."""
    meshes = list(meshes)
    objs = tuple(a for m in meshes for a in (m.verts, m.face_offsets, m.face_indices, getattr(m, "face_triangles", None)))
    if not all(read_only(a) for a in objs):
        return _meshes_key(meshes)
    scales = tuple(float(getattr(m, "size_scale", 1.0)) for m in meshes)
    return _MESHES_KEY.of(objs, lambda: _meshes_key(meshes), scales)


def read_only(a) -> bool:
    """Whether ``a`` is None or an array that cannot change in place (what a memo may key on
    by identity)."""
    return a is None or isinstance(a, np.ndarray) and not a.flags.writeable


_NEGATED = Memo(PER_MESH)      # (a, rows) -> -a[rows]


def negated_rows(a, rows) -> np.ndarray:
    """``-a[rows]`` (float64, read only), kept per pair of read-only arrays: a back's corner
    normals, its front's reversed (a relight's backs are the same arrays; made anew, the shading
    normals keyed on them were made anew too: 20 ms of the terrain's relight)."""
    def make():
        return frozen(-np.asarray(a, dtype=np.float64)[rows])
    return _NEGATED.of((a, rows), make) if read_only(a) and read_only(rows) else make()


_MESHES_KEY = Memo(16)         # the meshes' arrays -> meshes_key
_GEOMETRY_KEYS = Memo(8, refresh=True)   # (verts, polys) -> PatchSet.geometry_key


def _geometry_digest(verts, polys) -> bytes:
    h = hashlib.sha256()
    for a in (verts, polys):
        a = np.ascontiguousarray(a)
        h.update(str(a.dtype).encode() + str(a.shape).encode())
        h.update(a.tobytes())
    return h.digest()


def _meshes_key(meshes) -> bytes:
    h = hashlib.sha256()
    for m in meshes:
        for a in (m.verts, m.face_offsets, m.face_indices):
            a = np.ascontiguousarray(a)
            h.update(str(a.shape).encode() + a.tobytes())
        if getattr(m, "size_scale", 1.0) != 1.0:
            h.update(repr(float(m.size_scale)).encode())
        tris = getattr(m, "face_triangles", None)
        if tris is not None:                  # faces split along given triangles
            a = np.ascontiguousarray(tris, dtype=np.int64)
            h.update(b"triangles" + str(a.shape).encode() + a.tobytes())
    return h.digest()


@storable
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
    see_through: a :class:`..light.transmit.SeeThrough` (the faces shadow rays pass through,
                 :func:`..light.transmit.see_through` of the meshes) or None: every face opaque.
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
    see_through: object = None

    def __len__(self) -> int:
        return int(self.polys.shape[0])

    def emitting(self) -> np.ndarray:
        """(N,) bool: the patches that emit, ``emission.max(axis=1) > 0`` (the same values, NaN
        included), its bands compared a column at a time: faster than a max over each short row,
        and a relight asks three times."""
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

    def corner_ids(self) -> np.ndarray:
        """(N, 4) int64 each patch's corner vertices, a triangle's fourth its third (the corners
        a (N, 4, ...) per-corner array is laid out by, as :meth:`corners`)."""
        return np.where(self.polys < 0, self.polys[:, 2:3], self.polys)

    def corners(self, ids=None) -> np.ndarray:
        """(N, 4, 3) corner positions; a triangle repeats its last corner (a degenerate quad).
        ``ids`` (n,): only those patches' (n, 4, 3), as ``corners()[ids]`` without making every
        patch's corners (a few lamps on a large mesh). Rows by ``take``, faster than indexing
        with an (N, 4) index array."""
        p = self.polys if ids is None else self.polys.take(np.asarray(ids, dtype=np.int64).reshape(-1), axis=0)
        p = np.where(p[:, 3:] < 0, np.concatenate([p[:, :3], p[:, 2:3]], axis=1), p)
        return self.verts.take(p.reshape(-1), axis=0).reshape(len(p), 4, 3)

    def geometry_key(self) -> bytes:
        """Bytes that change exactly when the geometry (not materials) changes; for caching.
        Kept per pair of arrays (by identity, :meth:`.Memo.of`): the ray scenes, offsets and
        caches ask for it dozens of times a bake (the bunny: 59 hashes of 3 MB, 0.2 s)."""
        return _GEOMETRY_KEYS.of((self.verts, self.polys), lambda: _geometry_digest(self.verts, self.polys))

    def with_mesh_materials(self, meshes) -> "PatchSet":
        """A copy whose reflectivity, emission and see-through faces are read again from the
        source ``meshes`` (:meth:`_with_mesh_colours`), the geometry shared."""
        out = self._with_mesh_colours(meshes)
        if self.see_through is not None or any(getattr(m, "transmit", None) is not None for m in meshes):
            out.see_through = see_through(meshes)
        return out

    def _with_mesh_colours(self, meshes) -> "PatchSet":
        """A copy whose reflectivity and emission are read again from the source ``meshes``
        (each patch its source face's), the geometry shared: what a relight needs.

        Each patch's face is read from the meshes' face arrays laid end to end, by one index per
        patch, kept for the patches' ``source_face`` and ``owner`` arrays and the meshes' face
        counts (:func:`_material_index`: a relight's cached patches and elements are the same
        arrays): the same values as a pass over the patches per mesh, faster. The patch stage
        and the output elements read a relight's materials through it."""
        mats = [(np.asarray(m.face_rho, float), np.asarray(m.face_emission, float)) for m in meshes]
        index = _material_index(self, mats)
        if index is not None:
            # take: the rows faster than fancy indexing
            return self.with_materials(np.concatenate([r for r, _ in mats]).take(index, axis=0),
                                       np.concatenate([e for _, e in mats]).take(index, axis=0))
        rho = np.empty((len(self), 3))
        em = np.empty((len(self), 3))
        for oi, m in enumerate(meshes):
            sel = self.owner == oi
            rho[sel] = np.asarray(m.face_rho, float)[self.source_face[sel]]
            em[sel] = np.asarray(m.face_emission, float)[self.source_face[sel]]
        return self.with_materials(rho, em)

    def take(self, rows, see_through=False) -> "PatchSet":
        """The patches ``rows`` of this set, (R,) int or (N,) bool, over the same ``verts``
        (shared). ``see_through``: keep the see-through faces (read by owner and source face,
        so they hold for any rows); else none (every face of the subset blocks)."""
        rows = np.asarray(rows)
        rows = np.flatnonzero(rows) if rows.dtype == bool else rows.astype(np.int64, copy=False)
        return PatchSet(self.verts, self.polys[rows], self.centers[rows], self.normals[rows], self.areas[rows],
                        self.rho[rows], self.emission[rows], self.owner[rows], self.source_face[rows],
                        list(self.object_names), self.see_through if see_through else None)

    def with_materials(self, rho=None, emission=None) -> "PatchSet":
        """A copy with new reflectivity/emission and the same geometry (arrays shared)."""
        return PatchSet(
            self.verts, self.polys, self.centers, self.normals, self.areas,
            self.rho if rho is None else np.asarray(rho, float),
            self.emission if emission is None else np.asarray(emission, float),
            self.owner, self.source_face, list(self.object_names), self.see_through,
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
    return _MATERIAL_INDEX.of((sf, owner), lambda: _face_index(sf, owner, counts), counts)


def _face_index(source_face, owner, counts):
    """(N,) int64 each patch's face in the faces of all meshes laid end to end (``counts`` faces
    per mesh), or None when an owner or a face is out of range."""
    o = np.asarray(owner, dtype=np.int64)
    f = np.asarray(source_face, dtype=np.int64)
    if o.size == 0 or (o.min() >= 0 and o.max() < len(counts)):
        size = np.asarray(counts, dtype=np.int64)
        if o.size == 0 or (f.min() >= 0 and (f < size[o]).all()):
            return np.concatenate([[0], np.cumsum(size)]).astype(np.int64)[o] + f
    return None


def compact(verts, polys):
    """(verts, polys) without the vertices no poly uses, the polys renumbered (-1 stays -1)."""
    used = np.unique(polys[polys >= 0])
    remap = np.full(len(verts), -1, dtype=np.int64)
    remap[used] = np.arange(used.size)
    return verts[used], np.where(polys >= 0, remap[np.maximum(polys, 0)], -1)


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


def covering_faces(verts, face_offsets, face_indices) -> np.ndarray:
    """(F,) bool: the faces whose area (Newell's, of the whole ring) is above :data:`ZERO_AREA`
    of the mesh's squared size: those that cover something."""
    v = np.asarray(verts, dtype=np.float64)
    offsets, idx = np.asarray(face_offsets, dtype=np.int64), np.asarray(face_indices, dtype=np.int64)
    F = len(offsets) - 1
    nxt = np.arange(1, len(idx) + 1)
    nxt[offsets[1:] - 1] = offsets[:-1]
    cross, face = np.cross(v[idx], v[idx[nxt]]), np.repeat(np.arange(F), np.diff(offsets))
    area = 0.5 * np.linalg.norm(np.stack([np.bincount(face, cross[:, k], F) for k in range(3)], 1), axis=1)
    span = np.ptp(v, axis=0) if len(v) else np.zeros(3)
    return area > ZERO_AREA * float(span @ span)


def check_faces(mesh: MeshInput, verts, idx, sizes):
    """Raise :class:`PatchError` naming the object when the faces are unusable (or the values at
    their corners, ``corner_rho`` / ``corner_emission``: one row a corner, as the faces' values).

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
    for which in ("rho", "emission"):             # a texture's values at the corners, as the faces'
        c = getattr(mesh, "corner_" + which)
        if c is None:
            continue
        c = np.asarray(c, dtype=np.float64)
        if c.shape != (idx.size, 3):
            raise PatchError(f"{mesh.name!r}: corner_{which} must have shape ({idx.size}, 3), one row a face corner")
        if not np.all(np.isfinite(c)) or np.any(c < 0) or (which == "rho" and np.any(c >= 1)):
            raise PatchError(f"{mesh.name!r}: corner {which} must be finite and "
                             + ("in [0, 1) in each band" if which == "rho" else ">= 0"))
