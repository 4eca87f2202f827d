"""Corners under a surface closer over them than our rays start (core/output/covered.py), against
closed forms: a 4 x 4 m floor of 1 m quads under a sun from straight above, with a 2 x 2 m board
over its middle. Cycles' rays start on the floor and meet the board however close it is, so the
floor's corners under the board see no sun; in the open a corner has rho E / pi."""
import numpy as np
import pytest

from hemicube_radiosity.core.light.lamps import SunLight
from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.output.covered import TIE_ULPS
from hemicube_radiosity.core.pipeline import BakeSettings, bake
from hemicube_radiosity.core.rays import embree_available, mesh_offsets

pytestmark = pytest.mark.skipif(not embree_available(), reason="the corners' rays need Embree")

RHO, SUN = 0.5, 3.0
OPEN = RHO * SUN / np.pi


def _floor():
    xs = np.arange(-2.0, 2.5, 1.0)
    verts = [(x, y, 0.0) for y in xs for x in xs]
    faces = [(j * 5 + i, j * 5 + i + 1, (j + 1) * 5 + i + 1, (j + 1) * 5 + i) for j in range(4) for i in range(4)]
    return MeshInput.from_faces(verts, faces, rho=(RHO,) * 3, name="floor")


def _board(gap):
    return MeshInput.from_faces([(-1.2, -1.2, gap), (1.2, -1.2, gap), (1.2, 1.2, gap), (-1.2, 1.2, gap)],
                                [(0, 1, 2, 3)], rho=(RHO,) * 3, name="board")


def _floor_corners(gap):
    """(positions (n, 3), values (n, 3)) at the floor's face corners, baked with the board at
    ``gap`` above it, and the floor's ray offset."""
    r = bake([_floor(), _board(gap)], BakeSettings(patch_size=1.0, element_size=1.0, two_sided_reflection=False,
                                                     gather_rays=64),
             lights=[SunLight((0.0, 0.0, -1.0), strength=SUN)])
    E = r.elements
    own = np.flatnonzero(E.owner == 0)
    pos = E.verts[E.corner_ids()[own]].reshape(-1, 3)
    return pos, r.corner_values()[own].reshape(-1, 3), mesh_offsets(r.patches)[0]


def test_floor_corners_under_a_board_within_the_ray_offset_get_no_sun():
    pos, val, eps = _floor_corners(gap=1e-5)
    assert 1e-5 < 0.5 * eps                       # the board is within the floor's ray offset
    under = np.all(np.abs(pos[:, :2]) < 1.2, axis=1)
    assert under.sum() == 4 * 9                     # 9 vertices under the board, 4 faces each
    # the sun is blocked there; what the board's underside sends is its own dark (< 1% of the sun)
    assert val[under].max() < 0.01 * OPEN
    # in the open the sun (and a little reflected from the board's top: none reaches the floor)
    np.testing.assert_allclose(val[~under], OPEN, rtol=1e-6)


def test_a_board_above_the_ray_offset_was_already_seen():
    # the corners under a board 5 cm up were dark before covered.py: the same dark now
    pos, val, _ = _floor_corners(gap=0.05)
    under = np.all(np.abs(pos[:, :2]) < 1.2, axis=1)
    assert val[under, 0].max() < 0.1 * OPEN


def test_a_coincident_board_is_a_tie_and_covers_nothing():
    # a board in the floor's plane (z-fighting): neither covers the other; the floor's corners
    # keep the sun, as before (Cycles: either may be drawn)
    pos, val, _ = _floor_corners(gap=0.0)
    assert TIE_ULPS >= 1
    np.testing.assert_allclose(val, OPEN, rtol=1e-6)


def _block_with_lip(gap=2e-5):
    """A closed block on the floor from x = 0.95, and in front of it a lip: a single plane
    facing up, ``gap`` over the floor, from x = 0.8 to the block."""
    from hemicube_radiosity.core.builtin_scenes import box
    lip = MeshInput.from_faces([(0.8, -2.0, gap), (0.95, -2.0, gap), (0.95, 2.0, gap), (0.8, 2.0, gap)],
                               [(0, 1, 2, 3)], rho=(RHO,) * 3, name="lip")
    return [box((0.95, -2.0, 0.0), (1.95, 2.0, 0.3), (RHO,) * 3, name="block"), lip]


