"""Final gather: cosine rays that read a patch solution where they land."""
import numpy as np
import pytest

from tests.support.analytic import point_under_rectangle_corner
from hemicube_radiosity.core.output.gather import (
    final_gather, gather_matrix, patch_parameters, surface_values
)
from hemicube_radiosity.core.light.polygon_ff import polygon_form_factors
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.rays import embree_scene, ray_offsets
from hemicube_radiosity.core.hemisphere import sky_fraction
from hemicube_radiosity.core.builtin_scenes import closed_box, quad
from tests.support.patching import CountingScene


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
    from hemicube_radiosity.core.mesh.patches import MeshInput

    ps = build_patches(MeshInput.from_faces(c, [[0, 1, 2, 3], [1, 4, 2]]), None)
    vals = np.array([[1.0], [3.0], [7.0], [2.0], [5.0]])
    params = patch_parameters(ps)
    y = np.array([[1.0, 0.5, 0], [2.5, 0.25, 0]])
    got = surface_values(params, ps.polys, vals, np.array([0, 1]), y)
    # quad at (u, v) = (0.5, 0.5): mean of the corners; triangle: plane through (2,0)=3, (3,0)=5, (2,1)=7
    assert got[0, 0] == pytest.approx((1 + 3 + 7 + 2) / 4)
    assert got[1, 0] == pytest.approx(3 + 0.5 * 2 + 0.25 * 4)


def _rectangle_above(x1, x2, y1, y2, c):
    """Form factor from an upward point at the origin to the parallel rectangle [x1, x2] x
    [y1, y2] a height c above it: corner rectangles added and subtracted (closed form)."""
    def corner(a, b):
        return np.sign(a) * np.sign(b) * point_under_rectangle_corner(np.abs(a), np.abs(b), c)
    return corner(x2, y2) - corner(x1, y2) - corner(x2, y1) + corner(x1, y1)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_shared_ray_pattern_reads_a_plates_form_factor_along_a_row_under_its_edge(seed):
    """Floor points on a row that passes under the edge of a 1 m plate 0.5 m up: the cosine rays
    that hit the plate are its form factor (closed form), for the gather (the plate's value 1)
    and the sky fraction alike, which cast the same pattern (:func:`.hemisphere.cosine_lattice`).
    256 rays: RMS error along the row 0.42-0.50% of the hemisphere, at worst 1.3% (measured,
    seeds 0-2); the jittered grid the pattern replaced: 0.45-0.82%, at worst 2.2%."""
    plate = quad([(0, 0, 0.5), (0, 1, 0.5), (1, 1, 0.5), (1, 0, 0.5)], name="Plate")      # faces down
    floor = quad([(-2, -2, 0), (3, -2, 0), (3, 3, 0), (-2, 3, 0)], name="Floor")
    ps = build_patches([plate, floor], 0.25)
    x = np.linspace(-0.6, 0.6, 121)
    pts = np.column_stack([x, np.full_like(x, 0.37), np.zeros_like(x)])
    up = np.tile([0.0, 0.0, 1.0], (len(x), 1))
    F = _rectangle_above(-x, 1 - x, -0.37, 0.63, 0.5)
    scene = embree_scene(ps)
    on_plate = np.isin(np.arange(len(ps.verts)), ps.polys[ps.owner == 0]).astype(float)[:, None]
    G, sky = gather_matrix(ps, pts, up, scene, rays=256, seed=seed)
    eps = ray_offsets(ps, pts, up)                  # the rays start where the gather's do
    for got in (G.matvec(on_plate)[:, 0], 1 - sky_fraction(scene, pts, up, 256, seed=seed, eps=eps)):
        err = got - F
        assert np.sqrt(np.mean(err ** 2)) < 0.006
        assert np.abs(err).max() < 0.016
    np.testing.assert_allclose(sky, sky_fraction(scene, pts, up, 256, seed=seed, eps=eps), atol=1e-12)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_product_is_matvec_bit_for_bit(dtype):
    # the relight's sparse products (G in float32, the correction matrix in float64), in runs of
    # rows and on threads, sum every row as CSR.matvec does
    from hemicube_radiosity.core.util.sparse import CSR, product
    rng = np.random.default_rng(5)
    P, V, nnz = 3000, 2000, 1 << 21
    rows = np.sort(rng.integers(0, P - 10, nnz))               # the last rows empty
    M = CSR.from_coo(rows, rng.integers(0, V, nnz), rng.random(nnz), (P, V))
    M.data = M.data.astype(dtype)
    x = rng.random((V, 3)) - 0.4
    ref = M.matvec(x)
    for workers in (1, 2):
        assert np.array_equal(product(M, x, workers), ref)
        assert np.array_equal(product(M, x[:, 1], workers), ref[:, 1])


