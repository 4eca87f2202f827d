"""Lightmap texels from the output elements (``core/output/lightmap.py``), in plain NumPy.

A value linear in position is exact under bilinear interpolation on flat parallelograms, so a
lightmap of two walls meeting at a corner (one quad each, cut into a grid of elements) must read
it at every texel centre; texels around the islands are dilated; nothing an island covers is left
unset; the rasteriser covers a sliver thinner than a texel.
"""
from __future__ import annotations

import numpy as np

from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.output import lightmap as lm


def f(p):
    """A value linear in position, three bands, > 0 on the walls."""
    return np.stack([1 + p[..., 0] + 0.5 * p[..., 2], 2 + 0.3 * p[..., 1], 1.5 + 0.2 * p[..., 2]], -1)


def walls():
    """Two 2 x 1 m walls in one object: floor-like z = 0 (x, y in [0, 2] x [0, 1]) and x = 0
    standing on it; their UV triangles in two islands side by side, and their world triangles."""
    floor = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]], float)
    wall = np.array([[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1]], float)
    verts = np.vstack([floor, wall])
    mesh = MeshInput.from_faces(verts, [[0, 1, 2, 3], [4, 5, 6, 7]], name="walls")
    elements = build_patches([mesh], 0.1)
    uv_floor = np.array([[0.02, 0.02], [0.62, 0.02], [0.62, 0.32], [0.02, 0.32]])
    uv_wall = np.array([[0.70, 0.02], [0.98, 0.02], [0.98, 0.30], [0.70, 0.30]])
    tris = [(0, 1, 2), (0, 2, 3)]
    uv = np.array([[u[i] for i in t] for u in (uv_floor, uv_wall) for t in tris])
    world = np.array([[w[i] for i in t] for w in (floor, wall) for t in tris])
    return elements, uv, world


def corner_values(elements):
    c = elements.corners()                       # (N, 4, 3), a triangle's 4th corner its 3rd
    return f(c)


def test_texels_read_the_elements_exactly():
    elements, uv, world = walls()
    L = lm.bake_lightmap(elements, corner_values(elements), 0, uv, world, 64)
    assert L.size == (64, 64) and L.unset == 0
    tri, bary, inside = lm.rasterize(uv, 64, 64)
    pts, _ = lm.texel_points(world, tri[tri >= 0], bary[tri >= 0])
    want = np.zeros((64, 64, 3))
    want[tri >= 0] = f(pts)
    err = np.abs(L.image[tri >= 0] - want[tri >= 0]).max()
    assert err < 1e-5, err
    # every texel of an island and its margin holds a finite value > 0
    assert np.all(np.isfinite(L.image)) and np.all(L.image[L.filled] > 0)
    assert L.filled[L.covered].all()
    # the margin: 8 texels of dilation around each island, nothing further
    rows, cols = np.nonzero(L.covered)
    assert L.filled[:, :].sum() > L.covered.sum()
    far = np.ones((64, 64), bool)
    far[max(rows.min() - 9, 0):rows.max() + 10, :] = False
    assert not L.filled[far].any()
    assert L.filled[min(rows.max() + 8, 63), cols.min()]


def test_texel_centres_and_orientation():
    # texel (r, c) is centred at ((c + 0.5) / W, (r + 0.5) / H): a triangle covering the lower
    # left half of a 4 x 4 image holds the centres with c + r < 3 (and the diagonal, ties)
    uv = np.array([[[0, 0], [1, 0], [0, 1]]], float)
    tri, bary, inside = lm.rasterize(uv, 4, 4, reach=0.0)
    r, c = np.mgrid[0:4, 0:4]
    assert np.array_equal(inside, (r + c) <= 3)
    np.testing.assert_allclose(bary.sum(-1)[tri >= 0], 1.0)
    # barycentric: the centre (0.5, 0.5) texels -> uv (0.125, 0.125)
    np.testing.assert_allclose(bary[0, 0], [0.75, 0.125, 0.125])


def test_sliver_thinner_than_a_texel_is_covered():
    uv = np.array([[[0.1, 0.5], [0.9, 0.5], [0.9, 0.51]]], float)    # 0.32 texels tall at 32
    tri, bary, inside = lm.rasterize(uv, 32, 32)
    assert (tri >= 0).sum() >= 20 and not inside.any()
    # clamped onto the triangle: barycentric coordinates in [0, 1]
    b = bary[tri >= 0]
    assert b.min() >= 0 and np.allclose(b.sum(1), 1)


