"""Patches above faces: small pieces grouped into the patches the radiosity equation is solved for.

A wall modelled as 10,000 triangles is lit like a wall of four quads, so it should cost like one.
:func:`build_patches` never makes a piece larger than its input face; here the *small* pieces
are grouped into clusters of about the patch size:

* the same object and the same material (``material`` ids, :func:`piece_materials`: a textured
  material groups as a plain one, the cluster solving with its pieces' area-mean reflectance),
* normals within ``max_angle`` of each other (a curved surface becomes several clusters, each
  nearly planar: the pieces' normals are binned on the cube map, cells ``max_angle`` wide),
* the same cell of a world grid of the patch size (by the centre of the piece's bounding box),
  and connected through shared corner *positions* (not vertex ids: a flat-shaded, auto-smoothed
  or UV-seamed mesh has its vertices split along every edge, and groups as its smooth twin).

Only whole input faces (and pieces much smaller than the patch size) are grouped: pieces that
:func:`build_patches` cut from a coarse face already have the patch size and each stay a patch of
their own, so a scene modelled coarsely solves exactly as before. The pieces remain the geometry: hemi-cubes
draw the pieces with their cluster's id (visibility sees the real surfaces; a planar cluster is
drawn as its outline, the same region, :mod:`drawn`), direct light and the output are evaluated on
the pieces; only the unknowns of the solve are the clusters.

Units: world units for positions and sizes, radiance for emission; areas are sums over pieces.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .patches import PatchSet
from ..runtime.stored import storable
from ..util.unique import linked_labels, unique_ints, unique_rows

__all__ = ["Clusters", "group_pieces", "piece_materials", "welded", "DEFAULT_MAX_ANGLE"]

DEFAULT_MAX_ANGLE = 30.0       # degrees: normal spread allowed within one cluster


@storable
@dataclass
class Clusters:
    """K solve patches made of P pieces (a :class:`PatchSet`).

    of:       (P,) int64 cluster of each piece.
    centers:  (K, 3) float64 eye points: the centre of the cluster's piece nearest its centroid
              (on the surface even when the cluster is curved).
    normals:  (K, 3) float64 unit, area-weighted mean of the pieces' normals.
    areas:    (K,) float64 total area.
    rho:      (K, 3) float64 area-weighted mean reflectivity.
    emission: (K, 3) float64 area-weighted mean emitted radiance.
    owner:    (K,) int32 object of the cluster.
    """

    of: np.ndarray
    centers: np.ndarray
    normals: np.ndarray
    areas: np.ndarray
    rho: np.ndarray
    emission: np.ndarray
    owner: np.ndarray

    def __len__(self) -> int:
        return int(len(self.areas))

    @property
    def sizes(self) -> np.ndarray:
        """(K,) pieces per cluster."""
        return np.bincount(self.of, minlength=len(self))

    def mean(self, per_piece, piece_areas) -> np.ndarray:
        """(K, ...) area-weighted mean over each cluster's pieces of a (P, ...) array."""
        a = np.asarray(per_piece, dtype=np.float64)
        w = np.asarray(piece_areas, dtype=np.float64).reshape((-1,) + (1,) * (a.ndim - 1))
        out = np.zeros((len(self),) + a.shape[1:])
        np.add.at(out, self.of, a * w)
        return out / self.areas.reshape((-1,) + (1,) * (a.ndim - 1))

    def spread(self, per_cluster) -> np.ndarray:
        """(P, ...) each piece's cluster value."""
        return np.asarray(per_cluster).take(self.of, axis=0)     # take: 3x fancy indexing's speed

    def with_materials(self, pieces: PatchSet) -> "Clusters":
        """The same grouping with reflectivity and emission read again from ``pieces`` (a
        cluster of one piece takes that piece's values exactly)."""
        rho, em = (self.area_mean(a, pieces.areas) for a in (pieces.rho, pieces.emission))
        solo = np.flatnonzero(self.sizes[self.of] == 1)
        rho[self.of[solo]], em[self.of[solo]] = pieces.rho[solo], pieces.emission[solo]
        return Clusters(self.of, self.centers, self.normals, self.areas, rho, em, self.owner)

    def area_mean(self, per_piece, piece_areas) -> np.ndarray:
        """:meth:`mean` of a (P, 3) array, bit for bit (each cluster's products summed in piece
        order, from 0), by a bincount per band instead of ``np.add.at`` (a tenth of the time:
        a relight reads its materials onto the clusters every time)."""
        a = np.asarray(per_piece, dtype=np.float64)
        w = np.asarray(piece_areas, dtype=np.float64)
        K = len(self)
        # a band's products at a time (the same as (P, 3) times the (P, 1) areas, broadcast
        # along the short axis: slower)
        return np.stack([np.bincount(self.of, weights=a[:, k] * w, minlength=K) for k in range(a.shape[1])], 1) \
            / self.areas[:, None]


