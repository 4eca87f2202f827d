"""Direct light from lamps: closed forms (inverse square, cosine, spot cone, sun, area-light
form factors), hard shadows by construction, soft shadows against an exact half-covered light,
and Embree vs NumPy shadow rays."""
import sys

import numpy as np
import pytest

from hemicube_radiosity.core import builtin_scenes as scenes
from hemicube_radiosity.core.light.polygon_ff import polygon_form_factor
from hemicube_radiosity.core.light.lamps import (
    AreaLight, PointLight, SpotLight, SunLight, direct_irradiance, spot_attenuation
)
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.rays import EmbreeUnavailable, NumpyOccluder
from tests.support.markers import needs_embree


def floor(half=2.0, patch=0.25, z=0.0):
    return build_patches([scenes.quad([(-half, -half, z), (half, -half, z), (half, half, z),
                                       (-half, half, z)], name="floor")], patch)


def corner_parallel(x, y, h=1.0):
    """Form factor from a point (normal toward the plane) to the rectangle [0,x] x [0,y] on a
    parallel plane at distance h, the corner above the point (Siegel & Howell); odd in x, y."""
    x, y = np.asarray(x, float) / h, np.asarray(y, float) / h
    a, b = np.sqrt(1 + x * x), np.sqrt(1 + y * y)
    return (x / a * np.arctan(y / a) + y / b * np.arctan(x / b)) / (2 * np.pi)


def rect_parallel(px, py, x0, x1, y0, y1, h):
    """Point (px, py) to the rectangle [x0,x1] x [y0,y1] on a parallel plane h away."""
    return (corner_parallel(x1 - px, y1 - py, h) - corner_parallel(x0 - px, y1 - py, h)
            - corner_parallel(x1 - px, y0 - py, h) + corner_parallel(x0 - px, y0 - py, h))


def translate(x, y, z):
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


# ---------------------------------------------------------------------------------------- point


def test_point_light_inverse_square_and_cosine():
    p = floor()
    light = PointLight((0.3, -0.2, 1.5), color=(1.0, 0.5, 0.25), power_w=1000.0)
    H = direct_irradiance(p, [light], shadows="none")
    v = light.position - p.centers
    d2 = (v * v).sum(1)
    cos = v[:, 2] / np.sqrt(d2)
    exact = 1000.0 * cos / (4 * np.pi * d2)
    np.testing.assert_allclose(H, exact[:, None] * light.color, rtol=1e-12)
    # the two laws separately: straight below, then twice as far along the same axis
    q = build_patches([scenes.quad([(-0.01, -0.01, 0), (0.01, -0.01, 0), (0.01, 0.01, 0),
                                    (-0.01, 0.01, 0)])], None)
    e1 = direct_irradiance(q, [PointLight((0, 0, 1.0), power_w=4 * np.pi)], shadows="none")[0, 0]
    e2 = direct_irradiance(q, [PointLight((0, 0, 2.0), power_w=4 * np.pi)], shadows="none")[0, 0]
    e3 = direct_irradiance(q, [PointLight((np.sqrt(3), 0, 1.0), power_w=4 * np.pi)], shadows="none")[0, 0]
    assert e1 == pytest.approx(1.0) and e2 == pytest.approx(0.25)
    assert e3 == pytest.approx(0.5 / 4)  # distance 2, cos = 1/2
    # back side gets nothing
    assert direct_irradiance(q, [PointLight((0, 0, -1.0))], shadows="none")[0, 0] == 0


def test_sphere_light_equals_point_light_above_the_horizon():
    p = floor()
    exact = direct_irradiance(p, [PointLight((0.3, -0.2, 1.5), power_w=500)], shadows="none")
    sphere = direct_irradiance(p, [PointLight((0.3, -0.2, 1.5), power_w=500, radius=0.3,
                                              soft_falloff=False)], shadows="none")
    np.testing.assert_allclose(sphere, exact, rtol=1e-6)


def test_soft_falloff_disk_facing_receiver():
    # Blender's default soft falloff: a disk of radius r facing the receiver, radiance
    # P / (4 pi^2 r^2): straight below at distance d, H = P / (4 pi (d^2 + r^2)).
    q = build_patches([scenes.quad([(-1e-3, -1e-3, 0), (1e-3, -1e-3, 0), (1e-3, 1e-3, 0),
                                    (-1e-3, 1e-3, 0)])], None)
    for d, r in ((1.0, 0.25), (0.3, 0.5)):
        H = direct_irradiance(q, [PointLight((0, 0, d), power_w=100, radius=r)], shadows="none")
        assert H[0, 0] == pytest.approx(100 / (4 * np.pi * (d * d + r * r)), rel=1e-4)


