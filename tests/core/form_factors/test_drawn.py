"""The hemi-cube draws a planar cluster of pieces as its outline (core/form_factors/drawn.py): the same pixels
at a cost set by the clusters, not by how finely the faces were modelled."""
import numpy as np
import pytest

from hemicube_radiosity.core.form_factors import hemicube
from hemicube_radiosity.core import builtin_scenes as scenes
from hemicube_radiosity.core.mesh.clusters import group_pieces
from hemicube_radiosity.core.form_factors.drawn import draw_set
from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.mesh.stage import cut_patches as _cut
from hemicube_radiosity.core.pipeline import BakeSettings
from tests.support.shapes import uv_sphere


def _grouped(meshes):
    s = BakeSettings().resolved(meshes)
    return _cut(meshes, s)


def _both(monkeypatch, pieces, clusters, R=32):
    """F drawn as outlines and F drawn piece by piece."""
    out = []
    for flag in (True, False):
        monkeypatch.setattr(hemicube, "DRAW_OUTLINES", flag)
        out.append(hemicube.hemicube_form_factors(pieces, R, clusters=clusters))
    return out


def _triangle_areas(d):
    p = d.verts[d.polys[:, :3]]
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


def test_a_dense_cornell_box_is_drawn_as_a_few_triangles_per_patch_with_the_same_form_factors(monkeypatch):
    pieces, clusters = _grouped(scenes.tessellate(scenes.cornell_box(), 11))     # 3,872 triangles
    d = draw_set(pieces, clusters)
    assert d.outlined.mean() > 0.99
    assert len(d) < len(pieces) / 3.5                                 # measured: 983 of 3,872
    # every outlined cluster is tiled exactly: its triangles' area is its pieces'
    tri = d.polys[:, 3] < 0
    a = np.bincount(d.item_of, weights=np.where(tri, _triangle_areas(d), 0), minlength=len(clusters))
    np.testing.assert_allclose(a[d.outlined], clusters.areas[d.outlined], rtol=1e-9)
    lod, full = _both(monkeypatch, pieces, clusters)
    A, B = lod.to_dense(), full.to_dense()
    # the same pixels: each row's total, and its sky, agree to float32 rounding
    np.testing.assert_allclose(A.sum(axis=1), B.sum(axis=1), atol=1e-6)
    np.testing.assert_allclose(lod.sky, full.sky, atol=1e-6)
    # entries move only where a pixel centre lies on a border between coplanar surfaces (a
    # depth tie decided anew): measured 2.3e-4 at most, 1e-5 on average per row
    assert np.abs(A - B).max() < 1e-3
    assert np.abs(A - B).sum(axis=1).mean() < 1e-4


def test_a_closed_room_drawn_as_outlines_stays_watertight(monkeypatch):
    cb = scenes.cornell_box()
    lo = np.min([m.verts.min(0) for m in cb], 0)
    hi = np.max([m.verts.max(0) for m in cb], 0)
    room = scenes.box(lo - 0.1, hi + 0.1, inward=True, name="room")
    blocks = [m for m in cb if "Block" in m.name]
    pieces, clusters = _grouped(scenes.tessellate([room] + blocks, 9))
    assert draw_set(pieces, clusters).outlined.all()
    lod, full = _both(monkeypatch, pieces, clusters)
    assert lod.sky.max() == 0.0 and full.sky.max() == 0.0            # no pixel sees out
    np.testing.assert_allclose(lod.to_dense().sum(axis=1), full.to_dense().sum(axis=1), atol=1e-6)


def _grid(n, size=1.0, z=0.0, rho=None, diagonal_flip=False):
    """A square of n x n quads, each cut in two triangles (alternating diagonals with
    ``diagonal_flip``), facing +z; ``rho`` (n, n, 3) per quad or None."""
    xs = np.linspace(0, size, n + 1)
    verts = np.array([(x, y, z) for y in xs for x in xs], float)
    faces, r = [], []
    for j in range(n):
        for i in range(n):
            a, b, c, d = j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i
            col = (0.5, 0.5, 0.5) if rho is None else tuple(rho[j, i])
            if diagonal_flip and (i + j) % 2:
                faces += [[a, b, d], [b, c, d]]
            else:
                faces += [[a, b, c], [a, c, d]]
            r += [col, col]
    return MeshInput.from_faces(verts, faces, np.array(r), np.zeros((len(r), 3)), "grid")


def test_a_cluster_with_a_hole_is_drawn_piece_by_piece():
    rho = np.full((9, 9, 3), 0.5)
    rho[4, 4] = (0.1, 0.8, 0.1)                                        # another material inside
    pieces = build_patches([_grid(9, rho=rho)], 4.0)
    clusters = group_pieces(pieces, 4.0)
    assert len(clusters) == 2
    d = draw_set(pieces, clusters)
    inner = clusters.of[np.flatnonzero(pieces.rho[:, 1] > 0.7)[0]]
    assert d.outlined[inner] and not d.outlined[1 - inner]           # the ring has a hole
    assert np.sum(d.item_of == 1 - inner) == np.sum(clusters.of == 1 - inner)
    assert np.sum(d.item_of == inner) == 2                            # the inner quad: 2 triangles


