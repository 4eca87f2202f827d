"""Gather rays shared between the corners at one place (:mod:`...core.output.shared`): each
corner still reads its own hemisphere, against closed forms, a furnace and the unshared gather."""
import numpy as np
import pytest

from hemicube_radiosity.core.builtin_scenes import quad
from hemicube_radiosity.core.light.emitters import vertex_frames
from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.output import gather
from hemicube_radiosity.core.output.gather import correct_hits, gather_matrix
from hemicube_radiosity.core.util.sparse import product
from hemicube_radiosity.core.output.shared import share_corners
from hemicube_radiosity.core.rays import embree_available, embree_scene

pytestmark = pytest.mark.skipif(not embree_available(), reason="needs embreex")


def _fan(k=6, h=0.3, radius=1.0, centre=(0.0, 0.0, 0.0), up=1.0, name="fan"):
    """A flat-shaded fan of ``k`` triangles around an apex ``h`` above (``up`` = -1: below) the
    ring: every face its own corners (as a flat-shaded mesh's output vertices)."""
    a = np.arange(k) * 2 * np.pi / k
    c = np.asarray(centre, float)
    ring = c + np.c_[radius * np.cos(a), radius * np.sin(a), np.zeros(k)]
    apex = c + [0.0, 0.0, up * h]
    verts, faces = [], []
    for i in range(k):
        tri = [apex, ring[i], ring[(i + 1) % k]]
        faces.append([len(verts), len(verts) + 1, len(verts) + 2])
        verts += tri
    return MeshInput.from_faces(np.array(verts), faces, name=name)


def _scene(fan, ground=1000.0):
    g = ground
    floor = quad([(-g, -g, 0), (g, -g, 0), (g, g, 0), (-g, g, 0)], name="ground")
    return build_patches([fan, floor], None)


def _sharer(ps):
    x, n, _ = vertex_frames(ps)
    return share_corners(ps, x, n, embree_scene(ps))


def _apex_rows(ps, apex):
    """Vertex ids at the place ``apex`` (3,)."""
    return np.flatnonzero(np.all(np.abs(ps.verts - np.asarray(apex, float)) < 1e-12, axis=1))


def test_a_convex_fans_corners_each_read_their_own_tilted_sky_and_ground_in_closed_form():
    """A pyramid on a vast ground under the sky: from its apex, nothing of the pyramid is above a
    face's plane, so each face's corner sees the sky's (1 + cos t) / 2 and the ground's
    (1 - cos t) / 2 of its cosine lobe (t: its tilt). Shared, each estimate stays within the
    noise of as many independent rays, and over 8 patterns (seeds) the mean within its own."""
    ps = _scene(_fan(h=0.3))
    x, n, _ = vertex_frames(ps)
    apex = _apex_rows(ps, (0, 0, 0.3))
    assert len(apex) == 6
    share = share_corners(ps, x, n, embree_scene(ps))
    assert share is not None and share.size[share.position[apex]].tolist() == [6] * 6
    ground_vals = np.zeros((len(ps.verts), 1))
    ground_vals[np.unique(ps.polys[ps.owner == 1])] = 1.0
    want = (1 + n[apex, 2]) / 2
    rays, seeds = 256, 8
    sigma = np.sqrt(want * (1 - want) / rays)
    errs = []
    for seed in range(seeds):
        G, sky = gather_matrix(ps, x, n, embree_scene(ps), rays=rays, seed=seed, share=_sharer(ps))
        np.testing.assert_allclose(product(G, ground_vals)[apex, 0] + sky[apex], 1.0, atol=1e-6)
        errs.append(sky[apex] - want)
        assert np.all(np.abs(errs[-1]) <= 4 * sigma)
    assert np.all(np.abs(np.mean(errs, axis=0)) <= 4 * sigma / np.sqrt(seeds))
    # unshared, each corner's own lattice: the same truth
    G, sky = gather_matrix(ps, x[apex], n[apex], embree_scene(ps), rays=rays)
    assert np.all(np.abs(sky - want) <= 4 * sigma)


