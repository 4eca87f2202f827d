# SPDX-License-Identifier: GPL-3.0-or-later
"""Blender scene -> core input: depsgraph-evaluated meshes in world space, split at hard edges.

Nothing here modifies the scene: meshes are evaluated with ``evaluated_get(depsgraph).to_mesh()``
and freed again.

Vertex welding rule (the core shares a patch vertex exactly where two faces share a source
vertex, and averages radiosity there). Every face corner starts as its own vertex; corners of two
faces that share an edge are welded at both ends of that edge when the faces use the same
material and either

* both faces are smooth-shaded, the edge is not marked sharp and no other face shares it, or
* the faces are coplanar (normals within 1e-3 rad), so a wall cut into several faces stays one
  surface even when it is flat-shaded or its edges are marked sharp.

An edge three or more faces share (a wall standing on a floor along the edge of a face behind
it, the partition between two solids of a game level) parts its faces but coplanar ones, as
Blender's corner normals do: welded, a floor's corner at the wall's foot and the wall's shared a
vertex whose point lay in front of neither (godot_zdm2: 16.0% RMS against Cycles, 14.1% parted).

Everything else (flat-shaded corners of a box, sharp edges between smooth faces, material
borders) is a hard edge: each side gets its own vertex copies and colours do not bleed across.
Faces of an object with a negative-determinant matrix are reversed so they stay counter-clockwise
seen from the front in world space. N-gons that are not planar carry Blender's own loop
triangles (:mod:`.ngon_triangles`), the surface Cycles renders.

Which objects and where: :mod:`.visibility` (what a render sees); instances (collection,
Geometry Nodes, particles) from the depsgraph: :mod:`.instances`, placed here
(:func:`read_scene`). Materials: :mod:`.materials` (node values) and :mod:`.shading` (Cycles' own
evaluation, per corner or per material, on temporary copies). :class:`ObjectSource` carries ``corner_rho`` / ``corner_emission`` for every
corner of ``mesh.face_indices``; the mesh's ``face_rho`` / ``face_emission`` are their per-face
means.

:class:`SceneInput` carries ``lights`` and ``world`` that ``blender.read.lights.read_lights``
fills; the bake passes them on to ``core.pipeline.bake(lights=, world=)``.
"""
from __future__ import annotations

import zlib
from dataclasses import dataclass, field

import numpy as np

from ...core.mesh.patches import MeshInput
from ...core.runtime.cache import Memo, PER_MESH, frozen, inverse
from ...core.runtime.errors import RadiosityError
from ...core.runtime.notes import Note, note, subject_and_kind
from . import instances as inst_reader
from . import shading
from .face_emission import face_means
from .materials import corner_materials
from .transparency import material_transmit, mesh_transmit, see_through_note, solve_rho
from .ngon_triangles import bent_ngon_triangles, reversed_rings
from .split_normals import cycles_corner_normals
from .visibility import render_notes, world_matrix

__all__ = ["ReadError", "ObjectSource", "SceneInput", "read_object", "read_scene", "weld_corners",
           "GEOMETRY_TYPES", "check_writable", "instancers_only", "mesh_corner_normals"]

COPLANAR_COS = float(np.cos(1e-3))
# a face is of zero area below this fraction of the object's squared size (its bounding box
# diagonal): core.mesh.subdivide.build_patches drops such faces and refuses a mesh of nothing else
ZERO_AREA = 1e-12

# Object types a render draws as surfaces: meshes, and text, curves, surfaces and metaballs, which
# are read as the mesh Blender evaluates them to (a text object is geometry to an artist). A curve
# without bevel, extrusion or fill (a guide), or a metaball whose surface belongs to its family's
# base object, has no faces: it is left out with a note.
GEOMETRY_TYPES = frozenset({"MESH", "FONT", "CURVE", "SURFACE", "META"})
_TYPE_NAMES = {"FONT": "text", "CURVE": "curve", "SURFACE": "surface", "META": "metaball"}
# attribute names Blender keeps for itself (fixed type and domain) on every mesh
_RESERVED_ATTRIBUTES = frozenset({"position", "material_index", "sharp_face", "sharp_edge"})


