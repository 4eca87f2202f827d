"""Patch builder: areas, normals, shared vertices, n-gons, errors."""
import re
from collections import Counter

import numpy as np
import pytest

from hemicube_radiosity.core.mesh.patches import MeshInput, PatchError
from hemicube_radiosity.core.mesh.subdivide import build_patches, keeps_faces_whole
from hemicube_radiosity.core.builtin_scenes import box, cornell_box, tessellate


def edge_use(ps):
    c = Counter()
    for p in ps.polys:
        k = 4 if p[3] >= 0 else 3
        for i in range(k):
            c[tuple(sorted((int(p[i]), int(p[(i + 1) % k]))))] += 1
    return c


def test_unit_quad_grid():
    m = MeshInput.from_faces([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2, 3]])
    ps = build_patches(m, 0.25)
    assert len(ps) == 16 and len(ps.verts) == 25
    np.testing.assert_allclose(ps.areas, 1 / 16)
    np.testing.assert_allclose(ps.normals, [[0, 0, 1]] * 16, atol=1e-12)
    # centres on the 1/8 lattice
    np.testing.assert_allclose(np.sort(np.unique(ps.centers[:, 0].round(12))), [0.125, 0.375, 0.625, 0.875])


def test_rectangle_gets_square_patches():
    m = MeshInput.from_faces([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]], [[0, 1, 2, 3]])
    ps = build_patches(m, 0.5)
    assert len(ps) == 4 * 2
    np.testing.assert_allclose(ps.areas, 0.25)


def test_triangle_subdivision_conserves_area_and_normal():
    m = MeshInput.from_faces([[0, 0, 0], [3, 0, 0], [0, 4, 0]], [[0, 1, 2]])
    ps = build_patches(m, 1.0)
    n = 5  # longest edge 5 -> 5 segments on every edge
    assert len(ps) == n * n
    np.testing.assert_allclose(ps.areas, 6.0 / (n * n))
    assert np.all(ps.nsides == 3)
    np.testing.assert_allclose(ps.normals[:, 2], 1.0)


def test_closed_box_stays_watertight_with_uneven_edges():
    ps = build_patches(box((0, 0, 0), (2.0, 1.0, 0.7)), 0.3)
    # box faces have their own vertices, so each face is a separate grid: every interior edge used twice
    np.testing.assert_allclose(ps.areas.sum(), 2 * (2 * 1 + 2 * 0.7 + 1 * 0.7))
    # outward normals
    assert np.all(np.einsum("ij,ij->i", ps.normals, ps.centers - [1.0, 0.5, 0.35]) > 0)


def test_shared_mesh_edges_are_cut_at_the_same_points():
    # a cube whose 8 vertices are shared by its 6 faces, stretched so edges differ in length
    V = np.array([[x, y, z] for x in (0, 2) for y in (0, 1) for z in (0, 0.7)], float)

    def i(x, y, z):
        return x * 4 + y * 2 + z

    faces = [[i(0, 0, 0), i(0, 1, 0), i(1, 1, 0), i(1, 0, 0)], [i(0, 0, 1), i(1, 0, 1), i(1, 1, 1), i(0, 1, 1)],
             [i(0, 0, 0), i(1, 0, 0), i(1, 0, 1), i(0, 0, 1)], [i(0, 1, 0), i(0, 1, 1), i(1, 1, 1), i(1, 1, 0)],
             [i(0, 0, 0), i(0, 0, 1), i(0, 1, 1), i(0, 1, 0)], [i(1, 0, 0), i(1, 1, 0), i(1, 1, 1), i(1, 0, 1)]]
    ps = build_patches(MeshInput.from_faces(V, faces), 0.3)
    uses = edge_use(ps)
    assert set(uses.values()) == {2}, "a closed mesh must stay closed: every patch edge shared by two patches"
    # Euler characteristic of a sphere-like surface
    assert len(ps.verts) - len(uses) + len(ps) == 2


