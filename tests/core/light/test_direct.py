"""Exact direct light from emissive patches: Lambert's formula, horizon clipping, shadow rays."""
import numpy as np
import pytest

from tests.support.analytic import point_under_rectangle_corner
from hemicube_radiosity.core.light.emitters import emitter_direct, emitter_transport
from hemicube_radiosity.core.light.polygon_ff import polygon_form_factors
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.rays import embree_scene
from hemicube_radiosity.core.builtin_scenes import quad


SQ = np.array([[[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]], float)


def test_parallel_rectangle_matches_closed_form():
    pts = [[0.5, 0.5, 0], [0, 0, 0], [0.25, 0.5, 0]]
    F = polygon_form_factors(pts, [[0, 0, 1]] * 3, SQ, poly_normals=[[0, 0, -1]])[:, 0]
    expect = [4 * point_under_rectangle_corner(0.5, 0.5, 1), point_under_rectangle_corner(1, 1, 1),
              2 * point_under_rectangle_corner(0.25, 0.5, 1) + 2 * point_under_rectangle_corner(0.75, 0.5, 1)]
    np.testing.assert_allclose(F, expect, rtol=1e-12)


def test_polygon_across_the_horizon_is_clipped():
    wall = np.array([[[0, 1, -1], [1, 1, -1], [1, 1, 1], [0, 1, 1]]], float)
    F = polygon_form_factors([[0, 0, 0]], [[0, 0, 1]], wall)[0, 0]
    g = (np.arange(2000) + 0.5) / 2000
    x, z = np.meshgrid(g, g)
    quadrature = (z / (x * x + 1 + z * z) ** 2).mean() / np.pi  # only the half above the horizon
    assert F == pytest.approx(quadrature, rel=1e-6)


def test_emitter_shines_only_from_its_front_and_winding_does_not_matter():
    pts = [[0.5, 0.5, 0], [0.5, 0.5, 2]]
    F = polygon_form_factors(pts, [[0, 0, 1], [0, 0, -1]], SQ, poly_normals=[[0, 0, -1]])[:, 0]
    assert F[0] > 0.2 and F[1] == 0
    F2 = polygon_form_factors(pts[:1], [[0, 0, 1]], SQ[:, ::-1])[0, 0]
    assert F2 == pytest.approx(F[0], rel=1e-12)


def test_shadow_rays_block_exactly_the_covered_part_of_the_light():
    light = quad([(0, 0, 1), (0, 1, 1), (1, 1, 1), (1, 0, 1)], (0, 0, 0), (2.0, 1.0, 0.5), name="light")
    # a blocker at z = 0.5 covering x < 0.5 under the light: from (0.5,0.5,0) it hides x < 0.5 of the light
    blocker = quad([(-2, -2, 0.5), (0.5, -2, 0.5), (0.5, 3, 0.5), (-2, 3, 0.5)], name="blocker")
    floor = quad([(-1, -1, 0), (2, -1, 0), (2, 2, 0), (-1, 2, 0)], name="floor")
    ps = build_patches([light, blocker, floor], None)
    sc = embree_scene(ps)
    pts = np.array([[0.5, 0.5, 0.0], [1.5, 0.5, 0.0], [-1.0 + 1e-3, 0.5, 0.0]])
    D = emitter_direct(ps, pts, [[0, 0, 1]] * 3, scene=sc, samples=256)
    open_half = 2 * point_under_rectangle_corner(0.5, 0.5, 1)          # the x > 0.5 half of the light, seen from its edge
    np.testing.assert_allclose(D[0], open_half * np.array([2.0, 1.0, 0.5]), rtol=0.02)
    # (1.5,.5,0): the ray to the light's far corner (0,*,1) crosses z=.5 at x=.75 > .5: fully lit
    full = polygon_form_factors(pts[1:2], [[0, 0, 1]], SQ)[0, 0]
    np.testing.assert_allclose(D[1], full * np.array([2.0, 1.0, 0.5]), rtol=1e-6)  # float32 transport
    # far left under the blocker: fully shadowed
    np.testing.assert_allclose(D[2], 0.0, atol=1e-12)


def test_grid_of_is_grid_points_kept_for_the_geometry():
    # the patch grids a relight lights again: grid_points' values, the same arrays the second time
    from hemicube_radiosity.core import builtin_scenes as scenes
    from hemicube_radiosity.core.light.points import grid_of, grid_points, patch_average
    ps = build_patches(scenes.cornell_box(), 0.25)
    rows = np.arange(3, len(ps), 2)
    x, w = grid_points(ps.take(rows), 3)
    got = grid_of(ps, rows, 3)
    assert np.array_equal(got[0], x) and np.array_equal(got[3], w)
    assert np.array_equal(got[1], x.reshape(-1, 3))
    assert np.array_equal(got[2], np.repeat(ps.normals[rows], 9, axis=0))
    again = grid_of(ps, rows, 3)
    assert all(a is b for a, b in zip(got, again)) and not got[1].flags.writeable
    # patch_average through the kept grid: its mean over the grid, whatever part is centre-only
    light = lambda p, n, where: np.column_stack([p[:, 0] ** 2, p[:, 1], n[:, 2] + p[:, 2]])  # noqa: E731
    centre = np.zeros(len(ps), bool)
    centre[::3] = True
    xs, ws = grid_points(ps.take(~centre), 2)
    want = np.einsum("nk,nkc->nc", ws, light(xs.reshape(-1, 3), np.repeat(ps.normals[~centre], 4, axis=0), "")
                     .reshape(len(ws), 4, 3))
    for _ in range(2):
        got = patch_average(ps, 2, light, centre)
        assert np.array_equal(got[~centre], want)
        assert np.array_equal(got[centre], light(ps.centers[centre], ps.normals[centre], ""))


def test_a_lamp_face_cut_into_100_patches_shines_as_one_unit():
    """A 0.5 m lamp face cut into 10 x 10 patches (no clusters: the coarse path) shines as one
    unit: one contour and 64 shadow rays per point (4 x the face's 16: finer patches, finer
    shadows), not 100 contours and 4 rays per patch (400). Where nothing stands between, the light is the whole face's closed form (its
    outline's contour, exact); the same face with one patch of another emission (a texture's) or
    bent out of its plane shines patch by patch, as before."""
    from hemicube_radiosity.core.light.direct import DirectLight
    from hemicube_radiosity.core.pipeline import BakeSettings

    h = 0.25
    lamp = quad([(-h, -h, 1), (-h, h, 1), (h, h, 1), (h, -h, 1)], (0, 0, 0), (1.0, 0.5, 0.25), name="Lamp")
    floor = quad([(-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)], (0.5, 0.5, 0.5), name="Floor")
    settings = BakeSettings(patch_size=0.05, direct_samples=16, two_sided_emission=False)
    ps = build_patches([lamp, floor], 0.05)
    light = DirectLight.plan(ps, settings, [])
    assert light.emitters.size == 100 and light.groups.tolist() == [0] * 100 and light.samples == 64

    cast = []
    scene = light.scene()
    occluded = scene.occluded

    class Counting:
        scale = getattr(scene, "scale", 1.0)

        def occluded(self, o, d, tfar):
            cast.append(len(o))
            return occluded(o, d, tfar)
    light._scene = Counting()
    x = np.array([[0.0, 0.0, 0.0], [0.1, -0.2, 0.0], [0.6, 0.3, 0.0], [1.5, 1.5, 0.0]])
    got = light.at(x, np.tile([0.0, 0.0, 1.0], (4, 1)), "floor")
    assert sum(cast) == 64 * len(x)                    # 64 rays a point: all lit, no penumbra
    # the whole face's form factor (four corner rectangles, closed form) times its radiance
    exact = []
    for px, py, _ in x:
        def part(a, b):                                  # signed corner rectangles of [-h, h]^2
            return np.sign(a) * np.sign(b) * point_under_rectangle_corner(abs(a), abs(b), 1.0)
        exact.append(part(h - px, h - py) - part(-h - px, h - py) - part(h - px, -h - py) + part(-h - px, -h - py))
    np.testing.assert_allclose(got, np.array(exact)[:, None] * [1.0, 0.5, 0.25], rtol=1e-5)

    textured = ps.emission.copy()
    textured[light.emitters[7]] *= 0.9
    from dataclasses import replace
    assert DirectLight.plan(replace(ps, emission=textured), settings, []).groups is None
    bent = quad([(-h, -h, 1), (-h, h, 1.1), (h, h, 1), (h, -h, 1)], (0, 0, 0), (1.0,) * 3, name="Lamp")
    per_patch = DirectLight.plan(build_patches([bent, floor], 0.05), settings, [])
    assert per_patch.groups is None and per_patch.samples == 2


def test_a_curved_lamps_far_side_does_not_shadow_its_near_side():
    """A lamp modelled as a dense half-cylinder (48 strips, normals outward) shining as one
    group, seen from a point off to its side: the point sees the strips that face it, nothing
    stands between, so the light is the group's form factor, unshadowed (the sum of the strips'
    closed-form contours). Targets on the strips facing away send the point nothing, and the
    rays to them pass through the lamp itself: weighted by cos at the target clamped at 0 they
    count for nothing (with |cos|, or counted alike, they darkened the point by the part of the
    lamp it cannot see)."""
    k = 48
    a = np.linspace(0.0, np.pi, k + 1)
    r, L = 0.2, 1.0
    faces = [quad([(r * np.cos(a[i]), 0.0, 1 + r * np.sin(a[i])), (r * np.cos(a[i]), L, 1 + r * np.sin(a[i])),
                   (r * np.cos(a[i + 1]), L, 1 + r * np.sin(a[i + 1])), (r * np.cos(a[i + 1]), 0.0, 1 + r * np.sin(a[i + 1]))],
                  (0, 0, 0), (1.0, 1.0, 1.0), name=f"strip{i}") for i in range(k)]
    ps = build_patches(faces, None)
    assert np.all(np.einsum("ij,ij->i", ps.normals, ps.centers - [0.0, ps.centers[:, 1].mean(), 1.0]) > 0)  # outward
    x = np.array([[1.0, 0.5, 1.05], [0.0, 0.5, 2.0], [-0.8, 0.5, 1.6]])
    nx = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.6, 0.0, -0.8]])
    em = np.arange(len(ps))
    groups = np.zeros(len(ps), np.int64)
    F = polygon_form_factors(x, nx, ps.corners(), ps.normals).sum(axis=1)
    T = emitter_transport(ps, x, nx, em, scene=embree_scene(ps), samples=64, groups=groups)[:, 0]
    np.testing.assert_allclose(T, F, rtol=1e-5)


