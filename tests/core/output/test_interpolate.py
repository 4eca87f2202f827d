"""Bilinear evaluation of a bake at arbitrary surface points."""
import numpy as np

from hemicube_radiosity.core.output.interpolate import interpolate_at, locate
from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.builtin_scenes import box
from tests.support.patching import counted_points


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


# ----------------------------------------------------------------------------- the grid search
import pytest  # noqa: E402

from hemicube_radiosity.core.output import interpolate
from hemicube_radiosity.core.util import spatial  # noqa: E402
from hemicube_radiosity.core.output.interpolate import inverse_bilinear  # noqa: E402
from hemicube_radiosity.core.util.geometry import bilinear  # noqa: E402


def _bilinear(c, u, v):
    """c (..., 4, k) corner values; u, v (...,) -> (..., k)."""
    return bilinear(c, u[..., None], v[..., None])
from hemicube_radiosity.core.builtin_scenes import tessellate  # noqa: E402
from hemicube_radiosity.core.util.spatial import k_nearest  # noqa: E402


def _brute_locate(ps, points, owner=None, normals=None, candidates=8):
    """locate as it was before the grid: every point against every patch centre of its
    object, the ``candidates`` nearest by ``np.argpartition``, tried in the order it gives."""
    points = np.asarray(points, float)
    powner = ps.owner if owner is not None else np.zeros(len(ps), np.int64)
    owner = np.zeros(len(points), np.int64) if owner is None else np.asarray(owner)
    corners, size = ps.corners(), np.sqrt(ps.areas)
    idx, uv = np.empty(len(points), np.int64), np.empty((len(points), 2))
    for o in np.unique(owner):
        ids = np.flatnonzero(owner == o)
        cand_all = np.flatnonzero(powner == o)
        k = min(candidates, cand_all.size)
        p = points[ids]
        d2 = ((p[:, None, :] - ps.centers[cand_all][None]) ** 2).sum(-1)
        near = np.argpartition(d2, k - 1, axis=1)[:, :k] if k < cand_all.size else np.broadcast_to(
            np.arange(k), (ids.size, k))
        cand = cand_all[near]
        c = corners[cand]
        pp = np.broadcast_to(p[:, None, :], cand.shape + (3,))
        u, v = inverse_bilinear(c, pp)
        outside = np.maximum.reduce([np.zeros_like(u), -u, u - 1, -v, v - 1])
        uc, vc = np.clip(u, 0, 1), np.clip(v, 0, 1)
        score = outside + np.linalg.norm(_bilinear(c, uc, vc) - pp, axis=-1) / size[cand]
        if normals is not None:
            score = score + 10.0 * (np.einsum("mkj,mj->mk", ps.normals[cand], np.asarray(normals, float)[ids]) < 0.5)
        b = np.argmin(score, axis=1)
        r = np.arange(len(ids))
        idx[ids], uv[ids] = cand[r, b], np.stack([uc[r, b], vc[r, b]], 1)
    return idx, uv


def _mixed_scene():
    """Two patch sets: a box cut into quads with a rotated box of triangles (their points go
    through two grid levels), and a floor of 1 m quads beside 0.1 m ones (cells sized for the
    big ones, dozens of centres in a cell of the fine part)."""
    big = tessellate([MeshInput.from_faces(np.array([[0, 0, 0], [4, 0, 0], [4, 4, 0], [0, 4, 0]], float),
                                           [[0, 1, 2, 3]], name="big")], 4, triangles=False)[0]
    fine = tessellate([MeshInput.from_faces(np.array([[4, 0, 0], [5, 0, 0], [5, 1, 0], [4, 1, 0]], float),
                                            [[0, 1, 2, 3]], name="fine")], 10, triangles=False)[0]
    cat = np.concatenate
    offsets = cat([big.face_offsets, fine.face_offsets[1:] + big.face_offsets[-1]])
    floor = MeshInput(cat([big.verts, fine.verts]), offsets,
                      cat([big.face_indices, np.asarray(fine.face_indices) + len(big.verts)]),
                      cat([big.face_rho, fine.face_rho]), cat([big.face_emission, fine.face_emission]), "floor")
    a = build_patches([box((0, 0, 0.5), (1, 1, 1.5), name="a"),
                       tessellate([box((2, 0, 0.5), (3, 1, 1.0), rotate_z=0.4, name="b")], 3)[0]], 0.25)
    f = build_patches([floor], None)
    return a, f


