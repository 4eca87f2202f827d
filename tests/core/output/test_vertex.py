"""Vertex radiosities: the paper's averaging and boundary extrapolation."""
import numpy as np
import pytest

from hemicube_radiosity.core.mesh.patches import MeshInput, PatchSet
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.output.vertex import boundary_vertices, vertex_radiosity


def grid(nx=4, ny=3, size=(4.0, 3.0)):
    m = MeshInput.from_faces([[0, 0, 0], [size[0], 0, 0], [size[0], size[1], 0], [0, size[1], 0]], [[0, 1, 2, 3]])
    return build_patches(m, 1.0)


def test_linear_field_is_reproduced_exactly_at_every_vertex():
    # patch values from a linear function: averaging is exact inside, extrapolation exact on the boundary
    ps = grid()
    f = lambda p: 1.0 + 0.5 * p[:, 0] + 0.25 * p[:, 1]  # noqa: E731
    B = np.repeat(f(ps.centers)[:, None], 3, 1)
    Bv = vertex_radiosity(ps, B)
    np.testing.assert_allclose(Bv[:, 0], f(ps.verts), rtol=1e-7)
    # plain averaging is wrong on the boundary for the same field
    avg = vertex_radiosity(ps, B, extrapolate=False)
    assert np.abs(avg[:, 0] - f(ps.verts)).max() > 0.2


def test_constant_field_everywhere_and_clamped_at_zero():
    ps = grid()
    Bv = vertex_radiosity(ps, np.full((len(ps), 3), 2.5))
    np.testing.assert_allclose(Bv, 2.5)
    # a steep drop toward the boundary would extrapolate below zero: clamped
    B = np.where(ps.centers[:, :1] < 1, 0.0, 10.0).repeat(3, 1)
    assert vertex_radiosity(ps, B).min() >= 0


def test_surfaces_that_share_no_vertex_do_not_mix():
    a = MeshInput.from_faces([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2, 3]], name="a")
    b = MeshInput.from_faces([[1, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0]], [[0, 1, 2, 3]], name="b")
    ps = build_patches([a, b], 0.5)
    B = np.where(ps.owner[:, None] == 0, 1.0, 3.0).repeat(3, 1)
    Bv = vertex_radiosity(ps, B)
    on_a = np.isin(np.arange(len(ps.verts)), ps.polys[ps.owner == 0])
    np.testing.assert_allclose(Bv[on_a], 1.0)
    np.testing.assert_allclose(Bv[~on_a], 3.0)


def test_single_patch_takes_its_own_value():
    ps = build_patches(MeshInput.from_faces([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]), None)
    np.testing.assert_allclose(vertex_radiosity(ps, [[0.3, 0.2, 0.1]]), [[0.3, 0.2, 0.1]] * 3)


def test_cached_fits_and_frames_are_the_same_bit_for_bit():
    # a relight's vertex values come from the fits kept in the cache: the same arithmetic
    from hemicube_radiosity.core import builtin_scenes as scenes
    from hemicube_radiosity.core.runtime.cache import FormFactorCache
    from hemicube_radiosity.core.light.emitters import vertex_frames
    from hemicube_radiosity.core.output.vertex import frames
    ps = build_patches(scenes.cornell_box(), 0.25)
    rng = np.random.default_rng(3)
    w = rng.random(len(ps)) * (rng.random(len(ps)) > 0.2)
    cache = FormFactorCache()
    for weights in (None, w):
        for extrapolate in (True, False):
            for B in (rng.random((len(ps), 3)), rng.random((len(ps), 3)) - 0.5):
                ref = vertex_radiosity(ps, B, extrapolate, weights)
                for _ in range(2):                # made, then found in the cache
                    assert np.array_equal(vertex_radiosity(ps, B, extrapolate, weights, cache=cache), ref)
        ref = vertex_frames(ps, weights=weights)
        for _ in range(2):
            got = frames(ps, weights, cache)
            assert all(np.array_equal(a, b) for a, b in zip(got, ref))
    # new materials on the same geometry: the cached frames' reflectivity is the new one's
    other = ps.with_materials(rng.random((len(ps), 3)), ps.emission)
    assert all(np.array_equal(a, b) for a, b in zip(frames(other, w, cache), vertex_frames(other, weights=w)))


def test_a_field_zero_on_most_patches_sums_only_the_rest_bit_for_bit():
    # an emission field (a few patches glow) skips the zero terms of its sums: each band's
    # values are those it has beside a band that is nowhere 0 (which sums every term)
    from hemicube_radiosity.core import builtin_scenes as scenes
    from hemicube_radiosity.core.runtime.cache import FormFactorCache
    ps = build_patches(scenes.tessellate(scenes.cornell_box(), 2), 0.25)
    rng = np.random.default_rng(7)
    w = rng.random(len(ps)) * (rng.random(len(ps)) > 0.2)
    lit = rng.random(len(ps)) < 0.05
    for B in (np.where(lit[:, None], rng.random((len(ps), 3)), 0.0),
              np.where(lit[:, None], rng.random((len(ps), 3)) - 0.5, 0.0),
              np.zeros((len(ps), 3))):
        dense = np.column_stack([B, rng.random(len(ps)) + 0.1])
        for weights in (None, w):
            for extrapolate in (True, False):
                for cache in (None, FormFactorCache()):
                    got = vertex_radiosity(ps, B, extrapolate, weights, cache=cache)
                    assert np.array_equal(got, vertex_radiosity(ps, dense, extrapolate, weights)[:, :3])