# ----------------------------------------------------------------------------------------- spot


def test_spot_cone_inside_outside_and_blend():
    p = floor(half=3.0, patch=0.1)
    h, size, blend = 2.0, np.radians(50), 0.3
    spot = SpotLight((0, 0, h), (0, 0, -1), power_w=1000, spot_size=size, spot_blend=blend)
    H = direct_irradiance(p, [spot], shadows="none")[:, 0]
    v = spot.position - p.centers
    d = np.linalg.norm(v, axis=1)
    point = 1000 * (v[:, 2] / d) / (4 * np.pi * d * d)
    cos_axis = h / d
    ch = np.cos(size / 2)
    inside = cos_axis >= ch + (1 - ch) * blend      # past the blend: the full point light
    outside = cos_axis <= ch                        # beyond the cone edge: nothing
    ramp = ~inside & ~outside
    assert inside.sum() > 10 and outside.sum() > 10 and ramp.sum() > 10
    np.testing.assert_allclose(H[inside], point[inside], rtol=1e-12)
    assert np.all(H[outside] == 0)
    t = (cos_axis[ramp] - ch) / ((1 - ch) * blend)
    np.testing.assert_allclose(H[ramp], point[ramp] * (3 * t ** 2 - 2 * t ** 3), rtol=1e-12)
    assert np.all((H[ramp] > 0) & (H[ramp] < point[ramp]))
    # a hard edge with no blend
    assert spot_attenuation(np.cos(0.49 * size), size, 0.0) == 1.0
    assert spot_attenuation(np.cos(0.51 * size), size, 0.0) == 0.0


# ------------------------------------------------------------------------------------------ sun


@pytest.mark.parametrize("shadows", ["numpy", pytest.param("embree", marks=needs_embree)])
def test_sun_at_30_degrees_box_shadow(shadows):
    th = np.radians(30)
    p = build_patches([scenes.quad([(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)], name="floor"),
                       scenes.box((-0.5, -0.5, 0), (0.5, 0.5, 1.0), bottom=False)], 0.1)
    sun = SunLight((0, np.sin(th), -np.cos(th)), color=(1, 0.9, 0.8), strength=3.0)
    H = direct_irradiance(p, [sun], shadows=shadows)
    fl = p.owner == 0
    x = p.centers[fl]
    # geometric shadow of the 1 x 1 x 1 box: the ray toward the sun (0, -sin, cos) passes
    # through the box when |x| < 0.5 and -0.5 < y < 0.5 + tan(30 deg)
    shadow = (np.abs(x[:, 0]) < 0.5) & (x[:, 1] > -0.5) & (x[:, 1] < 0.5 + np.tan(th))
    lit = ~shadow
    assert shadow.sum() > 50
    assert np.all(H[fl][shadow] == 0)
    np.testing.assert_allclose(H[fl][lit], np.broadcast_to(3.0 * np.cos(th) * np.array([1, 0.9, 0.8]),
                                                          H[fl][lit].shape), rtol=1e-12)
    # box faces: the roof gets strength * cos 30, the face toward the sun (-y) strength * sin 30,
    # the far face (+y) nothing
    box = p.owner == 1
    n = p.normals[box]
    np.testing.assert_allclose(H[box][n[:, 2] > 0.5, 0], 3.0 * np.cos(th), rtol=1e-12)
    np.testing.assert_allclose(H[box][n[:, 1] < -0.5, 0], 3.0 * np.sin(th), rtol=1e-12)
    assert np.all(H[box][n[:, 1] > 0.5] == 0)


def test_a_light_that_casts_no_shadow_shines_through_the_box():
    """Blender's per-light 'Shadow' switch off: the floor under the box gets the full sun."""
    th = np.radians(30)
    p = build_patches([scenes.quad([(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)], name="floor"),
                       scenes.box((-0.5, -0.5, 0), (0.5, 0.5, 1.0), bottom=False)], 0.25)
    on = SunLight((0, np.sin(th), -np.cos(th)), strength=3.0)
    off = SunLight((0, np.sin(th), -np.cos(th)), strength=3.0, cast_shadows=False)
    fl = p.owner == 0
    H_on = direct_irradiance(p, [on])[fl, 0]
    H_off = direct_irradiance(p, [off])[fl, 0]
    assert (H_on == 0).sum() > 10
    np.testing.assert_allclose(H_off, 3.0 * np.cos(th), rtol=1e-12)


