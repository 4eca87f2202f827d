"""The backs of open surfaces: what Cycles reflects from the other side of a single plane.

The paper's patches reflect from their front only; in Cycles every surface reflects on both
sides (a single-plane wall lit from behind, a lamp panel's back 5 mm under a ceiling, a floor
turned away from the room by a negative scale). Here each face of an *open* surface gets a
back: the same face with its corners in reverse order, moved a hair (:func:`offset`) behind the
front, so that from either side the nearer of the two faces the viewer. The hemi-cube's depth
test, Embree's nearest hit and every front-only test then see two surfaces, nothing special.

An open surface is a connected part of a mesh (faces joined through edges that two faces share
with opposite orientation, corners welded by position) that has an edge no other face closes: a
border, an edge of three or more faces, or two faces of opposite orientation. A closed mesh (a
box, a sphere, a room modelled with thickness) is left as it is: its backs face its inside,
which no light reaches, so it pays nothing.

The backs are meshes of their own, after the fronts (``MeshInput.back_of``: the index of the
front), so the object's sizes, materials and grouping carry over and the writer can put a back's
light on the same object. A back's emission follows ``two_sided_emission``: the back of an
emitting face emits as its front does (Cycles' Emission shader), or nothing for one-sided
emitters; emitters then need no second, turned-around transport (:mod:`..light.direct`).

Units: world units; ``offset`` is a distance.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..runtime.cache import cache_key, cached, frozen
from ..util.unique import linked_labels, unique_rows
from .patches import covering_faces, meshes_key, negated_rows
from .sizes import mesh_boxes
from ..rays import START_BACKS, START_SHARE, START_ULPS

__all__ = ["with_backs", "backs_that_matter", "open_faces", "offset", "cutters", "backs_of_pieces"]

#: A back lies this share of its own mesh's diagonal behind its front (2.5e-6: a quarter of the
#: rays' start offset, :func:`.rays.ray_offsets`: a ray leaving a point next to a back must not
#: start on it) ...
OFFSET_SHARE = START_SHARE / START_BACKS
#: ... and at least this many float32 steps (16, of 2**-23 of the largest coordinate), so that
#: Embree's float32 vertices and the hemi-cube's float32 depths always tell the two sides apart.
OFFSET_ULPS = START_ULPS // START_BACKS
#: Rays from each probe point of an open face that look for what its back faces ...
PROBE_RAYS = 32
#: ... and from up to this many of the fronts they hit, this many rays, to tell a surface in
#: the open from one shut in by the backs of others.
SECOND_HITS = 8
SECOND_RAYS = 8
#: A back matters where the lit world or fronts in the open fill this share of its view (its
#: cosine-weighted probe rays): less, and it exchanges little light with the scene (the inside
#: of a scanned model, seen through the holes in its base).
FACING_SHARE = 1.0 / 8.0
#: Faces larger than this share of the scene's diagonal, squared, are probed at five points.
LARGE_FACE = 0.05
#: An emitting face's back is also probed this share of the way from each corner to its centre
#: (what it lights may lie where its centre's rays graze: an opening's rim 1 cm over a lamp).
NEAR_CORNER = 0.02


def _corner_next(offsets) -> np.ndarray:
    """(L,) index of the next corner of each corner's face (the last wraps to the first)."""
    L = int(offsets[-1])
    nxt = np.arange(1, L + 1, dtype=np.int64)
    ends = offsets[1:] - 1
    nxt[ends] = offsets[:-1]
    return nxt


def _face_of_corner(offsets) -> np.ndarray:
    counts = np.diff(offsets)
    return np.repeat(np.arange(len(counts), dtype=np.int64), counts)