def test_mixed_triangles_and_quads_conform():
    V = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0.5, 0]]
    ps = build_patches(MeshInput.from_faces(V, [[0, 1, 2, 3], [1, 4, 2]]), 0.2)
    uses = edge_use(ps)
    interior = [k for k, v in uses.items() if v == 2]
    boundary = [k for k, v in uses.items() if v == 1]
    assert all(v in (1, 2) for v in uses.values())
    # boundary length equals the outline's perimeter: no cracks (T-junctions would add boundary edges)
    L = sum(np.linalg.norm(ps.verts[a] - ps.verts[b]) for a, b in boundary)
    perim = 1 + 1 + 1 + 2 * np.hypot(1, 0.5)
    assert L == pytest.approx(perim, rel=1e-12)
    assert interior
    np.testing.assert_allclose(ps.areas.sum(), 1.5, rtol=1e-12)


def _irregular_plane(rng):
    """A 10 x 10 plane on a grid of random spacing, each cell a quad or one of its two
    triangulations: neighbours of every size and shape, sharing their vertices."""
    n = rng.integers(2, 8)
    xs = np.sort(np.concatenate([[0, 10], rng.uniform(0, 10, n)]))
    ys = np.sort(np.concatenate([[0, 10], rng.uniform(0, 10, n)]))
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    v = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], 1)
    N, faces = len(ys), []
    for i in range(len(xs) - 1):
        for j in range(N - 1):
            a = i * N + j
            q = [a, a + N, a + N + 1, a + 1]
            kind = rng.integers(3)
            faces += [q] if kind == 0 else ([q[:3], [q[0], q[2], q[3]]] if kind == 1 else [[q[0], q[1], q[3]], q[1:]])
    return MeshInput.from_faces(v, faces)


@pytest.mark.parametrize("seed", range(12))
def test_faces_of_any_shape_are_cut_without_cracks_or_overlaps(seed):
    """Each face is cut as a grid of its own whose points on a side are that side's own cuts:
    every patch edge inside the plane is used twice, once each way (no T-junction, no overlap),
    the outline is the plane's, the area is the plane's and every patch faces up."""
    m = _irregular_plane(np.random.default_rng(seed))
    for size in (0.3, 1.0, 2.7):
        ps = build_patches(m, size)
        directed = Counter()
        for p in ps.polys:
            k = 4 if p[3] >= 0 else 3
            for i in range(k):
                directed[int(p[i]), int(p[(i + 1) % k])] += 1
        assert max(directed.values()) == 1
        outline = [e for e in directed if e[::-1] not in directed]
        assert sum(np.linalg.norm(ps.verts[a] - ps.verts[b]) for a, b in outline) == pytest.approx(40.0, rel=1e-12)
        assert ps.areas.sum() == pytest.approx(100.0, rel=1e-12)
        assert np.all(ps.areas > 0) and np.all(ps.normals[:, 2] > 1 - 1e-12)


def test_one_long_edge_does_not_cut_a_whole_triangle_mesh():
    """A 10 m sliver beside a grid of 5 cm triangles, at a 1 m patch size: the sliver is cut
    along its length, the triangles stay whole. (Equalising every triangle's sides spread the
    sliver's ten segments over the whole connected grid: 100 pieces a triangle.)"""
    g = np.linspace(0.0, 1.0, 21)
    X, Y = np.meshgrid(g, g, indexing="ij")
    v = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], 1)
    faces = []
    for i in range(20):
        for j in range(20):
            a = i * 21 + j
            faces += [[a, a + 21, a + 22], [a, a + 22, a + 1]]
    tip = len(v)
    v = np.vstack([v, [[0.025, -10.0, 0.0]]])
    faces.append([0, tip, 21])                   # the sliver shares the grid's first 5 cm edge
    ps = build_patches(MeshInput.from_faces(v, faces), 1.0)
    sliver = ps.source_face == len(faces) - 1
    assert (~sliver).sum() == 800                 # the grid's triangles, whole
    assert 10 <= sliver.sum() <= 121              # the sliver cut along its ten metres (11 x 11 at most)
    assert ps.areas[sliver].sum() == pytest.approx(0.25, rel=1e-12)