def test_sun_with_angle_keeps_irradiance_above_the_horizon():
    p = floor()
    H = direct_irradiance(p, [SunLight((0.3, 0.1, -1), strength=2.0, angle=np.radians(10))],
                          shadows="none")
    cos = 1 / np.linalg.norm([0.3, 0.1, -1])
    np.testing.assert_allclose(H[:, 0], 2.0 * cos, rtol=1e-6)


# ----------------------------------------------------------------------------------------- area


def test_area_light_over_floor_matches_point_to_rectangle_form_factor():
    p = floor(half=2.0, patch=0.2)
    h, sx, sy, P = 1.7, 1.2, 0.6, 300.0
    light = AreaLight(translate(0.4, -0.1, h), "RECTANGLE", sx, sy, (1, 1, 1), P)
    x = p.centers
    F = rect_parallel(x[:, 0], x[:, 1], 0.4 - sx / 2, 0.4 + sx / 2, -0.1 - sy / 2, -0.1 + sy / 2, h)
    exact = P / (sx * sy) * F           # H = pi L F, L = P / (pi A)
    for shadows in ("none", "numpy"):
        H = direct_irradiance(p, [light], shadows=shadows)
        np.testing.assert_allclose(H[:, 0], exact, rtol=1e-9)
    # object scale multiplies the size, as in Cycles: scale 2 in X with size 0.6 == size 1.2
    m = translate(0.4, -0.1, h)
    m[0, 0] = 2.0
    H2 = direct_irradiance(p, [AreaLight(m, "RECTANGLE", sx / 2, sy, (1, 1, 1), P)], shadows="none")
    np.testing.assert_allclose(H2[:, 0], exact, rtol=1e-9)
    # one-sided: turned upside down (emitting up) it lights nothing below
    up = translate(0.4, -0.1, h)
    up[:3, :3] = np.diag([1.0, -1.0, -1.0])
    assert direct_irradiance(p, [AreaLight(up, "RECTANGLE", sx, sy, (1, 1, 1), P)],
                             shadows="none").max() == 0


def test_disk_area_light_on_axis():
    q = build_patches([scenes.quad([(-1e-3, -1e-3, 0), (1e-3, -1e-3, 0), (1e-3, 1e-3, 0),
                                    (-1e-3, 1e-3, 0)])], None)
    R, h, P = 0.4, 1.3, 50.0
    H = direct_irradiance(q, [AreaLight(translate(0, 0, h), "DISK", 2 * R, 0, (1, 1, 1), P)],
                          shadows="none")
    A = np.pi * R * R
    assert H[0, 0] == pytest.approx(P / A * R * R / (h * h + R * R), rel=1e-4)


def test_area_light_crossing_the_horizon_is_clipped():
    # a vertical light x in [-0.5, 0.5], z in [-0.5, 0.5] on the plane y = 1 facing -y; a floor
    # point at the origin sees only its upper half: F = perpendicular-rectangle closed form
    q = build_patches([scenes.quad([(-1e-3, -1e-3, 0), (1e-3, -1e-3, 0), (1e-3, 1e-3, 0),
                                    (-1e-3, 1e-3, 0)])], None)
    m = translate(0, 1.0, 0)
    m[:3, :3] = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])  # local -Z -> world -y
    light = AreaLight(m, "SQUARE", 1.0, 1.0, (1, 1, 1), 10.0)
    assert np.allclose(light.frame()[5], (0, -1, 0))

    def perp(s, z):  # point (normal +z) to [0,s] x [0,z] on a perpendicular plane 1 away
        c = np.sqrt(1 + z * z)
        return (np.arctan(s) - np.arctan(s / c) / c) / (2 * np.pi)

    F = 2 * perp(0.5, 0.5)
    H = direct_irradiance(q, [light], shadows="none")
    assert H[0, 0] == pytest.approx(10.0 / 1.0 * F, rel=1e-9)


def test_polygon_form_factor_against_closed_form():
    rng = np.random.default_rng(0)
    x = np.c_[rng.uniform(-1, 1, (50, 2)), np.zeros(50)]
    n = np.tile([0, 0, 1.0], (50, 1))
    poly = np.array([[-0.3, -0.2, 0.8], [0.5, -0.2, 0.8], [0.5, 0.4, 0.8], [-0.3, 0.4, 0.8]])
    F = polygon_form_factor(x, n, poly)
    np.testing.assert_allclose(F, rect_parallel(x[:, 0], x[:, 1], -0.3, 0.5, -0.2, 0.4, 0.8), rtol=1e-10)
    # reversed winding gives the same; entirely below the horizon gives zero
    np.testing.assert_allclose(polygon_form_factor(x, n, poly[::-1]), F, rtol=1e-12)
    assert np.all(polygon_form_factor(x, -n, poly) == 0)


