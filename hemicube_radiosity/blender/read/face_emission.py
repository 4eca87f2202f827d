# SPDX-License-Identifier: GPL-3.0-or-later
"""An emitting face's mean emission over its area, by Cycles (Blender glue only).

The corner bake (:mod:`.shading`) gives the emission at a face's corners, which is what an
emitter's light is made of if nothing else is known: a TV whose emissive image has a black
frame a few pixels wide then emits nothing (its four corners are black), and a lamp shade
whose texture is bright in the middle emits its border's light. The solve and the direct light
take one emitted radiance per face (``MeshInput.face_emission``), so that value is taken here as
the face's mean over its area instead.

How: a temporary copy of each baked mesh whose materials emit through nodes has its n-gons
triangulated, every face cut into an (n + 1) x (n + 1) grid (``bmesh.ops.subdivide_edges`` with grid
fill: quads into quads, triangles into triangles) and each small face **poked** (``bmesh.ops.poke``:
a vertex at its centre). Blender interpolates UVs and every corner attribute at the new vertices
and the new faces keep the face's attributes, so Cycles' EMIT vertex bake gives the emission at
those centres: the midpoint rule of the grid, each centre weighted by its small face's area. n
follows a budget of ``SAMPLES`` points per mesh (63 on a single quad, a 64 x 64 grid; 0 on a mesh
of ``SAMPLES`` faces or more: one point at each face's centre). The copy has the same world
matrix, bounds and texture space as the corner bake's copy, so object-space textures read alike.
Measured: a quad TV whose 64 x 64 image has a 3-pixel black frame emits its image's mean exactly
(its corners: 0).
"""
from __future__ import annotations

import numpy as np

__all__ = ["SAMPLES", "grid_cuts", "sample_faces", "face_means"]

FACE = "_hr_face"     # INT face attribute: the run mesh's polygon that a poked face comes from
SAMPLES = 65536       # sample points per mesh at most (but one per face at least)
MAX_CUTS = 63


def grid_cuts(faces):
    """n: each of ``faces`` faces is cut into an (n + 1) x (n + 1) grid for the sample budget."""
    return int(min(MAX_CUTS, max(0, int(np.sqrt(SAMPLES / max(faces, 1))) - 1)))


def _poked_copy(me, cuts):
    """A copy of mesh ``me``, its n-gons triangulated, every face cut into a grid of (cuts + 1)²
    and each small face poked; returns (mesh, index of the first vertex the poke made)."""
    import bmesh
    import bpy

    bm = bmesh.new()
    try:
        bm.from_mesh(me)
        lay = bm.faces.layers.int.new(FACE)
        for i, f in enumerate(bm.faces):
            f[lay] = i
        ngons = [f for f in bm.faces if len(f.verts) > 4]
        if ngons:
            bmesh.ops.triangulate(bm, faces=ngons)
        if cuts:
            bmesh.ops.subdivide_edges(bm, edges=bm.edges[:], cuts=cuts, use_grid_fill=True)
        first = len(bm.verts)
        bmesh.ops.poke(bm, faces=bm.faces[:])
        out = bpy.data.meshes.new(me.name + "_hr_poked")
        bm.to_mesh(out)
    finally:
        bm.free()
    for m in me.materials:
        out.materials.append(m)
    out.use_auto_texspace = False         # the poked faces lie inside the original's bounds, but
    out.texspace_location = me.texspace_location    # keep Generated coordinates identical anyway
    out.texspace_size = me.texspace_size
    return out, first


def _samples(me, first):
    """(face (S,) the run polygon of each sample, weight (S,) its triangle's area, loop (S,) one
    corner of it) for the vertices from index ``first`` on of poked mesh ``me``."""
    nl, nf = len(me.loops), len(me.polygons)
    lv = np.empty(nl, np.int64)
    me.loops.foreach_get("vertex_index", lv)
    ps = np.empty(nf, np.int64)
    me.polygons.foreach_get("loop_start", ps)
    pt = np.empty(nf, np.int64)
    me.polygons.foreach_get("loop_total", pt)
    area = np.empty(nf)
    me.polygons.foreach_get("area", area)
    src = np.empty(nf, np.int32)
    me.attributes[FACE].data.foreach_get("value", src)
    loop_face = np.repeat(np.arange(nf), pt)
    sel = np.flatnonzero(lv >= first)
    v = lv[sel] - first
    S = int(v.max()) + 1 if v.size else 0
    weight = np.bincount(v, weights=area[loop_face[sel]], minlength=S)
    loop = np.zeros(S, np.int64)
    loop[v] = sel
    face = src[loop_face[loop]].astype(np.int64)
    return face, weight, loop


def sample_faces(scene, runs, emitting, bake, prepare, made_obs, made_meshes, attribute):
    """{run index: (P,) -> (P, 3) mean emission per polygon of the run's mesh} for the runs of
    :func:`.shading.evaluate` whose mesh has a material in ``emitting`` (material name_full),
    from one EMIT bake of poked copies linked in ``scene``. ``bake`` / ``prepare``: shading's
    ``_bake`` and ``_prepare_bake``, ``attribute`` the colour attribute they bake into; the
    copies are appended to ``made_obs`` / ``made_meshes``."""
    import bpy

    todo = [i for i, r in enumerate(runs) if r.names and any(
        m is not None and m.name_full in emitting for m in r.ob.data.materials)]
    if not todo:
        return {}
    copies = []
    for i in todo:
        me = runs[i].ob.data
        poked, first = _poked_copy(me, grid_cuts(len(me.polygons)))
        old = poked.color_attributes.get(attribute)   # the corner bake's, copied along
        if old is not None:
            poked.color_attributes.remove(old)
        made_meshes.append(poked)
        ob = bpy.data.objects.new("_hr_poked", poked)
        ob.matrix_world = runs[i].ob.matrix_world
        made_obs.append((None, ob))
        scene.collection.objects.link(ob)
        copies.append((i, ob, first, len(me.polygons)))
    obs = [ob for _, ob, _, _ in copies]
    for r in runs:                       # the corner bake's copies are not baked again
        r.ob.select_set(False, view_layer=scene.view_layers[0])
    prepare(scene, obs)
    values = bake(scene, obs, "EMIT", set())
    out = {}
    for (i, ob, first, P), val in zip(copies, values):
        face, weight, loop = _samples(ob.data, first)
        e = np.where(np.isfinite(val[loop]), val[loop], 0.0)
        w = np.bincount(face, weights=weight, minlength=P)
        mean = np.stack([np.bincount(face, weights=weight * e[:, k], minlength=P) for k in range(3)], 1)
        out[i] = np.divide(mean, w[:, None], out=np.zeros((P, 3)), where=w[:, None] > 0)
    return out


def face_means(shaded, name, em, corner_loop, offsets, mats, face_mat):
    """``em`` (F, 3), the faces' emission as their corners' mean, with the faces whose material
    emits through nodes given their mean over the face (``shaded.face_emission``) instead.
    ``corner_loop``: the evaluated-mesh loop of every ``mesh.face_indices`` corner, ``offsets``
    (F + 1,) the faces' corner offsets, ``mats`` the object's materials, ``face_mat`` (F,) each
    face's slot."""
    fe = shaded.face_emission.get(name)
    if fe is None or not len(em):
        return em
    slots = [k for k, m in enumerate(mats) if m is not None and m.original.name_full in shaded.sampled]
    mask = np.isin(face_mat, slots)
    if not mask.any():
        return em
    em = em.copy()
    em[mask] = np.maximum(fe[corner_loop[offsets[:-1]]][mask], 0.0)
    return em
