# SPDX-License-Identifier: GPL-3.0-or-later
"""tools/cycles_reference.py: the Cycles bake reads the radiance the radiosity B is compared with.

Each unit convention the Blender light mapping relies on is pinned here against a closed form,
on scenes where Cycles' answer is (nearly) free of noise: a single plane, no occluders.
"""
import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tools import cycles_reference as cr  # noqa: E402

pytestmark = [pytest.mark.blender, pytest.mark.cycles]

RHO = 0.8


def floor(n=8, half=2.0, rho=RHO, emission=0.0, name="floor"):
    v, f = cr.grid_arrays(n, n, -half, half, -half, half)
    ob = cr.mesh_object(v, f, cr.diffuse_material((rho,) * 3, emission), name)
    return ob, v


def rect_factor(X, Y):
    """Differential element to a parallel rectangle X x Y (in units of the height), normal through
    a corner (Siegel & Howell); odd in X and in Y, so signed sums give any offset rectangle."""
    sx, sy = np.sqrt(1 + X * X), np.sqrt(1 + Y * Y)
    return (X / sx * np.arctan(Y / sx) + Y / sy * np.arctan(X / sy)) / (2 * np.pi)


def test_emission_strength_one_reads_one_in_combined_and_zero_in_diffuse():
    cr.new_empty_scene()
    ob, _ = floor(2, rho=0.0, emission=1.0, name="lamp")
    comb = cr.bake_vertex_radiance([ob], samples=4)
    diff = cr.bake_vertex_radiance([ob], samples=4, mode="DIFFUSE")
    np.testing.assert_allclose(comb.point["lamp"], 1.0, atol=1e-6)
    np.testing.assert_allclose(comb.corner["lamp"], 1.0, atol=1e-6)
    np.testing.assert_allclose(diff.point["lamp"], 0.0, atol=1e-6)
    assert comb.seconds > 0


@pytest.mark.parametrize("zenith_deg", [0.0, 30.0])
def test_sun_strength_is_irradiance(zenith_deg):
    """Sun of strength S: H = S cos(zenith) W/m^2, so a rho plane reads rho S cos / pi."""
    cr.new_empty_scene()
    ob, _ = floor(4)
    cr.add_light("SUN", (0, 0, 3), (math.radians(zenith_deg), 0, 0), energy=3.0, angle=0.0)
    want = RHO * 3.0 * math.cos(math.radians(zenith_deg)) / math.pi
    for mode in ("COMBINED", "DIFFUSE"):
        got = cr.bake_vertex_radiance([ob], samples=8, mode=mode).point["floor"]
        np.testing.assert_allclose(got, want, rtol=2e-4)


def test_point_light_intensity_is_power_over_4pi():
    """Point light P, radius 0: H = P cos / (4 pi d^2); inverse square and cosine at every vertex."""
    cr.new_empty_scene()
    ob, v = floor(8)
    cr.add_light("POINT", (0.3, -0.2, 1.0), energy=100.0, shadow_soft_size=0.0)
    got = cr.bake_vertex_radiance([ob], samples=8).point["floor"][:, 0]
    d = v - np.array([0.3, -0.2, 1.0])
    d2 = (d * d).sum(1)
    want = RHO / math.pi * 100.0 / (4 * math.pi) * (1.0 / np.sqrt(d2)) / d2
    np.testing.assert_allclose(got, want, rtol=1e-3)
    # the brightest corner is the one nearest the lamp (inverse square beats nothing else here)
    i0 = np.argmin(d2)
    assert got.max() == pytest.approx(got[i0])