def open_faces(verts, face_offsets, face_indices, tol) -> np.ndarray:
    """(F,) bool: the faces whose connected part of the mesh is open (module docstring).

    ``verts`` (V, 3) positions, ``face_offsets`` (F + 1,), ``face_indices`` (L,) as in
    :class:`.patches.MeshInput`; ``tol``: positions closer than this are one corner."""
    offsets = np.asarray(face_offsets, dtype=np.int64)
    F = len(offsets) - 1
    if F <= 0:
        return np.zeros(0, bool)
    v = np.asarray(verts, dtype=np.float64)
    ids = unique_rows(np.round(v / tol).astype(np.int64), return_inverse=True)[1].reshape(-1)
    a = ids[np.asarray(face_indices, dtype=np.int64)]
    b = a[_corner_next(offsets)]
    face = _face_of_corner(offsets)
    keep = a != b                               # an edge of no length joins nothing
    a, b, face = a[keep], b[keep], face[keep]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    edge, inv, count = unique_rows(np.stack([lo, hi], 1), return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    forward = (a < b).astype(np.int64)
    fwd = np.bincount(inv, weights=forward, minlength=len(edge))
    # closed: two faces, one along the edge and one against it
    closed = (count == 2) & (fwd == 1)
    bad = np.zeros(F, bool)
    bad[face[~closed[inv]]] = True
    # faces joined through closed edges: label propagation with pointer jumping
    order = np.argsort(inv, kind="stable")
    e_sorted, f_sorted = inv[order], face[order]
    pair = (e_sorted[1:] == e_sorted[:-1]) & closed[e_sorted[1:]]
    i, j = f_sorted[:-1][pair], f_sorted[1:][pair]
    label = linked_labels(F, i, j)
    return np.isin(label, label[bad])


def _vertex_normals(verts, offsets, indices, faces) -> np.ndarray:
    """(V, 3) unit normals at the vertices of ``faces``: the sum of their area vectors (Newell),
    or 0 where they cancel or no such face uses the vertex."""
    v = np.asarray(verts, dtype=np.float64)
    face = _face_of_corner(offsets)
    p = v[indices]
    q = p[_corner_next(offsets)]
    cross = np.cross(p, q)
    # sums by bincount: np.add.at's, in the same order, bit for bit, several times faster
    area = np.stack([np.bincount(face, cross[:, k], len(offsets) - 1) for k in range(3)], 1)
    area[~faces] = 0.0
    per_corner = area[face]
    n = np.stack([np.bincount(indices, per_corner[:, k], len(v)) for k in range(3)], 1)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    scale = float(np.abs(v).max(initial=0.0)) or 1.0
    return np.where(length > 1e-12 * scale * scale, n / np.maximum(length, 1e-300), 0.0)


def offset(verts) -> float:
    """How far a mesh's backs lie behind its fronts: :data:`OFFSET_SHARE` of its diagonal, at
    least :data:`OFFSET_ULPS` float32 steps of its largest coordinate."""
    v = np.asarray(verts, dtype=np.float64)
    if not len(v):
        return 0.0
    diag = float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))
    return max(OFFSET_SHARE * diag, OFFSET_ULPS * 2.0 ** -23 * float(np.abs(v).max()))


def _back(mesh, index, shape, emit: bool):
    """The back of some faces of ``mesh`` (their :func:`_back_geometry` ``shape``, cached for all
    backs as one item: hundreds of open meshes must not fill the cache's count of items)."""
    verts, new_offsets, face_indices, corner, sel, triangles = shape

    def corners(a):
        return None if a is None else np.asarray(a)[corner]

    em = np.asarray(mesh.face_emission, dtype=np.float64)[sel]
    corner_em = corners(mesh.corner_emission)
    if not emit:
        em = np.zeros_like(em)
        corner_em = None if corner_em is None else np.zeros_like(corner_em)
    material = getattr(mesh, "face_material", None)
    return replace(mesh, verts=verts, face_offsets=new_offsets, face_indices=face_indices,
                   face_rho=np.asarray(mesh.face_rho, dtype=np.float64)[sel], face_emission=em,
                   name=f"{mesh.name} (back)", corner_rho=corners(mesh.corner_rho),
                   corner_emission=corner_em,
                   corner_normal=None if getattr(mesh, "corner_normal", None) is None
                   else negated_rows(mesh.corner_normal, corner),
                   face_material=None if material is None else np.asarray(material)[sel],
                   face_triangles=triangles, back_of=index, back_faces=sel,
                   face_glossy=None if getattr(mesh, "face_glossy", None) is None
                   else np.asarray(mesh.face_glossy, dtype=np.float64)[sel])


