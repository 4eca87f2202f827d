# SPDX-License-Identifier: GPL-3.0-or-later
"""A folded n-gon is the surface Cycles renders: its own loop triangles (core/mesh/ngons.py,
blender/read/ngon_triangles.py), compared with Cycles' bake at its own corners.

A 10-gon crown (corners on a circle of 1 m, alternately 10 cm above and below 0.8 m) over a
floor, under a sun of angle 0 (a hard, deterministic shadow). Cut about its centre, as the core
cuts a convex n-gon, it was another surface with another shadow: floor corners in the sun that
Cycles has in the crown's shadow, and the other way round.

Run ``python -m tests.blender.test_bent_ngons`` to print the figures."""
from __future__ import annotations

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tools import cycles_reference as cr  # noqa: E402
from hemicube_radiosity.blender.read import scene as reader  # noqa: E402
from hemicube_radiosity.blender.read.lights import read_lights  # noqa: E402
from hemicube_radiosity.core.mesh.subdivide import build_patches  # noqa: E402
from hemicube_radiosity.core.pipeline import BakeSettings, bake  # noqa: E402
from tests.support.cycles_scenes import RHO, SETTINGS, floor_object  # noqa: E402

pytestmark = [pytest.mark.blender, pytest.mark.cycles]

ZEN = math.radians(60.0)          # the sun's zenith angle, from +x
SUNLIT = RHO * 3.0 * math.cos(ZEN) / math.pi      # a sunlit floor corner's direct light, 0.382


def _crown(name="crown", h=0.1, z0=0.8):
    a = 2 * np.pi * np.arange(10) / 10
    v = np.column_stack([np.cos(a), np.sin(a), z0 + h * np.where(np.arange(10) % 2, 1.0, -1.0)])
    return cr.mesh_object(v, [list(range(10))], cr.diffuse_material((RHO,) * 3), name)


def _world_triangles(ob):
    """Blender's loop triangles of ``ob`` in world space, (T, 3, 3), counter-clockwise seen
    from the front of the face (the corner order reversed under a mirroring matrix)."""
    me = ob.data
    M = np.array(ob.matrix_world)
    co = np.array([v.co[:] for v in me.vertices]) @ M[:3, :3].T + M[:3, 3]
    tris = np.array([t.vertices[:] for t in me.loop_triangles])
    return co[tris[:, ::-1] if np.linalg.det(M[:3, :3]) < 0 else tris]


def _same_triangles(patches, owner, want):
    """True when the patches of ``owner`` are the triangles ``want`` (T, 3, 3), each once, with
    its corners in the same cyclic order (so facing the same way)."""
    got = [patches.verts[p[:3]] for p, k in zip(patches.polys, patches.owner) if k == owner and p[3] < 0]
    if len(got) != (patches.owner == owner).sum() or len(got) != len(want):
        return False
    left = list(want)
    for g in got:
        hit = [i for i, w in enumerate(left) if any(np.allclose(np.roll(g, s, 0), w, atol=1e-6) for s in range(3))]
        if len(hit) != 1:
            return False
        left.pop(hit[0])
    return not left


def _at_corners(r, objects):
    """{name: (L, 3)} our vertex radiosity at every corner (loop) of ``objects``: the patch
    vertex of the corner's own face nearest to the corner."""
    P = r.patches
    out = {}
    for k, ob in enumerate(objects):
        me = ob.data
        co = np.array([v.co[:] for v in me.vertices]) @ np.array(ob.matrix_world)[:3, :3].T
        vals = np.empty((len(me.loops), 3))
        for p in me.polygons:
            vs = np.unique(P.polys[(P.owner == k) & (P.source_face == p.index)])
            vs = vs[vs >= 0]
            for corner in range(p.loop_start, p.loop_start + p.loop_total):
                x = co[me.loops[corner].vertex_index]
                vals[corner] = r.vertex_radiosity[vs[np.argmin(np.linalg.norm(P.verts[vs] - x, axis=1))]]
        out[ob.name] = vals
    return out