def test_dilation_fills_from_neighbours():
    img = np.zeros((5, 5, 1))
    known = np.zeros((5, 5), bool)
    img[2, 2], known[2, 2] = 3.0, True
    out, k = lm.dilate(img, known, passes=1)
    assert k.sum() == 9 and np.all(out[k] == 3.0)
    out, k = lm.dilate(img, known, passes=2)
    assert k.all()


def test_image_size():
    assert lm.image_size(4.0, 32, 1024) == 64
    assert lm.image_size(1e6, 32, 1024) == 1024
    assert lm.image_size(0.0, 32, 1024) == 8


def test_direct_light_at_the_texels_a_step_averaged_over_each_texel():
    """The direct light taken at the texels, the rest interpolated: a light that steps from 0
    to 1 across x = 0.73 on the floor (a hard shadow's edge, between the elements' vertices
    0.1 m apart and off the texel grid) reads 0 or 1 at every texel clear of it, and at the
    texels it crosses the share on its lit side of the square half a texel wide around the
    texel's centre (the box filter Cycles' bake applies), to the 4 x 4 points' resolution; the rest is E + rho * I with E, rho and I
    linear in position, which bilinear interpolation keeps exactly."""
    elements, uv, world = walls()
    c = elements.corners()
    E, rho, I = 0.1 * f(c), np.full(c.shape, 0.5), 0.2 * f(c)
    parts = (E, rho, np.zeros(c.shape), I)
    x0 = 0.73
    seen = []

    def direct(points, normals):
        seen.append(len(points))
        return np.repeat((points[:, :1] > x0) & (normals[:, 2:] > 0.5), 3, axis=1).astype(float)
    size = 64
    L = lm.bake_lightmap(elements, None, 0, uv, world, size, parts=parts, direct=direct, lighting_scale=np.ones((4, 3)))
    tri, bary, inside = lm.rasterize(uv, size, size)
    covered = tri >= 0
    # at the centres, exact at the anchors and at the cells the edge crosses (the rest
    # interpolated: fewer points than texels); then the 4 x 4 points of the texels it crosses
    assert sum(seen[:-1]) < covered.sum() and 0 < seen[-1] <= 16 * 2 * size
    # the points lit and read: a hair (INSET) inside their triangles
    pts, _ = lm.texel_points(world, tri[covered], bary[covered] * (1 - lm.INSET) + lm.INSET / 3)
    img = np.zeros((size, size, 3))
    img[covered] = pts
    # floor texels inside the island whose square lies in one triangle of the floor
    u0, u1, v0, v1 = 0.02 * size, 0.62 * size, 0.02 * size, 0.32 * size     # the floor's UV box, texels
    r, col = np.mgrid[0:size, 0:size]
    inner = inside & (col > u0 + 1) & (col + 1 < u1 - 1) & (r > v0 + 1) & (r + 1 < v1 - 1)
    diag = (r + 0.5 - v0) / (v1 - v0) - (col + 0.5 - u0) / (u1 - u0)      # the quad's diagonal
    inner &= np.abs(diag) * (u1 - u0) > 1.5
    # the exact share with x > x0 (x = 2 (u - u0) / (u1 - u0)) of the square half a texel wide
    # around each texel's centre (Cycles' bake jitters its samples over that: Blender's bake
    # differentials are half the texel's)
    edge = u0 + x0 / 2 * (u1 - u0)
    share = np.clip((col + 0.5 + lm.FOOTPRINT / 2 - edge) / lm.FOOTPRINT, 0, 1)
    want_D = np.repeat(share[..., None], 3, axis=-1)
    rest = 0.1 * f(img) + 0.5 * 0.2 * f(img)
    got_D = (L.image - rest) / 0.5
    crossed = inner & (share > 0) & (share < 1)
    clear = inner & ~crossed
    assert crossed.sum() >= 8 and clear.sum() > 400
    np.testing.assert_allclose(got_D[clear], want_D[clear], atol=1e-4)
    assert np.abs(got_D[crossed] - want_D[crossed]).max() <= 1 / 8 + 1e-6
    # the lighting pass: D + I (albedo scale 1), E and rho left out
    np.testing.assert_allclose(L.lighting[inner], got_D[inner] + 0.2 * f(img)[inner], atol=1e-4)