class ReadError(RadiosityError, ValueError):
    """The scene cannot be baked; the message names the object."""


@dataclass
class ObjectSource:
    """One object as the core sees it, plus what the writer needs to map results back."""

    name: str                 # object name (unique in the file)
    mesh: MeshInput           # world space, split at hard edges
    corner_loop: np.ndarray   # (L,) evaluated-mesh loop index of every mesh.face_indices entry
    matrix_world: np.ndarray  # (4, 4)
    flipped: bool             # negative determinant: face rings were reversed
    bake: bool                # False: occluder/emitter only, nothing is written for it
    eval_counts: tuple        # (vertices, loops, polygons) of the evaluated mesh
    notes: list = field(default_factory=list)   # what was approximated, one short line each
    corner_rho: np.ndarray = None       # (L, 3) reflectance at every mesh.face_indices corner
    corner_emission: np.ndarray = None  # (L, 3) emitted radiance there (mesh.face_rho/_emission
                                        # are their per-face means)


@dataclass
class SceneInput:
    objects: list
    lights: tuple = ()        # core.light.lamps objects, filled by blender.read.lights.read_lights
    world: object = None
    skipped: list = field(default_factory=list)   # notes of objects left out ("name: why")
    instanced: list = field(default_factory=list)  # the note on instances that take part

    @property
    def meshes(self):
        return [o.mesh for o in self.objects]

    def notes(self):
        """The readers' lines as :class:`Note` s: an object left out is a warning; an object's
        line is said of the object, unless it has its own subject (a material's, said once for
        every object that uses it); then the instances' note, and theirs (:func:`read_scene`)."""
        out = []
        for line in self.skipped:
            subject, kind, _ = subject_and_kind(line)
            out.append(Note(line, subject, kind, warning=True, topic="scene"))
        for line in self.instanced:         # the instances' note (of the whole bake) and theirs
            out.append(line if isinstance(line, Note) else Note(line, *subject_and_kind(line)[:2]))
        for o in self.objects:
            for n in o.notes:
                if isinstance(n, Note) and n.subject is not None:
                    out.append(n)
                else:
                    out.append(note(o.name, *((n.kind, n.warning) if isinstance(n, Note) else (n,))))
        return out


# ----------------------------------------------------------------------------- welding
def _union(n, i, j):
    """Connected-component labels of n nodes joined by pairs (i, j): hook + pointer jumping."""
    lab = np.arange(n)
    if i.size == 0:
        return lab
    while True:
        li, lj = lab[i], lab[j]
        if np.array_equal(li, lj):
            return lab
        m = np.minimum(li, lj)
        np.minimum.at(lab, li, m)
        np.minimum.at(lab, lj, m)
        while True:
            nl = lab[lab]
            if np.array_equal(nl, lab):
                break
            lab = nl