def test_outlines_touching_at_a_corner_are_cut_into_simple_loops():
    # a cell border slanting through the quads: one triangle of cluster 0 touches the rest of
    # it at a corner only, so its boundary passes that vertex twice
    from hemicube_radiosity.core.form_factors import drawn
    from hemicube_radiosity.core.mesh.clusters import make_clusters
    pieces = build_patches([_grid(8)], 4.0)
    of = (pieces.centers[:, 0] + 2.0 * pieces.centers[:, 1] > 0.43).astype(np.int64)
    clusters = make_clusters(pieces, of)
    pos, weld = np.unique(pieces.verts, axis=0, return_inverse=True)
    w = np.where(pieces.polys < 0, -1, weld.reshape(-1)[np.maximum(pieces.polys, 0)])
    _, lens, l_cl = drawn._outline_loops(w, of, np.ones(2, bool), pos, clusters.normals)
    assert sorted(lens[l_cl == 0]) == [3, 7] and (l_cl == 1).sum() == 1
    d = draw_set(pieces, clusters)
    assert d.outlined.all()
    a = np.bincount(d.item_of, weights=_triangle_areas(d), minlength=2)
    np.testing.assert_allclose(a, clusters.areas, rtol=1e-12)


def test_curved_clusters_are_drawn_piece_by_piece():
    pieces = build_patches([uv_sphere(24, 12)], 0.5)
    clusters = group_pieces(pieces, 0.5)
    d = draw_set(pieces, clusters)
    sizes = np.bincount(clusters.of)
    assert not d.outlined[sizes > 1].any()
    assert len(d) == len(pieces)


@pytest.mark.parametrize("n", [4, 18])
def test_collinear_border_points_are_left_out_on_both_sides_alike(n):
    # two coplanar clusters sharing a straight border of n segments: both outlines drop its
    # inner points (each cluster: 2 triangles) and share the border's two end points
    pieces = build_patches([_grid(n, size=2.0)], 4.0)
    of = (pieces.centers[:, 0] > 1.0).astype(np.int64)
    from hemicube_radiosity.core.mesh.clusters import make_clusters
    d = draw_set(pieces, make_clusters(pieces, of))
    assert d.outlined.all() and len(d) == 4 and len(d.verts) == 6


@pytest.mark.parametrize("faces", [[[0, 1, 2, 3], [0, 1, 2, 3]], [[0, 1, 2, 3], [0, 1, 2, 3], [3, 2, 1, 0]]])
def test_a_face_modelled_twice_is_drawn_as_its_pieces(faces):
    """A quad doubled (Blender's duplicate faces, the same vertices and winding) has no boundary
    edge: every edge is used twice. It has no outline, so it is drawn as its pieces. Before, the
    loop over each cluster's boundary edges read the first of none (an IndexError, found by
    tests/core/test_random_scenes.py's absurd inputs with one patch per face)."""
    from hemicube_radiosity.core.mesh.clusters import make_clusters

    quad = MeshInput.from_faces([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], faces, name="doubled")
    pieces = build_patches([quad], None)
    d = draw_set(pieces, make_clusters(pieces, np.zeros(len(pieces), np.int64)))
    assert not d.outlined.any() and len(d) == len(pieces)


def test_the_outlines_area_check_sums_each_cluster_as_alone():
    """:func:`drawn._area_differs` (every cluster's triangles at once) decides as the check of
    one cluster at a time did, from the same sums to the bit: clusters of 1 to 40 triangles,
    their areas given exactly, a little off, and off by more than the tolerance."""
    from hemicube_radiosity.core.form_factors import drawn
    rng = np.random.default_rng(2)
    pos = rng.normal(size=(500, 3)) * 10 ** rng.uniform(-2, 2, (500, 1))
    tris = [rng.integers(0, 500, (int(rng.integers(1, 41)), 3)) for _ in range(300)]
    alone = []
    for t in tris:
        p = pos[t]
        alone.append(0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum())
    alone = np.array(alone)
    areas = alone * rng.choice([1.0, 1 + 1e-12, 1 + 1e-6, 1 - 1e-6], size=len(alone))
    flat, kt, ks = np.concatenate(tris), np.repeat(np.arange(len(tris)), [len(t) for t in tris]), np.arange(len(tris))
    wrong = drawn._area_differs(pos, flat, kt, ks, areas)
    np.testing.assert_array_equal(wrong, np.abs(alone - areas) > 1e-9 * areas)
    assert 100 < wrong.sum() < 200
    exact = drawn._area_differs(pos, flat, kt, ks, alone)
    assert not exact.any()