def _points(ps, rng):
    """Patch corners (on edges several patches share: ties), points inside patches, points off
    the surfaces (near and far: the grid's last resort), each with its patch's owner and normal."""
    corners = ps.corners()
    sel = rng.integers(0, len(ps), 300)
    u, v = rng.uniform(0, 1, (2, len(sel)))
    inside = _bilinear(corners[sel], u, v)
    on_corner = corners[sel, rng.integers(0, 4, len(sel))]
    pts = np.concatenate([inside, on_corner, inside + rng.normal(0, 0.1, inside.shape),
                          on_corner[:20] + [40.0, -3.0, 7.0]])
    src = np.concatenate([sel, sel, sel, sel[:20]])
    nrm = ps.normals[src].copy()
    flip = rng.uniform(size=len(src)) < 0.2
    nrm[flip] = rng.normal(size=(int(flip.sum()), 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return pts, ps.owner[src], nrm


@pytest.mark.parametrize("brute,workers", [(0, 1), (512, 1), (0, 2)])
def test_locate_equals_a_brute_force_search(monkeypatch, brute, workers):
    """To the bit, ties included; ``brute``: objects of at most so many patches skip the grid
    (0: the grid for all; the objects here have 96 to 432 patches, 528 for points of any object);
    ``workers``: threads take the grid's chunks of points (their rows written at once)."""
    monkeypatch.setattr(interpolate, "_BRUTE", brute)
    maps = []
    real_map = interpolate.ordered_map
    monkeypatch.setattr(interpolate, "ordered_map", lambda fn, items, w: maps.append(w) or real_map(fn, items, w))
    rng = np.random.default_rng(3)
    for ps in _mixed_scene():
        pts, owner, nrm = _points(ps, rng)
        for args in ((owner, nrm), (owner, None), (None, None), (None, nrm)):
            for candidates in (8, 3, 64):      # 64: the far search, its fits pruned (_PRUNE)
                idx, uv = locate(ps, pts, *args, candidates=candidates, chunk=97, workers=workers)
                ref_idx, ref_uv = _brute_locate(ps, pts, *args, candidates=candidates)
                np.testing.assert_array_equal(idx, ref_idx)
                np.testing.assert_array_equal(uv, ref_uv)
    if brute == 0:
        assert max(maps) == workers             # the threads were asked for


@pytest.mark.parametrize("pairs", [None, 64])
def test_k_nearest_equals_a_full_sort(monkeypatch, pairs):
    """``pairs``: the (point, site) pairs handled at once, 64 to split every batch of points."""
    if pairs is not None:
        monkeypatch.setattr(spatial, "MAX_PAIRS", pairs)
    rng = np.random.default_rng(4)
    for trial in range(24):
        N = int(rng.integers(1, 300))
        k = int(rng.integers(1, min(N, 12) + 1))
        if trial % 3 == 0:        # a lattice: many equal distances, ties at the k-th go to the lower index
            sites = rng.integers(0, 5, (N, 3)) * 0.5
            pts = rng.integers(-2, 7, (200, 3)) * 0.25
        else:                     # a scatter flattened towards a plane, and points far outside it
            sites = rng.normal(size=(N, 3)) * [1, 1, 0.01 * trial]
            pts = np.concatenate([rng.normal(size=(180, 3)) * 1.5, rng.normal(size=(20, 3)) * 100])
        cell = (None, 0.05, 0.3, 2.0)[trial % 4]
        idx, d2 = k_nearest(sites, pts, k, cell=cell, chunk=61)
        full = ((pts[:, None, :] - sites[None]) ** 2).sum(-1)
        ref = np.argsort(full, axis=1, kind="stable")[:, :k]
        np.testing.assert_array_equal(idx, ref)
        np.testing.assert_array_equal(d2, np.take_along_axis(full, ref, 1))


def test_k_nearest_through_coarse_levels_equals_a_full_sort():
    """Sites dense in a few spots and sparse elsewhere (a level's small patches beside its floors),
    many neighbours asked: most points settle only on coarse levels, whose cubes skip the cells and
    sites beyond the k-th found on the finer level; the result is still the full sort's."""
    rng = np.random.default_rng(7)
    for trial in range(6):
        spots = rng.uniform(-10, 10, (4, 3)) * [1, 1, 0.05]
        dense = np.concatenate([c + rng.normal(size=(300, 3)) * 0.05 for c in spots])
        sites = np.concatenate([dense, rng.uniform(-10, 10, (200, 3)) * [1, 1, 0.05]])
        if trial % 2:
            sites = np.round(sites * 4) / 4           # a lattice's ties
        pts = np.concatenate([rng.uniform(-12, 12, (300, 3)) * [1, 1, 0.1], dense[::7] + 0.01])
        k = (9, 65, 33)[trial % 3]
        idx, d2 = k_nearest(sites, pts, k, cell=0.1, chunk=97)
        full = ((pts[:, None, :] - sites[None]) ** 2).sum(-1)
        ref = np.argsort(full, axis=1, kind="stable")[:, :k]
        np.testing.assert_array_equal(idx, ref)
        np.testing.assert_array_equal(d2, np.take_along_axis(full, ref, 1))


def test_a_dense_objects_whole_faces_need_no_search(monkeypatch):
    """A dense object in a coarse room (the Cornell box's tall block as 4,000 triangles, finer
    than the patches and the detail size): its faces are whole as patches and as elements, so
    the patch solution reaches its element vertices at their patch's corner, without `locate`
    (the search costs per vertex, and a dense object has many). The bake is what the search gives to 1e-6 of its
    mean; only the coarse room's element vertices are searched for."""
    from hemicube_radiosity.core.output import indirect as output
    from hemicube_radiosity.core.pipeline import BakeSettings, bake
    from hemicube_radiosity.core.builtin_scenes import cornell_box, tessellate

    room = cornell_box()
    meshes = room[:7] + tessellate(room[7:], 20)
    searched = counted_points(monkeypatch, output, "locate")
    fast = bake(meshes, BakeSettings())
    block = fast.elements.owner == fast.elements.object_names.index("TallBlock")
    on_block = np.unique(fast.elements.polys[block])
    on_block = on_block[on_block >= 0]
    assert len(on_block) > 2000 and searched[0] == len(fast.elements.verts) - len(on_block)
    monkeypatch.setattr(output, "_whole_faces", lambda p, e: (np.zeros(0, np.int64),) * 2)
    searched.clear()
    slow = bake(meshes, BakeSettings())
    assert sum(searched) >= len(fast.elements.verts)
    lum = np.array([0.2126, 0.7152, 0.0722])
    d = np.abs(fast.vertex_radiosity - slow.vertex_radiosity) @ lum
    assert d.mean() < 1e-6 * (slow.vertex_radiosity @ lum).mean()


def test_interpolate_located_is_the_corners_bilinear_bit_for_bit():
    # the corners and weights kept for a relight (located_corners) give _bilinear's values
    from hemicube_radiosity.core import builtin_scenes as scenes
    from hemicube_radiosity.core.output.interpolate import interpolate_located
    P = build_patches(scenes.tessellate(scenes.cornell_box()[:3], 2) + scenes.cornell_box()[3:], 0.3)
    rng = np.random.default_rng(3)
    idx = rng.integers(0, len(P), 4000)
    uv = rng.random((4000, 2))
    vals = rng.random((len(P.verts), 3)) - 0.3
    polys = P.polys[idx].copy()
    tri = polys[:, 3] < 0
    assert tri.any() and (~tri).any()
    polys[tri, 3] = polys[tri, 2]
    assert np.array_equal(interpolate_located(P, vals, idx, uv), _bilinear(vals[polys], uv[:, 0], uv[:, 1]))


def _vector_inverse_bilinear(c, p, iterations=8):
    """The Gauss-Newton as it was written on (..., 3) vectors, before it was worked one
    coordinate at a time: the reference the faster one must equal bit for bit."""
    u = np.full(p.shape[:-1], 0.5)
    v = np.full(p.shape[:-1], 0.5)
    for _ in range(iterations):
        r = _bilinear(c, u, v) - p
        du = (1 - v)[..., None] * (c[..., 1, :] - c[..., 0, :]) + v[..., None] * (c[..., 2, :] - c[..., 3, :])
        dv = (1 - u)[..., None] * (c[..., 3, :] - c[..., 0, :]) + u[..., None] * (c[..., 2, :] - c[..., 1, :])
        a, b, d = (np.einsum("...i,...i", x, y) for x, y in ((du, du), (du, dv), (dv, dv)))
        gu, gv = np.einsum("...i,...i", du, r), np.einsum("...i,...i", dv, r)
        det = a * d - b * b
        tiny = det <= 1e-30 * np.maximum(a * d, 1e-300)
        det = np.where(tiny, 1.0, det)
        u = np.clip(u - np.where(tiny, 0.0, (d * gu - b * gv) / det), -0.5, 1.5)
        v = np.clip(v - np.where(tiny, 0.0, (a * gv - b * gu) / det), -0.5, 1.5)
    return u, v


def test_inverse_bilinear_is_the_vector_gauss_newton_bit_for_bit():
    """Warped quads, points on and off them, degenerate quads (a triangle's last two corners
    equal, a quad folded to a segment), a batch of (points, candidates) as locate passes them
    (the points broadcast along the candidates); and it really inverts: an exact point's (u, v)
    comes back."""
    rng = np.random.default_rng(5)
    h = 20000
    c = (rng.random((h, 1, 3)) * 3 + np.array([[0, 0, 0], [0.1, 0, 0.01], [0.1, 0.1, 0.02], [0, 0.1, -0.01]])
         * rng.random((h, 1, 1)) + rng.normal(0, 0.005, (h, 4, 3)))
    c[:500, 3] = c[:500, 2]
    c[500:600, 2:] = c[500:600, :2]
    u0, v0 = rng.random(h), rng.random(h)
    exact = _bilinear(c, u0, v0)
    for p in (exact, exact + rng.normal(0, 0.02, exact.shape)):
        got, ref = inverse_bilinear(c, p), _vector_inverse_bilinear(c, p)
        np.testing.assert_array_equal(got[0], ref[0])
        np.testing.assert_array_equal(got[1], ref[1])
    cand = c[:8000].reshape(1000, 8, 4, 3)
    pp = np.broadcast_to(exact[:1000, None, :], (1000, 8, 3))
    for g, r in zip(inverse_bilinear(cand, pp), _vector_inverse_bilinear(cand, pp)):
        np.testing.assert_array_equal(g, r)
    good = (rng.random((h, 1, 3)) * 3 + np.array([[0, 0, 0], [0.1, 0, 0.01], [0.1, 0.1, 0.02], [0, 0.1, -0.01]])
            * (0.5 + 0.5 * rng.random((h, 1, 1))) + rng.normal(0, 0.002, (h, 4, 3)))
    u, v = inverse_bilinear(good, _bilinear(good, u0, v0))
    assert np.abs(u - u0).max() < 1e-9 and np.abs(v - v0).max() < 1e-9


def test_many_small_objects_are_located_together_as_one_by_one():
    """Objects of at most ``candidates`` patches (a face's elements, when texels are keyed by
    face) are settled all at once per patch count: the same patch and (u, v), to the bit, as
    each object searched alone by the brute force, ties and points off the surfaces included."""
    from dataclasses import replace
    rng = np.random.default_rng(8)
    for ps in _mixed_scene():
        sizes = rng.integers(1, 12, len(ps))                   # 1 to 11 patches a key: both ways
        group = np.repeat(np.arange(len(ps)), sizes)[:len(ps)]
        key = ps.owner.astype(np.int64) * 10_000 + group
        small = replace(ps, owner=key)
        pts, _, nrm = _points(ps, rng)
        src = np.argmin(((pts[:, None, :] - ps.centers[None]) ** 2).sum(-1), axis=1)
        idx, uv = locate(small, pts, key[src], nrm, chunk=97)
        for k in np.unique(key[src]):
            at = np.flatnonzero(key[src] == k)
            ref_idx, ref_uv = _brute_locate(small, pts[at], key[src][at], nrm[at])
            np.testing.assert_array_equal(idx[at], ref_idx)
            np.testing.assert_array_equal(uv[at], ref_uv)