def weld_corners(loop_vert, loop_edge, poly_start, poly_total, face_material, face_smooth,
                 edge_sharp, face_normal):
    """Vertex id per loop (corner) following the welding rule in the module docstring.

    Returns (corner_vertex (L,), source_vertex (V',)): new vertex ids and the original vertex each
    one copies.
    """
    L = loop_vert.size
    F = poly_start.size
    loop_face = np.repeat(np.arange(F), poly_total)
    pos = np.arange(L) - poly_start[loop_face]
    nxt = np.where(pos == poly_total[loop_face] - 1, poly_start[loop_face], np.arange(L) + 1)
    order = np.argsort(loop_edge, kind="stable")
    es = loop_edge[order]
    start = np.searchsorted(es, es, side="left")
    count = np.searchsorted(es, es, side="right") - start      # the faces on each loop's edge
    # each loop with its edge's first; on an edge more faces share, with every earlier one too
    # (coplanar pairs weld there, wherever they are in the edge's list)
    rep = np.where(count > 2, np.arange(L) - start - 1, 0).clip(0)
    k = np.repeat(np.arange(L), rep)
    a = 1 + np.arange(k.size) - np.repeat(np.cumsum(rep) - rep, rep)
    l1 = np.concatenate([order[start], order[start[k] + a]])
    l2 = np.concatenate([order, order[k]])
    count = np.concatenate([count, count[k]])
    keep = l1 != l2
    l1, l2, count = l1[keep], l2[keep], count[keep]
    f1, f2 = loop_face[l1], loop_face[l2]
    e = loop_edge[l2]
    coplanar = np.einsum("ij,ij->i", face_normal[f1], face_normal[f2]) > COPLANAR_COS
    smooth = face_smooth[f1] & face_smooth[f2] & ~edge_sharp[e] & (count == 2)
    weld = (face_material[f1] == face_material[f2]) & (smooth | coplanar)
    l1, l2 = l1[weld], l2[weld]
    same = loop_vert[l1] == loop_vert[l2]
    i = np.concatenate([l1, nxt[l1]])
    j = np.concatenate([np.where(same, l2, nxt[l2]), np.where(same, nxt[l2], l2)])
    ok = loop_vert[i] == loop_vert[j]          # guards degenerate faces
    lab = _union(L, i[ok], j[ok])
    uniq, first_loop, corner_vertex = np.unique(lab, return_index=True, return_inverse=True)
    return corner_vertex.reshape(-1), loop_vert[first_loop]


# ----------------------------------------------------------------------------- objects
def _layer(me, name, n, dtype, key="value"):
    """Attribute ``name`` of ``me`` as (n,) ``dtype``, or None when the mesh has no such layer. An
    attribute's ``foreach_get`` copies its array in one go (about 50 times faster than the same
    values through ``me.loops`` / ``me.polygons`` / ``me.edges``, which go item by item)."""
    a = me.attributes.get(name)
    if a is None or len(a.data) != n:
        return None
    out = np.empty(n, dtype)
    a.data.foreach_get(key, out)
    return out


def _get(coll, prop, n, dtype):
    out = np.empty(n, dtype)
    if n:
        coll.foreach_get(prop, out)
    return out


def _mesh_arrays(me):
    """(positions, loop vertex, loop edge, face loop start, face loop count, material index, smooth,
    sharp edge) of an evaluated mesh, from its attribute layers (Blender 4+: '.corner_vert',
    '.corner_edge', 'material_index', 'sharp_face', 'sharp_edge'; an absent layer is its default,
    0 or False), falling back to the item properties."""
    nv, nl, nf, ne = len(me.vertices), len(me.loops), len(me.polygons), len(me.edges)
    co = _get(me.vertices, "co", nv * 3, np.float32)
    lv = _layer(me, ".corner_vert", nl, np.int32)
    lv = _get(me.loops, "vertex_index", nl, np.int32) if lv is None else lv
    le = _layer(me, ".corner_edge", nl, np.int32)
    le = _get(me.loops, "edge_index", nl, np.int32) if le is None else le
    ps = _get(me.polygons, "loop_start", nf, np.int32)
    pt = _get(me.polygons, "loop_total", nf, np.int32)
    mi = _layer(me, "material_index", nf, np.int32)
    mi = np.zeros(nf, np.int32) if mi is None else mi
    sharp_face = _layer(me, "sharp_face", nf, bool)
    sm = np.ones(nf, bool) if sharp_face is None else ~sharp_face
    sh = _layer(me, "sharp_edge", ne, bool)
    sh = np.zeros(ne, bool) if sh is None else sh
    return (co.reshape(-1, 3).astype(np.float64), lv.astype(np.int64), le.astype(np.int64),
            ps.astype(np.int64), pt.astype(np.int64), mi.astype(np.int64), sm, sh)