def test_a_buried_corner_s_open_side_under_a_lip_is_lit_from_under_it():
    """The floor's vertices at x = 1 are buried in a block standing at x = 0.95: they take the
    light where their edge from x = 0 meets the block (core/output/sides.py), a point under a
    lip 20 um over the floor, within the floor's ray offset. Rays started at that offset read the
    sun over the lip; Cycles' rays from the point, and ours started half way to the lip
    (covered.start_offsets), meet it: no sun."""
    r = bake([_floor()] + _block_with_lip(), BakeSettings(patch_size=2.0, element_size=2.0,
                                                             two_sided_reflection=False, gather_rays=64),
             lights=[SunLight((0.0, 0.0, -1.0), strength=SUN)])
    E = r.elements
    own = np.flatnonzero((E.owner == 0) & (np.abs(E.centers[:, 0] - 0.5) < 1e-9))      # the faces x in [0, 1]
    pos = E.verts[E.corner_ids()[own]].reshape(-1, 3)
    val = r.corner_values()[own].reshape(-1, 3)
    at_block = np.abs(pos[:, 0] - 1.0) < 1e-9
    open_end = np.abs(pos[:, 0]) < 1e-9
    assert at_block.sum() == 8 and open_end.sum() == 8
    np.testing.assert_allclose(val[open_end], OPEN, rtol=0.01)     # and a little light off the block
    D = r.corner_parts()[2][own].reshape(-1, 3)
    assert D[at_block].max() < 1e-3 * SUN / np.pi                # no sun under the lip


def test_the_first_loop_triangle_holding_a_corner_wins():
    """lift._first_row_holding against the plain rule: of a face's loop triangles (rows of
    (face, three of its corners)), the first row that holds the corner; -1 where none does."""
    from hemicube_radiosity.core.output.lift import _first_row_holding

    rng = np.random.default_rng(5)
    ft = np.concatenate([np.stack([np.full(4, f), *rng.permutation(np.tile(np.arange(6), 2))[:12].reshape(3, 4)], 1)
                         for f in (0, 2, 3)])
    face = rng.integers(0, 5, 400)
    j = rng.integers(-1, 7, 400)
    want = np.array([next((r for r, row in enumerate(ft) if row[0] == f and c in row[1:]), -1) if c >= 0 else -1
                     for f, c in zip(face, j)])
    got = _first_row_holding(ft, face, j)
    assert (want >= 0).sum() > 100 and (want < 0).sum() > 50        # both kinds drawn
    np.testing.assert_array_equal(got, want)
    assert (_first_row_holding(ft[:0], face, j) == -1).all()


def _slope_under_a_plane(depth=0.1):
    """Truck town's grass at its ground ring, in small: a strip of 1 m quads, two across, folded
    at x = 0: flat in the open for x < 0, sloping ``depth`` down under a 2 x 4 m plane at z = 0
    for x > 0 (the plane's left edge on the fold)."""
    verts = [(x, y, -depth * max(x, 0.0)) for y in np.arange(-2.0, 2.5) for x in (-1.0, 0.0, 1.0)]
    faces = [(3 * j + i, 3 * j + i + 1, 3 * j + i + 4, 3 * j + i + 3) for j in range(4) for i in range(2)]
    strip = MeshInput.from_faces(verts, faces, rho=(RHO,) * 3, name="strip")
    plane = MeshInput.from_faces([(0.0, -2.0, 0.0), (2.0, -2.0, 0.0), (2.0, 2.0, 0.0), (0.0, 2.0, 0.0)],
                                 [(0, 1, 2, 3)], rho=(RHO,) * 3, name="plane")
    return [strip, plane]