def test_convex_ngon_and_concave_ngon():
    pent = [[0, 0, 0], [2, 0, 0], [2.5, 1, 0], [1, 2, 0], [-0.5, 1, 0]]
    ps = build_patches(MeshInput.from_faces(pent, [[0, 1, 2, 3, 4]]), None)
    assert len(ps) == 5 and np.all(ps.nsides == 4)
    x, y = np.array(pent)[:, 0], np.array(pent)[:, 1]
    shoelace = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    assert ps.areas.sum() == pytest.approx(shoelace, rel=1e-12)
    L = [[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0]]
    ps = build_patches(MeshInput.from_faces(L, [[0, 1, 2, 3, 4, 5]]), 0.5)
    assert ps.areas.sum() == pytest.approx(3.0, rel=1e-12)
    assert np.all(ps.normals[:, 2] > 0.999)
    # no patch centre falls in the notch of the L
    assert not np.any((ps.centers[:, 0] > 1) & (ps.centers[:, 1] > 1))


def test_owner_and_source_face_and_materials():
    meshes = cornell_box()
    ps = build_patches(meshes, 0.5)
    assert ps.object_names == [m.name for m in meshes]
    red = ps.owner == ps.object_names.index("RedWall")
    np.testing.assert_allclose(ps.rho[red], [[0.63, 0.065, 0.05]] * int(red.sum()))
    light = ps.owner == ps.object_names.index("Light")
    assert np.all(ps.emission[light] > 0) and np.all(ps.emission[~light] == 0)
    for oi, m in enumerate(meshes):
        assert ps.source_face[ps.owner == oi].max() < len(m.face_offsets) - 1


@pytest.mark.parametrize("bad, message", [
    (dict(faces=[[0, 1]]), "fewer than 3"),
    (dict(faces=[[0, 1, 7]]), "does not exist"),
    (dict(rho=(1.0, 0.5, 0.5)), "reflectivity"),
    (dict(emission=(-1, 0, 0)), "negative emission"),
    (dict(verts=[[0, 0, 0], [1, 0, 0], [np.nan, 1, 0]]), "not finite"),
    (dict(verts=[[0, 0, 0], [1, 0, 0], [2, 0, 0]]), "zero area"),
])
def test_bad_input_names_object_and_problem(bad, message):
    args = dict(verts=[[0, 0, 0], [1, 0, 0], [0, 1, 0]], faces=[[0, 1, 2]], rho=(0.5,) * 3, emission=(0,) * 3)
    args.update(bad)
    m = MeshInput.from_faces(args["verts"], args["faces"], args["rho"], args["emission"], name="Wall.001")
    with pytest.raises(PatchError, match=message) as e:
        build_patches(m, 0.5)
    assert "Wall.001" in str(e.value)


def scaled_room(scale, float32=False):
    """closed_box of side ``scale`` (uneven emission so the radiosities vary over the room)."""
    from hemicube_radiosity.core.builtin_scenes import closed_box

    m = closed_box((scale, 1.3 * scale, 0.8 * scale), rho=(0.6, 0.5, 0.4), emission=(0.0, 0.0, 0.0))[0]
    m.face_emission[5] = (2.0, 2.0, 2.0)             # one wall lights the room
    if float32:                                       # what Blender hands over
        m.verts = m.verts.astype(np.float32)
    return [m]


@pytest.mark.parametrize("float32", [False, True])
def test_same_patches_at_any_scale(float32):
    # 1 mm cut at 0.125 mm measured 8.0000004 patches in float32 and was cut 9 x 9
    counts = {s: build_patches(scaled_room(s, float32), 0.125 * s) for s in (1e-3, 1.0, 1e3)}
    ref = counts[1.0]
    assert len(ref) == 2 * (8 * 11 + 8 * 7 + 11 * 7)
    for s, ps in counts.items():
        assert len(ps) == len(ref) and len(ps.verts) == len(ref.verts), s
        np.testing.assert_allclose(ps.areas / s ** 2, ref.areas, rtol=1e-5)
        np.testing.assert_allclose(ps.centers / s, ref.centers, rtol=0, atol=1e-6)


def test_same_patches_far_from_the_origin():
    # float32 rounding grows with the coordinates, not with the edge: the count must not change
    m = box((1000.0, 1000.0, 1000.0), (1001.0, 1001.0, 1001.0), inward=True)
    m.verts = m.verts.astype(np.float32)
    assert len(build_patches(m, 0.125)) == 6 * 64