def _back_geometry(mesh, faces):
    """(verts, face offsets, face indices, each corner's corner of the front, the faces, face
    triangles or None) of :func:`_back`."""
    offsets = np.asarray(mesh.face_offsets, dtype=np.int64)
    indices = np.asarray(mesh.face_indices, dtype=np.int64)
    counts = np.diff(offsets)
    sel = np.flatnonzero(faces)
    # corners of the chosen faces, each face's ring reversed after its first corner
    start, n = offsets[sel], counts[sel]
    new_offsets = np.zeros(sel.size + 1, dtype=np.int64)
    new_offsets[1:] = np.cumsum(n)
    k = np.arange(int(new_offsets[-1]), dtype=np.int64) - np.repeat(new_offsets[:-1], n)
    nn = np.repeat(n, n)
    corner = np.repeat(start, n) + np.where(k == 0, 0, nn - k)
    normals = _vertex_normals(mesh.verts, offsets, indices, faces)
    used = np.unique(indices[corner])
    remap = np.full(len(mesh.verts), -1, dtype=np.int64)
    remap[used] = np.arange(used.size)
    verts = np.asarray(mesh.verts, dtype=np.float64)[used] - offset(mesh.verts) * normals[used]
    return frozen(verts, new_offsets, remap[indices[corner]], corner, sel,
                  _back_triangles(getattr(mesh, "face_triangles", None), sel, counts))


def _back_triangles(rows, sel, counts):
    """``MeshInput.face_triangles`` ``rows`` (T, 4) of a mesh whose faces ``sel`` (S,) become
    its back (:func:`_back`: each ring reversed after its first corner, ``counts`` (F,) corners
    a face): the same triangles turned around, on the back's faces; None when none is left."""
    if rows is None or len(rows) == 0:
        return None
    rows = np.asarray(rows, dtype=np.int64).reshape(-1, 4)
    new_face = np.full(len(counts), -1, dtype=np.int64)
    new_face[sel] = np.arange(sel.size)
    rows = rows[new_face[rows[:, 0]] >= 0]
    if not len(rows):
        return None
    n = counts[rows[:, 0]][:, None]
    local = np.where(rows[:, 1:] == 0, 0, n - rows[:, 1:])   # corner j of the front is n - j
    return np.column_stack([new_face[rows[:, 0]], local[:, ::-1]])


def with_backs(meshes, two_sided_emission=True, lights=(), world=None, probe_rays=PROBE_RAYS,
               cache=None) -> list:
    """``meshes`` followed by a back (a mesh of its own, ``back_of`` its index) for the open
    faces (:func:`open_faces`) of each mesh whose backs can matter (:func:`backs_that_matter`);
    closed meshes get none. ``two_sided_emission``: the backs of emitting faces emit as their
    fronts do, else nothing. ``lights`` (core.light lamps) and ``world`` ((3,) radiance or None)
    decide which backs may be lit; ``probe_rays`` per point look for what a back faces. Which
    backs matter depends on geometry and on where the sources are, not on their strength or
    colour: kept in ``cache`` (a relight casts no ray)."""
    meshes = list(meshes)
    some = [m for m in meshes if len(m.verts)]
    if not some:
        return meshes
    lo, hi = mesh_boxes(some)       # each mesh's box, kept per verts array: a relight's are the same
    span = hi.max(axis=0) - lo.min(axis=0) if all(np.asarray(m.verts).dtype == np.float64 for m in some) \
        else np.ptp(np.concatenate([np.asarray(m.verts) for m in some]), axis=0)   # (the same: the ptp of all)
    tol = 1e-9 * (float(np.linalg.norm(span)) or 1.0)
    key = meshes_key(meshes)
    opened = _cached_open(meshes, tol, cache, key)
    if not opened:
        return meshes
    matter = _cached_backs(meshes, opened, lights, world, probe_rays, cache, two_sided_emission, key)
    faces = {i: f & matter[i] for i, f in opened.items() if (f & matter[i]).any()}
    shapes = cached(cache, cache_key(key + b"".join(np.packbits(f).tobytes() for f in faces.values()),
                                     ("back", tuple(faces))),
                    lambda: [_back_geometry(meshes[i], f) for i, f in faces.items()])
    return meshes + [_back(meshes[i], i, shape, two_sided_emission) for i, shape in zip(faces, shapes)]