def test_the_corners_of_an_unseen_face_at_a_seen_vertex_are_baked_on_their_own_face():
    """The sloping quad lies under the plane: the scene does not see it (core/output/sides.py
    open_elements), but its corners on the fold share their vertices with the flat quad in the
    open. Cycles bakes each face corner on its own triangle, moved toward its centre, under the
    plane: no sun. Those corners were left their vertex's light (the full sun, 0.41 at truck town's
    grass corners where Cycles had 0.00); the flat quad's corners there keep the sun."""
    r = bake(_slope_under_a_plane(), BakeSettings(patch_size=1.0, element_size=1.0, two_sided_reflection=False,
                                                  gather_rays=64),
             lights=[SunLight((0.0, 0.0, -1.0), strength=SUN)])
    E = r.elements
    strip = np.flatnonzero(E.owner == 0)
    pos = E.verts[E.corner_ids()[strip]]                               # (n, 4, 3)
    val, D = r.corner_values()[strip], r.corner_parts()[2][strip]
    on_fold = np.abs(pos[..., 0]) < 1e-9
    slope = (E.centers[strip, 0] > 0)[:, None] & on_fold
    flat = (E.centers[strip, 0] < 0)[:, None] & on_fold
    assert slope.sum() == 8 and flat.sum() == 8          # 5 vertices on the fold, 2 faces each side
    assert D[slope].max() < 1e-3 * SUN / np.pi                         # the plane over them: no sun
    assert val[slope].max() < 0.02 * OPEN
    np.testing.assert_allclose(val[flat], OPEN, rtol=0.02)               # the open side: the sun


def _block_on_a_shelf(c=0.1, h=0.04, top=0.5):
    """One mesh, as the living room's: a closed 4 x 4 x 0.2 m shelf (its top at z = 0) and on it a
    closed block whose bottom face covers [0, 1] x [-1, 1] of the shelf's top, its long bottom
    edges chamfered ``c`` out and ``h`` up (22 deg, facing down and out): the chamfers' feet are
    vertices of the shelf's solid too."""
    from hemicube_radiosity.core.builtin_scenes import box
    shelf = box((-2.0, -2.0, -0.2), (2.0, 2.0, 0.0), (RHO,) * 3, name="shelf")
    off, idx = np.asarray(shelf.face_offsets), np.asarray(shelf.face_indices)
    faces = [tuple(idx[off[k]:off[k + 1]]) for k in range(len(off) - 1)]
    verts = [tuple(x) for x in np.asarray(shelf.verts)]
    sec = [(0.0, 0.0), (1.0, 0.0), (1.0 + c, h), (1.0 + c, top), (-c, top), (-c, h)]
    n, b = len(sec), len(verts)
    verts += [(x, -1.0, z) for x, z in sec] + [(x, 1.0, z) for x, z in sec]
    block = [(n + i, n + (i + 1) % n, (i + 1) % n, i) for i in range(n)]
    block += [tuple(range(n)), tuple(range(2 * n - 1, n - 1, -1))]          # the two end caps
    faces += [tuple(b + i for i in q) for q in block]
    return MeshInput.from_faces(verts, faces, rho=(RHO,) * 3, name="shelf")


def test_a_buried_chamfer_foot_is_baked_at_its_own_point():
    """The chamfers' feet are buried (core/output/sides.py): their corners took the light where
    their edge from the open side meets the shelf, a little up the chamfer, where the room is
    open: 0.15-0.26 against the block's lit top's 0.61. Cycles bakes the corner at the foot, a hair
    over the shelf, which its rays meet: under a tenth of the lit top (0.04-0.06 of 0.87 in
    tests/blender/test_covered_corners.py, the same block and shelf as two objects). Those face
    corners are now lit at their own point as any covered corner is: 0.015-0.03."""
    r = bake([_block_on_a_shelf()], BakeSettings(patch_size=1.0, element_size=1.0, gather_rays=64),
             lights=[SunLight((0.3, 0.2, -0.9), strength=SUN)], world=np.array([0.3, 0.35, 0.4]))
    E = r.elements
    pos = E.verts[E.corner_ids()]
    foot = (np.abs(pos[..., 2]) < 1e-9) & (np.abs(np.abs(pos[..., 1]) - 1.0) < 1e-9) & \
        ((np.abs(E.normals[:, 0]) > 0.3) & (E.normals[:, 2] < 0))[:, None]          # its faces' corners
    top = (np.abs(pos[..., 2] - 0.5) < 1e-9) & (E.normals[:, 2] > 0.9)[:, None]
    val = r.corner_values().mean(axis=2)
    assert foot.sum() >= 4 and top.sum() >= 4
    assert val[foot].max() < 0.1 * val[top].mean()


