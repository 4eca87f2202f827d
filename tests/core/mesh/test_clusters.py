"""Patches above faces: dense meshes are grouped into patches of the patch size, and the closed
forms, the furnace and the rasteriser/Embree agreement still hold when every face is pre-cut into
hundreds of triangles."""
import numpy as np
from tests.support import fronts
import pytest

from tests.support.analytic import parallel_rectangles, perpendicular_rectangles
from hemicube_radiosity.core import builtin_scenes as scenes
from hemicube_radiosity.core.mesh.clusters import group_pieces
from hemicube_radiosity.core.form_factors.drawn import draw_set
from hemicube_radiosity.core.form_factors.embree import embree_hemicube_form_factors
from hemicube_radiosity.core.light.polygon_ff import group_form_factors, polygon_form_factors
from hemicube_radiosity.core.form_factors.hemicube import hemicube_form_factors
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.pipeline import BakeSettings, bake
from tests.support.shapes import uv_sphere


def cluster_factor(pieces, clusters, F, src=0, dst=1):
    """Area-weighted factor from object ``src`` to object ``dst`` out of a cluster matrix."""
    D = F.to_dense()
    a, b = clusters.owner == src, clusters.owner == dst
    A = clusters.areas[a]
    return float((A[:, None] * D[np.ix_(a, b)]).sum() / A.sum())


def test_coarse_scenes_are_not_grouped():
    """Pieces cut from coarse quads already have the patch size: no clusters, the same bake. The
    same box triangulated is cut into triangles of a quarter of a patch: grouped, it costs what
    the quads cost."""
    quads = build_patches(scenes.cornell_box(), 0.25)
    assert group_pieces(quads, 0.25) is None
    tris = build_patches(scenes.tessellate(scenes.cornell_box(), 1), 0.25)
    grouped = group_pieces(tris, 0.25)
    assert len(tris) > 3 * len(quads) and 0.7 * len(quads) < len(grouped) < 1.1 * len(quads)


def test_a_dense_wall_is_solved_as_tens_of_patches_not_thousands_of_faces():
    m = scenes.tessellate([scenes.quad([(0, 0, 0), (2, 0, 0), (2, 2, 0), (0, 2, 0)])], 50)   # 5000 tris
    p = build_patches(m, 0.5)
    c = group_pieces(p, 0.5)
    assert len(p) == 5000 and len(c) == 16                        # a 4 x 4 grid of 0.5 m cells
    # triangles go by their box's centre: a quad's two triangles stay together, so a cell holds
    # 12 or 13 of the 0.04 m quads across (0.2304 to 0.2704 m^2) and its outline is a rectangle
    np.testing.assert_allclose(c.areas, 0.25, rtol=0.082)
    assert len(draw_set(p, c)) == 2 * len(c)
    assert c.areas.sum() == pytest.approx(4.0)
    # eye points on the surface, inside their own cell
    assert np.all(np.abs(c.centers[:, 2]) < 1e-12)


def test_grouping_never_crosses_materials_or_sharp_creases():
    # one flat strip, half red half white, folded 90 degrees in the middle of the white half
    red = scenes.tessellate([scenes.quad([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], rho=(0.8, 0.1, 0.1))], 10)[0]
    white = scenes.tessellate([scenes.quad([(1, 0, 0), (2, 0, 0), (2, 1, 0), (1, 1, 0)], rho=(0.7, 0.7, 0.7))], 10)[0]
    wall = scenes.tessellate([scenes.quad([(2, 0, 0), (2, 0, 1), (2, 1, 1), (2, 1, 0)], rho=(0.7, 0.7, 0.7))], 10)[0]
    p = build_patches([red, white, wall], 4.0)                  # one cell for everything
    c = group_pieces(p, 4.0)
    for k in range(len(c)):
        members = c.of == k
        assert len(np.unique(p.rho[members], axis=0)) == 1       # one material
        n = p.normals[members]
        assert np.degrees(np.arccos(np.clip(n @ n[0], -1, 1))).max() < 30   # no crease inside
    # a smooth sphere is cut by normal: every cluster within the grouping angle
    sphere = uv_sphere(48, 24)
    ps = build_patches([sphere], 10.0)
    cs = group_pieces(ps, 10.0, max_angle=30)
    assert 10 < len(cs) < 200
    spread = [np.degrees(np.arccos(np.clip(ps.normals[cs.of == k] @ cs.normals[k], -1, 1))).max()
              for k in range(len(cs))]
    assert max(spread) < 30