def _cached_open(meshes, tol, cache, key) -> dict:
    """{mesh index: (F,) bool :func:`open_faces`} of the meshes with an open face, kept in
    ``cache`` under their geometry ``key`` (a relight reads the same meshes again). A face of
    zero area (:func:`.patches.covering_faces`) has no back: it covers nothing, and a back of
    only such faces was refused as a mesh of nothing (a real room's degenerate slivers)."""
    fronts = [i for i, m in enumerate(meshes)
              if getattr(m, "back_of", -1) < 0 and len(m.verts) and len(m.face_offsets) >= 2]

    def make():
        faces = [open_faces(m.verts, m.face_offsets, m.face_indices, tol)
                 & covering_faces(m.verts, m.face_offsets, m.face_indices) for m in (meshes[i] for i in fronts)]
        return np.concatenate([np.zeros(0, bool), *faces])
    flat = np.asarray(cached(cache, cache_key(key, ("open-covering-faces", tol, tuple(fronts))), make), bool)
    ends = np.cumsum([len(meshes[i].face_offsets) - 1 for i in fronts])
    return {i: f for i, f in zip(fronts, np.split(flat, ends[:-1]) if fronts else ()) if f.any()}


def _sources_key(lights, world) -> str:
    """What of the sources decides which backs matter: each lamp's place or direction (an
    environment map: that there is one), and whether the world is lit."""
    parts = []
    for light in lights or ():
        pos, to = getattr(light, "position", None), getattr(light, "direction", None)
        parts.append(("p", tuple(np.round(np.asarray(pos, float), 12))) if pos is not None else
                     ("d", tuple(np.round(np.asarray(to, float), 12))) if to is not None else ("w",))
    on = world is not None and bool(np.any(np.asarray(world, dtype=np.float64) > 0))
    return repr((sorted(parts), on))


def _cached_backs(meshes, opened, lights, world, probe_rays, cache, emit, geometry) -> dict:
    """:func:`backs_that_matter`, kept in ``cache`` under the geometry and the sources' places."""
    order = sorted(opened)
    key = cache_key(geometry + b"".join(np.packbits(opened[i]).tobytes() for i in order),
                    ("backs", probe_rays, emit, _sources_key(lights, world)))
    def make():
        found = backs_that_matter(meshes, opened, lights, world, probe_rays, emit)
        return np.concatenate([found[i] for i in order])
    flat = cached(cache, key, make)
    flat = np.asarray(flat, dtype=bool)
    ends = np.cumsum([len(opened[i]) for i in order])
    return dict(zip(order, np.split(flat, ends[:-1])))