def test_a_corner_whose_sun_passes_under_a_lip_beside_it_gets_no_sun():
    """A 20 x 20 m floor (ray offset 2.8e-4) under a sun 45 deg up toward +x, and a board 1e-4
    over it from x = 1.5e-4 on, beside the floor's corner at the origin, not over it. Cycles
    bakes the corner of the face toward +x 7e-5 in (x = y = 7e-5): its ray toward the sun rises
    8e-5 by the board's edge and meets its underside: no sun; the vertex's rays start 2.8e-4 up,
    over the board, and read the sun (truck town's grass corners beside a kerb: 0.56 where Cycles
    has 0.10). The corners of the faces toward -x, 7e-5 the other way, pass over the board's edge:
    the full sun."""
    xs = np.array([-10.0, -1.0, 0.0, 1.0, 10.0])
    verts = [(x, y, 0.0) for y in xs for x in xs]
    faces = [(j * 5 + i, j * 5 + i + 1, (j + 1) * 5 + i + 1, (j + 1) * 5 + i) for j in range(4) for i in range(4)]
    floor = MeshInput.from_faces(verts, faces, rho=(RHO,) * 3, name="floor")
    board = MeshInput.from_faces([(1.5e-4, -1.0, 1e-4), (1.0, -1.0, 1e-4), (1.0, 1.0, 1e-4), (1.5e-4, 1.0, 1e-4)],
                                 [(0, 1, 2, 3)], rho=(RHO,) * 3, name="board")
    r = bake([floor, board], BakeSettings(patch_size=20.0, element_size=20.0, two_sided_reflection=False,
                                          gather_rays=16),
             lights=[SunLight((-1.0, 0.0, -1.0), strength=SUN)])
    E = r.elements
    assert 1e-4 < 0.5 * mesh_offsets(r.patches)[0]              # the board lies within the ray offset
    pos, D = E.verts[E.corner_ids()], r.corner_parts()[2]
    at = np.all(np.abs(pos) < 1e-12, axis=2) & (E.owner == 0)[:, None]
    east = at & (E.centers[:, 0] > 0)[:, None]
    west = at & (E.centers[:, 0] < 0)[:, None]
    assert east.sum() == 2 and west.sum() == 2
    assert D[east].max() < 1e-3 * SUN / np.pi
    np.testing.assert_allclose(D[west], SUN * np.cos(np.pi / 4) / np.pi, rtol=1e-3)