def test_parallel_squares_cut_into_hundreds_of_triangles_match_siegel_howell():
    # each square modelled as 2 x 16 x 16 = 512 triangles; the receiver grouped into 8 x 8 patches
    m = scenes.tessellate(scenes.parallel_squares(1.0), 16)
    p = build_patches(m, 1 / 8)
    c = group_pieces(p, 1 / 8)
    assert len(p) == 1024 and len(c) == 128
    F = hemicube_form_factors(p, 128, clusters=c, receivers=np.flatnonzero(c.owner == 0))
    assert cluster_factor(p, c, F) == pytest.approx(parallel_rectangles(), rel=5e-3)
    recv = np.flatnonzero(c.owner == 0)
    np.testing.assert_allclose(F.row_sums()[recv] + F.sky[recv], 1.0, atol=1e-6)


def test_perpendicular_squares_cut_into_hundreds_of_triangles_match_siegel_howell():
    m = scenes.tessellate(scenes.perpendicular_squares(), 20)
    p = build_patches(m, 0.1)
    c = group_pieces(p, 0.1)
    assert len(p) == 1600 and len(c) == 200
    F = hemicube_form_factors(p, 128, clusters=c, receivers=np.flatnonzero(c.owner == 0))
    assert cluster_factor(p, c, F) == pytest.approx(perpendicular_rectangles(), rel=1e-2)


def test_embree_casts_the_rasteriser_pixels_for_clusters_too():
    m = scenes.tessellate(scenes.cornell_box(), 6)
    p = build_patches(m, 0.5)
    c = group_pieces(p, 0.5)
    recv = np.arange(0, len(c), 7)
    # turned hemi-cubes: unturned, pixel centres of this regular grid fall exactly on triangle
    # edges, which the two may give to either side (rows then differ by ~0.5%, sums agree)
    Fh = hemicube_form_factors(p, 32, clusters=c, receivers=recv, rotate_seed=1).to_dense()[recv]
    Fe = embree_hemicube_form_factors(p, 32, clusters=c, receivers=recv, rotate_seed=1).to_dense()[recv]
    assert Fh.sum() > 0.5 * len(recv)
    np.testing.assert_allclose(Fh, Fe, atol=1e-6)


@pytest.mark.parametrize("rho", [0.5, 0.9])
def test_furnace_with_every_face_cut_into_hundreds_of_triangles(rho):
    m = scenes.tessellate(scenes.closed_box(size=(1.0, 1.3, 0.8), rho=(rho,) * 3, emission=(1.0,) * 3), 12)
    assert sum(len(x.face_offsets) - 1 for x in m) == 6 * 288
    r = bake(m, BakeSettings(patch_size=0.2, resolution=64, tolerance=1e-7, max_iterations=2000))
    assert r.clusters is not None and r.unknowns < len(r.patches) / 5
    assert r.solution.converged
    np.testing.assert_allclose(r.solution.B, 1 / (1 - rho), rtol=5e-3)
    np.testing.assert_allclose(r.vertex_radiosity, 1 / (1 - rho), rtol=5e-3)
    assert r.solution.energy["imbalance"] < 5e-3


