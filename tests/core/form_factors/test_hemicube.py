"""NumPy hemi-cube form factors against closed forms, enclosure identities and exact coverage."""
import numpy as np
import pytest

from tests.support.analytic import object_factor, parallel_rectangles, perpendicular_rectangles
from hemicube_radiosity.core import builtin_scenes as scenes
from hemicube_radiosity.core.form_factors.hemicube import hemicube_form_factors
from hemicube_radiosity.core.form_factors.pixels import pixel_directions, pixel_weights, receiver_frames
from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.runtime.progress import Cancelled


# ------------------------------------------------------------------------------------------
# independent truth


def point_to_polygon(point, normal, poly):
    """Unoccluded form factor from a differential area to a convex polygon (K, 3) above it:
    the contour integral 1/(2 pi) |sum_k angle_k n . unit(r_k x r_k+1)|."""
    r = np.asarray(poly, float) - point
    rn = np.roll(r, -1, axis=0)
    cross = np.cross(r, rn)
    norm = np.linalg.norm(cross, axis=1)
    angle = np.arctan2(norm, np.einsum("ki,ki->k", r, rn))
    return abs(np.sum(angle * (cross @ normal) / norm)) / (2 * np.pi)


def test_closed_forms_are_the_catalogue_values():
    assert parallel_rectangles() == pytest.approx(0.1998, abs=5e-5)
    assert perpendicular_rectangles() == pytest.approx(0.2000, abs=5e-5)
    square = [(0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
    # corner of a unit square at unit height: 1/4 of the centred 2x2 square
    assert point_to_polygon(np.zeros(3), np.array([0, 0, 1.0]), square) == pytest.approx(
        0.25 * 4 / np.pi * np.arctan(1 / np.sqrt(2)) / np.sqrt(2), rel=1e-12)


# ------------------------------------------------------------------------------------------
# scenes


def quad_mesh(corners, name):
    return MeshInput.from_faces(np.asarray(corners, float), [[0, 1, 2, 3]], name=name)


def box_mesh(lo, hi, inward, bottom=True, triangles=False, name="box"):
    """Axis-aligned box; ``inward`` for a room; faces as quads or split into two triangles."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    faces = [[(x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)],
             [(x0, y0, z0), (x1, y0, z0), (x1, y0, z1), (x0, y0, z1)],
             [(x0, y1, z0), (x0, y1, z1), (x1, y1, z1), (x1, y1, z0)],
             [(x0, y0, z0), (x0, y0, z1), (x0, y1, z1), (x0, y1, z0)],
             [(x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (x1, y0, z1)]]
    if bottom:
        faces.append([(x0, y0, z0), (x0, y1, z0), (x1, y1, z0), (x1, y0, z0)])  # outward CCW
    verts = np.array([p for f in faces for p in f], float)
    polys = [list(range(4 * i, 4 * i + 4))[::-1 if inward else 1] for i in range(len(faces))]
    if triangles:
        polys = [t for p in polys for t in ([p[0], p[1], p[2]], [p[0], p[2], p[3]])]
    return MeshInput.from_faces(verts, polys, name=name)


# ------------------------------------------------------------------------------------------
# closed forms


def test_parallel_squares_match_siegel_howell():
    # receiver cut into 16 x 16 = 256 patches: the centre-point rule is then 1.5e-4 relative off
    p = build_patches(scenes.parallel_squares(1.0), 1 / 16)
    receivers = np.flatnonzero(p.owner == 0)
    assert receivers.size == 256
    F = hemicube_form_factors(p, 128, receivers=receivers)
    exact = parallel_rectangles()
    assert object_factor(p, F, 0, 1) == pytest.approx(exact, rel=5e-3)
    # with nothing else in the scene the rest of every hemisphere is sky
    np.testing.assert_allclose(F.row_sums()[receivers] + F.sky[receivers], 1.0, atol=1e-6)


def test_perpendicular_squares_match_siegel_howell():
    # a uniform 10 x 10 subdivision of the receiver is enough (0.05 % off at R = 128); the
    # wall's edge on the receiver's horizon is clipped at the horizon, not dropped
    p = build_patches(scenes.perpendicular_squares(), 0.1)
    F = hemicube_form_factors(p, 128, receivers=np.flatnonzero(p.owner == 0))
    assert object_factor(p, F, 0, 1) == pytest.approx(perpendicular_rectangles(), rel=1e-2)


# ------------------------------------------------------------------------------------------
# enclosures


# Triangulated faces are cut into grids that do not match their neighbours' along the room's
# edges (T-junctions, vertices not shared): a pixel centre lying exactly on such a crack (the
# room is symmetric enough for that) can see through it, so a little sky is allowed there.
@pytest.mark.parametrize("triangles,sky_max", [(False, 1e-6), (True, 1e-3)], ids=["quads", "triangles"])
def test_rows_sum_to_one_in_a_closed_box(triangles, sky_max):
    p = build_patches([box_mesh((0, 0, 0), (1, 1.5, 0.8), inward=True, triangles=triangles)], 0.3)
    F = hemicube_form_factors(p, 128)
    np.testing.assert_allclose(F.row_sums(), 1.0, atol=1e-3)
    assert F.sky.max() < sky_max
    assert np.all(F.to_dense().diagonal() == 0)
    assert F.data.dtype == np.float32 and F.indices.dtype == np.int32
    assert F.meta == {"method": "hemicube", "resolution": 128, "rotate_seed": None}


def room_with_block():
    room = box_mesh((0, 0, 0), (2, 2, 1.5), inward=True, name="room")
    block = box_mesh((0.6, 0.7, 0), (1.2, 1.3, 0.7), inward=False, bottom=False, name="block")
    return build_patches([room, block], 0.25)


def test_reciprocity_and_closure_in_a_room_with_a_block():
    p = room_with_block()
    F = hemicube_form_factors(p, 64, rotate_seed=3)
    # floor patches under the open-bottomed block see only its back faces: nothing, not sky
    c = p.centers
    under = (p.owner == 0) & (c[:, 2] == 0) & (np.abs(c[:, 0] - 0.9) < 0.3) & (np.abs(c[:, 1] - 1.0) < 0.3)
    assert under.sum() == 6
    rows = F.row_sums()
    np.testing.assert_allclose(rows[~under], 1.0, atol=1e-3)
    assert np.all(rows[under] == 0)
    assert F.sky.max() < 1e-6
    AF = p.areas[:, None] * F.to_dense()
    # object to object (sums over many patches): A_room F_room,block = A_block F_block,room
    # within 0.5 % (the block's rows sum to one, so the right side is the block's area)
    room, block = p.owner == 0, p.owner == 1
    to_block = AF[np.ix_(room, block)].sum()
    assert to_block == pytest.approx(AF[np.ix_(block, room)].sum(), rel=5e-3)
    # source face to source face: total mismatch within 2 % of the total exchange
    face = p.owner * 6 + p.source_face
    groups = [face == g for g in np.unique(face)]
    G = np.array([[AF[np.ix_(a, b)].sum() for b in groups] for a in groups])
    assert np.abs(G - G.T).sum() < 2e-2 * G.sum()
    # patch pairs that see each other well: one hemi-cube per patch, centre-point rule and
    # pixel aliasing leave a median mismatch below 5 %
    big = (AF > 0.01 * p.areas.min()) & (AF.T > 0.01 * p.areas.min())
    rel = np.abs(AF - AF.T)[big] / np.maximum(AF, AF.T)[big]
    assert np.median(rel) < 0.05


# ------------------------------------------------------------------------------------------
# sky and occlusion


def floor_patches(extra=()):
    floor = quad_mesh([(-0.5, -0.5, 0), (0.5, -0.5, 0), (0.5, 0.5, 0), (-0.5, 0.5, 0)], "floor")
    return build_patches([floor, *extra], 0.25)


OCCLUDER = np.array([(-1, -1, 1), (-1, 1, 1), (1, 1, 1), (1, -1, 1)], float)  # faces down


def test_open_plane_sees_only_sky():
    p = floor_patches()
    F = hemicube_form_factors(p, 64)
    assert F.nnz == 0
    np.testing.assert_allclose(F.sky, 1.0, atol=1e-6)


@pytest.mark.parametrize("facing", ["front", "back"])
def test_occluder_above_removes_its_form_factor_from_the_sky(facing):
    corners = OCCLUDER if facing == "front" else OCCLUDER[::-1]
    p = floor_patches([quad_mesh(corners, "occluder")])
    floor = np.flatnonzero(p.owner == 0)
    F = hemicube_form_factors(p, 128, receivers=floor)
    exact = np.array([point_to_polygon(p.centers[i], p.normals[i], OCCLUDER) for i in floor])
    np.testing.assert_allclose(F.sky[floor], 1 - exact, atol=2e-3)
    seen = F.row_sums()[floor]
    if facing == "front":
        np.testing.assert_allclose(seen, exact, atol=2e-3)
    else:  # a back face blocks the sky but is no form-factor entry
        assert F.nnz == 0 and np.all(seen == 0)


def test_per_pixel_depth_splits_interpenetrating_quads():
    # A: the plane z = 1 over [-1, 1]^2; B: the plane z = 1 + x / 2 crossing A along x = 0.
    # Seen from the origin, B is in front for x < 0 and A for x > 0, and the split is the plane
    # x = 0 through the eye: F_A = F(A, x > 0) and F_B = F(B, x < 0) exactly. Both centres are
    # at depth 1, so a per-polygon depth test would give one of them everything.
    A = np.array([(-1, -1, 1), (-1, 1, 1), (1, 1, 1), (1, -1, 1)], float)
    B = np.array([(-1, -1, 0.5), (-1, 1, 0.5), (1, 1, 1.5), (1, -1, 1.5)], float)
    tiny = 1e-3
    receiver = quad_mesh([(-tiny, -tiny, 0), (tiny, -tiny, 0), (tiny, tiny, 0), (-tiny, tiny, 0)], "r")
    p = build_patches([receiver, quad_mesh(A, "A"), quad_mesh(B, "B")], None)
    F = hemicube_form_factors(p, 128, receivers=[0])
    o, n = np.zeros(3), np.array([0, 0, 1.0])
    exact_a = point_to_polygon(o, n, [(0, -1, 1), (0, 1, 1), (1, 1, 1), (1, -1, 1)])
    exact_b = point_to_polygon(o, n, [(-1, -1, 0.5), (-1, 1, 0.5), (0, 1, 1), (0, -1, 1)])
    row = dict(zip(*F.row(0)))
    assert row[1] == pytest.approx(exact_a, rel=1e-2)
    assert row[2] == pytest.approx(exact_b, rel=1e-2)
    # the halves differ enough that giving all to either quad would fail the checks above
    assert point_to_polygon(o, n, A) > 1.5 * exact_a and point_to_polygon(o, n, B) > 1.5 * exact_b


def test_pixel_directions_and_weights_are_the_item_buffer_order():
    # a square far smaller than a pixel, centred on the ray through pixel k's centre and facing
    # the receiver, covers pixel k alone: its entry is exactly that pixel's weight. One square
    # per face and several per face (corner and middle pixels) check the order of the faces,
    # rows and columns shared by the rasteriser, pixel_directions and pixel_weights.
    R = 16
    dirs, w = pixel_directions(R), pixel_weights(R)
    assert dirs.shape == (3 * R * R, 3) and w.shape == (3 * R * R,)
    assert w.sum() == pytest.approx(1.0, abs=1e-12)
    tiny, half = 1e-3, 0.004
    receiver = quad_mesh([(-tiny, -tiny, 0), (tiny, -tiny, 0), (tiny, tiny, 0), (-tiny, tiny, 0)], "r")
    frame = receiver_frames(np.array([[0.0, 0.0, 1.0]]))[0]
    side = R * R // 2
    picks = [0, R - 1, R * (R - 1), R * R - 1, R * R // 2 + 3]                  # top face
    for f in range(4):                                                         # +X, -X, +Y, -Y
        base = R * R + f * side
        picks += [base, base + R - 1, base + side - 1, base + 5 * R + 9]
    meshes = [receiver]
    for i, k in enumerate(picks):
        d = frame.T @ dirs[k]
        d /= np.linalg.norm(d)
        a = np.cross(d, [0.3, 0.5, 0.7])
        a /= np.linalg.norm(a)
        b = np.cross(a, d)
        meshes.append(quad_mesh([d + half * (sa * a + sb * b) for sa, sb in
                                 [(-1, -1), (1, -1), (1, 1), (-1, 1)]], f"p{i}"))
    p = build_patches(meshes, None)
    F = hemicube_form_factors(p, R, receivers=[0])
    row = dict(zip(*F.row(0)))
    assert len(row) == len(picks)
    for i, k in enumerate(picks):
        (pid,) = np.flatnonzero(p.owner == i + 1)
        assert row[pid] == np.float32(w[k])
    assert F.sky[0] == pytest.approx(1 - w[picks].sum(), abs=1e-6)


# ------------------------------------------------------------------------------------------
# rotation, receivers, progress


def test_rotation_is_reproducible_and_keeps_row_sums():
    p = build_patches(scenes.closed_box(), 0.25)
    F0 = hemicube_form_factors(p, 32)
    F1 = hemicube_form_factors(p, 32, rotate_seed=7)
    F2 = hemicube_form_factors(p, 32, rotate_seed=7, batch=5)
    F3 = hemicube_form_factors(p, 32, rotate_seed=8)
    for a in ("indptr", "indices", "data"):
        np.testing.assert_array_equal(getattr(F1, a), getattr(F2, a))
    D0, D1, D3 = F0.to_dense(), F1.to_dense(), F3.to_dense()
    assert np.abs(D1 - D3).max() > 1e-4 and np.abs(D0 - D1).max() > 1e-4
    # entries move a little (aliasing), never a lot
    assert np.abs(D0 - D1).max() < 0.2 * D0.max()
    for F in (F0, F1, F3):
        np.testing.assert_allclose(F.row_sums(), 1.0, atol=1e-5)
    assert F1.meta["rotate_seed"] == 7


def test_receiver_subset_gives_the_same_rows():
    p = room_with_block()
    full = hemicube_form_factors(p, 32, rotate_seed=1).to_dense()
    some = np.array([40, 3, 77, 3])
    part = hemicube_form_factors(p, 32, rotate_seed=1, receivers=some)
    D = part.to_dense()
    np.testing.assert_array_equal(D[some], full[some])
    others = np.setdiff1d(np.arange(len(p)), some)
    assert not D[others].any() and not part.sky[others].any()
    with pytest.raises(ValueError):
        hemicube_form_factors(p, 32, receivers=[len(p)])
    with pytest.raises(ValueError):
        hemicube_form_factors(p, 33)


def test_progress_and_cancel():
    p = build_patches(scenes.closed_box(), 0.25)
    seen = []
    hemicube_form_factors(p, 16, progress=seen.append, batch=10)
    assert seen[0] == 0.0 and seen[-1] == 1.0 and seen == sorted(seen)
    calls = []
    with pytest.raises(Cancelled):
        hemicube_form_factors(p, 16, batch=10, cancelled=lambda: calls.append(1) or len(calls) > 2)


def test_the_forecasts_sample_times_receivers_and_leaves_f_as_it_was():
    """``probe`` gets the seconds one hemi-cube took in a sample drawn before the others (its
    rows thrown away: F bit for bit as without it), and None where there are too few
    receivers to sample; a cancel during the sample stops the whole."""
    from hemicube_radiosity.core.form_factors import hemicube
    p = build_patches(scenes.closed_box(), 0.25)
    said = []
    F = hemicube_form_factors(p, 16, batch=2, probe=said.append)
    assert len(said) == 1 and 0 < said[0] < 1
    plain = hemicube_form_factors(p, 16, batch=2)
    np.testing.assert_array_equal(F.to_dense(), plain.to_dense())
    np.testing.assert_array_equal(F.sky, plain.sky)
    few = []
    hemicube_form_factors(p, 16, batch=len(p) // hemicube.PROBE_MIN_BATCHES + 1, probe=few.append)
    assert few == [None]
    with pytest.raises(Cancelled):
        hemicube_form_factors(p, 16, batch=2, probe=said.append, cancelled=lambda: True)
    assert len(said) == 1