def corner_normals(me, smooth):
    """(L, 3) float64 Blender's normal at every corner (loop) of an evaluated mesh, in its local
    space: what Cycles shades with (smooth faces, custom normals); None where every face is flat
    and there are no custom normals (the faces' own normals say it all) or this Blender has no
    ``corner_normals``."""
    if not (np.any(smooth) or getattr(me, "has_custom_normals", False)) or not hasattr(me, "corner_normals"):
        return None
    n = np.empty(len(me.loops) * 3, np.float32)
    if len(n):
        me.corner_normals.foreach_get("vector", n)
    return n.reshape(-1, 3).astype(np.float64)


def mesh_corner_normals(me) -> np.ndarray:
    """(L, 3) the normal Cycles shades every corner of mesh ``me`` with, in its local space
    (:func:`.split_normals.cycles_corner_normals` of its own arrays): a lightmap's texels."""
    _, lv, le, ps, pt, _, sm, sh = _mesh_arrays(me)
    n = np.empty(len(me.loops) * 3)
    if len(n):
        me.corner_normals.foreach_get("vector", n)
    return cycles_corner_normals(me, n.reshape(-1, 3), lv, le, ps, pt, sm, sh)


def _normals_in_world(n, M):
    """Unit normals ``n`` (L, 3) in local space carried to world space by ``M`` (4, 4): the inverse
    transpose, so they stay on the side of the surface they were on (a mirror included)."""
    w = np.asarray(n, dtype=np.float64) @ inverse(np.asarray(M, dtype=np.float64)[:3, :3])
    length = np.linalg.norm(w, axis=1, keepdims=True)
    return np.divide(w, length, out=np.zeros_like(w), where=length > 0)


_IN_WORLD = Memo(PER_MESH)       # (corner normals, corner loops), matrix -> the world's, read only


def _world_corner_normals(cn, M, corner_loop):
    """``_normals_in_world(cn, M)[corner_loop]``, made once per pair of arrays (a relight reads
    the same ones: :func:`.split_normals.cycles_corner_normals` and :func:`_welded` keep them)
    and matrix: the same read-only array, which what the bake keys on it finds again."""
    M = np.asarray(M, dtype=np.float64)

    def make():
        return frozen(_normals_in_world(cn, M)[corner_loop])
    if cn.flags.writeable or corner_loop.flags.writeable:     # may change in place: made every time
        return _normals_in_world(cn, M)[corner_loop]
    return _IN_WORLD.of((cn, corner_loop), make, M.tobytes())


def _newell(verts, corner_vertex, poly_start, poly_total):
    """(unit face normals (F,3), face areas (F,)) from world-space corners. Taken relative to each
    face's first corner (no cancellation far from the origin): for a triangle and a quad the area
    is the core's own (half the cross product of the sides, of the diagonals), for an n-gon its
    area projected on its mean plane."""
    L = corner_vertex.size
    loop_face = np.repeat(np.arange(poly_start.size), poly_total)
    pos = np.arange(L) - poly_start[loop_face]
    nxt = np.where(pos == poly_total[loop_face] - 1, poly_start[loop_face], np.arange(L) + 1)
    origin = verts[corner_vertex[poly_start]][loop_face]
    a, b = verts[corner_vertex] - origin, verts[corner_vertex[nxt]] - origin
    n = np.add.reduceat(np.cross(a, b), poly_start, axis=0) if L else np.zeros((0, 3))
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, ln, out=np.zeros_like(n), where=ln > 0), 0.5 * ln[:, 0]


def _within_faces(corner, offsets, per_face):
    """``corner`` where it varies within a face (a texture), else None (the faces say it all)."""
    if corner is None or not len(per_face):
        return None
    spread = np.abs(corner - np.repeat(per_face, np.diff(offsets), axis=0)).max()
    return corner if spread > 1e-6 else None


def material_ids(mats) -> np.ndarray:
    """(S,) int64 an id per material slot, the same for one material in every object (its
    name's CRC-32; an empty slot, Blender's default surface, is 0): which faces may be grouped
    into one patch (:func:`core.mesh.clusters.piece_materials`)."""
    return np.array([zlib.crc32(m.name_full.encode()) if m is not None else 0 for m in mats], np.int64)


