# SPDX-License-Identifier: GPL-3.0-or-later
"""``core/output/texel_cover.py``: where a lightmap texel lies among its face's elements when the
nearest centres mislead (a bent face cut into slivers), and what covers it.

Truth by construction: a strip 3 cm wide and 42 cm long cut into sheared slivers 2 mm across (as
the living room's bevel strips are cut), a linear field on its vertices. The element holding a
point reads the field there exactly (linear interpolation of a linear field); a sliver a column
over reads it elsewhere."""
from __future__ import annotations

import numpy as np
import pytest

from hemicube_radiosity.core.mesh.patches import PatchSet
from hemicube_radiosity.core.output import lightmap as lm
from hemicube_radiosity.core.output.interpolate import interpolate_corner_values
from hemicube_radiosity.core.output.texel_cover import OFF, Cover
from hemicube_radiosity.core.rays import embree_available
from hemicube_radiosity.core.util.geometry import bilinear

pytestmark = pytest.mark.skipif(not embree_available(), reason="needs Embree")

ROWS, WIDTH, LENGTH, SHEAR = 15, 0.002, 0.42, 0.7


def slivers():
    """The strip's elements: row j spans y in [j, j + 1] * WIDTH, its corners shifted along x by
    SHEAR * y, cut into two triangles 42 cm long; one face (0) of object 0."""
    y = np.arange(ROWS + 1) * WIDTH
    left = np.stack([SHEAR * y, y, np.zeros_like(y)], 1)
    right = left + [LENGTH, 0.0, 0.0]
    verts = np.concatenate([left, right])
    R = ROWS + 1
    tris = []
    for j in range(ROWS):
        tris += [(j, R + j, j + 1, -1), (R + j, R + j + 1, j + 1, -1)]
    polys = np.array(tris, np.int64)
    c = verts[polys[:, :3]]
    n = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    areas = 0.5 * np.linalg.norm(n, axis=1)
    N = len(polys)
    return PatchSet(verts, polys, c.mean(1), n / (2 * areas)[:, None], areas, np.full((N, 3), 0.5),
                    np.zeros((N, 3)), np.zeros(N, np.int32), np.zeros(N, np.int32), ["strip"])


def test_relocate_finds_the_sliver_that_holds_each_point():
    el = slivers()
    rng = np.random.default_rng(3)
    t = rng.uniform(0.05, 0.95, 400)                        # along the strip
    s = rng.uniform(0.0, 1.0, 400) * ROWS * WIDTH           # across it
    points = np.stack([SHEAR * s + t * LENGTH, s, np.zeros_like(s)], 1)
    normals = np.tile([0.0, 0.0, 1.0], (len(points), 1))
    faces = np.zeros(len(points), np.int64)
    field = lambda x: 1.0 + 3.0 * x[..., 1] / (ROWS * WIDTH) + 0.5 * x[..., 0]       # linear
    corner = field(el.verts)[np.where(el.polys < 0, el.polys[:, 2:3], el.polys)][..., None]   # (N, 4, 1)
    idx, uv = lm.locate_texels(el, points, normals, 0, faces)
    off = np.linalg.norm(bilinear(el.corners()[idx], uv[:, :1], uv[:, 1:]) - points, axis=1)
    before = np.abs(interpolate_corner_values(corner, idx, uv)[:, 0] - field(points))
    # the nearest centres mislead: many points are read in a sliver that does not hold them
    assert (off > 1e-3).sum() > 20 and before.max() > 0.3
    idx2, uv2 = Cover(el, 0).relocate(points, normals, faces, idx, uv)
    off2 = np.linalg.norm(bilinear(el.corners()[idx2], uv2[:, :1], uv2[:, 1:]) - points, axis=1)
    after = np.abs(interpolate_corner_values(corner, idx2, uv2)[:, 0] - field(points))
    # every point lies in its element now, to OFF of the element's size (2 mm slivers: 20 microns)
    assert np.all(off2 <= OFF * np.sqrt(el.areas[idx2])) and after.max() < 0.005
    # the points located well keep their element and (u, v), bit for bit
    good = off <= OFF * np.sqrt(el.areas[idx])
    assert good.sum() > 100 and np.array_equal(idx2[good], idx[good]) and np.array_equal(uv2[good], uv[good])


def test_a_face_over_a_point_nearer_than_the_ray_offset_covers_it():
    # a 10 m floor (face 0) and a lid (face 1) over its middle: 0.05 mm over it covers it (the
    # object's ray offset: 1e-5 of its diagonal, 0.14 mm); half a float32 step over it (a
    # duplicate) does not, nor 1 mm over it (our rays start under it, as Cycles' do)
    def scene(gap):
        v = np.array([(0, 0, 0), (10, 0, 0), (10, 10, 0), (0, 10, 0),
                      (3, 3, gap), (7, 3, gap), (7, 7, gap), (3, 7, gap)], float)
        polys = np.array([(0, 1, 2, 3), (4, 5, 6, 7)], np.int64)
        c = v[polys]
        return PatchSet(v, polys, c.mean(1), np.tile([0.0, 0.0, 1.0], (2, 1)), np.array([100.0, 16.0]),
                        np.full((2, 3), 0.5), np.zeros((2, 3)), np.zeros(2, np.int32), np.array([0, 1], np.int32),
                        ["ground"])
    points = np.array([(5.0, 5.0, 0.0), (1.0, 1.0, 0.0), (6.9, 5.0, 0.0)])
    normals = np.tile([0.0, 0.0, 1.0], (3, 1))
    faces = np.zeros(3, np.int64)
    lift = Cover(scene(5e-5), 0).lifts(points, normals, faces)
    step = 2.0 ** -23 * 6.9                          # a float32 step of the largest coordinate
    assert np.isfinite(lift[[0, 2]]).all() and np.isnan(lift[1])
    assert np.allclose(lift[[0, 2]], 8 * 2.0 ** -23 * np.array([5.0, 6.9]))  # 8 steps, under half the gap
    assert np.isnan(Cover(scene(0.5 * step), 0).lifts(points, normals, faces)).all()   # a tie covers nothing
    assert np.isnan(Cover(scene(1e-3), 0).lifts(points, normals, faces)).all()         # over the offset


def test_a_lightmap_s_texels_read_their_own_sliver_s_reflected_light():
    # what texel_values reads (located_parts): with the cover, the field where each texel lies
    el = slivers()
    rng = np.random.default_rng(5)
    t, s = rng.uniform(0.05, 0.95, 300), rng.uniform(0.0, 1.0, 300) * ROWS * WIDTH
    points = np.stack([SHEAR * s + t * LENGTH, s, np.zeros_like(s)], 1)
    normals = np.tile([0.0, 0.0, 1.0], (len(points), 1))
    faces = np.zeros(len(points), np.int64)
    field = 1.0 + 3.0 * el.verts[:, 1] / (ROWS * WIDTH)
    I = np.repeat(field[np.where(el.polys < 0, el.polys[:, 2:3], el.polys)][..., None], 3, axis=2)
    parts = (np.zeros_like(I), np.full_like(I, 0.5), np.zeros_like(I), I)
    truth = 1.0 + 3.0 * s / (ROWS * WIDTH)
    without = lm.located_parts(el, parts, points, normals, 0, faces)[2][:, 0]
    with_ = lm.located_parts(el, parts, points, normals, 0, faces, cover=Cover(el, 0))[2][:, 0]
    assert np.abs(without - truth).max() > 0.3          # measured 1.42: a sliver 1 cm across the strip
    assert np.abs(with_ - truth).max() < 0.005