def test_a_furnace_gives_every_shared_corner_exactly_its_radiance():
    """Radiance 1 on every surface and from the world: each corner's weights, normalised, read 1
    whatever its rays found (a concave fan, a funnel, whose corners see each other's faces)."""
    ps = _scene(_fan(h=0.4, up=-1.0, centre=(0, 0, 0.5)))
    x, n, _ = vertex_frames(ps)
    apex = _apex_rows(ps, (0, 0, 0.1))
    G, sky, H = gather_matrix(ps, x, n, embree_scene(ps), rays=128, share=_sharer(ps), hits=True)
    got = product(G, np.ones((len(ps.verts), 1)))[:, 0] + sky
    np.testing.assert_allclose(got[apex], 1.0, atol=2e-6)
    np.testing.assert_allclose(got, 1.0, atol=2e-6)
    assert H.shape[1] == 6 and np.all(np.diff(H[:, 0]) >= 0)
    # the hits carry each corner's weights: a correction that reads the surfaces' exact values
    # (here their interpolation itself) adds nothing
    vals = ps.verts[:, 2:3] + 1.0
    none = correct_hits(G, H, ps, vals, lambda y, pid: y[:, 2:3] + 1.0, np.ones(len(ps), bool))
    np.testing.assert_allclose(none, 0.0, atol=1e-5)


def test_a_funnels_shared_corners_read_what_their_own_rays_read_within_the_noise():
    """The funnel's faces light each other: per corner, over 12 patterns (seeds), the shared
    estimates of a field on the surfaces and of the sky scatter about 16,384 unshared rays'
    as 256 unshared rays' do (at most 1.5 times as far), with no bias beyond their noise."""
    ps = _scene(_fan(h=0.5, up=-1.0, centre=(0, 0, 0.6)))
    x, n, _ = vertex_frames(ps)
    apex = _apex_rows(ps, (0, 0, 0.1))
    vals = 0.2 + ps.verts[:, :1] ** 2 + 0.3 * ps.verts[:, 2:3]
    share = share_corners(ps, x, n, embree_scene(ps))
    assert len(apex) == 6 and (share.size[share.position[apex]] >= 2).sum() >= 4
    Gr, skyr = gather_matrix(ps, x[apex], n[apex], embree_scene(ps), rays=16384)
    want = np.column_stack([product(Gr, vals)[:, 0], skyr])
    assert 0.3 < skyr.min() and skyr.max() < 0.9                    # the faces hide much of the sky
    shared, alone = [], []
    for seed in range(12):
        G, sky = gather_matrix(ps, x, n, embree_scene(ps), rays=256, seed=seed, share=_sharer(ps))
        shared.append(np.column_stack([product(G, vals)[apex, 0], sky[apex]]) - want)
        G, sky = gather_matrix(ps, x[apex], n[apex], embree_scene(ps), rays=256, seed=seed)
        alone.append(np.column_stack([product(G, vals)[:, 0], sky]) - want)
    shared, alone = np.array(shared), np.array(alone)                # (seeds, corners, 2)
    rms_s, rms_a = (np.sqrt((e ** 2).mean(axis=(0, 1))) for e in (shared, alone))
    assert np.all(rms_s <= 1.5 * rms_a)
    assert np.all(np.abs(shared.mean(axis=(0, 1))) <= 4 * rms_s / np.sqrt(12 * 6))


def test_corners_far_apart_in_normal_or_parted_by_a_wall_share_nothing():
    """A box's corners (90 degrees apart) cast their own rays: the same G as unshared, bit for bit;
    two coplanar floor triangles meeting at a wall's foot keep their corners apart."""
    from hemicube_radiosity.core.builtin_scenes import box
    ps = build_patches(box((0, 0, 0), (1, 1, 1)), None)
    x, n, _ = vertex_frames(ps)
    assert share_corners(ps, x, n, embree_scene(ps)) is None
    G1, s1, H1 = gather_matrix(ps, x, n, embree_scene(ps), rays=32, share=_sharer(ps), hits=True)
    G0, s0, H0 = gather_matrix(ps, x, n, embree_scene(ps), rays=32, hits=True)
    assert np.array_equal(G1.indptr, G0.indptr) and np.array_equal(G1.data, G0.data)
    assert np.array_equal(s1, s0) and np.array_equal(H1, H0)
    # a floor of two triangles, each with its own corners, a thin wall standing on their diagonal
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    floor = MeshInput.from_faces(v, [[0, 1, 2], [3, 4, 5]], name="floor")
    wall = quad([(0, 0, 0), (1, 1, 0), (1, 1, 1), (0, 0, 1)], name="wall")
    both = build_patches([floor, wall], None)
    x, n, _ = vertex_frames(both)
    assert share_corners(both, x, n, embree_scene(both)) is None
    alone = build_patches([floor], None)
    x, n, _ = vertex_frames(alone)
    share = share_corners(alone, x, n, embree_scene(alone))
    assert share is not None and sorted(np.diff(share.clusters).tolist()) == [1, 1, 2, 2]