def _in_world(obj, depsgraph, co, lv):
    """(verts_w (V, 3) world positions, used (V,) bool vertices a face uses, M (4, 4) the world
    matrix, flipped: M mirrors) of an object's vertices ``co`` (V, 3) used by the corners ``lv``;
    :class:`ReadError` for positions or a transform that are not finite, or a zero scale. ``co``
    is changed: unused vertices are set to 0 (a NaN there must not spread)."""
    used = np.zeros(len(co), bool)
    used[lv] = True
    bad = np.flatnonzero(used & ~np.all(np.isfinite(co), axis=1))
    if bad.size:
        raise ReadError(f"'{obj.name}': {bad.size} vertex position(s) are not finite (NaN or "
                        f"infinity), first vertex {int(bad[0])}: fix or delete them")
    M = world_matrix(obj, depsgraph)
    if not np.all(np.isfinite(M)):
        raise ReadError(f"'{obj.name}': its transform is not finite (NaN or infinity in location, "
                        "rotation or scale)")
    co[~used] = 0.0      # loose vertices are not read; a NaN there must not spread
    det = float(np.linalg.det(M[:3, :3]))
    if abs(det) < 1e-300:
        raise ReadError(f"'{obj.name}' has a zero scale; nothing to bake")
    return co @ M[:3, :3].T + M[:3, 3], used, M, det < 0


_WELDED = Memo(PER_MESH)       # digest of a mesh's arrays in world space -> _welded's (a relight reads them again)


def _welded(verts_w, used, flipped, lv, le, ps, pt, mi, sm, sh):
    """(face normals (F, 3), areas (F,), the used vertices' extent (3,), corner vertex (L,),
    source vertex (V',), face offsets (F + 1,), each corner's loop (L,), the mesh's vertices
    (V', 3) and face indices (L,)) of a mesh's world positions and arrays (:func:`_newell`,
    :func:`weld_corners`), kept for the last meshes read by their arrays' values: a relight
    reads the same meshes again and gets the same arrays (read only), so what the bake keys on
    them is found without hashing them again."""
    import hashlib

    h = hashlib.sha256(b"flipped" if flipped else b"")
    for a in (verts_w, used, lv, le, ps, pt, mi, sm, sh):
        h.update(str((a.dtype, a.shape)).encode() + np.ascontiguousarray(a).tobytes())

    def make():
        normals, areas = _newell(verts_w, lv, ps, pt)
        normals *= -1.0 if flipped else 1.0
        corner_vertex, src_vertex = weld_corners(lv, le, ps, pt, mi, sm, sh, normals)
        # face rings in face order; reversed per face when the matrix mirrors
        loop_face = np.repeat(np.arange(ps.size), pt)
        pos = np.arange(lv.size) - ps[loop_face]
        corner_loop = ps[loop_face] + (pt[loop_face] - 1 - pos if flipped else pos)
        return frozen(normals, areas, np.ptp(verts_w[used], axis=0), corner_vertex, src_vertex,
                      np.concatenate([[0], np.cumsum(pt)]), corner_loop, verts_w[src_vertex],
                      corner_vertex[corner_loop])
    return _WELDED.get(h.digest(), make)


