"""N-gons: source faces of more than four corners split into triangles and quads, the first
step of cutting a mesh into patches (:func:`.subdivide.build_patches` cuts only triangles and
quads).

A convex n-gon becomes n quads around its centre; the new vertex on each of its edges (the edge
midpoint) is shared with the neighbour across that edge, whose triangle or quad is re-cut so that
no T-junction remains. A concave n-gon is cut by ear clipping (:func:`ear_clip`).

A face listed in ``MeshInput.face_triangles`` is split into exactly those triangles instead:
the reader lists the n-gons that are not planar (:func:`bent_faces`) with Blender's own loop
triangles. A planar n-gon is the same surface however it is cut, but a folded one is not: Cycles
renders Blender's triangles, and a fan about the centre (or our ear clipping) makes another
surface, centimetres off on a 10-gon folded by 10 cm, which shadows and buries what lies
between the two. Those triangles add no vertex; a neighbouring fan's edge midpoint on one of
their edges re-cuts them as it does a triangle of the mesh (no T-junction).

Shapes: positions (V, 3) float64 in world units; polys (F, 4) int64 vertex indices, -1 in
column 3 for a triangle.
"""
from __future__ import annotations

import numpy as np

from .patches import MeshInput, PatchError, check_faces, read_only
from ..runtime.cache import Memo, PER_MESH, frozen

__all__ = ["ear_clip", "to_tris_and_quads", "bent_faces", "BENT"]

#: An n-gon is bent (:func:`bent_faces`) when a corner lies farther than this share of the
#: face's size (the diagonal of its corners' box) off the plane through their mean along the
#: Newell normal. 1e-4 is a tenth of a millimetre on a metre: a thousand times float32's
#: rounding of a position (6e-8), so an n-gon flat as modelled and then moved, rotated or
#: scaled stays planar and keeps its cut; and a fold below it tilts a piece by about 2e-4
#: radians (the light on it changes by at most 2e-4 of a lamp's) and moves the surface by a
#: tenth of a millimetre a metre, where a bench scene's errors are percents. The bench's living room has 49
#: n-gons: 31 planar to 1e-7 of their size, 18 bent by more than 1e-3 (11 by more than 1e-2).
BENT = 1e-4
#: A quad is cut along Blender's triangles only when it is warped by more than this (of its size,
#: or of its width where that is less: a bevel's strip 5 cm wide and 4.5 m long twisted by 1.2 cm,
#: 3e-3 of its size, tilts its two triangles by 9 degrees and buries one under the bilinear quad):
#: the core's bilinear quad and Blender's two triangles part by up to half the warp, so a quad of a
#: smooth curved surface (a subdivided mesh: warps of 1e-3 and less) stays one bilinear piece, and
#: a strongly warped one (a bevel's twisted corner: millimetres on a few centimetres) is cut as
#: Cycles renders it.
WARPED = 1e-2

_SPLIT = Memo(PER_MESH, max_bytes=256 << 20)     # a mesh's arrays -> to_tris_and_quads (the last bakes')


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


def ear_clip(p: np.ndarray) -> list:
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


