"""Short gather rays far from their face's corners (core/output/short_hits.py): which hits
are short, and the cells they read, against sums done here from the hits themselves."""
import numpy as np

from hemicube_radiosity.core.builtin_scenes import quad
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.output.gather import gather_matrix, patch_parameters
from hemicube_radiosity.core.output.short_hits import RATIO, ShortCells, short_hits
from hemicube_radiosity.core.rays import embree_scene

H_PLATE = 0.02          # m: a plate's points over a 2 m floor face, facing down at it


def _case():
    floor = quad([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], name="floor")
    ps = build_patches([floor], 10.0)                     # one face, its corners 1 m out
    assert len(ps) == 1
    g = np.linspace(-0.9, 0.9, 7)
    X, Y = np.meshgrid(g, g)
    pts = np.stack([X.ravel(), Y.ravel(), np.full(X.size, H_PLATE)], 1)
    nrm = np.tile([0.0, 0.0, -1.0], (len(pts), 1))
    _, _, H = gather_matrix(ps, pts, nrm, embree_scene(ps), rays=64, hits=True)
    return ps, pts, H


def test_a_hit_is_short_when_its_ray_is_under_a_quarter_of_its_way_to_the_face_s_nearest_corner():
    ps, pts, H = _case()
    y = H[:, 2:5].astype(np.float64)
    t = np.linalg.norm(y - pts[H[:, 0].astype(int)], axis=1)
    corners = ps.verts[ps.polys[0]]
    d = np.linalg.norm(y[:, None, :] - corners[None], axis=2).min(axis=1)
    short = short_hits(ps, pts, H)
    np.testing.assert_array_equal(short, RATIO * t < d)
    assert 0.3 < short.mean() < 1.0          # most, not all: rays near the corners, grazing rays
    assert not short_hits(ps, pts, H, exclude=np.ones(1, bool)).any()


def test_each_short_hit_reads_a_cell_that_holds_it_no_larger_than_its_ray():
    ps, pts, H = _case()
    cells = ShortCells(ps, pts, H)
    short, at = cells.columns(ps, patch_parameters(ps), pts, H)
    np.testing.assert_array_equal(short, short_hits(ps, pts, H))
    assert len(cells.keys) == len(np.unique(at[short])) < short.sum()     # rays share cells
    y = H[short, 2:5].astype(np.float64)
    t = np.linalg.norm(y - pts[H[short, 0].astype(int)], axis=1)
    off = np.abs(cells.points[at[short]] - y)[:, :2].max(axis=1)       # along the floor's edges
    # the cell, a power of two across, not above the ray's length, holds the hit: its centre
    # is at most half its side off along each edge, so at most half the ray's length
    assert np.all(off <= t / 2 + 1e-9)
    np.testing.assert_allclose(cells.points[:, 2], 0.0, atol=1e-12)
    np.testing.assert_array_equal(cells.faces, 0)