def read_object(obj, depsgraph, bake=True, shaded=None) -> ObjectSource:
    """One mesh object, evaluated (modifiers applied), in world space. ``shaded``: the
    :func:`.shading.shade` batch that holds this object's Cycles evaluations (None: evaluate this
    object alone)."""
    if obj.type not in GEOMETRY_TYPES:
        raise ReadError(f"'{obj.name}' is not a mesh object (it is a {obj.type.lower()})")
    ob_eval = obj.evaluated_get(depsgraph)
    me = ob_eval.to_mesh()
    if me is None:
        raise ReadError(f"'{obj.name}' has no faces: Blender gives no mesh for this "
                        f"{_TYPE_NAMES.get(obj.type, 'object')}")
    try:
        co, lv, le, ps, pt, mi, sm, sh = _mesh_arrays(me)
        counts = (len(me.vertices), len(me.loops), len(me.polygons))
        cn = cycles_corner_normals(me, corner_normals(me, sm), lv, le, ps, pt, sm, sh)
        tris = bent_ngon_triangles(me, co, lv, ps, pt)
        mats = [s.material for s in ob_eval.material_slots] or [None]
        per_slot, see_notes = material_transmit(mats, me, _caustics(depsgraph))
    finally:
        ob_eval.to_mesh_clear()
    if ps.size == 0:
        raise ReadError(f"'{obj.name}' has no faces" + _no_faces_why(obj))
    verts_w, used, M, flipped = _in_world(obj, depsgraph, co, lv)
    mi = np.clip(mi, 0, len(mats) - 1)
    normals, areas, span, corner_vertex, src_vertex, offsets, corner_loop, verts, indices = _welded(
        verts_w, used, flipped, lv, le, ps, pt, mi, sm, sh)
    if not np.any(areas > ZERO_AREA * float(span @ span)):
        raise ReadError(f"'{obj.name}': every face has zero area")
    loop_face = np.repeat(np.arange(ps.size), pt)
    if shaded is None:
        shaded = shading.shade([obj], depsgraph)
    notes = render_notes(obj, ob_eval)
    corner_rho, corner_em, corner_glossy, mat_notes = corner_materials(
        obj.name, mats, mi[loop_face], corner_loop, shaded, set(np.unique(mi).tolist()))
    notes += [s for s in mat_notes + see_notes if s not in notes]
    rho = np.add.reduceat(corner_rho, offsets[:-1], axis=0) / pt[:, None]
    em = np.add.reduceat(corner_em, offsets[:-1], axis=0) / pt[:, None]
    em = face_means(shaded, obj.name, em, corner_loop, offsets, mats, mi)   # emission over the face
    glossy = np.add.reduceat(corner_glossy, offsets[:-1], axis=0) / pt[:, None]
    mesh = MeshInput(verts, offsets, indices, rho, em, obj.name,
                     _within_faces(corner_rho, offsets, rho), _within_faces(corner_em, offsets, em),
                     material_ids(mats)[mi],
                     corner_normal=None if cn is None else _world_corner_normals(cn, M, corner_loop),
                     face_triangles=reversed_rings(tris, pt) if flipped else tris,
                     face_glossy=glossy if np.any(glossy > 0) else None,
                     transmit=mesh_transmit(per_slot, mi, mi[loop_face], corner_loop))
    if mesh.transmit is not None:
        notes.append(see_through_note(obj.name))
        mesh.face_rho = solve_rho(rho, corner_rho, mesh.transmit, offsets)
    return ObjectSource(obj.name, mesh, corner_loop, M, flipped, bake, counts, notes,
                        corner_rho, corner_em)


def read_scene(depsgraph, objects, others=(), instancers=(), cache=None) -> SceneInput:
    """``objects`` are baked; ``others`` take part as occluders/emitters only, and so do the
    instances (:mod:`.instances`) of the instancers named in ``instancers`` (None: of every
    instancer the render shows). The materials that Cycles must evaluate are evaluated for all of
    them in one batch (:func:`.shading.shade`; ``cache``: the bake's cache, whose folder keeps
    those evaluations too).

    An object that cannot be baked (no faces, every face of zero area, positions or transform
    not finite, a zero scale: :func:`read_object`'s :class:`ReadError`) is left out with one note
    naming it and why, and the rest bakes: one broken object must not stop a scene of hundreds.
    An instancer without faces of its own (an Empty, a Geometry Nodes object that only makes
    instances) is no problem: its instances take part. Only when none of ``objects`` is left is
    the bake refused, with that object's own line (or one line naming them all)."""
    protos, made = inst_reader.gather(depsgraph, instancers)
    try:
        protos_obs = [p.ob for p in protos]
        shaded = shading.shade(list(objects) + list(others) + protos_obs, depsgraph, cache)
        out, skipped, problems, only_instancing = [], [], [], []
        for o in objects:
            try:
                out.append(read_object(o, depsgraph, True, shaded))
            except ReadError as ex:
                if o.name in made and _faceless(o, depsgraph):
                    only_instancing.append(o.name)
                    continue
                problems.append(str(ex))
                skipped.append(f"{ex}; left out")
        if objects and not out:
            if not problems:
                raise ReadError(instancers_only(only_instancing))
            raise ReadError(problems[0] if len(problems) == 1 else _none_bakeable(problems))
        for o in others:
            try:
                out.append(read_object(o, depsgraph, False, shaded))
            except ReadError:
                continue  # an occluder without faces simply does not occlude
        placed, counts, emits, inst_notes = _place_instances(protos, depsgraph, shaded)
        out += placed
    finally:
        inst_reader.remove(protos)
    said = inst_reader.note(counts, emits)
    said = [Note(said, None, said)] if said else []
    said += [Note(n, None, n, warning=True, topic="scene") for n in inst_reader.unread(depsgraph, made, instancers)]
    return SceneInput(out, skipped=skipped, instanced=said + inst_notes)