def backs_that_matter(meshes, opened, lights=(), world=None, probe_rays=PROBE_RAYS, emit=True) -> dict:
    """{mesh index: (F,) bool}: which of the open faces ``opened`` ({index: (F,) bool}) have a
    back that can take part in the light.

    A back matters where a source reaches it (a lamp behind the face's plane or a sun on its back,
    by a shadow ray), where the lit world (or an environment map) above the horizon fills at least
    :data:`FACING_SHARE` of its view (the world below a terrain lights its underside in Cycles too,
    for no one to see), or where that much of its view is the fronts of surfaces that are not shut
    in (their own rays find some front, or escape, not only the backs of others). With ``emit``
    (two-sided emitters) the back of an emitting face matters wherever it faces any surface, probed
    from near its corners too (:data:`NEAR_CORNER`). The rest are left out, so a scene pays nothing
    for them: the underside of a floor, the outside of a room built of single planes in a dark
    world, the inside of a box without a bottom standing on a floor (it faces only its own walls'
    backs and the floor they shut in), the inside of a scanned model seen through holes in its base.

    Probed from each face's centre (and halfway to each corner on faces larger than
    :data:`LARGE_FACE` of the scene's diagonal squared) with ``probe_rays`` cosine rays against
    the fronts, and from up to :data:`SECOND_HITS` of the fronts they hit with
    :data:`SECOND_RAYS` rays each. Without Embree every back is kept."""
    from ..rays import embree_available

    out = {i: f.copy() for i, f in opened.items()}
    if not embree_available():
        return out
    scene, offsets, centres, normals, areas, corner, corner_face = _fan_scene(meshes)
    sel = np.concatenate([offsets[i] + np.flatnonzero(f) for i, f in opened.items()])
    if not sel.size or scene is None:
        return out
    eps = np.concatenate([np.full(max(len(m.face_offsets) - 1, 0), START_BACKS * offset(m.verts)) for m in meshes])
    # rays start as the bake's do (:func:`.rays.ray_offsets`): off each face by its mesh's offset
    points, at = _probe_points(sel, centres, areas, corner, corner_face, scene.scale)
    n, start_eps = normals[sel], eps[sel][at]
    S, R = len(sel), probe_rays
    matter, world_on = _lit(scene, lights, world, points, n[at], at, S, start_eps)
    hit, x, m, escaped, up = _probe(scene, normals, points, -n[at], R, start_eps)
    ray_face = np.repeat(at, R)
    rays = np.bincount(ray_face, minlength=S)
    if emit:                                    # an emitter's back shines on whatever it faces
        lamp = _face_emission(meshes, offsets, sel) > 0
        matter |= lamp & (np.bincount(ray_face, weights=~escaped, minlength=S) > 0)
        k = np.full(len(centres), -1, np.int64)
        k[sel[lamp]] = np.flatnonzero(lamp)
        on, k = k[corner_face] >= 0, k[corner_face][k[corner_face] >= 0]    # and from its corners
        near = corner[on] + NEAR_CORNER * (centres[corner_face[on]] - corner[on])
        esc = _probe(scene, normals, near, -normals[sel[k]], R, eps[sel[k]])[3]
        matter |= np.bincount(np.repeat(k, R), weights=~esc, minlength=S) > 0
    if world_on:                                # the lit sky over a share of its view
        matter |= np.bincount(ray_face, weights=escaped & up, minlength=S) >= FACING_SHARE * rays
    # fronts over a share of its view, not shut in: their own rays find some front, or escape
    front = np.flatnonzero((hit >= 0) & ~matter[ray_face])
    if front.size:
        fronts = np.bincount(ray_face[front], minlength=S)
        matter |= fronts * _open_share(scene, normals, x, m, front, ray_face[front], S, eps[hit]) >= FACING_SHARE * rays
    return _per_mesh(opened, matter)


def _probe_points(sel, centres, areas, corner, corner_face, scale):
    """Where the backs of faces ``sel`` (S,) are probed from: each face's centre, and halfway to
    each corner on faces larger than :data:`LARGE_FACE` of ``scale`` squared. Returns the points
    (P, 3) and the face of each, as an index into ``sel`` (P,)."""
    big = np.zeros(len(centres), bool)
    big[sel] = areas[sel] > (LARGE_FACE * scale) ** 2
    of_sel = np.full(len(centres), -1, np.int64)
    of_sel[sel] = np.arange(sel.size)
    on = big[corner_face]
    halfway = 0.5 * (corner[on] + centres[corner_face[on]])
    at = np.concatenate([np.arange(len(sel)), of_sel[corner_face[on]]]).astype(np.int64)
    return np.concatenate([centres[sel], halfway]), at


def _per_mesh(opened, matter) -> dict:
    """{mesh index: (F,) bool}: ``matter`` (S,), one per open face of ``opened`` in its order,
    scattered back onto each mesh's faces (False where a face is not open)."""
    out = {o: np.zeros_like(f) for o, f in opened.items()}
    for (o, f), m in zip(opened.items(), np.split(matter, np.cumsum([f.sum() for f in opened.values()])[:-1])):
        out[o][f] = m
    return out