def _small(pieces: PatchSet, size) -> np.ndarray:
    """(P,) pieces that are whole input faces (not cut to the patch size) or smaller than a third
    of a patch (cut from a face only a little larger than a patch): those are grouped. ``size``:
    a number, or (P,) each piece's (its object's: :mod:`.sizes`). Pieces cut
    from a coarse face already have about the patch's area (a quad more than a quarter of it on
    each side, a triangle half of that) and stay alone."""
    face = pieces.owner.astype(np.int64) * (1 << 32) + pieces.source_face
    whole = unique_ints(face, return_inverse=True, return_counts=True)
    uncut = whole[2][whole[1].reshape(-1)] == 1
    return uncut | (pieces.areas < size * size / 3)


def _normal_bins(normals, max_angle):
    """(P,) int64 cube-map cell of each normal, cells about ``max_angle`` degrees wide."""
    axis = np.abs(normals).argmax(axis=1)
    sign = np.take_along_axis(normals, axis[:, None], axis=1)[:, 0] >= 0
    face = axis * 2 + sign
    uv = np.zeros((len(normals), 2))
    for a in range(3):
        sel = axis == a
        others = [k for k in range(3) if k != a]
        uv[sel] = normals[sel][:, others] / np.abs(normals[sel, a])[:, None]
    step = np.tan(np.radians(max_angle))
    cells = int(np.ceil(2.0 / step))
    ij = np.clip(np.floor((uv + 1.0) / step), 0, cells - 1).astype(np.int64)
    return (face * cells + ij[:, 0]) * cells + ij[:, 1]


def _clutter(pieces: PatchSet, corners, size) -> np.ndarray:
    """(P,) bool pieces of objects whose bounding box's diagonal is under ``size`` (a number, or
    (P,) each piece's): small separate things (pebbles, cups, books) grouped as a volume."""
    M = int(pieces.owner.max()) + 1
    lo = np.full((M, 3), np.inf)
    hi = np.full((M, 3), -np.inf)
    np.minimum.at(lo, pieces.owner, corners.min(axis=1))
    np.maximum.at(hi, pieces.owner, corners.max(axis=1))
    return np.linalg.norm(hi - lo, axis=1)[pieces.owner] < size


def _plane_groups(pieces: PatchSet, key, size) -> np.ndarray:
    """(P,) int64 equal for pieces of one key whose planes are within about a quarter of
    ``size`` of each other along the key's mean normal (a floor and a rug group; a floor and a
    table top above it in the same cell do not)."""
    K = int(key.max()) + 1
    w = pieces.areas
    n = np.stack([np.bincount(key, weights=w * pieces.normals[:, k], minlength=K) for k in range(3)], 1)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    d = np.einsum("ij,ij->i", n[key], pieces.centers)
    return unique_rows(np.stack([key, np.floor(d / (0.25 * np.asarray(size))).astype(np.int64)], 1),
                       return_inverse=True)[1].reshape(-1).astype(np.int64)


def connected_components(keys, polys):
    """(P,) label of each piece's connected component (through shared vertices) among pieces
    of equal key: label propagation with pointer jumping, all edges at once."""
    p, c = np.nonzero(polys >= 0)
    v = polys[p, c]
    # pieces meeting at a vertex, within the same key: link consecutive ones
    order = np.lexsort((p, keys[p], v))
    v, p = v[order], p[order]
    same = (v[1:] == v[:-1]) & (keys[p][1:] == keys[p][:-1])
    return linked_labels(len(keys), p[:-1][same], p[1:][same])


def welded(verts, polys) -> np.ndarray:
    """``polys`` (N, 4) (-1: a triangle's fourth) with every vertex id replaced by the id of its
    position (V, 3): vertices at one place (within 1e-9 of the scene's diagonal) get one id,
    so faces meet where their corners meet, whatever the mesh's vertex splits."""
    v = np.asarray(verts, dtype=np.float64)
    if not len(v):
        return np.asarray(polys)
    tol = 1e-9 * (float(np.linalg.norm(v.max(axis=0) - v.min(axis=0))) or 1.0)
    ids = unique_rows(np.round(v / tol).astype(np.int64), return_inverse=True)[1].reshape(-1)
    polys = np.asarray(polys, dtype=np.int64)
    return np.where(polys < 0, -1, ids[np.maximum(polys, 0)])


def piece_materials(pieces: PatchSet, meshes) -> np.ndarray:
    """(P,) int64 material key of each piece: pieces with equal keys may share a patch.

    A face of a mesh that names its materials (``MeshInput.face_material``) keys on that id and
    its emitted radiance, so a textured reflectance groups (the patch solves with the area mean,
    the output keeps each corner's); a face of a mesh that does not keys on its reflectance and
    emitted radiance. Emitters group only with equal emission. The backs of open surfaces
    (:mod:`.backs`) group among themselves only: a back may face what no front near it faces
    (the inside of two pebbles that overlap)."""
    rows = []
    for m in meshes:
        rho, em = np.asarray(m.face_rho, float), np.asarray(m.face_emission, float)
        F = len(rho)
        ids = getattr(m, "face_material", None)
        side = 2.0 if getattr(m, "back_of", -1) >= 0 else 0.0
        if ids is None:
            rows.append(np.hstack([np.full((F, 1), side), rho, em]))
        else:
            ids = np.asarray(ids, dtype=np.float64).reshape(-1, 1)
            rows.append(np.hstack([np.full((F, 1), side + 1.0), ids, np.zeros((F, 2)), em]))
    key = unique_rows(np.concatenate(rows), return_inverse=True)[1].reshape(-1)
    start = np.concatenate([[0], np.cumsum([len(r) for r in rows])]).astype(np.int64)
    return key[start[pieces.owner.astype(np.int64)] + pieces.source_face.astype(np.int64)].astype(np.int64)