def test_area_light_radiance_is_power_over_pi_area():
    """Square area light (normalize on) of power P and side s: L = P / (pi s^2), so the floor
    below gets H = pi L F = P F / s^2 with F the exact point-to-rectangle factor."""
    cr.new_empty_scene()
    ob, v = floor(8)
    s, h, P = 1.0, 1.0, 50.0
    cr.add_light("AREA", (0, 0, h), energy=P, size=s, shape="SQUARE")
    got = cr.bake_vertex_radiance([ob], samples=64).point["floor"][:, 0]
    x, y = v[:, 0], v[:, 1]
    a0, a1 = (-s / 2 - x) / h, (s / 2 - x) / h
    b0, b1 = (-s / 2 - y) / h, (s / 2 - y) / h
    F = rect_factor(a1, b1) - rect_factor(a0, b1) - rect_factor(a1, b0) + rect_factor(a0, b0)
    want = RHO / math.pi * P * F / s ** 2
    rel = np.abs(got / want - 1)
    assert rel.mean() < 0.005 and rel.max() < 0.02, (rel.mean(), rel.max())


def test_area_light_normalize_off_radiance_is_power_over_pi():
    """normalize off: radiance P / pi per unit area, i.e. the result scales with the area s^2."""
    cr.new_empty_scene()
    ob, v = floor(8)
    h, P = 1.0, 50.0
    light = cr.add_light("AREA", (0, 0, h), energy=P, size=0.5, shape="SQUARE")
    if not hasattr(light.data, "normalize"):
        pytest.skip(f"Blender {bpy.app.version_string}: an area light has no 'normalize' (4.5 has it); "
                    "it is always normalized, which the test above checks")
    light.data.normalize = False
    got = cr.bake_vertex_radiance([ob], samples=64).point["floor"][:, 0]
    x, y = v[:, 0], v[:, 1]
    centre = np.argmin(x * x + y * y)
    q = 0.25 / h
    F = 4 * rect_factor(q, q)
    assert got[centre] == pytest.approx(RHO / math.pi * P * F, rel=0.01)


def test_world_colour_times_strength_is_sky_radiance():
    cr.new_empty_scene()
    ob, _ = floor(2)
    cr.set_world((0.5, 0.25, 1.0), 2.0)
    got = cr.bake_vertex_radiance([ob], samples=16).point["floor"]
    np.testing.assert_allclose(got, np.broadcast_to(RHO * np.array([1.0, 0.5, 2.0]), got.shape), rtol=1e-4)


def test_point_domain_is_the_mean_of_corners_and_cache_round_trips(tmp_path):
    cr.new_empty_scene()
    ob, v = floor(4)
    cr.add_light("POINT", (0.5, 0.5, 0.7), energy=30.0, shadow_soft_size=0.0)
    a = cr.cached_bake([ob], tmp_path, samples=4)
    assert not a.cached and len(list(tmp_path.iterdir())) == 1
    # Blender's own POINT-domain bake averages the corners the same way
    me = ob.data
    attr = me.color_attributes.new("p", "FLOAT_COLOR", "POINT")
    me.color_attributes.active_color = attr
    ob.select_set(True)
    bpy.context.view_layer.objects.active = ob
    bpy.ops.object.bake(type="COMBINED", pass_filter=cr.PASS_FILTERS["COMBINED"], target="VERTEX_COLORS")
    p = np.empty(len(me.vertices) * 4, np.float32)
    attr.data.foreach_get("color", p)
    np.testing.assert_allclose(a.point["floor"], p.reshape(-1, 4)[:, :3], rtol=1e-5, atol=1e-7)
    me.color_attributes.remove(attr)
    assert a.corner["floor"].shape == (len(me.loops), 3)
    b = cr.cached_bake([ob], tmp_path, samples=4)
    assert b.cached and b.seconds == pytest.approx(a.seconds)
    np.testing.assert_array_equal(a.point["floor"], b.point["floor"])
    # a change the bake would see (light power) is a new key
    next(o for o in bpy.context.scene.objects if o.type == "LIGHT").data.energy = 31.0
    c = cr.cached_bake([ob], tmp_path, samples=4)
    assert not c.cached
    np.testing.assert_allclose(c.point["floor"], a.point["floor"] * 31 / 30, rtol=1e-4)