def _lit(scene, lights, world, points, normals, at, S, eps):
    """((S,) bool the faces a lamp or a sun reaches on their back, by one shadow ray from each
    probe point ``points`` (P, 3) of face ``at`` (P,) behind its ``normals`` (P, 3), starting
    ``eps`` (P,) off it; whether
    the world is lit: by ``world`` (3,) or an environment map among ``lights``)."""
    world_on = world is not None and bool(np.any(np.asarray(world, dtype=np.float64) > 0))
    lit = np.zeros(S, bool)
    for light in lights or ():
        pos, to = getattr(light, "position", None), getattr(light, "direction", None)
        if pos is None and to is None:          # an environment map: the world, by direction
            world_on = True
            continue
        d = np.asarray(pos, float) - points if pos is not None else np.tile(-np.asarray(to, float), (len(points), 1))
        behind = np.einsum("pj,pj->p", d, normals) < 0
        free = ~scene.occluded((points - eps[:, None] * normals)[behind], d[behind],
                               None if pos is None else np.full(behind.sum(), 1 - 1e-6))
        reached = np.zeros(len(points), bool)
        reached[np.flatnonzero(behind)[free]] = True
        np.logical_or.at(lit, at, reached)
    return lit, world_on


def _open_share(scene, normals, x, m, front, face, S, eps) -> np.ndarray:
    """(S,) per face, the share of its front hits (rays ``front`` hit ``x`` (R, 3) with normal
    ``m`` (R, 3), of face ``face`` (k,)) that are not shut in: of up to :data:`SECOND_HITS` of
    them, how many cast :data:`SECOND_RAYS` rays (starting ``eps`` (R,) off) of which one escapes
    or finds a front."""
    order = np.argsort(face, kind="stable")
    front, face = front[order], face[order]
    first = np.searchsorted(face, face, side="left")
    keep = (np.arange(face.size) - first) < SECOND_HITS
    front, face = front[keep], face[keep]
    h2, _, _, esc2, _ = _probe(scene, normals, x[front], m[front], SECOND_RAYS, eps[front])
    open2 = (esc2 | (h2 >= 0)).reshape(-1, SECOND_RAYS).any(axis=1)
    return np.bincount(face, weights=open2, minlength=S) / np.maximum(np.bincount(face, minlength=S), 1)


def _fans(tris, tri_face, scale):
    """An Embree scene of the meshes' faces as triangle fans (enough to probe what a face faces;
    the bake's own scenes are of its patches), answering as :class:`.rays.EmbreeScene` does with
    the face (numbered over all meshes) for the patch; its nearest hits on every core (Embree
    lets go of the GIL)."""
    from ..rays import EmbreeScene, import_embreex
    from ..runtime.parallel import ordered_map, resolve_workers

    class Fans(EmbreeScene):
        def __init__(self):                     # (not from a PatchSet)
            rtcs, TriangleMesh = import_embreex()
            self.tri_patch, self.scale, self.n_patches = tri_face, scale, int(tri_face.max(initial=-1)) + 1
            self._scene = rtcs.EmbreeScene()
            self._mesh = TriangleMesh(self._scene, np.ascontiguousarray(tris, dtype=np.float32))

        def intersect(self, origins, directions, tfar=None):
            n = len(origins)
            step = max(1 << 16, -(-n // (4 * resolve_workers(0))))
            parts = list(ordered_map(lambda s: EmbreeScene.intersect(self, origins[s:s + step], directions[s:s + step]),
                                     range(0, n, step), resolve_workers(0)))
            if not parts:
                return np.zeros(0, np.int64), np.zeros(0, np.float32)
            return np.concatenate([p for p, _ in parts]), np.concatenate([t for _, t in parts])
    return Fans()


def _fan_scene(meshes):
    """The meshes' faces, numbered over all meshes: (scene, offsets {mesh: its first face},
    centres (F, 3) (the corners' mean), unit normals (F, 3), areas (F,), and every corner's
    position (L, 3) with its face (L,))."""
    tris, tri_face, corner, following, corner_face, offsets, start = [], [], [], [], [], {}, 0
    for i, m in enumerate(meshes):
        off = np.asarray(m.face_offsets, dtype=np.int64)
        idx = np.asarray(m.face_indices, dtype=np.int64)
        offsets[i] = start
        if len(off) < 2:
            continue
        v = np.asarray(m.verts, dtype=np.float64)
        counts = np.diff(off)
        face = _face_of_corner(off)
        k = np.arange(len(idx)) - np.repeat(off[:-1], counts)
        c = np.flatnonzero((k >= 1) & (k < np.repeat(counts, counts) - 1))    # fan triangles' middles
        tris.append(np.stack([v[idx[off[face[c]]]], v[idx[c]], v[idx[c + 1]]], 1))
        tri_face.append(start + face[c])
        corner.append(v[idx])
        following.append(v[idx[_corner_next(off)]])
        corner_face.append(start + face)
        start += len(off) - 1
    if not corner:
        return None, offsets, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)), np.zeros(0, np.int64)
    tris, corner, following = np.concatenate(tris), np.concatenate(corner), np.concatenate(following)
    corner_face = np.concatenate(corner_face)
    F = start
    area = np.stack([np.bincount(corner_face, weights=0.5 * w, minlength=F)
                     for w in np.cross(corner, following).T], 1)
    size = np.linalg.norm(area, axis=1)
    count = np.bincount(corner_face, minlength=F)
    centre = np.stack([np.bincount(corner_face, weights=corner[:, k], minlength=F) for k in range(3)], 1) \
        / np.maximum(count, 1)[:, None]
    scale = float(np.linalg.norm(corner.max(axis=0) - corner.min(axis=0))) or 1.0
    scene = _fans(tris, np.concatenate(tri_face).astype(np.int64), scale) if len(tris) else None
    return scene, offsets, centre, area / np.maximum(size, 1e-300)[:, None], size, corner, corner_face


