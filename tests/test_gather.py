"""Final gather: cosine rays that read a patch solution where they land."""
import numpy as np
import pytest

from hemicube_radiosity.core.gather import final_gather, patch_parameters, surface_values
from hemicube_radiosity.core.geometry import polygon_form_factors
from hemicube_radiosity.core.patches import build_patches
from hemicube_radiosity.core.rays import embree_scene
from hemicube_radiosity.core.scenes import closed_box, quad


def test_constant_field_in_a_closed_room_is_gathered_exactly():
    ps = build_patches(closed_box(size=(1.0, 1.3, 0.8)), 0.25)
    vals = np.full((len(ps.verts), 3), 0.7)
    pts = np.array([[0.5, 0.5, 0.0], [0.02, 0.6, 0.3], [0.5, 1.3, 0.79]])
    nrm = np.array([[0, 0, 1], [1, 0, 0], [0, -1, 0]], float)
    G = final_gather(ps, vals, pts, nrm, embree_scene(ps), rays=64)
    np.testing.assert_allclose(G, 0.7, rtol=1e-6)


def test_wall_seen_from_the_floor_matches_the_analytic_form_factor_and_world_fills_the_rest():
    floor = quad([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], name="floor")
    wall = quad([(-1, 1, 0), (1, 1, 0), (1, 1, 1), (-1, 1, 1)], name="wall")   # faces -y
    ps = build_patches([floor, wall], 0.5)
    vals = np.where(np.isin(np.arange(len(ps.verts)), ps.polys[ps.owner == 1]), 1.0, 0.0)[:, None]
    x = np.array([[0.0, 0.2, 0.0]])
    F = polygon_form_factors(x, [[0, 0, 1]], ps.corners()[ps.owner == 1]).sum()
    rays = 4096
    G = final_gather(ps, vals, x, [[0, 0, 1]], embree_scene(ps), rays=rays, world=[0.25])[0, 0]
    sky = 1 - F
    expect = F * 1.0 + sky * 0.25
    sigma = np.sqrt(F * (1 - F) / rays)   # stratification only makes it smaller
    assert G == pytest.approx(expect, abs=4 * sigma * 0.75)


def test_surface_values_are_bilinear_on_quads_and_linear_on_triangles():
    c = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0], [3, 0, 0]], float)
    from hemicube_radiosity.core.patches import MeshInput

    ps = build_patches(MeshInput.from_faces(c, [[0, 1, 2, 3], [1, 4, 2]]), None)
    vals = np.array([[1.0], [3.0], [7.0], [2.0], [5.0]])
    params = patch_parameters(ps)
    y = np.array([[1.0, 0.5, 0], [2.5, 0.25, 0]])
    got = surface_values(params, ps.polys, vals, np.array([0, 1]), y)
    # quad at (u, v) = (0.5, 0.5): mean of the corners; triangle: plane through (2,0)=3, (3,0)=5, (2,1)=7
    assert got[0, 0] == pytest.approx((1 + 3 + 7 + 2) / 4)
    assert got[1, 0] == pytest.approx(3 + 0.5 * 2 + 0.25 * 4)