# ------------------------------------------------------------------------------------- shadows


def half_covered_scene():
    """A floor, a 1 x 1 area light at height 2 facing down, and a thin blocker just under the
    light's half x < 0 (it faces down, so the floor sees its front)."""
    meshes = [scenes.quad([(-1.5, -1.5, 0), (1.5, -1.5, 0), (1.5, 1.5, 0), (-1.5, 1.5, 0)], name="floor"),
              scenes.quad([(-1.5, -1.5, 1.999), (-1.5, 1.5, 1.999), (0, 1.5, 1.999), (0, -1.5, 1.999)],
                          name="blocker")]
    return build_patches(meshes, 0.25), AreaLight(translate(0, 0, 2.0), "SQUARE", 1.0, 1.0, (1, 1, 1), 100.0)


@pytest.mark.parametrize("shadows", ["numpy", pytest.param("embree", marks=needs_embree)])
def test_soft_shadow_of_a_half_covered_area_light(shadows):
    p, light = half_covered_scene()
    H = direct_irradiance(p, [light], shadows=shadows, samples=64, seed=3)
    fl = p.owner == 0
    x = p.centers[fl]
    # only the uncovered half x in [0, 0.5] reaches the floor (the blocker sits 1 mm below it)
    exact = 100.0 * rect_parallel(x[:, 0], x[:, 1], 0.0, 0.5, -0.5, 0.5, 2.0)
    full = 100.0 * rect_parallel(x[:, 0], x[:, 1], -0.5, 0.5, -0.5, 0.5, 2.0)
    # 64 stratified samples (8 columns, 4 of them uncovered): the estimate weighs the uncovered
    # columns by their share of the unshadowed integrand (a consistent estimator, not an exact
    # one): measured error 0.7% of the largest unshadowed value (1.6% with 16 samples)
    assert np.abs(H[fl, 0] - exact).max() < 0.012 * full.max()
    assert np.all(H[fl, 0] < full)


@needs_embree
def test_embree_and_numpy_shadows_agree():
    th = np.radians(35)
    p = build_patches(scenes.cornell_box(), 0.2)
    lights = [PointLight((0.7, 1.1, 1.6), (1, 0.8, 0.6), 300, 0.0),
              PointLight((1.3, 0.9, 1.5), (1, 1, 1), 200, 0.15),
              SpotLight((1.0, 0.3, 1.7), (0.1, 0.6, -1), (1, 1, 1), 400, 0.1, np.radians(70), 0.2),
              SunLight((0.2, np.sin(th), -np.cos(th)), (1, 1, 1), 2.0, np.radians(3)),
              AreaLight(translate(1.01, 1.02, 1.93), "ELLIPSE", 0.5, 0.3, (1, 1, 1), 80)]
    He = direct_irradiance(p, lights, shadows="embree", samples=9, seed=1)
    Hn = direct_irradiance(p, lights, shadows="numpy", samples=9, seed=1)
    Hz = direct_irradiance(p, lights, shadows="none", samples=9, seed=1)
    assert (Hz - He).max() > 0.1 * He.max()          # the scene does cast shadows
    np.testing.assert_allclose(He, Hn, rtol=1e-9, atol=1e-12 * He.max())


def test_numpy_occluder_against_brute_force():
    p = build_patches(scenes.cornell_box(), 0.3)
    occ = NumpyOccluder(p)
    rng = np.random.default_rng(2)
    o = rng.uniform(0.05, 1.95, (400, 3))
    d = rng.normal(size=(400, 3))
    tf = rng.uniform(0.1, 3.0, 400)
    c = p.corners()
    tris = np.concatenate([c[:, [0, 1, 2]], c[:, [0, 2, 3]]])
    tris = tris[np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1) > 0]
    # brute force: every ray against every triangle (Cramer's rule)
    e1, e2 = tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    s = o[:, None] - tris[None, :, 0]
    A = np.stack([np.broadcast_to(-d[:, None], s.shape), np.broadcast_to(e1, s.shape),
                  np.broadcast_to(e2, s.shape)], -1)
    ok = np.abs(np.linalg.det(A)) > 1e-12
    sol = np.zeros(s.shape)
    sol[ok] = np.linalg.solve(A[ok], s[ok][..., None])[..., 0]
    t, u, v = sol[..., 0], sol[..., 1], sol[..., 2]
    brute = (ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & (t < tf[:, None])).any(1)
    np.testing.assert_array_equal(occ.occluded(o, d, tf), brute)
    assert 50 < brute.sum() < 350