def test_varying_marks_both_sides_of_a_jump():
    light = np.ones((4, 6, 3))
    light[:, 3:] = 2.0
    known = np.ones((4, 6), bool)
    known[0, 0] = False
    v = lm.varying(light, known)
    assert v[:, 2:4].all() and not v[:, :2].any() and not v[:, 4:].any()
    assert not lm.varying(light * 1.05 ** np.arange(6)[None, :, None] / 2 ** (np.arange(6) >= 3)[None, :, None],
                          known).any()
    # scaled, the same texels; a faint light halving from texel to texel is not marked
    assert np.array_equal(lm.varying(7.5 * light, known), v)
    faint = np.concatenate([light, 1e-3 * 0.5 ** np.arange(6)[None, :, None] * np.ones((2, 6, 3))])
    assert not lm.varying(faint, np.ones((6, 6), bool))[5:].any()        # (row 4 meets row 3)
    # two islands side by side (columns 0-2 on the floor, 3-5 on a wall far away): no jump
    pts = np.zeros((4, 6, 3))
    pts[..., 0] = np.arange(6)[None, :] * 0.1
    pts[:, 3:, 2] = 5.0
    nrm = np.zeros((4, 6, 3))
    nrm[..., 2] = 1.0
    assert not lm.varying(light, known, surface=(pts, nrm, np.full((4, 6), 0.1))).any()
    pts[:, 3:, 2] = 0.0                          # one surface: the jump counts
    assert np.array_equal(lm.varying(light, known, surface=(pts, nrm, np.full((4, 6), 0.1))), v)


def test_a_thin_strip_beside_a_wall_reads_its_own_element():
    """A 2 cm bevel strip, one face 4 m long, along the top edge of a wall modelled as a grid of
    0.1 m faces, its normal 69 degrees from the wall's (a chamfer toward the roof, as Blender's
    Bevel modifier makes one), in one object, neither cut further: the 8 element centres nearest
    a point on the strip are the wall's, and a lookup by position and normal alone reads the
    wall's light there. Each element holds its own face's number (the strip's is 0): with the
    points' face given, every point on the strip reads 0.0."""
    h, w, n, tilt = 1.0, 4.0, 10, np.radians(21.0)
    d = 0.02 * np.array([0.0, np.cos(tilt), np.sin(tilt)])                      # in and up
    a, b = np.array([0, 0, h], float), np.array([w, 0, h], float)
    xs, zs = np.linspace(0, w, 4 * n + 1), np.linspace(0, h, n + 1)
    grid = np.array([[x, 0.0, z] for z in zs for x in xs])                       # faces -y
    k = len(xs)
    wall = [[4 + r * k + c, 4 + r * k + c + 1, 4 + (r + 1) * k + c + 1, 4 + (r + 1) * k + c]
            for r in range(n) for c in range(4 * n)]
    mesh = MeshInput.from_faces(np.vstack([[a, b, b + d, a + d], grid]), [[0, 1, 2, 3]] + wall, name="wall")
    elements = build_patches([mesh], 0)                                          # a patch per face
    values = np.repeat(elements.source_face.astype(float)[:, None, None], 4, axis=1).repeat(3, axis=2)
    rng = np.random.default_rng(3)
    s, r = rng.uniform(0.0, 1.0, (400, 1)), rng.uniform(0.05, 0.95, (400, 1))
    points = a + s * (b - a) + r * d
    normal = np.cross(b - a, d)
    normals = np.tile(normal / np.linalg.norm(normal), (len(points), 1))
    alone = lm.evaluate(elements, values, points, normals, 0)
    assert (alone[:, 0] > 0.5).mean() > 0.5            # without the face: most read the wall
    own = lm.evaluate(elements, values, points, normals, 0, faces=np.zeros(len(points), np.int64))
    np.testing.assert_array_equal(own, 0.0)
    # a point whose face has no element of its own keeps the first answer, not an error
    kept = lm.evaluate(elements, values, points[:5], normals[:5], 0, faces=np.full(5, 10**6, np.int64))
    np.testing.assert_array_equal(kept, alone[:5])