def test_a_leaning_corner_whose_sun_passes_under_a_ledge_beside_it_gets_no_sun():
    """The floor of the test above (ray offset 2.8e-4), its corners shaded with a normal leaning
    30 deg toward -x: a crease (core/output/crease.py), lit from a point 1% into its element
    (x = y = 5e-3) a ray offset off it along the bisector of its two normals. A ledge 1 mm up
    from x = 5e-4 to 3e-3 over y > 0, beyond the reach of the first test (the ray offset's rise).
    Cycles' ray from the north-east corner's bake point (7e-5 in) passes under the ledge's edge
    and meets its underside: no sun; ours started past the ledge and read the sun at cos 75 deg
    (the living room's bevel corner 614: 0.40 where Cycles, in the shadow of the face beside it,
    has 0.12). The south-west corner's ray passes beside the ledge: the sun."""
    xs = np.array([-10.0, -1.0, 0.0, 1.0, 10.0])
    verts = [(x, y, 0.0) for y in xs for x in xs]
    faces = [(j * 5 + i, j * 5 + i + 1, (j + 1) * 5 + i + 1, (j + 1) * 5 + i) for j in range(4) for i in range(4)]
    floor = MeshInput.from_faces(verts, faces, rho=(RHO,) * 3, name="floor")
    lean = np.radians(30.0)
    floor.corner_normal = np.tile([-np.sin(lean), 0.0, np.cos(lean)], (len(floor.face_indices), 1))
    ledge = MeshInput.from_faces([(5e-4, 0.0, 1e-3), (3e-3, 0.0, 1e-3), (3e-3, 1.0, 1e-3), (5e-4, 1.0, 1e-3)],
                                 [(0, 1, 2, 3)], rho=(RHO,) * 3, name="ledge")
    r = bake([floor, ledge], BakeSettings(patch_size=20.0, element_size=20.0, two_sided_reflection=False,
                                          gather_rays=16),
             lights=[SunLight((-1.0, 0.0, -1.0), strength=SUN)])
    E = r.elements
    assert 1e-3 > mesh_offsets(r.patches)[0] / np.sin(np.pi / 4)   # beyond the rise's reach
    pos, D = E.verts[E.corner_ids()], r.corner_parts()[2]
    at = np.all(np.abs(pos) < 1e-12, axis=2) & (E.owner == 0)[:, None]
    ne = at & np.all(E.centers[:, :2] > 0, axis=1)[:, None]
    sw = at & np.all(E.centers[:, :2] < 0, axis=1)[:, None]
    assert ne.sum() == 1 and sw.sum() == 1
    lit = SUN * np.cos(np.radians(75.0)) / np.pi
    assert D[ne].max() < 1e-3 * lit
    np.testing.assert_allclose(D[sw], lit, rtol=1e-3)


def test_a_corner_behind_its_own_warped_face_still_finds_the_floor_under_it():
    """One mesh: the floor and a 2 x 2 m lid facing down, rising from 5 um over the floor at y =
    -0.5 to 0.2 m at y = 1.5, warped 2 cm (one bilinear piece, not cut along Blender's triangles:
    core/mesh/ngons.py ``WARPED``): the living room's bevel undersides on the shelf, 4.7 um over
    it. Cycles bakes corner 0 on Blender's first triangle (0, 1, 2), which near the corner runs
    a hair behind the bilinear lid; its rays meet the floor 9 um under it, which sees the sun and
    sky only through the wedge between the two (an upper bound: the sky above 13 degrees' slit,
    2.5% of the floor's hemisphere, 0.3% of the open floor's light at the lid). Ours met the lid's
    own face first along the corner's normal and stopped there: the corner kept its vertex's light,
    read from under the floor, 84% of the open floor's. Corner 3, on the triangle (0, 2, 3), was
    dark already."""
    gap = 5e-6
    xs = np.arange(-2.0, 2.5, 1.0)
    verts = [(x, y, 0.0) for y in xs for x in xs]
    faces = [(j * 5 + i, j * 5 + i + 1, (j + 1) * 5 + i + 1, (j + 1) * 5 + i) for j in range(4) for i in range(4)]
    verts += [(-0.5, -0.5, gap), (-0.5, 1.5, 0.2), (1.5, 1.5, 0.22), (1.5, -0.5, gap)]
    faces += [(25, 26, 27, 28)]
    sky = np.array([0.3, 0.35, 0.4])
    r = bake([MeshInput.from_faces(verts, faces, rho=(RHO,) * 3, name="floor")],
             BakeSettings(patch_size=1.0, element_size=1.0, two_sided_reflection=False, gather_rays=64),
             lights=[SunLight((0.2, 0.1, -1.0), strength=SUN)], world=sky)
    E = r.elements
    assert gap < 0.5 * mesh_offsets(r.patches)[0]              # the floor lies within the ray offset
    pos, val = E.verts[E.corner_ids()], r.corner_values().mean(axis=2)
    lid = (E.source_face == 16)[:, None]
    feet = lid & (np.abs(pos[..., 2] - gap) < 1e-9) & (np.abs(np.abs(pos[..., 0] - 0.5) - 1.0) < 1e-9)
    far = ~lid & np.all(np.abs(pos[..., :2]) > 1.9, axis=2)
    open_floor = RHO * (SUN / np.linalg.norm((0.2, 0.1, 1.0)) / np.pi + sky.mean())
    assert feet.sum() == 2 and far.sum() >= 4
    np.testing.assert_allclose(val[far], open_floor, rtol=0.05)     # (and what the lid's edge sends)
    assert val[feet].max() < 0.05 * open_floor