def group_pieces(pieces: PatchSet, size, max_angle=DEFAULT_MAX_ANGLE, material=None, scales=None,
                 backs=None) -> Clusters | None:
    """Group ``pieces`` into clusters of about ``size`` (see the module docstring); None when no
    two pieces would be grouped (every patch is its own piece). ``scales`` (M,): each object's
    factor on ``size`` (``MeshInput.size_scale``; default 1).

    ``material``: (P,) int material key per piece (:func:`piece_materials`; default: equal
    reflectivity and emission). ``backs`` (P,) bool or None: pieces of the backs of open
    surfaces (:mod:`.backs`), which group within their object only, never as clutter: the back
    of a pebble faces its inside, which the fronts of the pebbles beside it do not see."""
    if not size or len(pieces) == 0:
        return None
    if scales is not None and np.any(np.asarray(scales) != 1.0):
        size = float(size) * np.asarray(scales, dtype=np.float64)[pieces.owner]
    small = _small(pieces, size)
    if small.sum() < 2:
        return None
    if material is None:
        material = unique_rows(np.hstack([pieces.rho, pieces.emission]), return_inverse=True)[1]
    lo = pieces.verts.min(axis=0)
    # a piece's cell is that of its bounding box's centre, not its centroid: the two triangles
    # of a quad share the box's centre when the quad is aligned with the world's axes (a wall
    # modelled as a grid of quads), so the cells' borders follow the quads' edges rather than
    # zigzagging through them (the outline :mod:`drawn` draws stays a few straight edges)
    corners = pieces.corners()
    centre = 0.5 * (corners.min(axis=1) + corners.max(axis=1))
    # (a centre on a cell border, as a grid of quads puts whole rows of them, goes the same way
    # for every one: rounded to 1e-9 of a cell first, float noise does not pick the side)
    cell = np.floor(np.round((centre - lo) / np.reshape(size, (-1, 1)), 9)).astype(np.int64)
    # clutter: the pieces of objects smaller than a patch group across objects (owner -1),
    # whether or not they touch: 1,500 pebbles in a cell are a few patches, not 1,500 x 6
    clutter = _clutter(pieces, corners, size) & small
    if backs is not None:
        clutter &= ~np.asarray(backs, dtype=bool)
    owner = np.where(clutter, -1, pieces.owner.astype(np.int64))
    parts = np.stack([owner, np.asarray(material, np.int64).reshape(-1),
                      _normal_bins(pieces.normals, max_angle), *cell.T], axis=1)
    # a piece that is not small keys on its own index: it stays alone
    parts = np.where(small[:, None], parts, -1 - np.arange(len(pieces))[:, None])
    key = unique_rows(parts, return_inverse=True)[1].reshape(-1)
    polys = welded(pieces.verts, pieces.polys)
    # pieces of one key in one plane meet through a vertex of their own: surfaces that touch
    # without sharing corners (T-junctions, the rule in game levels) group as if they did;
    # clutter's pieces of one key all do
    plane = _plane_groups(pieces, key, size)
    plane = np.where(clutter, plane.max() + 1 + key, plane)
    label = connected_components(key, np.concatenate([polys, (plane + polys.max() + 1)[:, None]], 1))
    of = unique_ints(label, return_inverse=True)[1].reshape(-1).astype(np.int64)
    if of.max() + 1 == len(pieces):
        return None
    return make_clusters(pieces, of)


def make_clusters(pieces: PatchSet, of) -> Clusters:
    K = int(of.max()) + 1
    a = pieces.areas
    areas = np.bincount(of, weights=a, minlength=K)
    single = np.bincount(of, minlength=K) == 1

    def mean(x):
        s = np.stack([np.bincount(of, weights=a * x[:, k], minlength=K) for k in range(x.shape[1])], 1)
        return s / areas[:, None]

    centroid = mean(pieces.centers)
    n = mean(pieces.normals)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    # eye point: the centre of the piece nearest the centroid, so a curved cluster's eye is on it
    d = np.linalg.norm(pieces.centers - centroid[of], axis=1)
    order = np.lexsort((d, of))
    first = order[np.r_[0, np.flatnonzero(np.diff(of[order])) + 1]]
    centers = pieces.centers[first]
    # a cluster of one piece is that piece exactly
    solo = np.flatnonzero(single)
    piece_of_solo = first[solo]
    n[solo] = pieces.normals[piece_of_solo]
    rho, em = mean(pieces.rho), mean(pieces.emission)
    rho[solo], em[solo] = pieces.rho[piece_of_solo], pieces.emission[piece_of_solo]
    areas[solo] = a[piece_of_solo]
    return Clusters(of, centers, n, areas, rho, em, pieces.owner[first].astype(np.int32))