def test_a_triangle_without_area_leaves_its_texels_to_its_neighbours():
    """A quad with two corners at one place (a bevel's collapsed corner) is a triangle and a
    triangle without area; its UV island still spans both halves. The flat half's texels measure
    no point of the surface (Cycles shades them with a NaN normal): they go to the real half
    within reach and to the dilation, so the seam along the diagonal is not dark. Before, they
    were lit with a zero normal: 0.1 (no direct light) beside the real half's 0.6."""
    tri_ = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0]], float)
    mesh = MeshInput.from_faces(tri_, [[0, 1, 2]], name="corner")
    elements = build_patches([mesh], 0.1)
    uv_q = np.array([[0.1, 0.1], [0.9, 0.1], [0.9, 0.5], [0.1, 0.5]])
    world_q = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 0, 0]], float)      # corner 3 on corner 0
    uv = np.array([uv_q[[0, 1, 2]], uv_q[[0, 2, 3]]])
    world = np.array([world_q[[0, 1, 2]], world_q[[0, 2, 3]]])
    assert list(lm.flat_triangles(world)) == [False, True]
    c = elements.corners()
    parts = (np.zeros(c.shape), np.full(c.shape, 0.5), np.zeros(c.shape), np.full(c.shape, 0.2))

    def direct(points, normals):
        return np.repeat(normals[:, 2:] > 0.5, 3, axis=1).astype(float)
    size = 64
    L = lm.bake_lightmap(elements, None, 0, uv, world, size, parts=parts, direct=direct)
    tri, _, _ = lm.rasterize(uv, size, size)
    flat_half = tri == 1                                     # texels the flat triangle held
    assert flat_half.sum() > 300
    # the real half: 0.5 x (1 + 0.2), everywhere it covers
    np.testing.assert_allclose(L.image[L.covered], 0.6, atol=1e-6)
    # the flat half is no island of its own: its texels beside the real half are dilated from it
    # (8 texels), none of them dark, none counted as covered beyond the real half's reach
    real = lm.rasterize(uv[:1], size, size)[0] >= 0          # the real half's texels, its rim too
    near = flat_half & L.filled
    assert near.sum() > 100 and not (L.covered & ~real).any()
    np.testing.assert_allclose(L.image[near], 0.6, atol=1e-6)