def _floor_by_a_wall_end(rho_wall=0.0):
    """The floor of :func:`_floor` and a black block (a wall, 0.2 m thick, 1 m high) standing on
    it from x = -2 to x = 0, its sunny face at y = -0.2 and its back on the line y = 0; its end
    stands on the floor's vertex (0, 0). The sun shines from -y, 40 degrees off the zenith: the
    wall's shadow lies on the floor for x < 0 from y = 0 to y = tan 40 = 0.84, and its edge runs
    along x = 0 through that vertex."""
    from hemicube_radiosity.core.builtin_scenes import box
    return [_floor(), box((-2.0, -0.2, 0.0), (0.0, 0.0, 1.0), (rho_wall,) * 3, name="wall")]


def test_a_shadow_s_edge_through_a_vertex_parts_its_corners():
    """zdm2's floors at a wall's end: Cycles bakes each face corner on its own face, nudged toward
    its centre, so at the vertex (0, 0) the corner of the floor's face behind the wall
    ([-1, 0] x [0, 1]) is in the wall's shadow and that of the face beside it ([0, 1] x [0, 1])
    in the sun. The vertex is lit once, from one point: both corners took its light (the
    shadowed one the full sun, zdm2's floors at 0.94 where Cycles has 0.31). Closed forms: with
    the wall black, no sky and a flat floor, nothing reaches the shadowed corner but the sun's
    penumbra (Blender's default sun angle: none at a corner on the edge's far side); the lit one
    has rho E cos 40 / pi."""
    tilt = np.radians(40.0)
    sun = SunLight((0.0, np.sin(tilt), -np.cos(tilt)), strength=SUN)
    r = bake(_floor_by_a_wall_end(), BakeSettings(patch_size=1.0, element_size=1.0, two_sided_reflection=False,
                                                  gather_rays=64), lights=[sun])
    E = r.elements
    cid, cv = E.corner_ids(), r.corner_values()
    lit = RHO * SUN * np.cos(tilt) / np.pi

    def corner_at(centre):
        e = np.flatnonzero((E.owner == 0) & np.all(np.abs(E.centers - centre) < 1e-9, axis=1))
        assert len(e) == 1
        k = np.flatnonzero(np.all(np.abs(E.verts[cid[e[0]]]) < 1e-9, axis=1))
        return cv[e[0], k[0]]
    behind, beside = corner_at((-0.5, 0.5, 0.0)), corner_at((0.5, 0.5, 0.0))
    np.testing.assert_allclose(beside, lit, rtol=1e-3)
    assert behind.max() < 0.01 * lit


def _plate_and_back(gap):
    """A plate z = 0, [0, 1]^2, facing up (owner 0), and its back (owner 1, :mod:`..mesh.backs`)
    ``gap`` under it, facing down: the patches and the meshes' ``back_of``."""
    from types import SimpleNamespace

    from hemicube_radiosity.core.mesh.patches import PatchSet
    sq = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    verts = np.vstack([sq, sq[::-1] - [0, 0, gap]])
    polys = np.array([[0, 1, 2, 3], [4, 5, 6, 7]])
    P = PatchSet(verts, polys, verts[polys].mean(axis=1), np.array([[0, 0, 1.0], [0, 0, -1.0]]), np.ones(2),
                 np.full((2, 3), RHO), np.zeros((2, 3)), np.array([0, 1], np.int32), np.zeros(2, np.int32),
                 ["plate", "plate (back)"])
    return P, [SimpleNamespace(back_of=-1), SimpleNamespace(back_of=0)]