def bent_faces(verts, face_offsets, face_indices, tol=BENT, quad_tol=WARPED) -> np.ndarray:
    """(F,) bool: the faces of more than four corners that are not planar, a corner farther than
    ``tol`` times the face's size off its mean plane (:data:`BENT`), and the quads warped by more
    than ``quad_tol`` of their size or their width, whichever is less (:data:`WARPED`).
    ``verts`` (V, 3), ``face_offsets`` (F + 1,), ``face_indices`` (L,) as in :class:`MeshInput`."""
    off = np.asarray(face_offsets, dtype=np.int64)
    idx = np.asarray(face_indices, dtype=np.int64)
    sizes = np.diff(off)
    out = np.zeros(len(sizes), bool)
    big = np.flatnonzero(sizes >= 4)
    if big.size == 0:
        return out
    v = np.asarray(verts, dtype=np.float64)
    k = sizes[big]
    start = np.concatenate([[0], np.cumsum(k)[:-1]])
    corner = np.repeat(off[big], k) + np.arange(int(k.sum())) - np.repeat(start, k)
    nxt = corner + 1
    nxt[start + k - 1] = off[big]
    face = np.repeat(np.arange(big.size), k)
    p = v[idx[corner]]
    centre = np.add.reduceat(p, start, axis=0) / k[:, None]
    a, b = p - centre[face], v[idx[nxt]] - centre[face]      # about the centre: no cancellation
    n = np.add.reduceat(np.cross(a, b), start, axis=0)
    twice_area = np.linalg.norm(n, axis=1)
    n /= np.maximum(twice_area, 1e-300)[:, None]
    off_plane = np.maximum.reduceat(np.abs(np.einsum("lj,lj->l", a, n[face])), start)
    size = np.linalg.norm(np.maximum.reduceat(p, start, axis=0) - np.minimum.reduceat(p, start, axis=0), axis=1)
    # a quad's warp against its width too (twice its area over its size: the size itself for a
    # square): a long thin strip twisted by a centimetre over its 5 cm is warped, however long
    width = np.where(k == 4, np.minimum(size, twice_area / np.maximum(size, 1e-300)), size)
    out[big] = off_plane > np.where(k == 4, quad_tol, tol) * width
    return out


def _given_triangles(mesh, off, idx, sizes):
    """The faces split along ``mesh.face_triangles``: ((G,) int64 faces, (T, 4) int64 polys of
    their triangles (-1 last), (T,) int64 their faces), or None when none is given. Raises
    :class:`PatchError` for a row that names no face, or a corner outside its face."""
    rows = getattr(mesh, "face_triangles", None)
    if rows is None or len(rows) == 0:
        return None
    rows = np.asarray(rows, dtype=np.int64).reshape(-1, 4)
    face, local = rows[:, 0], rows[:, 1:]
    if face.min() < 0 or face.max() >= len(sizes) or local.min() < 0 or np.any(local >= sizes[face][:, None]):
        raise PatchError(f"{mesh.name!r}: face_triangles name a face or a corner that does not exist")
    polys = np.full((len(rows), 4), -1, dtype=np.int64)
    polys[:, :3] = idx[off[face][:, None] + local]
    return np.unique(face), polys, face


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
            new = [(int(ring[t[0]]), int(ring[t[1]]), int(ring[t[2]]), -1) for t in ear_clip(p)]
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
        return [(ring2[t[0]], ring2[t[1]], ring2[t[2]], -1) for t in ear_clip(rp)]
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


def to_tris_and_quads(mesh: MeshInput):
    """Split n-gons: convex ones into n quads around their centre, concave ones by ear clipping,
    those with ``face_triangles`` into those triangles (which count as triangles of the mesh).

    Returns verts (V', 3), polys (F', 4) with -1 for triangles, and the source face per poly.
    New vertices on a source edge (edge midpoints) are shared by the faces on both sides.
    Made once per mesh's read-only arrays and then read only: a bake cuts the same meshes at
    the patch size, at the detail size and whole, and asks whether they keep their faces whole
    (the living room's n-gons took 1.2 s of a bake, split 11 times over).
    """
    arrays = (mesh.verts, mesh.face_offsets, mesh.face_indices, getattr(mesh, "face_triangles", None))
    if not all(read_only(a) for a in arrays):          # may change in place: made every time
        return _to_tris_and_quads(mesh)

    return _SPLIT.of(arrays, lambda: frozen(*_to_tris_and_quads(mesh)))


def _to_tris_and_quads(mesh: MeshInput):
    verts = np.asarray(mesh.verts, dtype=np.float64)
    off = np.asarray(mesh.face_offsets, dtype=np.int64)
    idx = np.asarray(mesh.face_indices, dtype=np.int64)
    sizes = np.diff(off)
    check_faces(mesh, verts, idx, sizes)
    polys, src = _small_faces(off, idx, sizes)
    big = np.flatnonzero(sizes > 4)
    given = _given_triangles(mesh, off, idx, sizes)
    if given is not None:
        faces, tris, tri_src = given
        keep = ~np.isin(src, faces)
        polys = np.concatenate([polys[keep], tris])
        src = np.concatenate([src[keep], tri_src])
        big = big[~np.isin(big, faces)]
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