# ------------------------------------------------------------------------------------- errors


def test_bad_inputs_and_missing_embree(monkeypatch):
    with pytest.raises(ValueError, match="spot_size"):
        SpotLight((0, 0, 1), (0, 0, -1), spot_size=4.0)
    with pytest.raises(ValueError, match="direction"):
        SunLight((0, 0, 0))
    with pytest.raises(ValueError, match="shape"):
        AreaLight(np.eye(4), "TRIANGLE")
    p = floor()
    with pytest.raises(ValueError, match="shadows"):
        direct_irradiance(p, [PointLight((0, 0, 1))], shadows="yes")
    for mod in ("embreex", "embreex.rtcore_scene", "embreex.mesh_construction"):
        monkeypatch.setitem(sys.modules, mod, None)
    with pytest.raises(EmbreeUnavailable):
        direct_irradiance(p, [PointLight((0, 0, 1))], shadows="embree")
    # 'auto' falls back to NumPy and still shadows
    H = direct_irradiance(p, [PointLight((0, 0, 1))], shadows="auto")
    assert H.max() > 0


def test_the_suns_disk_in_closed_form_is_its_clipped_contour_and_the_exact_disk():
    """:func:`distant_form_factor` (one vector for every receiver) against the contour clipped
    receiver by receiver (:func:`polygon_form_factor`, what the sun used) and the exact disk,
    ``sin^2(h) cos(theta)``, for receivers that see it whole: to 1e-8 relative (the contour's
    own round-off, from offsets ``poly - x`` taken at coordinates of 300 m, is about 1e-9 where
    the sun grazes the receiver); 0 as the contour's for receivers wholly below it; receivers
    it crosses the horizon of are left to the caller."""
    from hemicube_radiosity.core.light.polygon_ff import distant_form_factor
    from hemicube_radiosity.core.util.geometry import disk_polygons
    rng = np.random.default_rng(5)
    n = rng.normal(size=(4000, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    x = rng.uniform(-300, 300, size=(4000, 3))
    to_sun = np.array([0.3, 0.4, 0.8]) / np.linalg.norm([0.3, 0.4, 0.8])
    for h in (0.5 * np.radians(0.526), np.radians(5.0)):
        rel = disk_polygons(to_sun[None], -to_sun[None], np.full(1, np.tan(h)))[0]
        F, settled = distant_form_factor(n, rel)
        clipped = polygon_form_factor(x, n, disk_polygons(x + to_sun, np.broadcast_to(-to_sun, x.shape),
                                                          np.full(len(x), np.tan(h))))
        cos = n @ to_sun
        whole, below = settled & (cos > 0), settled & (cos <= 0)
        assert 0.4 < whole.mean() < 0.55 and 0.4 < below.mean() < 0.55
        assert np.all(F[below] == 0) and np.all(clipped[below] == 0)
        np.testing.assert_allclose(F[whole], clipped[whole], rtol=1e-8)
        exact = np.sin(h) ** 2 * cos[whole]
        # the 64-gon of the disk's area: its vector form factor is the disk's to (sides / 2 pi)^-2 h^2
        np.testing.assert_allclose(F[whole], exact, rtol=1e-8 + 2 * h ** 2)
        assert np.all(F[~settled] == 0) and np.all(np.abs(cos[~settled]) < 1.01 * np.sin(h))


def test_lamps_on_two_threads_light_as_on_one_bit_for_bit():
    """Chunks of receivers on threads: each chunk draws its own random stream, so the sun's and
    a sphere lamp's soft shadows (and the sun's closed-form disk) are the same for any count."""
    p = build_patches([scenes.quad([(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)], name="floor"),
                       scenes.box((-0.5, -0.5, 0), (0.5, 0.5, 1.0), bottom=False)], 0.05)
    assert len(p) > 2 * 4096
    lights = [SunLight((0.2, 0.5, -0.8), strength=3.0, angle=np.radians(8)),
              PointLight((0.3, 1.2, 1.5), power_w=200.0, radius=0.2)]
    one = direct_irradiance(p, lights, samples=4, workers=1)
    two = direct_irradiance(p, lights, samples=4, workers=2)
    np.testing.assert_array_equal(one, two)
    assert (one[:, 0] == 0).sum() > 100 and (one[:, 0] > 0).sum() > 1000