def test_fill_buried_cached_rings_are_the_same_bit_for_bit():
    from hemicube_radiosity.core.runtime.cache import FormFactorCache
    from hemicube_radiosity.core.output.vertex import fill_buried
    ps = grid(8, 6, (8.0, 6.0))
    w = np.ones(len(ps))
    w[(ps.centers[:, 0] > 2) & (ps.centers[:, 0] < 6) & (ps.centers[:, 1] > 1) & (ps.centers[:, 1] < 5)] = 0.0
    rng = np.random.default_rng(2)
    cache = FormFactorCache()
    for _ in range(3):
        vals = vertex_radiosity(ps, rng.random((len(ps), 3)), weights=w)
        ref = fill_buried(ps, vals, w)
        assert not np.array_equal(ref, vals)              # something was filled
        assert np.array_equal(fill_buried(ps, vals, w, cache=cache), ref)
    assert fill_buried(ps, vals, np.ones(len(ps)), cache=cache) is vals   # nothing buried


def test_fit_substitution_is_the_row_major_one_bit_for_bit():
    # _fit_solve substitutes in (n, k, T) copies: the same operations as on (T, n, k) rows
    from hemicube_radiosity.core.output.vertex import _fit_solve, _lu
    rng = np.random.default_rng(11)
    M = rng.random((500, 4, 4)) + 4 * np.eye(4) * rng.random((500, 1, 1))
    rhs = rng.random((500, 4, 3)) - 0.5
    A, perm = _lu(M)
    x = np.take_along_axis(rhs, perm[:, :, None], axis=1)
    for i in range(1, 4):
        for j in range(i):
            x[:, i] -= A[:, i, j, None] * x[:, j]
    for i in range(3, -1, -1):
        for j in range(i + 1, 4):
            x[:, i] -= A[:, i, j, None] * x[:, j]
        x[:, i] /= A[:, i, i, None]
    assert np.array_equal(_fit_solve(M, (A, perm), rhs), x)
    np.testing.assert_allclose(x, np.linalg.solve(M, rhs), rtol=1e-9, atol=1e-12)


def frame_fold():
    """Six triangles of the grey-white room's window frame (its moulding, in metres about the
    vertex at its end): the faces turn at the vertex, and one is a sliver (0.3 mm^2, its
    centre 2 cm from the vertex, its normal 90 degrees from the others')."""
    verts = np.array([[-0.25363, 0.0, 0.0], [-0.21568, -0.01493, 0.03697], [0.0, -0.00752, 0.03863],
                      [-0.03795, -0.01493, 0.03697], [0.0, 0.0, 0.0], [0.0, -0.00375, 0.01932],
                      [-0.05, -0.01963, 0.04846]])
    tris = np.array([[2, 3, 4], [2, 4, 5], [0, 4, 3], [0, 3, 1], [1, 3, 6], [2, 6, 3]])
    c = verts[tris]
    cross = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    n = len(tris)
    return PatchSet(verts, np.concatenate([tris, np.full((n, 1), -1)], 1), c.mean(axis=1),
                    cross / (2 * area[:, None]), area, np.full((n, 3), 0.8), np.zeros((n, 3)),
                    np.zeros(n, np.int32), np.arange(n, dtype=np.int32), ["frame"])


def test_a_fold_extrapolates_no_further_than_the_papers_line():
    # the boundary vertex 4 at the fold's end is fitted to three patch centres and one interior
    # vertex (3), four samples for four unknowns, nearly in one plane with the vertex off it: the
    # exact fit of a field that is not linear (light mirrored onto the frame, 0.084 and 0.062 on
    # the faces, 0 on the sliver that no ray met) reached 73 at the vertex, and the final gather
    # read it there (the room's window frames 260 to 520 where Cycles has 1 to 2). The paper's
    # line from an interior vertex through a patch's centre reaches at most the samples' range
    # widened by its width: here 0.17.
    ps = frame_fold()
    assert (interior_vertices(ps) == [3]).all()
    B = np.array([0.084, 0.0, 0.062, 0.062, 0.062, 0.084])[:, None].repeat(3, 1)
    Bv = vertex_radiosity(ps, B)
    assert 0.0 <= Bv[4, 0] <= 2 * 0.084
    assert np.all(Bv <= 2 * 0.084) and np.all(Bv >= 0)
    # a constant field stays constant on the fold, to the fit's rounding
    np.testing.assert_allclose(vertex_radiosity(ps, np.full((len(ps), 3), 0.062)), 0.062, rtol=1e-9)


def interior_vertices(ps):
    return np.flatnonzero(~boundary_vertices(ps.polys, len(ps.verts)))