def crown_case(samples=64):
    """(Cycles, ours, ours cut about the centre) at the floor's corners (band means), and our
    patches."""
    cr.new_empty_scene()
    fl = floor_object(40, 2.0)
    crown = _crown()
    cr.add_light("SUN", (0, 0, 5), (ZEN, 0, math.pi / 2), energy=3.0, angle=0.0)
    ref = cr.bake_vertex_radiance([fl, crown], samples=samples)
    dg = bpy.context.evaluated_depsgraph_get()
    meshes = reader.read_scene(dg, [fl, crown]).meshes
    lights, world, _ = read_lights(dg)
    r = bake(meshes, BakeSettings(**SETTINGS), lights=lights, world=world)
    ours = _at_corners(r, [fl, crown])["floor"].mean(axis=1)
    given = meshes[1].face_triangles
    for m in meshes:
        m.face_triangles = None
    fan = _at_corners(bake(meshes, BakeSettings(**SETTINGS), lights=lights, world=world), [fl, crown])["floor"]
    return ref.corner["floor"].mean(axis=1), ours, fan.mean(axis=1), r.patches, given, _world_triangles(crown)


def test_a_folded_10_gon_shadows_the_floor_as_in_cycles():
    """Our crown's patches are Blender's 8 loop triangles, corner for corner. On the floor, the
    corners where the two cuts' shadows differ (12, by more than 0.05) are within 0.01 of
    Cycles (measured 0.0033 at most: Cycles' 64 samples of the bounce light); cut about its
    centre they were the whole sun off (0.378 to 0.383; the sun alone gives 0.382). Over all
    floor corners the largest difference is 0.045 (on the crown's outline's shadow), 0.383
    before."""
    cycles, ours, fan, patches, given, tris = crown_case()
    assert given is not None and len(given) == 8
    assert _same_triangles(patches, 1, tris)
    moved = np.abs(fan - ours) > 0.05
    assert moved.sum() >= 10, moved.sum()
    assert np.abs(ours - cycles)[moved].max() < 0.01
    assert np.abs(fan - cycles)[moved].min() > 0.9 * SUNLIT
    assert np.abs(ours - cycles).max() < 0.06 < np.abs(fan - cycles).max()


def test_a_mirrored_or_planar_ngon_is_cut_as_blender_or_as_before():
    """Under a negative scale (its rings reversed by the reader) the crown's patches are still
    Blender's triangles in world space, facing as its face does; a planar 10-gon gets no
    triangles and keeps the cut about its centre (10 quads). Read twice, the crown's triangles are
    the same read-only rows."""
    cr.new_empty_scene()
    crown = _crown()
    crown.scale = (-1.0, 1.0, 1.0)
    crown.location = (3.0, 0.0, 0.0)
    flat = _crown("flat", h=0.0)
    dg = bpy.context.evaluated_depsgraph_get()
    meshes = reader.read_scene(dg, [crown, flat]).meshes
    assert meshes[1].face_triangles is None
    # read again (a relight): the same read-only rows, which what is kept per mesh keys on
    again = reader.read_scene(dg, [crown, flat]).meshes
    assert again[0].face_triangles is meshes[0].face_triangles
    assert not meshes[0].face_triangles.flags.writeable
    P = build_patches(meshes, None)
    assert _same_triangles(P, 0, _world_triangles(crown))
    assert np.all(P.normals[P.owner == 0] @ [0.0, 0.0, 1.0] > 0.5)     # mirrored in x: still up
    assert (P.owner == 1).sum() == 10 and np.all(P.polys[P.owner == 1, 3] >= 0)


if __name__ == "__main__":
    cycles, ours, fan, patches, given, tris = crown_case()
    moved = np.abs(fan - ours) > 0.05
    print(f"floor corners moved {moved.sum()}: |ours - Cycles| max {np.abs(ours - cycles)[moved].max():.4f}, "
          f"centre cut min {np.abs(fan - cycles)[moved].min():.4f} max {np.abs(fan - cycles)[moved].max():.4f}")
    print(f"all floor corners: |ours - Cycles| max {np.abs(ours - cycles).max():.4f} mean "
          f"{np.abs(ours - cycles).mean():.4f}; centre cut max {np.abs(fan - cycles).max():.4f} mean "
          f"{np.abs(fan - cycles).mean():.4f}")
    import os
    os._exit(0)
