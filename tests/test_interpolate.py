"""Bilinear evaluation of a bake at arbitrary surface points."""
import numpy as np

from hemicube_radiosity.core.interpolate import interpolate_at, locate
from hemicube_radiosity.core.patches import MeshInput, build_patches
from hemicube_radiosity.core.scenes import box


def test_bilinear_field_is_exact_on_a_skewed_quad_grid():
    # a non-rectangular planar quad cut into a 3x3 grid; a bilinear field in (s,t) of the source quad
    c = np.array([[0, 0, 0], [3, 0.4, 0], [3.5, 2.5, 0], [-0.3, 2, 0]], float)
    ps = build_patches(MeshInput.from_faces(c, [[0, 1, 2, 3]]), 1.2)
    rng = np.random.default_rng(0)
    s, t = rng.uniform(0, 1, (2, 500))
    bil = lambda s, t: ((1 - s) * (1 - t))[:, None] * c[0] + (s * (1 - t))[:, None] * c[1] + (s * t)[:, None] * c[2] + ((1 - s) * t)[:, None] * c[3]  # noqa: E501,E731
    pts = bil(s, t)
    # values at patch vertices of a field linear in world x, y: bilinear interpolation reproduces it
    f = lambda x: (2 + x[:, 0] - 0.5 * x[:, 1])[:, None]  # noqa: E731
    got = interpolate_at(ps, f(ps.verts), pts)
    np.testing.assert_allclose(got, f(pts), rtol=1e-9)


def test_points_go_to_the_right_object_and_face_by_normal():
    ps = build_patches([box((0, 0, 0), (1, 1, 1), name="a"), box((2, 0, 0), (3, 1, 1), name="b")], 0.5)
    vals = np.zeros((len(ps.verts), 1))
    vals[np.unique(ps.polys[ps.owner == 1])] = 5.0
    # the box corner (1,0,0) belongs to the faces x1, y0, z0 of object a; the normal picks x1
    idx, uv = locate(ps, [[1, 0, 0], [1, 0, 0], [2.5, 0.5, 1.0]], owner=[0, 0, 1],
                     normals=[[1, 0, 0], [0, 0, -1], [0, 0, 1]])
    np.testing.assert_allclose(ps.normals[idx], [[1, 0, 0], [0, 0, -1], [0, 0, 1]], atol=1e-12)
    got = interpolate_at(ps, vals, [[0.5, 0.5, 1.0], [2.5, 0.5, 1.0]], owner=[0, 1])
    np.testing.assert_allclose(got[:, 0], [0.0, 5.0])


def test_triangle_patches_interpolate_barycentrically():
    c = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0]], float)
    ps = build_patches(MeshInput.from_faces(c, [[0, 1, 2]]), None)
    vals = np.array([[1.0], [3.0], [5.0]])
    got = interpolate_at(ps, vals, [[0.5, 0.5, 0], [1, 1, 0], [0, 0, 0]])
    np.testing.assert_allclose(got[:, 0], [1 + 0.25 * 2 + 0.25 * 4, 1 + 0.5 * 2 + 0.5 * 4, 1.0], rtol=1e-9)