def test_a_bakes_transports_outline_each_emitter_set_once(monkeypatch):
    """The transports of a bake (stand-ins, vertices, gather hits, bright areas) ask for the
    same lamps' outlines again and again: each emitter set's outline is made once and kept
    (emitters._outline), and the bake is the same as one that makes it every time."""
    import hashlib
    from hemicube_radiosity.core.light import emitters as direct
    from hemicube_radiosity.core.light.outline import GroupOutline
    from hemicube_radiosity.core import builtin_scenes as scenes
    from hemicube_radiosity.core.pipeline import BakeSettings, bake
    made = []
    real = GroupOutline.of.__func__

    def of(cls, polys, groups, normals):
        made.append(hashlib.sha256(np.ascontiguousarray(polys).tobytes()).hexdigest())
        return real(cls, polys, groups, normals)
    monkeypatch.setattr(GroupOutline, "of", classmethod(of))
    direct._OUTLINES.clear()
    meshes = scenes.tessellate(scenes.cornell_box(), 8)
    s = BakeSettings(workers=1, resolution=16, gather_rays=16)
    kept = bake(meshes, s)
    assert len(made) >= 2 and len(made) == len(set(made))
    monkeypatch.setattr(direct._OUTLINES, "keep", 0)         # made every time, as before
    made.clear()
    again = bake(meshes, s)
    assert len(made) > len(set(made))
    assert np.array_equal(kept.vertex_radiosity, again.vertex_radiosity)


