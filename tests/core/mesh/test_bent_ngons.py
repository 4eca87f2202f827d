"""N-gons that are not planar are cut along the triangles given with them
(``MeshInput.face_triangles``: Blender's loop triangles, the surface Cycles renders); planar ones
keep the core's own cut (core/mesh/ngons.py)."""
from collections import Counter

import numpy as np

from hemicube_radiosity.core.mesh.backs import with_backs
from hemicube_radiosity.core.mesh.ngons import BENT, WARPED, bent_faces
from hemicube_radiosity.core.mesh.patches import MeshInput, meshes_key
from hemicube_radiosity.core.mesh.subdivide import build_patches


def _octagon(fold=0.3):
    """A regular octagon of radius 1 about the z axis, folded along y: z = fold |x|."""
    a = 2 * np.pi * np.arange(8) / 8 + np.pi / 8
    x, y = np.cos(a), np.sin(a)
    return np.column_stack([x, y, fold * np.abs(x)])


# a strip, not a fan from corner 0: 0 1 7 | 1 6 7 | 1 2 6 | 2 5 6 | 2 3 5 | 3 4 5
STRIP = np.array([[0, 1, 7], [1, 6, 7], [1, 2, 6], [2, 5, 6], [2, 3, 5], [3, 4, 5]])


def _tri_area(p):
    return 0.5 * np.linalg.norm(np.cross(p[1] - p[0], p[2] - p[0]))


def _same_cycle(a, b):
    """True when the corner lists a and b (k, 3) are the same up to a cyclic shift."""
    return any(np.allclose(np.roll(a, s, axis=0), b, atol=1e-12) for s in range(len(a)))


def test_a_folded_octagon_is_cut_along_its_given_triangles():
    """Exactly the six given triangles, corner for corner in their order, each of its own area
    (half the cross product of two sides), normal to its own plane; no vertex added."""
    v = _octagon()
    m = MeshInput.from_faces(v, [range(8)])
    m.face_triangles = np.column_stack([np.zeros(6, np.int64), STRIP])
    ps = build_patches(m, None)
    assert len(ps) == 6 and np.all(ps.polys[:, 3] == -1) and len(ps.verts) == 8
    got = [ps.verts[p[:3]] for p in ps.polys]
    for t in STRIP:
        want = v[t]
        k = [i for i, g in enumerate(got) if _same_cycle(g, want)]
        assert len(k) == 1, t
        np.testing.assert_allclose(ps.areas[k[0]], _tri_area(want), rtol=1e-12)
        n = np.cross(want[1] - want[0], want[2] - want[0])
        np.testing.assert_allclose(ps.normals[k[0]], n / np.linalg.norm(n), atol=1e-12)
    # the two triangles wholly on the side x > 0 (0 1 7, 1 6 7) lie in the plane z = 0.3 x:
    # their flat areas times sqrt(1 + 0.3^2)
    flat = _octagon(0.0)
    on_one_side = [i for i, g in enumerate(got) if any(_same_cycle(g, v[t]) for t in STRIP[:2])]
    np.testing.assert_allclose(ps.areas[on_one_side].sum(),
                               sum(_tri_area(flat[t]) for t in STRIP[:2]) * np.sqrt(1.09), rtol=1e-12)
    # the own cut (no triangles given) makes another surface: 8 quads about the centre
    own = build_patches(MeshInput.from_faces(v, [range(8)]), None)
    assert len(own) == 8 and len(own.verts) == 8 + 1 + 8
    assert abs(own.areas.sum() - ps.areas.sum()) > 1e-3