def test_every_loop_clipped_at_once_as_one_at_a_time():
    """:func:`drawn._ear_clip_loops` (the fans of convex loops found for many loops at once)
    gives each loop's triangles, in order, as :func:`drawn._ear_clip` of the loop alone, and
    fails the same loops: convex polygons (some with collinear or repeated vertices, either
    winding), star-shaped and self-crossing ones, degenerate ones, up to 60 vertices."""
    from hemicube_radiosity.core.form_factors import drawn
    rng = np.random.default_rng(5)
    pos, loops, normals = [], [], []
    for i in range(600):
        m = int(rng.integers(3, 61 if i % 10 == 0 else 9))
        kind = i % 6
        ang = np.sort(rng.uniform(0, 2 * np.pi, m))
        r = np.ones(m) if kind in (0, 1) else rng.uniform(0.3, 1.0, m)
        xy = np.stack([r * np.cos(ang), r * np.sin(ang)], 1)
        if kind == 1 and m > 4:                       # a vertex on a side, and one repeated
            xy[2] = 0.5 * (xy[1] + xy[3])
            xy[m - 1] = xy[m - 2]
        if kind == 3:
            xy = xy[rng.permutation(m)]
        if kind == 4:
            xy[:] = xy[:1] + rng.uniform(0, 1, (m, 1)) * (xy[1] - xy[0])    # all on one line
        if kind == 5:
            xy = xy[::-1]
        axis = int(rng.integers(3))
        p3 = np.insert(xy, axis, rng.normal(), axis=1)
        n = np.zeros(3)
        n[axis] = rng.choice([-1.0, 1.0])
        loops.append(np.arange(m) + sum(len(q) for q in pos))
        pos.append(p3)
        normals.append(n + rng.normal(scale=0.1, size=3))
    pos = np.concatenate(pos)
    tris, tri_loop, bad = drawn._ear_clip_loops(pos, np.concatenate(loops), np.array([len(L) for L in loops]),
                                                np.array(normals))
    for l, (L, n) in enumerate(zip(loops, normals)):
        alone = drawn._ear_clip(pos, list(L), n)
        assert bad[l] == (alone is None)
        if alone is not None:
            np.testing.assert_array_equal(tris[tri_loop == l], alone)
    assert 50 < bad.sum() < 500 and (tri_loop[1:] >= tri_loop[:-1]).all()


def test_outline_loops_found_at_once_as_walked_one_cluster_at_a_time():
    """:func:`drawn._outline_loops` (the loops of every cluster whose boundary is simple cycles
    found at once) gives the loops :func:`drawn._loops` walks cluster by cluster, in order: grids
    of squares cut into random clusters (some with several loops, holes, corners touching)."""
    from hemicube_radiosity.core.form_factors import drawn
    rng = np.random.default_rng(3)
    for trial in range(6):
        n = 12
        ij = np.stack(np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij"), -1).reshape(-1, 2)
        pos = np.column_stack([ij, np.zeros(len(ij))]).astype(float)
        v = lambda i, j: i * (n + 1) + j                                      # noqa: E731
        quads = np.array([[v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)] for i in range(n) for j in range(n)])
        keep = rng.uniform(size=len(quads)) > 0.15 * (trial % 3)
        quads = quads[keep]
        if trial % 2:                                             # some squares as two triangles
            tri = rng.uniform(size=len(quads)) < 0.5
            t = quads[tri]
            quads = np.concatenate([quads[~tri],
                                    np.column_stack([t[:, [0, 1, 2]], np.full(len(t), -1)]),
                                    np.column_stack([t[:, [0, 2, 3]], np.full(len(t), -1)])])
        of = rng.integers(0, 9, len(quads))
        K = int(of.max()) + 1
        ok = np.ones(K, bool)
        normals = np.tile([0.0, 0.0, 1.0], (K, 1))
        flat, lens, l_cl = drawn._outline_loops(quads, of, ok, pos, normals)
        # as walked before: cluster by cluster, the boundary's edges by (cluster, vertex)
        want = []
        for k in range(K):
            p = quads[of == k]
            edges = [(int(r[c]), int(r[(c + 1) % (3 if r[3] < 0 else 4)])) for r in p for c in range(3 if r[3] < 0 else 4)]
            und = [tuple(sorted(e)) for e in edges]
            bnd = sorted(e for e in edges if und.count(tuple(sorted(e))) == 1)
            if len(bnd) < 3 or any(und.count(u) > 2 or (und.count(u) == 2 and edges.count(e) == 2)
                                   for u, e in zip(und, edges)):
                continue
            got = drawn._loops([e[0] for e in bnd], [e[1] for e in bnd], pos, normals[k])
            want += [(k, L) for L in (got or [])]
        assert [int(c) for c in l_cl] == [k for k, _ in want]
        np.testing.assert_array_equal(lens, [len(L) for _, L in want])
        np.testing.assert_array_equal(flat, [x for _, L in want for x in L])