def instancers_only(names):
    """The line refusing a selection of nothing but instancers (``names``)."""
    listed = ", ".join(f"'{n}'" for n in names[:3]) + (f" and {len(names) - 3} more" if len(names) > 3 else "")
    return (f"{listed} only make{'s' if len(names) == 1 else ''} instances, which take part as "
            "occluders and reflectors but are not baked: select the meshes to bake as well")


def _faceless(obj, depsgraph):
    """True when the evaluated mesh of ``obj`` has no faces of its own."""
    if obj.type != "MESH":
        return False
    ob_eval = obj.evaluated_get(depsgraph)
    return ob_eval.data is None or len(ob_eval.data.polygons) == 0


def _place_instances(protos, depsgraph, shaded):
    """(sources, {instancer: instances placed}, any emits, notes) of the instance prototypes: each read
    once at the identity, then one :class:`ObjectSource` (``bake`` False) per matrix, named after
    its instancer ("Scatter [instance 3]"). A prototype that cannot be read (no faces) or an
    instance of zero scale takes no part."""
    out, counts, emits, notes = [], {}, False, []
    for p in protos:
        try:
            src = read_object(p.ob, depsgraph, False, shaded)
        except ReadError:
            continue
        emits |= bool(np.any(src.mesh.face_emission > 0))
        subject = f"instances of '{p.source}'"
        notes += [n if isinstance(n, Note) and n.subject is not None
                  else note(subject, *((n.kind, n.warning) if isinstance(n, Note) else (n,)))
                  for n in src.notes]
        for M, par in zip(p.matrices, p.instancers):
            if not np.all(np.isfinite(M)) or abs(float(np.linalg.det(M[:3, :3]))) < 1e-300:
                continue
            counts[par] = counts.get(par, 0) + 1
            out.append(_placed(src, M, f"{par} [instance {counts[par]}]"))
    return out, counts, emits, notes


_PLACED = Memo(PER_MESH)     # a prototype's arrays, an instance's matrix -> its placed geometry


def _placed(src, M, name):
    """A copy of ``src`` (read at the identity) placed by the world matrix ``M``; a mirroring
    matrix reverses every face's ring so faces stay counter-clockwise seen from the front."""
    m = src.mesh
    flipped = float(np.linalg.det(M[:3, :3])) < 0
    L = m.face_indices.size
    if flipped:
        counts = np.diff(m.face_offsets)
        face = np.repeat(np.arange(counts.size), counts)
        start = m.face_offsets[:-1][face]
        perm = start + (counts[face] - 1 - (np.arange(L) - start))
    else:
        perm = np.arange(L)

    def corners(a):
        return None if a is None else a[perm]

    def geometry():
        # read only, as a read mesh's arrays
        return frozen(m.verts @ M[:3, :3].T + M[:3, 3], m.face_indices[perm],
                      None if m.corner_normal is None else _normals_in_world(m.corner_normal[perm], M))
    held = (m.verts, m.face_indices, m.face_offsets, m.corner_normal)
    # a relight places the same prototype's arrays again: the same arrays, so what the bake keys
    # on them (face spans, the meshes' key) is found, not made for every instance again
    verts, indices, normals = _PLACED.of(held, geometry, np.asarray(M, dtype=np.float64).tobytes()) \
        if all(a is None or not a.flags.writeable for a in held) else geometry()

    mesh = MeshInput(verts, m.face_offsets, indices, m.face_rho, m.face_emission, name,
                     corners(m.corner_rho), corners(m.corner_emission), m.face_material,
                     corner_normal=normals,
                     face_triangles=reversed_rings(m.face_triangles, np.diff(m.face_offsets)) if flipped
                     else m.face_triangles, face_glossy=m.face_glossy,
                     transmit=_placed_transmit(m.transmit, perm))
    return ObjectSource(name, mesh, src.corner_loop[perm], M, flipped, False, src.eval_counts, [],
                        corners(src.corner_rho), corners(src.corner_emission))