def test_only_folded_ngons_are_bent_and_planar_ones_keep_their_cut():
    """bent_faces: the folded octagon (corners 0.09 off its mean plane, 0.045 of its size) is
    bent; the flat one, turned and moved 1000 units away in float32, is not (float rounding
    is 1e-7 of the size, a thousandth of BENT); a face of 0.5 x BENT is not, 2 x BENT is;
    triangles never are, nor a planar quad."""
    rng = np.random.default_rng(4)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    flat = (_octagon(0.0) @ q.T + 1000.0).astype(np.float32).astype(np.float64)
    size = np.linalg.norm(np.ptp(_octagon(0.0), axis=0))      # the box diagonal, 2.613
    # one corner lifted by h off the plane of the others: the mean of the corners is h / 8
    # high, so that corner lies (7/8) h off the mean plane (a hair less, the plane tilts)
    lifted = []
    for share in (0.5, 2.0):
        w = _octagon(0.0)
        w[3, 2] = share * BENT * size / (7 / 8)
        lifted.append(w)
    tri = np.array([[0, 0, 0], [1, 0, 0.3], [0, 1, 0]])
    verts = np.concatenate([_octagon(), flat, *lifted, tri, _octagon()[:4]])
    faces = [range(0, 8), range(8, 16), range(16, 24), range(24, 32), range(32, 35), range(35, 39)]
    off = np.concatenate([[0], np.cumsum([len(f) for f in faces])])
    idx = np.concatenate([list(f) for f in faces])
    assert bent_faces(verts, off, idx).tolist() == [True, False, False, True, False, False]
    # a planar octagon keeps the cut it had: its 8 quads about its centre, whatever the other
    # face of the mesh is given
    m = MeshInput.from_faces(np.concatenate([_octagon(0.0), _octagon() + [3, 0, 0]]), [range(8), range(8, 16)])
    alone = build_patches(MeshInput.from_faces(_octagon(0.0), [range(8)]), None)
    m.face_triangles = np.column_stack([np.ones(6, np.int64), STRIP])
    both = build_patches(m, None)
    mine = both.source_face == 0
    np.testing.assert_array_equal(both.verts[both.polys[mine]], alone.verts[alone.polys])
    assert (both.source_face == 1).sum() == 6


def test_a_warped_quad_is_cut_as_blender_triangulates_it():
    """A quad counts as bent only when warped by more than WARPED of its size (a curved surface's
    quads stay bilinear pieces); given its triangles it is cut into exactly those two."""
    size = np.sqrt(2.0)                                   # the unit square's diagonal
    quads = []
    for share in (0.5, 2.0):
        h = share * WARPED * size * 4                     # corner 2 up h: the corners lie h / 4 off
        quads.append(np.array([[0, 0, 0], [1, 0, 0], [1, 1, h], [0, 1, 0]], float))
    verts = np.concatenate(quads)
    off, idx = np.array([0, 4, 8]), np.arange(8)
    assert bent_faces(verts, off, idx).tolist() == [False, True]
    m = MeshInput.from_faces(quads[1], [range(4)])
    m.face_triangles = np.array([[0, 0, 1, 3], [0, 1, 2, 3]])
    ps = build_patches(m, None)
    assert len(ps) == 2 and np.all(ps.polys[:, 3] == -1) and len(ps.verts) == 4
    np.testing.assert_allclose(np.sort(ps.areas), np.sort([0.5, _tri_area(quads[1][[1, 2, 3]])]), rtol=1e-12)


def test_a_long_thin_quad_is_warped_against_its_width():
    """The warp of a quad is judged against its width where that is less than its size: the
    corners' distance off the mean plane over min(size, 2 area / size), 2 area / size being the
    size itself for a square. A strip 90 times longer than wide (a bevel: 4.5 m by 5 cm), its
    corners h / 4 off for h / 4 = 0.1 WARPED x its size, is bent (its width's 9 WARPED); the same
    at 0.1 WARPED x its width is not; a square keeps its answer either side of WARPED."""
    length, width = 4.5, 0.05
    size = np.hypot(length, width)
    quads = []
    for share, L, W, s in ((0.1, length, width, size), (0.1, length, width, width * length / size),
                           (0.9, 1.0, 1.0, np.sqrt(2.0)), (1.1, 1.0, 1.0, np.sqrt(2.0))):
        h = share * WARPED * s * 4                        # corner 2 up h: the corners lie h / 4 off
        quads.append(np.array([[0, 0, 0], [L, 0, 0], [L, W, h], [0, W, 0]], float))
    verts = np.concatenate(quads)
    off, idx = np.arange(0, 17, 4), np.arange(16)
    assert bent_faces(verts, off, idx).tolist() == [True, False, False, True]


