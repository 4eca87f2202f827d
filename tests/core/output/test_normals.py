"""Shading normals at the output vertices (core/output/normals.py): the source faces' corner
normals interpolated where each vertex lies, checked against the interpolation written out."""
import numpy as np

from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.output.normals import MAX_LEAN, shading_normals


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _flat(elements):
    return np.tile([0.0, 0.0, 1.0], (len(elements.verts), 1))


def test_a_quad_s_corner_normals_are_bilinear_over_it():
    N = _unit([(0.3, 0, 1), (0, 0.3, 1), (-0.3, 0, 1), (0, -0.2, 1)])
    m = MeshInput.from_faces([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1, 2, 3)])
    m.corner_normal = N
    el = build_patches([m], 0.25)                          # a 4 x 4 grid of elements
    got = shading_normals(el, [m], _flat(el))
    u, v = el.verts[:, 0], el.verts[:, 1]                  # the unit square: (u, v) = (x, y)
    want = _unit((1 - u)[:, None] * (1 - v)[:, None] * N[0] + u[:, None] * (1 - v)[:, None] * N[1]
                 + u[:, None] * v[:, None] * N[2] + (1 - u)[:, None] * v[:, None] * N[3])
    assert len(el.verts) == 25
    np.testing.assert_allclose(got, want, atol=1e-9)


def test_a_triangle_s_corner_normals_are_barycentric():
    N = _unit([(0.5, 0, 1), (0, 0.5, 1), (0, 0, 1)])
    m = MeshInput.from_faces([(0, 0, 0), (2, 0, 0), (0, 2, 0)], [(0, 1, 2)])
    m.corner_normal = N
    el = build_patches([m], 0.5)
    got = shading_normals(el, [m], _flat(el))
    s, t = el.verts[:, 0] / 2, el.verts[:, 1] / 2
    want = _unit((1 - s - t)[:, None] * N[0] + s[:, None] * N[1] + t[:, None] * N[2])
    assert len(el.verts) > 10
    np.testing.assert_allclose(got, want, atol=1e-9)


def test_without_corner_normals_or_past_the_lean_the_geometric_normal_stays():
    m = MeshInput.from_faces([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1, 2, 3)])
    el = build_patches([m], 0.5)
    flat = _flat(el)
    assert shading_normals(el, [m], flat) is flat
    lean = np.radians(MAX_LEAN + 1.0)
    m.corner_normal = np.tile([np.sin(lean), 0.0, np.cos(lean)], (4, 1))
    np.testing.assert_array_equal(shading_normals(el, [m], flat), flat)
    lean = np.radians(MAX_LEAN - 10.0)
    m.corner_normal = np.tile([np.sin(lean), 0.0, np.cos(lean)], (4, 1))
    np.testing.assert_allclose(shading_normals(el, [m], flat)[:, 0], np.sin(lean), atol=1e-12)