def test_shared_gather_is_identical_forked_and_with_any_chunking(monkeypatch):
    """Forked workers, threads and one chunk make the same G, sky and hits, bit for bit."""
    monkeypatch.setattr(gather, "PROCESS_RAYS", 0)
    ps = _scene(_fan(k=7, h=0.5, up=-1.0, centre=(0, 0, 0.5)))
    ps2 = build_patches([_fan(k=5, h=0.2), _fan(k=7, h=0.4, up=-1.0, centre=(3, 0, 0.5)),
                         quad([(-9, -9, 0), (9, -9, 0), (9, 9, 0), (-9, 9, 0)], name="ground")], None)
    for mesh in (ps, ps2):
        x, n, _ = vertex_frames(mesh)
        assert share_corners(mesh, x, n, embree_scene(mesh)) is not None
        runs = [gather_matrix(mesh, x, n, embree_scene(mesh), rays=16, chunk_rays=16 * c, workers=w,
                              hits=True, share=_sharer(mesh)) for w, c in ((1, 4096), (1, 2), (2, 3))]
        G1, s1, H1 = runs[0]
        for G, s, H in runs[1:]:
            assert np.array_equal(G.indptr, G1.indptr) and np.array_equal(G.indices, G1.indices)
            assert np.array_equal(G.data, G1.data) and np.array_equal(s, s1) and np.array_equal(H, H1)


def test_the_open_fraction_shared_by_corners_finds_the_same_buried_and_open_vertices():
    """A flat-shaded floor (every triangle its own corners) with a block standing on it: the
    corners under the block see nothing, those beside it half the hemisphere or more; shared,
    each corner's fraction tells them apart as its own rays do (the same side of a quarter)."""
    from hemicube_radiosity.core.builtin_scenes import box
    from hemicube_radiosity.core.output.shared import shared_open_fraction
    from hemicube_radiosity.core.hemisphere import open_fraction
    g = np.linspace(-2, 2, 9)
    verts, faces = [], []
    for i in range(8):
        for j in range(8):
            a, b, c, d = ((g[i], g[j], 0), (g[i + 1], g[j], 0), (g[i + 1], g[j + 1], 0), (g[i], g[j + 1], 0))
            for tri in ((a, b, c), (a, c, d)):
                faces.append([len(verts), len(verts) + 1, len(verts) + 2])
                verts += tri
    floor = MeshInput.from_faces(np.array(verts, float), faces, name="floor")
    ps = build_patches([floor, box((-0.5, -0.5, 0), (0.5, 0.5, 1), bottom=False)], None)
    x, n, _ = vertex_frames(ps)
    scene = embree_scene(ps)
    share = share_corners(ps, x, n, scene)
    assert share is not None and np.diff(share.clusters).max() == 6
    shared = shared_open_fraction(ps, x, n, scene, 0.2, share, rays=16)
    alone = open_fraction(ps, x, n, scene, 0.2, rays=256)
    on_floor = np.unique(ps.polys[ps.owner == 0])
    inside = on_floor[np.all(np.abs(ps.verts[on_floor, :2]) < 0.49, axis=1)]
    assert np.all(shared[inside] == 0.0) and np.all(alone[inside] == 0.0)
    np.testing.assert_array_equal(shared[on_floor] < 0.25, alone[on_floor] < 0.25)
    assert np.abs(shared - alone).max() < 0.2


def test_a_mesh_whose_few_corners_share_casts_as_before():
    """Below MIN_JOINED of the vertices joining another's rays (a smooth mesh with one
    flat-shaded fan), every vertex casts its own: no reordering for a few rays saved."""
    from hemicube_radiosity.core.output.shared import MIN_JOINED, joined_ahead
    ground = quad([(-9, -9, 0), (9, -9, 0), (9, 9, 0), (-9, 9, 0)], name="ground")
    ps = build_patches([_fan(k=6, h=0.3, centre=(0, 0, 0.01)), ground], 0.5)
    x, n, _ = vertex_frames(ps)
    assert 0 < 11 < MIN_JOINED * len(ps.verts)
    assert share_corners(ps, x, n, embree_scene(ps)) is None and joined_ahead(ps) == 0