def test_tiny_mesh_keeps_its_faces_and_concave_stays_concave():
    # no absolute area floor or convexity epsilon: a micrometre L-shape cuts like a metre one
    L = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0]], float)
    for s in (1e-6, 1.0, 1e6):
        ps = build_patches(MeshInput.from_faces(L * s, [[0, 1, 2, 3, 4, 5]]), 0.5 * s)
        assert len(ps) == len(build_patches(MeshInput.from_faces(L, [[0, 1, 2, 3, 4, 5]]), 0.5))
        assert ps.areas.sum() == pytest.approx(3.0 * s * s, rel=1e-12)
        assert not np.any((ps.centers[:, 0] > s) & (ps.centers[:, 1] > s))


def _bakes(scales):
    from hemicube_radiosity.core.pipeline import BakeSettings, bake

    return {s: bake(scaled_room(s, float32=True), BakeSettings(patch_size=0.125 * s, element_size=None))
            for s in scales}


def _assert_same(res, atol_rel):
    ref = res[1.0]
    scale = np.abs(ref.solution.B).max()
    for s, r in res.items():
        assert r.solution.B.shape == ref.solution.B.shape, s
        np.testing.assert_allclose(r.solution.B, ref.solution.B, rtol=0, atol=atol_rel * scale, err_msg=str(s))
        np.testing.assert_allclose(r.vertex_radiosity, ref.vertex_radiosity, rtol=0, atol=atol_rel * scale,
                                   err_msg=str(s))


def test_bake_is_scale_invariant():
    # powers of two scale every float exactly: the bake must then be the same to round-off
    _assert_same(_bakes((2.0 ** -10, 1.0, 2.0 ** 10)), 1e-6)


def test_bake_is_scale_invariant_to_1e4_at_decimal_scales():
    # a room corner's edge through a pixel centre went to whichever wall's depth rounded nearer
    # (an F entry moved by 0.002); vertices on a sub-pixel grid and a fill rule decide it the
    # same at every scale (measured 1.5e-8 of max B)
    _assert_same(_bakes((1e-3, 1.0, 1e3)), 1e-4)


def test_corners_of_some_patches_are_those_of_all():
    """``corners(ids)`` is ``corners()[ids]``, triangles repeating their last corner, for a set
    of quads and triangles, any order and repeats."""
    from hemicube_radiosity.core.builtin_scenes import tessellate
    p = build_patches(cornell_box() + tessellate(cornell_box(), 2), None)
    tri = p.polys[:, 3] < 0
    assert tri.any() and (~tri).any()
    c = p.corners()
    assert np.array_equal(c[tri, 3], c[tri, 2]) and np.array_equal(c[~tri, 3], p.verts[p.polys[~tri, 3]])
    ids = np.array([len(p) - 1, 0, 3, 3, int(np.flatnonzero(tri)[0])])
    assert np.array_equal(p.corners(ids), c[ids]) and p.corners(np.zeros(0, int)).shape == (0, 4, 3)