def test_a_neighbour_s_fan_leaves_no_t_junction_on_the_given_triangles():
    """A flat hexagon fanned about its centre beside the folded octagon, sharing its edge 1-2:
    the edge's midpoint re-cuts the triangle on that edge, so every inner edge is used by two
    patches and only the outline's (the two rings less the shared edge) by one; the octagon's
    area is its triangles'."""
    v = _octagon()
    a, b = v[1], v[2]
    radial = np.array([(a + b)[0], (a + b)[1], 0.0])
    radial /= np.linalg.norm(radial)
    # 6 corners, convex, in the plane through the shared edge and the radial direction
    new = [a + 0.5 * radial + 0.25 * (a - b), a + radial, b + radial, b + 0.5 * radial + 0.25 * (b - a)]
    verts = np.concatenate([v, np.array(new)])
    ring = [2, 1, 8, 9, 10, 11]
    m = MeshInput.from_faces(verts, [range(8), ring])
    m.face_triangles = np.column_stack([np.zeros(6, np.int64), STRIP])
    ps = build_patches(m, None)
    use = Counter()
    for p in ps.polys:
        k = 4 if p[3] >= 0 else 3
        for i in range(k):
            use[tuple(sorted((int(p[i]), int(p[(i + 1) % k]))))] += 1
    assert set(use.values()) <= {1, 2}
    outline = [e for e, n in use.items() if n == 1]
    length = sum(np.linalg.norm(ps.verts[i] - ps.verts[j]) for i, j in outline)
    ring_len = lambda p: sum(np.linalg.norm(p[i] - p[(i + 1) % len(p)]) for i in range(len(p)))
    want = ring_len(v) + ring_len(verts[ring]) - 2 * np.linalg.norm(a - b)
    np.testing.assert_allclose(length, want, rtol=1e-12)
    np.testing.assert_allclose(ps.areas[ps.source_face == 0].sum(),
                               sum(_tri_area(v[t]) for t in STRIP), rtol=1e-12)


def test_backs_carry_the_triangles_turned_around_and_the_key_follows_them():
    """A folded octagon facing down alone under a lit world is open: its back (the ring reversed
    after its first corner, a hair behind, facing the sky) is cut along the same six triangles,
    each turned around; and meshes_key changes with the triangles."""
    v = _octagon()
    m = MeshInput.from_faces(v, [range(7, -1, -1)])          # facing down: corner j is vertex 7 - j
    key = meshes_key([m])
    tris = (7 - STRIP)[:, ::-1]                               # the strip, counter-clockwise from below
    m.face_triangles = np.column_stack([np.zeros(6, np.int64), tris])
    front = build_patches(m, None)
    assert len(front) == 6 and np.all(front.normals[:, 2] < 0)
    assert meshes_key([m]) != key
    both = with_backs([m], world=np.ones(3))
    assert len(both) == 2 and both[1].back_of == 0
    ps = build_patches(both, None)
    back = ps.polys[ps.owner == 1]
    assert len(back) == 6
    for t in STRIP:                                          # counter-clockwise from above
        want = v[t]
        found = [p for p in back if any(np.all(np.linalg.norm(ps.verts[np.roll(p[:3], s)] - want, axis=1) < 1e-4)
                                        for s in range(3))]
        assert len(found) == 1, t
    nf = ps.normals[ps.owner == 0]
    nb = ps.normals[ps.owner == 1]
    np.testing.assert_allclose(np.sort(nf @ [0, 0, 1]), np.sort(-(nb @ [0, 0, 1])), atol=1e-6)


def test_a_mesh_s_ngons_are_split_once_for_its_read_only_arrays():
    """to_tris_and_quads keeps its split per mesh arrays that cannot change in place (a bake
    cuts the same meshes at several sizes), read only; writable arrays are split every call."""
    from hemicube_radiosity.core.mesh.ngons import to_tris_and_quads

    m = MeshInput.from_faces(_octagon(), [range(8)])
    m.face_triangles = np.column_stack([np.zeros(6, np.int64), STRIP])
    first = to_tris_and_quads(m)
    assert to_tris_and_quads(m) is not first
    for a in (m.verts, m.face_offsets, m.face_indices):
        a.flags.writeable = False
    assert to_tris_and_quads(m) is not to_tris_and_quads(m)      # the triangles still writable
    m.face_triangles.flags.writeable = False
    kept = to_tris_and_quads(m)
    assert to_tris_and_quads(m) is kept and not any(a.flags.writeable for a in kept)
    for a, b in zip(first, kept):
        np.testing.assert_array_equal(a, b)
    # a plain n-gon (no triangles given): the same, its fan's new vertices included
    p = MeshInput.from_faces(_octagon(0.0), [range(8)])
    for a in (p.verts, p.face_offsets, p.face_indices):
        a.flags.writeable = False
    assert to_tris_and_quads(p) is to_tris_and_quads(p) and len(to_tris_and_quads(p)[0]) == 8 + 1 + 8