def test_receivers_a_polygon_lies_wholly_below_get_exactly_0_the_others_as_alone():
    """polygon_form_factor leaves out the contour of receivers that see no corner above their
    tangent plane (the sun behind a wall: half a scene): 0 there, as the contour made it; every
    other receiver gets what it gets on its own."""
    from hemicube_radiosity.core.light.polygon_ff import polygon_form_factor

    rng = np.random.default_rng(3)
    x = rng.uniform(-1.0, 1.0, (60, 3))
    n = rng.normal(size=(60, 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    for poly in (SQ[0] + [0.0, 0.0, 1.0], SQ[0][None] + rng.uniform(-0.5, 0.5, (60, 1, 3))):
        F = polygon_form_factor(x, n, poly)
        per = np.broadcast_to(poly, (60,) + poly.shape[-2:])
        h = np.einsum("nkc,nc->nk", per - x[:, None], n)
        below = ~(h > 0).any(axis=1)
        assert below.any() and not below.all()
        assert np.all(F[below] == 0.0)
        alone = [polygon_form_factor(x[i:i + 1], n[i:i + 1], per[i:i + 1])[0] for i in np.flatnonzero(~below)]
        np.testing.assert_allclose(F[~below], alone, rtol=1e-14, atol=0)


@pytest.mark.parametrize("angle", [0.0, 0.05])
def test_a_sun_wholly_on_one_side_of_a_leaning_point_s_plane_is_lit_from_that_side_only(monkeypatch, angle):
    """``split_at`` with ``facing`` and ``low`` (a leaning texel: the lamps from above its
    plane at the point, from below it at Cycles' lifted start) lights a sun from one side only
    where its disk lies wholly on that side (its direction more than its half angle off the
    plane): the other side's samples would all be left out, 0. On an open floor (no shadow)
    every point gets what both sides summed give (the sun's cosine to the shading normal where
    it is above the plane, else what the lifted start sees), bit for bit for a sun without
    size (a disk's samples are drawn per call: to rounding where neither the plane nor the
    shading normal's horizon cuts the disk), and the below-plane
    rays are asked for only at the points whose plane the sun's disk reaches below."""
    from hemicube_radiosity.core.light import direct as direct_mod
    from hemicube_radiosity.core.light.direct import DirectLight
    from hemicube_radiosity.core.light.lamps import SunLight
    from hemicube_radiosity.core.light.lamp_cache import lamp_irradiance
    from hemicube_radiosity.core.mesh.patches import MeshInput
    from hemicube_radiosity.core.mesh.subdivide import build_patches
    floor = MeshInput.from_faces([(-5, -5, 0), (5, -5, 0), (5, 5, 0), (-5, 5, 0)], [(0, 1, 2, 3)], name="floor")
    patches = build_patches([floor], 0)
    rng = np.random.default_rng(2)
    m = 300
    x = np.column_stack([rng.uniform(-2, 2, (m, 2)), np.zeros(m)])
    # faces tilted up to 40 degrees (their plane's normal), shading normals leaning off them
    facing = np.column_stack([rng.uniform(-0.6, 0.6, (m, 2)), np.ones(m)])
    facing /= np.linalg.norm(facing, axis=1, keepdims=True)
    shade = facing + np.column_stack([rng.uniform(-0.5, 0.5, (m, 2)), np.zeros(m)])
    shade /= np.linalg.norm(shade, axis=1, keepdims=True)
    low = x + 0.01 * shade
    sun = SunLight(direction=(-np.cos(np.radians(20.0)), 0.0, -np.sin(np.radians(20.0))), strength=3.0, angle=angle)
    light = DirectLight(patches, [sun], np.zeros(0, np.int64), 1, light_samples=4)
    asked = []

    def counted(*a, points=None, facing=None, **k):
        asked.append((len(points), None if facing is None else np.asarray(facing).copy()))
        return lamp_irradiance(*a, points=points, facing=facing, **k)
    monkeypatch.setattr(direct_mod, "lamp_irradiance", counted)
    got = light.split_at(x, shade, "t", facing=facing, low=low)[:, 0]
    monkeypatch.setattr(direct_mod, "lamp_irradiance", lamp_irradiance)
    eps = light.offsets(x, shade)
    kw = dict(samples=4, seed=0, index=0)
    want = lamp_irradiance(patches, [sun], None, points=x, normals=shade, eps=eps, facing=facing, **kw) / np.pi
    want += lamp_irradiance(patches, [sun], None, points=low, normals=shade, eps=np.zeros(m), facing=-facing,
                            **kw) / np.pi
    s = facing @ -np.asarray(sun.direction)
    reach = np.sin(0.5 * angle) + 1e-9
    if angle == 0:
        np.testing.assert_array_equal(got, want)
    else:           # the disk's samples drawn per call: the same to rounding where it is not cut
        clear = (np.abs(s) > reach) & (np.abs(shade @ -np.asarray(sun.direction)) > reach)
        np.testing.assert_allclose(got[clear], want[clear], rtol=1e-12)
    assert [n for n, _ in asked] == [int((s > -reach).sum()), int((s < reach).sum())]
    assert (s > reach).sum() > 100 and (s < -reach).sum() > 20          # both sides are tested
    assert (got[s < -reach, 0] > 0).any() and (got[s > reach, 0] > 0).mean() > 0.5
