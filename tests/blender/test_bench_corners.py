# SPDX-License-Identifier: GPL-3.0-or-later
"""bench/real_scenes.py compares us with Cycles at Cycles' own face corners; a corner Cycles shades
on a triangle without area (``real_scenes.flat_bake_corners``) is no measurement of its face and is
left out. Blender's colour-attribute bake gives each corner the first loop triangle holding it; on
a triangle whose edges are parallel Cycles bakes at the triangle's third vertex with an undefined
geometric normal: the sky and bounced light drop out, and a flat-shaded face reads 0, one with
custom normals the sun alone through the third corner's normal (the living room's walls). Sun and
sky over lifted faces lit evenly: we read the face's light at every corner."""
from __future__ import annotations

import os
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.support import ROOT  # noqa: E402

for _p in (os.path.join(ROOT, "bench"), os.path.join(ROOT, "tools")):
    if _p not in sys.path:
        sys.path.insert(0, _p)

import real_scenes  # noqa: E402
from tools import cycles_reference as cr  # noqa: E402

pytestmark = [pytest.mark.blender, pytest.mark.cycles]


N = (0.75, -0.3, 0.59)       # the custom normal of every corner of "doubled" and "twin"
A, B = np.array([0.0, 0.81, 0.83]), np.array([-0.29, 0.0, 0.71])   # a wall leaning back, as


def _scene():
    """A floor, and 1 m over it: a quad with two corners at one place (its first loop triangle has
    no area) and custom normals ``N`` in a plane leaning back from x (the living room's wall face
    186 at 20 x its size), its twin in the same plane without the doubled corner, and a
    flat-shaded level quad with three corners in a line (its first loop triangle has no area);
    the bench's sun and sky: every lifted face lit the same all over."""
    cr.new_empty_scene()
    v, f = cr.grid_arrays(4, 4, -3.0, 3.0, -3.0, 3.0, 0.0)
    floor = cr.mesh_object(v, f, cr.diffuse_material((0.5,) * 3), "floor")
    m = cr.diffuse_material((0.8,) * 3)
    o = np.array([0.0, 0.0, 1.0])
    doubled = cr.mesh_object([o, o, o + A, o + B], [[0, 1, 2, 3]], m, "doubled")
    inline = cr.mesh_object([(-2, 0, 1), (-1.5, 0, 1), (-1, 0, 1), (-1.5, 1, 1)], [[0, 1, 2, 3]], m, "inline")
    o = np.array([1.5, -1.5, 1.0])
    g = np.arange(4) / 3.0
    idx = np.arange(16).reshape(4, 4)
    quads = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], -1).reshape(-1, 4)
    twin = cr.mesh_object([o + a * A + b * B for a in g for b in g], quads, m, "twin")   # 3 x 3 quads
    for ob in (doubled, twin):
        ob.data.normals_split_custom_set([N] * len(ob.data.loops))
    real_scenes.add_sun(bpy.context.scene)
    cr.set_world(real_scenes.SKY)
    return [floor, doubled, inline, twin]


def _ours(objs, pos, centroid, normal, own, face):
    from hemicube_radiosity.blender.bake import BakeJob
    from hemicube_radiosity.core.settings import BakeSettings

    job = BakeJob.prepare(bpy.context, objs, BakeSettings())
    job.run()
    r = job.result
    index = {n: i for i, n in enumerate(r.elements.object_names)}
    owner = np.array([index.get(objs[o].name, -1) for o in own])
    return real_scenes.values_at_corners(r.elements, r.corner_values(), pos, centroid, normal, owner, face)


def test_corners_cycles_bakes_on_a_triangle_without_area_are_left_out(tmp_path):
    objs = _scene()
    pos, centroid, normal, area, own, face, _ = real_scenes.corner_geometry(objs)
    flat = real_scenes.flat_bake_corners(objs)
    # both quads are split (0, 1, 2), (0, 2, 3): corners 0, 1, 2 of each are shaded on a triangle
    # without area, corner 3 on the other
    first = np.r_[0, np.flatnonzero(np.diff(own)) + 1][own]           # each object's first corner
    expect = np.isin(own, (1, 2)) & ((np.arange(len(own)) - first) % 4 != 3)
    assert expect.sum() == 6
    np.testing.assert_array_equal(flat, expect)

    ref = cr.bake_vertex_radiance(objs, samples=64, seed=1)
    cand = cr.bake_vertex_radiance(objs, samples=64, seed=2)
    R = np.concatenate([ref.corner[o.name] for o in objs])
    C = np.concatenate([cand.corner[o.name] for o in objs])
    lifted = own >= 1
    tilted, level = R[own == 3].mean(), R[(own == 2) & ~flat].mean()
    assert tilted > 0.5 and level > 0.5
    # Cycles: the face's light at the corners shaded on a triangle with area
    np.testing.assert_allclose(R[(own == 1) & ~flat].mean(axis=1), tilted, rtol=0.02)
    np.testing.assert_allclose(R[own == 3].mean(axis=1), tilted, rtol=0.02)
    # ... and at the others the sun alone through the third corner's normal, rho / pi E N.L (custom
    # normals; no sky, no bounce: 0.68 where the face has 1.04), or nothing (flat shading)
    el, az = np.radians(real_scenes.SUN_ELEVATION), np.radians(real_scenes.SUN_AZIMUTH)
    to_sun = np.array([np.sin(az) * np.cos(el), -np.cos(az) * np.cos(el), np.sin(el)])
    sun_alone = 0.8 / np.pi * real_scenes.SUN_STRENGTH * float(np.dot(N, to_sun) / np.linalg.norm(N))
    np.testing.assert_allclose(R[(own == 1) & flat].mean(axis=1), sun_alone, rtol=0.01)
    assert sun_alone < 0.8 * tilted
    assert np.all(R[(own == 2) & flat] == 0)

    vals, matched = _ours(objs, pos, centroid, normal, own, face)
    assert matched[lifted].all()
    # ours: the face's light at every corner, on a flat triangle or not
    np.testing.assert_allclose(vals[np.isin(own, (1, 3))].mean(axis=1), tilted, rtol=0.03)
    np.testing.assert_allclose(vals[own == 2].mean(axis=1), level, rtol=0.03)

    # the bench's error over the lifted faces: small with the flat corners left out, not with them in
    keep = dict(ref=R[lifted], cand=C[lifted], emit=np.zeros_like(R[lifted]), area=area[lifted], pos=pos[lifted],
                centroid=centroid[lifted], normal=normal[lifted], owner=own[lifted], face=face[lifted])
    np.savez(tmp_path / "out.npz", flat=flat[lifted], **keep)
    np.savez(tmp_path / "in.npz", **keep)
    left_out, _, n_out = real_scenes.compare(tmp_path / "out.npz", vals[lifted])
    kept_in, _, n_in = real_scenes.compare(tmp_path / "in.npz", vals[lifted])
    # (Cycles' zeros in the open are no geometry's doing: compared, as bench/dark_corners.py says)
    assert (n_out, n_in) == (lifted.sum() - 6, lifted.sum())
    assert left_out["rms_raw"] < 0.02             # 0.9%
    assert kept_in["rms_raw"] > 0.06              # 9.4%: three corners at 70% of the light