def test_a_covered_point_s_sun_ray_passes_the_backs_cycles_has_not():
    """A point a hair off the plate's edge, between the plate's plane and its back's, lit by a sun
    a little below the horizon: its ray passes under the plate (nothing there in Cycles) but
    crosses the back 5 mm on. A covered corner is lit from such a start (a few float32 steps off
    its point: the living room's notch, wall corner 7273: 0.03 where Cycles has 0.33); its sun is
    the open one, E cos / pi (radiance arriving), which the bake's own shadow rays (backs included) read as 0."""
    from types import SimpleNamespace

    from hemicube_radiosity.core.light.direct import DirectLight
    from hemicube_radiosity.core.output.covered import _front_light
    gap = 1e-3
    P, meshes = _plate_and_back(gap)
    to_sun = np.array([-1.0, 0.0, -0.1]) / np.linalg.norm([-1.0, 0.0, -0.1])
    direct = DirectLight(patches=P, lights=[SunLight(tuple(-to_sun), strength=SUN)],
                         emitters=np.zeros(0, np.int64), samples=1)
    ctx = SimpleNamespace(direct=direct, meshes=meshes)
    start = np.array([[1.0001, 0.5, -0.5 * gap]])
    n = np.array([[-1.0, 0.0, 0.0]])
    blocked = direct.at(start, n, "test", eps=np.zeros(1), facing=n)
    assert blocked.max() == 0.0                                # the back stops the bake's own ray
    open_sun = SUN * float(n[0] @ to_sun) / np.pi
    np.testing.assert_allclose(_front_light(ctx, start, n, n), open_sun, rtol=1e-9)
    # the plate itself still shades: the same point under the plate's middle, sun from above
    # it (through the plate), reads nothing
    direct2 = DirectLight(patches=P, lights=[SunLight((0.0, 0.0, -1.0), strength=SUN)],
                          emitters=np.zeros(0, np.int64), samples=1)
    under = np.array([[0.5, 0.5, -2 * gap]])
    up = np.array([[0.0, 0.0, 1.0]])
    assert _front_light(SimpleNamespace(direct=direct2, meshes=meshes), under, up, up).max() == 0.0


def test_covered_corners_are_found_again_when_only_the_shading_normals_change(monkeypatch):
    """Which corners are lit at their bake point depends on their shading normals (a leaning
    corner's pick, above), so the cached picks are keyed on the meshes' corner normals too: a
    relight after Shade Flat (the same geometry, other normals) finds them again, and one with
    the same normals reads them from the cache."""
    from hemicube_radiosity.core.output import covered
    from hemicube_radiosity.core.runtime.cache import FormFactorCache

    calls = []
    find = covered._find
    monkeypatch.setattr(covered, "_find", lambda *a, **k: calls.append(1) or find(*a, **k))
    xs = np.array([-10.0, -1.0, 0.0, 1.0, 10.0])
    verts = [(x, y, 0.0) for y in xs for x in xs]
    faces = [(j * 5 + i, j * 5 + i + 1, (j + 1) * 5 + i + 1, (j + 1) * 5 + i) for j in range(4) for i in range(4)]
    ledge = MeshInput.from_faces([(5e-4, 0.0, 1e-3), (3e-3, 0.0, 1e-3), (3e-3, 1.0, 1e-3), (5e-4, 1.0, 1e-3)],
                                 [(0, 1, 2, 3)], rho=(RHO,) * 3, name="ledge")
    cache = FormFactorCache()

    def baked(lean):
        floor = MeshInput.from_faces(verts, faces, rho=(RHO,) * 3, name="floor")
        floor.corner_normal = np.tile([-np.sin(lean), 0.0, np.cos(lean)], (len(floor.face_indices), 1))
        bake([floor, ledge], BakeSettings(patch_size=20.0, element_size=20.0, two_sided_reflection=False,
                                          gather_rays=16),
             lights=[SunLight((-1.0, 0.0, -1.0), strength=SUN)], cache=cache)
        return len(calls)
    first = baked(np.radians(30.0))
    assert first >= 1
    assert baked(0.0) > first                       # other normals: found again
    again = len(calls)
    assert baked(0.0) == again                      # the same: from the cache