def backs_of_pieces(meshes, pieces) -> np.ndarray | None:
    """(P,) bool: which ``pieces`` (a PatchSet cut from ``meshes``) are of a back; None: none are."""
    back = np.array([getattr(m, "back_of", -1) >= 0 for m in meshes or ()], dtype=bool)
    return back[np.asarray(pieces.owner, dtype=np.int64)] if back.any() else None


def cutters(meshes, faces):
    """(len(faces),) bool, which of ``faces`` (a PatchSet of the meshes' faces) may cut along
    contacts (:func:`.contact.cut_along_contacts`), or None for all (no backs). A back lies a
    hair behind its front, whose own line already cuts: its line would part a sliver off the
    floor beside every single-plane wall."""
    back = backs_of_pieces(meshes, faces)
    return None if back is None else ~back



def _probe(scene, normals, points, directions_about, rays, eps):
    """``rays`` cosine rays from each of ``points`` (P, 3) about ``directions_about`` (P, 3),
    starting ``eps`` (P,) off along it:
    (hit (P * rays,) the face whose front a ray hit, or -1; where (P * rays, 3) it hit; that
    face's normal (P * rays, 3); escaped and up (P * rays,) bool: the ray found nothing; it
    points above the horizon (+Z, Blender's up))."""
    from ..hemisphere import cosine_lattice
    from ..util.geometry import in_frames, tangent_frames

    local = cosine_lattice(rays, 7)
    d = in_frames(local, tangent_frames(directions_about)).reshape(-1, 3)
    o = np.repeat(points + eps[:, None] * directions_about, rays, axis=0)
    pid, t = scene.intersect(o, d)
    escaped = pid < 0
    nrm = normals[np.maximum(pid, 0)]
    front = (pid >= 0) & (np.einsum("pj,pj->p", nrm, d) < 0)
    where = o + np.where(front, t, 0.0)[:, None] * d
    return np.where(front, pid, -1), where, nrm, escaped, d[:, 2] > 0


def _face_emission(meshes, offsets, sel) -> np.ndarray:
    """(S,) the largest band of each face's emission, of the faces ``sel`` numbered over all meshes."""
    return np.concatenate([np.asarray(m.face_emission, dtype=np.float64).reshape(-1, 3).max(axis=1)
                           if len(m.face_offsets) >= 2 else np.zeros(0) for m in meshes])[sel]