def _none_bakeable(problems, shown=3):
    """One line for a selection of which no object can be baked."""
    more = len(problems) - shown
    return (f"none of the {len(problems)} selected objects can be baked: " + "; ".join(problems[:shown])
            + (f"; and {more} more" if more > 0 else ""))


def _no_faces_why(obj):
    """Why a non-mesh object evaluated to no faces, for its error line or note."""
    if obj.type in ("CURVE", "FONT"):
        return " (a curve without bevel, extrusion or fill makes no surface)" if obj.type == "CURVE" else ""
    if obj.type == "META":
        return " (a metaball's surface belongs to its family's base object, the one without a number)"
    return ""


def check_writable(objects, settings):
    """Raise :class:`ReadError` naming the object when the bake's result could not be written
    the way ``settings`` asks, before any work (so a refused bake changes nothing); returns the
    notes to add (an existing colour attribute replaced in place)."""
    name = settings.attribute_name
    if not name.strip():
        raise ReadError("the attribute name is empty: give the colour attribute a name")
    if name.startswith(".") or name in _RESERVED_ATTRIBUTES:
        raise ReadError(f"the attribute name '{name}' is one Blender keeps for itself; choose another")
    notes = []
    if settings.output_mode != "in_place":
        return notes
    for ob in objects:
        if ob.type != "MESH":
            raise ReadError(f"'{ob.name}' is a {_TYPE_NAMES.get(ob.type, ob.type.lower())} object: "
                            "in place writes to a mesh; bake it as a copy (Output: Baked Copy)")
        lib = ob.library or ob.data.library
        if lib is not None or ob.override_library is not None:
            where = f" from library '{lib.name}'" if lib is not None else " (a library override)"
            raise ReadError(f"'{ob.name}' is linked{where}, read-only here: bake it as a copy "
                            "(Output: Baked Copy), or make it local to bake in place")
        me = ob.data
        attr = me.attributes.get(name)
        if attr is None:
            continue
        if me.color_attributes.get(name) is None:
            raise ReadError(f"mesh '{me.name}' of '{ob.name}' already has a non-colour attribute "
                            f"named '{name}' ({attr.data_type} on {attr.domain.lower()}s): choose "
                            "another attribute name, or rename or remove it")
        if (attr.data_type, attr.domain) != ("FLOAT_COLOR", "CORNER"):
            notes.append(f"{ob.name}: its colour attribute '{name}' ({attr.data_type} on "
                         f"{attr.domain.lower()}s) is replaced by the bake's (FLOAT_COLOR on corners)")
    return notes


def _caustics(depsgraph) -> bool:
    """Whether the scene's Cycles follows refractive caustics (glass passes light there)."""
    cy = getattr(depsgraph.scene, "cycles", None)
    return bool(getattr(cy, "caustics_refractive", False))


def _placed_transmit(tr, perm):
    """An instance's see-through faces: the prototype's, its corners' UVs in ``perm`` order."""
    if tr is None or tr.corner_uv is None:
        return tr
    from dataclasses import replace

    return replace(tr, corner_uv=tr.corner_uv[perm])