def test_take_by_rows_or_mask_keeps_see_through_only_when_asked():
    """``take(rows)`` is every per-patch field at ``rows`` over the shared vertices, the same for
    the rows as ints and as a bool mask (in index order); see-through faces only with
    ``see_through=True``, and then the subset's mask is the set's at those rows (the faces are
    read by owner and source face)."""
    from hemicube_radiosity.core.light.transmit import Transmit
    floor = MeshInput.from_faces([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0]], [[0, 1, 2, 3]], name="floor")
    leaf = MeshInput.from_faces([[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], [[0, 1, 2, 3]], name="leaf")
    leaf.transmit = Transmit(np.array([0.5]))
    p = build_patches([floor, leaf], 0.5)
    mask = np.zeros(len(p), bool)
    mask[[1, 4, len(p) - 1]] = True
    rows = np.flatnonzero(mask)
    a, b = p.take(rows), p.take(mask)
    for f in ("polys", "centers", "normals", "areas", "rho", "emission", "owner", "source_face"):
        assert np.array_equal(getattr(a, f), getattr(p, f)[rows]) and np.array_equal(getattr(b, f), getattr(p, f)[rows])
    assert a.verts is p.verts and a.object_names == ["floor", "leaf"] and a.object_names is not p.object_names
    assert p.see_through is not None and a.see_through is None
    kept = p.take(mask, see_through=True)
    assert np.array_equal(kept.see_through.patch_mask(kept), p.see_through.patch_mask(p)[rows])
    assert kept.see_through.patch_mask(kept).tolist() == [False, False, True]
    assert len(p.take(np.zeros(0, np.int64))) == 0 and len(p.take(np.zeros(len(p), bool))) == 0


def _same_patches(a, b):
    return all(np.array_equal(getattr(a, f), getattr(b, f))
               for f in ("verts", "polys", "centers", "normals", "areas", "rho", "emission", "owner", "source_face"))


def _ngon_scene():
    """A convex hexagon (split into quads around its centre, its edges halved) beside a
    triangle that shares one of its edges (re-cut at that midpoint), and a concave L (ear
    clipped, edges kept)."""
    ang = np.linspace(0, 2 * np.pi, 6, endpoint=False)
    hexa = np.stack([0.4 * np.cos(ang), 0.4 * np.sin(ang), np.zeros(6)], 1)
    verts = np.concatenate([hexa, [[0.6, 0.3, 0.0]]])
    L = [[0, 0, 1], [2, 0, 1], [2, 1, 1], [1, 1, 1], [1, 2, 1], [0, 2, 1]]
    return [MeshInput.from_faces(verts, [list(range(6)), [0, 6, 1]]), MeshInput.from_faces(np.array(L) * 0.2, [list(range(6))])]


@pytest.mark.parametrize("scene", ["dense box", "n-gons", "float32 far away"])
def test_keeps_faces_whole_exactly_when_building_cuts_nothing(scene):
    """keeps_faces_whole(meshes, size) measures the edges instead of building: it must say True
    exactly when build_patches at that size makes the faces' own PatchSet, array for array
    (then a bake reuses the faces it built once), around the sizes where the answer turns."""
    if scene == "dense box":
        meshes = tessellate(cornell_box(), 6)
    elif scene == "n-gons":
        meshes = _ngon_scene()
    else:
        m = box((1000.0, 1000.0, 1000.0), (1001.0, 1001.0, 1001.0), inward=True)
        m.verts = m.verts.astype(np.float32)
        meshes = [m]
    faces = build_patches(meshes, None)
    edges = np.concatenate([np.linalg.norm(np.roll(faces.verts[p[p >= 0]], -1, axis=0) - faces.verts[p[p >= 0]], axis=1)
                            for p in faces.polys])
    longest = float(edges.max())
    sizes = [longest * f for f in (0.3, 0.5, 0.99, 1 - 1e-9, 1.0, 1 + 1e-9, 1.01, 2.0)] + [0.0, None]
    answers = []
    for size in sizes:
        whole = keeps_faces_whole(meshes, size)
        assert whole == _same_patches(build_patches(meshes, size), faces), size
        answers.append(whole)
    assert answers[0] is False and answers[-3] is True      # both answers are asked for


def test_keeps_faces_whole_names_the_object_as_build_patches_does():
    bad = MeshInput.from_faces([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 5]], name="Broken")
    with pytest.raises(PatchError, match="'Broken'.*vertex that does not exist"):
        keeps_faces_whole([bad], 0.1)


@pytest.mark.parametrize("corner, message", [
    (np.full((3, 3), 0.5), "corner_rho must have shape (4, 3)"),
    (np.full((4, 3), 1.0), "corner rho must be finite and in [0, 1)"),
    (np.full((4, 3), np.nan), "corner rho must be finite"),
])
def test_corner_values_are_checked_as_the_faces_are(corner, message):
    """A texture's values at the corners (MeshInput.corner_rho) of the wrong shape read past the
    corners in the output stage (an IndexError in core/output/corners.py); out of range, they
    lit vertices brighter than any source. They are refused with the faces' own checks."""
    m = MeshInput.from_faces([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [[0, 1, 2, 3]], name="tex")
    m.corner_rho = corner
    with pytest.raises(PatchError, match=re.escape(f"'tex': {message}")):
        build_patches([m], 0.5)