def test_texels_located_on_workers_are_the_same_and_on_their_own_face():
    """Texels located on two workers (forked processes, each a share of the faces) read the
    same elements and (u, v) as on one, bit for bit; every texel is found on an element of its
    own face, and the element's bilinear map at (u, v) gives back its point."""
    from hemicube_radiosity.core.util.geometry import bilinear
    elements, uv, world = walls()
    rng = np.random.default_rng(7)
    m = 60000                                    # above two shares of 20,000 points
    face = rng.integers(0, 2, m)
    a, b = rng.uniform(0.0, 1.0, (2, m))
    floor = np.stack([2 * a, b, np.zeros(m)], 1)
    wall = np.stack([np.zeros(m), a, b], 1)
    points = np.where(face[:, None] == 0, floor, wall)
    normals = np.where(face[:, None] == 0, [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    one = lm.locate_texels(elements, points, normals, 0, face, workers=1)
    two = lm.locate_texels(elements, points, normals, 0, face, workers=2)
    assert len(lm._face_shares(face, np.arange(m), 2)) == 2
    np.testing.assert_array_equal(one[0], two[0])
    np.testing.assert_array_equal(one[1], two[1])
    idx, at = two
    np.testing.assert_array_equal(elements.source_face[idx], face)
    back = bilinear(elements.corners()[idx], at[:, :1], at[:, 1:])
    np.testing.assert_allclose(back, points, atol=1e-9)


def test_a_texel_s_sub_points_share_the_sky_s_rays_and_read_its_view_factor():
    """A floor meeting a tall wall (both 40 m long): the sky seen from a floor point at
    distance d from the wall is 1 - (1 - d / sqrt(d^2 + h^2)) / 2 (the view factor to an
    infinitely long perpendicular plate of height h). Texels 2 cm wide beside the wall averaged
    over their sub-points (:func:`lightmap._sub_mean`, the world a source not probed) read the
    closed form's mean over their square, their points sharing the 256 rays out
    (:data:`lightmap.SUB_SKY`): a sixteenth of the rays of each point casting all of them, to
    the same answer within the rays' noise."""
    from hemicube_radiosity.core.light.direct import DirectLight
    from hemicube_radiosity.core.rays import embree_available
    if not embree_available():
        import pytest
        pytest.skip("the sky's rays need Embree")
    h, L = 3.0, 20.0
    floor = MeshInput.from_faces([[-L, 0, 0], [L, 0, 0], [L, 10, 0], [-L, 10, 0]], [[0, 1, 2, 3]], name="floor")
    wall = MeshInput.from_faces([[-L, 0, 0], [-L, 0, h], [L, 0, h], [L, 0, 0]], [[0, 1, 2, 3]], name="wall")
    patches = build_patches([floor, wall], 0)
    light = DirectLight(patches, [], np.zeros(0, np.int64), 1, world=np.ones(3))
    rays = []
    real = light.scene().occluded

    class Counting:
        def occluded(self, o, d, *a):
            rays.append(len(o))
            return real(o, d, *a)
    light._scene = Counting()

    def split(points, normals, samples=None, which=None, facing=None, low=None, **shared):
        return light.split_at(points, normals, "t", samples, which, facing, low, **shared)
    pitch, m = 0.02, 8                             # texels along y from the wall: a row of 8
    tri_w = np.array([[[-1, 0, 0], [1, 0, 0], [1, 1, 0]], [[-1, 0, 0], [1, 1, 0], [-1, 1, 0]]], float)
    px = np.array([[[0, 0], [100, 0], [100, 50]], [[0, 0], [100, 50], [0, 50]]], float)   # 1 texel = 2 cm
    cols, rows = np.full(m, 50), np.arange(m)
    tri = np.zeros(m, np.int64)
    which, sub = lm._sub_texels(px, tri, np.stack([cols + 0.5, rows + 0.5], 1))
    assert np.array_equal(np.bincount(which), np.full(m, 16))
    Ds, need, D = np.zeros((m, 1, 3)), np.ones((m, 1), bool), np.zeros((m, 3))
    got = {}
    for share in (1, lm.SUB_SKY):
        old, lm.SUB_SKY = lm.SUB_SKY, share
        rays.clear()
        try:
            got[share] = lm._sub_mean(split, tri_w, None, False, tri, which, sub, Ds, need, D,
                                      probed=np.array([False]))[:, 0]
        finally:
            lm.SUB_SKY = old
        got[share, "rays"] = sum(rays)
    assert got[1, "rays"] == 16 * got[lm.SUB_SKY, "rays"] == 16 * 16 * m * 256 // 16
    # the closed form's mean over each texel's square (the points' y, off the wall)
    y = np.linspace(0, 1, 201)[None] * 0.5 * pitch + (rows[:, None] + 0.25) * pitch
    want = (1 - 0.5 * (1 - y / np.sqrt(y * y + h * h))).mean(axis=1)
    for share in (1, lm.SUB_SKY):                  # measured: within 0.005 (the lattice's steps)
        np.testing.assert_allclose(got[share], want, atol=0.01)
    np.testing.assert_allclose(got[lm.SUB_SKY], got[1], atol=0.005)


def test_rim_texels_take_their_inside_neighbours_parts_and_are_not_located(monkeypatch):
    """A texel whose centre lies outside its triangle (an island's rim) reads the mean of its
    8 neighbours inside on its face, its emission, reflectivity and reflected light as its
    direct light (Cycles' margin extends an island from its texels): with E, rho, I and D
    linear in position or constant, its value is its neighbours' mean, to rounding; only the
    inside texels (and a rim texel with no such neighbour) are located."""
    elements, uv, world = walls()
    c = elements.corners()
    parts = (0.1 * f(c), np.full(c.shape, 0.5), np.zeros(c.shape), 0.2 * f(c))
    located = []
    real = lm.located_parts

    def counted(elements, parts, points, *a, **k):
        located.append(len(points))
        return real(elements, parts, points, *a, **k)
    monkeypatch.setattr(lm, "located_parts", counted)
    size, faces = 64, np.array([0, 0, 1, 1])
    L = lm.bake_lightmap(elements, None, 0, uv, world, size, parts=parts, faces=faces,
                         direct=lambda p, n: np.ones((len(p), 3)))
    tri, _, inside = lm.rasterize(uv, size, size)
    covered = tri >= 0
    face = np.where(covered, faces[np.maximum(tri, 0)], -1)
    rim = np.argwhere(covered & ~inside)
    assert len(rim) > 50
    alone = 0
    for r, col in rim:
        nb = [(r + dr, col + dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if (dr or dc)
              and 0 <= r + dr < size and 0 <= col + dc < size and inside[r + dr, col + dc]
              and face[r + dr, col + dc] == face[r, col]]
        if not nb:
            alone += 1
            continue
        want = np.mean([L.image[p] for p in nb], axis=0)
        np.testing.assert_allclose(L.image[r, col], want, rtol=1e-6)
    assert sum(located) == inside[covered].sum() + alone