def test_a_lamp_modelled_as_many_faces_lights_like_one():
    """Direct light from a grouped emitter (boundary contour, shadow rays over the whole group)
    equals the face-by-face sum, and the bake matches the coarse model of the same scene."""
    rng = np.random.default_rng(5)
    lamp = scenes.tessellate([scenes.cornell_box()[5]], 12)
    p = build_patches(lamp, None)
    pts = rng.uniform((-0.5, -0.5, 0.0), (2.5, 2.5, 2.2), (800, 3))
    nrm = rng.normal(size=(800, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    groups = (p.centers[:, 0] > 1.0).astype(int)                 # two halves
    ref = polygon_form_factors(pts, nrm, p.corners(), p.normals)
    ref = np.stack([ref[:, groups == g].sum(1) for g in (0, 1)], 1)
    np.testing.assert_allclose(group_form_factors(pts, nrm, p.corners(), groups, p.normals), ref, atol=1e-12)


def test_group_form_factors_group_by_group_equal_the_flat_pairs_bit_for_bit(monkeypatch):
    """A few groups are evaluated group by group (points x edges blocks, in blocks of points),
    many groups as flat (point, group) pairs: the same sums in the same order, bit for bit,
    including the points below part of a group (clipped contours) and a small block size."""
    from hemicube_radiosity.core.light import polygon_ff
    rng = np.random.default_rng(8)
    lamp = scenes.tessellate([scenes.cornell_box()[5]], 9)
    p = build_patches(lamp, None)
    groups = (p.centers[:, 0] > 1.0).astype(int) + 2 * (p.centers[:, 2] > 1.0)
    groups = np.unique(groups, return_inverse=True)[1]
    pts = rng.uniform((-0.5, -0.5, 1.0), (2.5, 2.5, 2.2), (600, 3))
    nrm = rng.normal(size=(600, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    by_group = group_form_factors(pts, nrm, p.corners(), groups, p.normals)
    monkeypatch.setattr(polygon_ff, "BLOCK_PAIRS", 97)
    small_blocks = group_form_factors(pts, nrm, p.corners(), groups, p.normals)
    monkeypatch.setattr(polygon_ff, "GROUP_LOOP", 0)
    flat = group_form_factors(pts, nrm, p.corners(), groups, p.normals)
    assert (flat > 0).sum() > 100 and groups.max() >= 1
    assert np.array_equal(by_group, flat) and np.array_equal(small_blocks, flat)


def test_clipped_contour_answers_points_below_the_whole_region_without_clipping():
    """A point that sees the whole region at or below its horizon (wholly behind, or in its
    plane) sees nothing of it: F = 0, ok, without the clipping; the points that see part of it
    get what the clipping gives them among any others, bit for bit, and what the face-by-face
    sum gives."""
    from hemicube_radiosity.core.light import polygon_ff
    from hemicube_radiosity.core.light.outline import GroupOutline
    rng = np.random.default_rng(11)
    lamp = build_patches([scenes.cornell_box()[5]], None)              # the lamp, facing down
    o = GroupOutline.of(lamp.corners(), np.zeros(len(lamp), int), lamp.normals)
    centre = lamp.centers.mean(axis=0)
    pts = centre + rng.uniform((-1.5, -1.5, -1.5), (1.5, 1.5, -0.05), (400, 3))   # below the lamp
    nrm = rng.normal(size=(400, 3))
    nrm[:100] = np.abs(nrm[:100]) * (0, 0, -1)                       # facing away: nothing seen
    nrm[100:120] = lamp.normals[0]                                    # in the horizon's plane: nothing
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    pts[100:120, 2] = centre[2]
    F, ok = polygon_ff._clipped_contour(pts, nrm, o.edges, lamp.normals[0])
    assert ok.all() and not F[:120].any()
    part = np.flatnonzero(F > 0)
    assert part.size > 100
    Fp, okp = polygon_ff._clipped_rows(pts[120:], nrm[120:], o.edges, lamp.normals[0])
    assert np.array_equal(F[120:], Fp) and okp.all()
    ref = polygon_form_factors(pts, nrm, lamp.corners(), lamp.normals).sum(axis=1)
    np.testing.assert_allclose(F, ref, atol=1e-12)


def test_dense_cornell_box_bakes_like_the_coarse_one():
    """The same box modelled as 8,192 triangles: a few hundred patches, and the floor and back
    wall within 5% of the coarse model's bake at the defaults (the light is the same; only the
    modelling changed; the triangulated coarse model itself differs from the quads by 2.8%).
    One-sided emitters here: the two-sided lamp 2 mm under the ceiling paints a hot spot on it
    that patches of 0.25 m resolve differently whatever the modelling (pointwise ~9% apart,
    the same mean: checked below)."""
    from hemicube_radiosity.core.output.interpolate import interpolate_at

    s = BakeSettings(two_sided_emission=False)
    coarse = bake(scenes.cornell_box(), s)
    dense = bake(scenes.tessellate(scenes.cornell_box(), 16), s)
    assert fronts(dense, dense.patches.owner).sum() == 8192 and dense.unknowns < 600
    g = np.linspace(0.1, 1.9, 12)
    u, v = [a.ravel() for a in np.meshgrid(g, g)]
    lum = np.array([0.2126, 0.7152, 0.0722])
    for name, pts, n in (("Floor", np.stack([u, v, 0 * u], 1), (0, 0, 1)),
                         ("BackWall", np.stack([u, 0 * u + 2, v], 1), (0, -1, 0))):
        vals = []
        for r in (coarse, dense):
            oi = r.elements.object_names.index(name)
            vals.append(interpolate_at(r.elements, r.vertex_radiosity, pts, owner=np.full(len(pts), oi),
                                       normals=np.tile(n, (len(pts), 1))) @ lum)
        assert np.abs(vals[1] - vals[0]).mean() / vals[0].mean() < 0.05, name
    two = [bake(m, BakeSettings()) for m in (scenes.cornell_box(), scenes.tessellate(scenes.cornell_box(), 16))]
    oi = [r.elements.object_names.index("Floor") for r in two]
    mean = [interpolate_at(r.elements, r.vertex_radiosity, np.stack([u, v, 0 * u], 1), owner=np.full(u.size, o),
                           normals=np.tile((0, 0, 1), (u.size, 1))).mean(0) @ lum for r, o in zip(two, oi)]
    assert mean[1] == pytest.approx(mean[0], rel=0.03)


def test_a_dense_lamp_split_in_cells_has_straight_cell_outlines():
    """A lamp modelled as 3,362 triangles and split into 9 cells by a grid that does not
    follow its mesh has cell borders along jagged triangle paths (34-62 edges per cell, 342 in
    all, before); straightened (the same polyline for both cells of a border) each cell has 4 or
    5 edges (38), and the cells' sum is still the whole lamp's closed form (to 3e-16): its
    unoccluded transport equals the untessellated quad's to float32 precision. Each cell keeps
    its own faces' form factor to within the sliver of triangles along its borders (1.2% of
    the lamp's at these points; asserted below 2%)."""
    from hemicube_radiosity.core.light.emitters import emitter_transport
    from hemicube_radiosity.core.light.outline import GroupOutline

    rng = np.random.default_rng(9)
    quad = [scenes.cornell_box()[5]]
    coarse = build_patches(quad, None)
    dense = build_patches(scenes.tessellate(quad, 41), None)
    assert len(coarse) == 1 and len(dense) == 2 * 41 * 41
    size = np.ptp(coarse.verts[:, 0]) / 2.6                       # cell borders across the triangles
    groups = group_pieces(dense, size).of
    G = groups.max() + 1
    assert G >= 9
    outline = GroupOutline.of(dense.corners(), groups, dense.normals)
    assert outline.edge_count.max() <= 6 and outline.edge_count.sum() <= 6 * G
    lo, hi = coarse.verts.min(0), coarse.verts.max(0)
    pts = rng.uniform(lo - (0.5, 0.5, 2.0), hi + (0.5, 0.5, -0.05), (240, 3))
    nrm = rng.normal(size=(240, 3))
    nrm[:, 2] = np.abs(nrm[:, 2])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    whole = polygon_form_factors(pts, nrm, coarse.corners(), coarse.normals)[:, 0]
    F = group_form_factors(pts, nrm, dense.corners(), groups, dense.normals, outline)
    np.testing.assert_allclose(F.sum(1), whole, rtol=1e-11, atol=1e-15)
    T = emitter_transport(dense, pts, nrm, np.arange(len(dense)), groups=groups)
    T1 = emitter_transport(coarse, pts, nrm, [0])
    np.testing.assert_allclose(T.sum(1, dtype=np.float64), T1[:, 0], rtol=2e-6, atol=1e-9)
    faces = polygon_form_factors(pts, nrm, dense.corners(), dense.normals)
    own = np.stack([faces[:, groups == g].sum(1) for g in range(G)], 1)
    assert np.abs(F - own).max() < 0.02 * whole.max()


@pytest.mark.parametrize("kind", ["cells", "scattered"])
def test_straightened_group_outlines_keep_the_exact_sum(monkeypatch, kind):
    """Straightening every border (not only those of groups with many edges) of a dense lamp
    split at random: into Voronoi cells (straightened: 93-236 edges in all become 18-55) or face
    by face at random (scattered faces: their outlines would cross, so they are kept), the sum
    over the groups is the whole lamp's closed form to round-off."""
    from hemicube_radiosity.core.light import outline as group_outline
    from hemicube_radiosity.core.light.outline import GroupOutline

    monkeypatch.setattr(group_outline, "STRAIGHTEN_ABOVE", 0)
    rng = np.random.default_rng(0)
    p = build_patches(scenes.tessellate([scenes.cornell_box()[5]], 23), None)
    c, pn = p.corners(), p.normals
    lo, hi = p.verts.min(0), p.verts.max(0)
    pts = rng.uniform(lo - (0.3, 0.3, 1.5), hi + (0.3, 0.3, -0.02), (200, 3))
    nrm = rng.normal(size=(200, 3))
    nrm[:, 2] = np.abs(nrm[:, 2])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    whole = polygon_form_factors(pts, nrm, c, pn).sum(1)
    for _ in range(6):
        k = int(rng.integers(2, 12))
        if kind == "cells":
            seeds = rng.uniform(lo, hi, (k, 3))
            g = np.linalg.norm(p.centers[:, None, :2] - seeds[None, :, :2], axis=2).argmin(1)
        else:
            g = rng.integers(0, k, len(c))
        g = np.unique(g, return_inverse=True)[1].reshape(-1)
        outline = GroupOutline.of(c, g, pn)
        if kind == "cells":
            assert outline.edge_count.max() <= 12
        F = group_form_factors(pts, nrm, c, g, pn, outline)
        np.testing.assert_allclose(F.sum(1), whole, rtol=1e-12, atol=1e-15)


def test_curved_groups_seen_from_everywhere_sum_their_faces_exactly():
    """A dense sphere cut into curved groups (a hot cap shining on a room): the normal cone
    that decides most point-group pairs at once, and the face-by-face sum over the faces turned
    to the point only, give the plain sum over every face of :func:`polygon_form_factors`."""
    from hemicube_radiosity.core.light import polygon_ff
    from hemicube_radiosity.core.light.outline import GroupOutline

    rng = np.random.default_rng(3)
    p = build_patches([uv_sphere(48, 24)], None)
    c, pn = p.corners(), p.normals
    g = group_pieces(p, 0.7).of                                       # cells and 30-degree normal bins
    outline = GroupOutline.of(c, g, pn)
    assert (~outline.planar).sum() >= 8
    pts = np.concatenate([rng.uniform(-3, 3, (300, 3)), p.centers[::7] * 1.0001])   # far, and on the ball
    nrm = rng.normal(size=(len(pts), 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    every = polygon_form_factors(pts, nrm, c, pn)
    want = np.stack([every[:, g == k].sum(1) for k in range(g.max() + 1)], 1)
    F = group_form_factors(pts, nrm, c, g, pn, outline)
    np.testing.assert_allclose(F, want, rtol=1e-9, atol=1e-13)
    # the cone settles most pairs without a face-by-face test
    n_front, count = polygon_ff.in_front(pts, outline)
    assert ((n_front == 0) | (n_front == count[None])).mean() > 0.8


def test_a_clusters_light_costs_a_few_stand_ins_and_keeps_its_mean(monkeypatch):
    """The direct stage lights a grouped cluster at 32 stand-in centres (area strata in
    Morton order), not at every face's, so its cost follows the clusters. Each cluster's direct
    source still matches the closed-form mean over all its faces (a Lambertian square lamp over
    a floor of 20,000 triangles, nothing in between)."""
    from hemicube_radiosity.core.light import stage as direct_light
    from hemicube_radiosity.core.light.direct import DirectLight

    floor = scenes.tessellate([scenes.quad([(0, 0, 0), (2, 0, 0), (2, 2, 0), (0, 2, 0)], rho=(0.6,) * 3,
                                           name="Floor")], 100)
    lamp = scenes.quad([(0.3, 0.2, 0.8), (0.3, 0.9, 0.8), (1.0, 0.9, 0.8), (1.0, 0.2, 0.8)],
                       emission=(5.0,) * 3, name="Lamp")               # faces down, off-centre
    counted = []
    at = DirectLight.at

    def counting(self, x, n, where="", **kw):
        counted.append((where, len(x)))
        return at(self, x, n, where, **kw)
    monkeypatch.setattr(DirectLight, "at", counting)
    r = bake(floor + [lamp], BakeSettings(patch_size=0.25))
    c, p = r.clusters, r.patches
    on_floor = c.owner == p.object_names.index("Floor")
    assert (p.owner == 0).sum() == 20000 and on_floor.sum() == 64 and c.sizes[on_floor].min() > 250
    # the solve's light: 32 points a floor cluster (8 x the 2 x 2 light points; the plain and the
    # seen mean share them), 2 x 2 on each of the lamp's 9 patches; the output vertices apart
    assert sorted(counted) == [("grouped-centres", 32 * 64), ("patch-points-2", 4 * 9), ("vertices", 10301)]
    # truth: 5 x the form factor to the lamp at every face centre, area-weighted per cluster
    lp = build_patches([lamp], None)
    F = polygon_form_factors(p.centers, p.normals, lp.corners(), lp.normals).sum(1)
    truth = np.bincount(c.of, weights=p.areas * 5.0 * F, minlength=len(c)) / c.areas
    got = r.source[on_floor, 0] / 0.6
    np.testing.assert_allclose(got, truth[on_floor], rtol=0.01)
    assert abs(got @ c.areas[on_floor] / (truth[on_floor] @ c.areas[on_floor]) - 1) < 1e-3
    # every face centre lit (no stand-ins): the same means, from 20,000 points
    monkeypatch.setattr(direct_light, "STAND_INS", 10 ** 6)
    every = bake(floor + [lamp], BakeSettings(patch_size=0.25))
    err_stand = np.abs(got - truth[on_floor]) / truth[on_floor]
    err_every = np.abs(every.source[on_floor, 0] / 0.6 - truth[on_floor]) / truth[on_floor]
    assert err_every.max() < 1e-6 < err_stand.max()


def test_a_lamps_slivers_shine_with_their_neighbours():
    """The clusters' grid cuts the Cornell box's lamp wherever its cells fall: as 128 triangles
    it made 4 emitter groups, as 882 it made 9 (slivers along two cell borders), and each group
    costs every lit point 16 shadow rays. Groups under half a patch join their nearest
    neighbour in the same plane: 4 groups at both sizes, whose form factors still sum to the
    lamp's closed form. A sliver never joins a group in another plane (a furnace box is one
    object: its walls' groups stay apart)."""
    from hemicube_radiosity.core.light.direct import DirectLight

    boxes = {n: scenes.tessellate(scenes.cornell_box(), n) for n in (8, 21)}
    s = BakeSettings().resolved(boxes[8])                  # 'auto': 0.247 m patches
    counts = []
    for n, box in boxes.items():
        p = build_patches(box, s.patch_size)
        c = group_pieces(p, s.patch_size)
        plan = DirectLight.plan(p, s, [], clusters=c)
        g = plan.groups
        counts.append((int(np.unique(c.of[plan.emitters]).size), int(g.max()) + 1))
        em = plan.emitters
        for k in range(g.max() + 1):                       # each group in one plane
            assert np.abs(p.normals[em[g == k]] @ p.normals[em[g == k]][0]).min() > 1 - 1e-9
        rng = np.random.default_rng(1)
        pts = rng.uniform((0.2, 0.2, 0.1), (1.8, 1.8, 1.5), (200, 3))
        nrm = np.tile((0.0, 0.0, 1.0), (200, 1))
        lamp = build_patches([scenes.cornell_box()[5]], None)
        whole = polygon_form_factors(pts, nrm, lamp.corners(), lamp.normals).sum(1)
        F = group_form_factors(pts, nrm, p.corners()[em], g, p.normals[em])
        np.testing.assert_allclose(F.sum(1), whole, rtol=1e-9)
    assert counts == [(4, 4), (9, 4)]
    box = scenes.tessellate(scenes.closed_box(size=(1.0, 1.3, 0.8), emission=(1.0,) * 3), 12)
    p = build_patches(box, 0.2)
    plan = DirectLight.plan(p, BakeSettings(patch_size=0.2), [], clusters=group_pieces(p, 0.2))
    for k in range(plan.groups.max() + 1):
        nk = p.normals[plan.emitters[plan.groups == k]]
        assert np.abs(nk @ nk[0]).min() > 1 - 1e-9