def test_transport_product_transposed_is_apply_transport_bit_for_bit():
    # the relight keeps its cached transports transposed to float64 (emitters.transposed_transport):
    # the same sums as the (P, M) float32 transport and as emitters.apply_transport's einsum
    from hemicube_radiosity.core.light.emitters import apply_transport, transport_product, transposed_transport
    rng = np.random.default_rng(3)
    T = rng.random((5000, 37)).astype(np.float32)
    T[rng.random(T.shape) < 0.3] = 0
    L = rng.random((37, 3)) * 5
    ref = apply_transport(T, L)
    Tt = transposed_transport(T)
    assert Tt.shape == (37, 5000) and Tt.dtype == np.float64 and Tt.flags.c_contiguous
    assert np.array_equal(transport_product(T, L), ref)
    assert np.array_equal(transport_product(Tt, L, transposed=True), ref)
    assert transport_product(np.zeros((4, 0), np.float32), np.zeros((0, 3))).shape == (4, 3)


def test_gather_directions_are_the_einsum_of_the_frames_bit_for_bit():
    """`geometry.in_frames` (the gather's and the open fraction's rays in world space) sums the
    three axes as einsum did: a relight's cached G and the reference bakes keep every bit."""
    from hemicube_radiosity.core.util.geometry import in_frames, tangent_frames
    from hemicube_radiosity.core.hemisphere import cosine_lattice
    rng = np.random.default_rng(3)
    n = rng.normal(size=(500, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    local, frames = cosine_lattice(64, 2), tangent_frames(n, rng.uniform(0, 6, 500))
    d = in_frames(local, frames)
    assert d.shape == (500, len(local), 3)
    assert np.array_equal(d, np.einsum("rj,mjc->mrc", local, frames))
    assert np.allclose(np.linalg.norm(d, axis=2), 1.0) and (np.einsum("mrc,mc->mr", d, n) > 0).all()


def test_correction_matrix_in_shares_on_threads_is_one_piece_bit_for_bit(monkeypatch):
    """The hits cut at row boundaries into shares, one per thread (a dense curved mesh's
    many hits on abrupt elements kept one core busy and the other waiting), and each share into runs: C is the same for any
    count and any run length, and it is what
    :func:`correct_hits` adds (its independent sum) for values read through ``read``."""
    from hemicube_radiosity.core.output import gather
    from hemicube_radiosity.core.output.gather import correct_hits, correction_matrix
    ps = build_patches(closed_box(size=(1.0, 1.3, 0.8)), 0.1)
    rng = np.random.default_rng(7)
    idx = rng.choice(len(ps), 300, replace=False)
    G, sky, H = gather_matrix(ps, ps.centers[idx], ps.normals[idx], embree_scene(ps), rays=64, hits=True)
    select = rng.random(len(ps)) < 0.5
    extra = 40
    x = rng.random((extra, 3))
    calls = []

    def read(y, pid, hits=None):
        calls.append(len(y))
        cols = np.stack([pid % extra, (pid * 7 + 3) % extra], axis=1)
        w = np.stack([np.abs(np.sin(y.sum(1))), np.cos(y[:, 0]) ** 2], axis=1)
        return cols, w
    one = correction_matrix(G, H, ps, select, read, extra, workers=1)
    assert calls == [int(select[H[:, 1].astype(np.int64)].sum())]
    monkeypatch.setattr(gather, "CORRECTION_SHARE", 500)
    for workers in (2, 3):
        calls.clear()
        many = correction_matrix(G, H, ps, select, read, extra, workers=workers)
        assert len(calls) == workers and min(calls) > 0
        for a in ("indptr", "indices", "data"):
            np.testing.assert_array_equal(getattr(many, a), getattr(one, a))
    # each share made in runs of a few hits, cut at row boundaries: the same C, bit for bit
    monkeypatch.setattr(gather, "CORRECTION_RUN", 97)
    for workers in (1, 2):
        calls.clear()
        runs = correction_matrix(G, H, ps, select, read, extra, workers=workers)
        assert len(calls) > 10 and max(calls) < 97 + 64      # a run ends at its row's end
        for a in ("indptr", "indices", "data"):
            np.testing.assert_array_equal(getattr(runs, a), getattr(one, a))
    vals = rng.random((len(ps.verts), 3))

    def exact(y, pid):
        c, w = read(y, pid)
        return np.einsum("hc,hck->hk", w, x[c])
    want = correct_hits(G, H, ps, vals, exact, select)
    got = one.matvec(np.concatenate([vals, x]))
    assert np.abs(want).max() > 1e-3
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12)


def test_directions_rounded_to_float32_once_are_the_float64_ones_cast():
    """``in_frames(..., np.float32)`` (the sky rays handed to Embree) rounds the same float64
    sums once: the float64 directions cast, bit for bit."""
    from hemicube_radiosity.core.util.geometry import in_frames, tangent_frames
    from hemicube_radiosity.core.hemisphere import cosine_lattice
    rng = np.random.default_rng(4)
    n = rng.normal(size=(300, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    local, frames = cosine_lattice(256, 0), tangent_frames(n)
    d32 = in_frames(local, frames, np.float32)
    assert d32.dtype == np.float32
    np.testing.assert_array_equal(d32, in_frames(local, frames).astype(np.float32))


def test_a_cells_points_sharing_the_sky_rays_read_its_mean_within_one_points_noise():
    """An abrupt cell's mean sky fraction (:meth:`.abrupt.AbruptGrid._means`) from its 16
    jittered points each casting 16 of the 256 rays (``split``), against each casting all 256:
    cells 4 cm square on a floor row under the edge of a 1 m plate 0.5 m up, the truth the mean
    of the plate's closed-form form factor at the 16 points. The shared-out mean differs from
    the 16 x 256 one by less than 1 sigma of one point's 256-ray estimate (binomial; measured:
    at most 0.59 sigma, 1.1% of the hemisphere), and is as close to the truth as one 256-ray
    point reads its own (the test above: RMS < 0.6%; measured 0.49%, the 16 x 256 mean's
    0.26%); it casts 256 rays a cell, not 4,096."""
    plate = quad([(0, 0, 0.5), (0, 1, 0.5), (1, 1, 0.5), (1, 0, 0.5)], name="Plate")      # faces down
    floor = quad([(-2, -2, 0), (3, -2, 0), (3, 3, 0), (-2, 3, 0)], name="Floor")
    ps = build_patches([plate, floor], 0.25)
    rng = np.random.default_rng(7)
    centres = np.linspace(-0.6, 0.6, 61)
    a, b = (g.ravel() for g in np.meshgrid(np.arange(4), np.arange(4), indexing="ij"))
    jit = (np.stack([a, b], 1)[None] + rng.uniform(size=(len(centres), 16, 2))) / 4 - 0.5     # (C, 16, 2)
    xy = jit * 0.04 + np.column_stack([centres, np.full_like(centres, 0.37)])[:, None]
    pts = np.column_stack([xy.reshape(-1, 2), np.zeros(xy.size // 2)])
    up = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    truth = 1 - _rectangle_above(-pts[:, 0], 1 - pts[:, 0], -pts[:, 1], 1 - pts[:, 1], 0.5).reshape(-1, 16).mean(1)
    scene = CountingScene(embree_scene(ps))
    eps = ray_offsets(ps, pts, up)
    full = sky_fraction(scene, pts, up, 256, eps=eps).reshape(-1, 16).mean(1)
    assert scene.rays == 256 * len(pts)
    scene.rays = 0
    shared = sky_fraction(scene, pts, up, 256, eps=eps, split=16, chunk_rays=1000).reshape(-1, 16).mean(1)
    assert scene.rays == 16 * len(pts)
    sigma = np.sqrt(truth * (1 - truth) / 256)
    assert np.all(np.abs(shared - full) <= sigma + 1e-12)
    assert np.sqrt(np.mean((shared - truth) ** 2)) < 0.006
    assert np.sqrt(np.mean((full - truth) ** 2)) < 0.006
    # the same for any chunking (a chunk holds whole cells)
    np.testing.assert_array_equal(sky_fraction(scene, pts, up, 256, eps=eps, split=16).reshape(-1, 16).mean(1),
                                  shared)


def test_a_grid_whose_4x4_blocks_share_the_sky_rays_reads_each_blocks_mean_within_one_points_noise():
    """The abrupt grid's points (:class:`.abrupt.AbruptGrid`) cast a sixteenth of the 256 sky
    rays each, by (row % 4) * 4 + column % 4 (:meth:`~.abrupt.AbruptGrid._sky_parts`): any 4 x 4
    points in a row and a column cast the pattern once, a cell's four corners four sixteenths
    of it. Blocks of 4 x 4 points 5 cm apart (3 x 3 cells) on a floor row under the edge of a
    1 m plate 0.5 m up, read as the mean of their points (the light a gather ray landing in
    the block's cells reads, on the mean): within 1 sigma of one point's 256-ray estimate of the
    same mean with all 256 rays at every point (measured: at most 0.84 sigma), and against the
    closed-form truth an RMS under 1.6% and under four times one 256-ray point's at each
    block's middle (measured 1.33%, against 0.42% for one point and 0.20% for all rays at every
    point: each point's sixteenth of the lattice samples the plate's edge from its own place;
    in 2 x 2 blocks of cells, a quarter each, 0.67%). What the grid's points cast is read by the
    gather's rays landing on abrupt elements, light reflected once more: on the bench's real
    scenes the RMS against Cycles moved by less than 0.01 points."""
    from hemicube_radiosity.core.output.abrupt import AbruptGrid

    assert AbruptGrid.SKY_SPLIT == 16
    grid = AbruptGrid.__new__(AbruptGrid)                 # its layout only: elements of nu x nv cells
    grid.nu, grid.nv = np.array([3, 2, 1, 5, 7]), np.array([3, 2, 1, 2, 6])
    points = (grid.nu + 1) * (grid.nv + 1)
    grid.offset = np.concatenate([[0], np.cumsum(points)[:-1]])
    part = grid._sky_parts(int(points.sum()))
    for m, (nu, nv) in enumerate(zip(grid.nu, grid.nv)):   # every 4 x 4 window: all sixteen parts
        p = part[grid.offset[m]:grid.offset[m] + points[m]].reshape(nu + 1, nv + 1)
        for i in range(nu + 1):
            for j in range(nv + 1):
                w = p[i:i + 4, j:j + 4].ravel()
                assert len(set(w)) == len(w)             # no part twice in a window
                if w.size == 16:
                    assert sorted(w) == list(range(16))
    plate = quad([(0, 0, 0.5), (0, 1, 0.5), (1, 1, 0.5), (1, 0, 0.5)], name="Plate")      # faces down
    floor = quad([(-2, -2, 0), (3, -2, 0), (3, 3, 0), (-2, 3, 0)], name="Floor")
    ps = build_patches([plate, floor], 0.25)
    centres = np.linspace(-0.6, 0.6, 49)
    grid.nu = grid.nv = np.full(len(centres), 3, np.int64)    # one block an element, point i * 4 + j
    grid.offset = 16 * np.arange(len(centres))
    a, b = (g.ravel() * 0.05 - 0.075 for g in np.meshgrid(np.arange(4), np.arange(4), indexing="ij"))
    pts = np.column_stack([(centres[:, None] + a).ravel(), (0.37 + b[None] + 0 * centres[:, None]).ravel(),
                           np.zeros(16 * len(centres))])
    up = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    truth = (1 - _rectangle_above(-pts[:, 0], 1 - pts[:, 0], -pts[:, 1], 1 - pts[:, 1], 0.5)).reshape(-1, 16).mean(1)
    scene = CountingScene(embree_scene(ps))
    eps = ray_offsets(ps, pts, up)
    full = sky_fraction(scene, pts, up, 256, eps=eps).reshape(-1, 16).mean(1)
    scene.rays = 0
    shared = sky_fraction(scene, pts, up, 256, eps=eps, split=16, part=grid._sky_parts(len(pts))).reshape(-1, 16).mean(1)
    assert scene.rays == 16 * len(pts)
    sigma = np.sqrt(truth * (1 - truth) / 256)
    assert np.all(np.abs(shared - full) <= sigma + 1e-12)
    # one point at each block's middle with all 256 rays, against its own truth
    mid = np.column_stack([centres, np.full_like(centres, 0.37), np.zeros_like(centres)])
    one = sky_fraction(scene, mid, up[:len(mid)], 256, eps=ray_offsets(ps, mid, up[:len(mid)]))
    one_truth = 1 - _rectangle_above(-centres, 1 - centres, -0.37, 0.63, 0.5)
    rms = np.sqrt(np.mean((shared - truth) ** 2))
    assert rms < 0.016 and rms < 4 * np.sqrt(np.mean((one - one_truth) ** 2))