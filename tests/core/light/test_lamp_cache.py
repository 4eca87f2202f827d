"""Lamps' light kept for a relight (core/light/lamp_cache.py): the same light as
direct_irradiance gives, and a relight of a lamp's strength or colour casts no ray again."""
from dataclasses import replace

import numpy as np

from hemicube_radiosity.core import builtin_scenes as scenes
from hemicube_radiosity.core.light import lamp_cache
from hemicube_radiosity.core.light.lamps import AreaLight, PointLight, SpotLight, SunLight, direct_irradiance
from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.pipeline import BakeSettings, bake
from hemicube_radiosity.core.runtime.cache import FormFactorCache
from tests.support.markers import needs_embree


def _lamps(scale=1.0, tint=(1.0, 1.0, 1.0)):
    m = np.eye(4)
    m[:3, 3] = (0.2, 0.1, 1.4)
    t = np.asarray(tint)
    return [PointLight((0.3, -0.2, 1.5), color=(1.0, 0.5, 0.25) * t, power_w=800.0 * scale, radius=0.2),
            SpotLight((-0.4, 0.3, 1.2), (0.1, 0.0, -1.0), color=t, power_w=500.0 * scale, radius=0.1,
                      spot_size=1.0),
            SunLight((0.3, 0.4, -0.866), color=(1.0, 0.9, 0.8) * t, strength=3.0 * scale, angle=0.2),
            AreaLight(m, shape="DISK", size_x=0.4, color=t, power_w=200.0 * scale)]


def _scene():
    """A floor under a block, so every lamp casts a penumbra."""
    return build_patches(_meshes(), 0.25)


def _meshes():
    return [scenes.box((-2, -2, -0.01), (2, 2, 0.0), name="floor"),
            scenes.box((-0.3, -0.3, 0.0), (0.3, 0.3, 0.6), bottom=False, name="block")]


@needs_embree
def test_unit_lamps_scaled_equal_the_direct_light_and_a_relight_casts_no_ray(monkeypatch):
    p = _scene()
    lamps = _lamps()
    want = direct_irradiance(p, lamps, samples=8, seed=3)
    assert want.max() > 0 and (want[:, 0] < 0.5 * want[:, 0].max()).any()   # lit, with shadows
    cache = FormFactorCache()
    got = lamp_cache.lamp_irradiance(p, lamps, cache, samples=8, seed=3)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * want.max())
    # one lamp lit apart at its place in the list draws the list's random stream for it
    alone = [replace(li, **{lamp_cache.SCALE[type(li)]: 0.0}) if k != 2 else li for k, li in enumerate(lamps)]
    np.testing.assert_allclose(lamp_cache.lamp_irradiance(p, [lamps[2]], None, samples=8, seed=3, index=2),
                               direct_irradiance(p, alone, samples=8, seed=3), rtol=1e-12, atol=1e-12 * want.max())
    # a relight: every lamp 1.7x and tinted; no lamp's light is computed again
    calls = []
    real = lamp_cache.light_irradiance
    monkeypatch.setattr(lamp_cache, "light_irradiance", lambda *a, **k: calls.append(1) or real(*a, **k))
    tint = (0.2, 1.0, 0.6)
    relit = lamp_cache.lamp_irradiance(p, _lamps(1.7, tint), cache, samples=8, seed=3)
    assert calls == []
    np.testing.assert_allclose(relit, direct_irradiance(p, _lamps(1.7, tint), samples=8, seed=3),
                               rtol=1e-12, atol=1e-12 * want.max())
    # a moved lamp is cast again; other sample counts and seeds are other streams
    moved = _lamps()
    moved[0] = PointLight((0.5, -0.2, 1.5), color=(1.0, 0.5, 0.25), power_w=800.0, radius=0.2)
    lamp_cache.lamp_irradiance(p, moved, cache, samples=8, seed=3)
    lamp_cache.lamp_irradiance(p, lamps, cache, samples=8, seed=4)
    assert len(calls) == 1 + 4
    # a dark lamp gives nothing and casts nothing
    dark = [SunLight((0.3, 0.4, -0.866), strength=0.0, angle=0.2)]
    assert not lamp_cache.lamp_irradiance(p, dark, cache).any() and len(calls) == 5


@needs_embree
def test_a_bake_relit_in_strength_is_the_first_times_the_factor_and_casts_no_lamp_ray(monkeypatch):
    meshes = _meshes()
    cache = FormFactorCache()
    s = BakeSettings(patch_size=0.5, element_size=0.25)
    first = bake(meshes, s, lights=_lamps(), cache=cache)
    calls = []
    real = lamp_cache.light_irradiance
    monkeypatch.setattr(lamp_cache, "light_irradiance", lambda *a, **k: calls.append(1) or real(*a, **k))
    again = bake(meshes, s, lights=_lamps(2.5), cache=cache)
    assert calls == []
    a, b = np.asarray(first.corner_values()), np.asarray(again.corner_values())
    assert a.max() > 0
    np.testing.assert_allclose(b, 2.5 * a, rtol=1e-9, atol=1e-12 * a.max())


def _sky(w=128, h=64):
    """(h, w, 3) an equirectangular map (rows bottom-up): a dim ground, a sky brightening to the
    zenith and a small sun of 2,000 (most of the light) (its peaks): a world that varies by direction."""
    lat = (np.arange(h) + 0.5) / h * np.pi - np.pi / 2
    lon = 2 * np.pi * (0.5 - (np.arange(w) + 0.5) / w)
    LAT, LON = np.meshgrid(lat, lon, indexing="ij")
    d = np.stack([np.cos(LAT) * np.cos(LON), np.cos(LAT) * np.sin(LON), np.sin(LAT)], -1)
    L = 1.0 + 2.0 * np.sin(np.maximum(LAT, 0.0))
    sun = np.array([0.3, 0.2, 0.93]) / np.linalg.norm([0.3, 0.2, 0.93])
    L = L + 2000.0 * (d @ sun > np.cos(np.radians(4.0)))
    L = np.where(LAT < 0, 0.3, L)
    return np.repeat(L[..., None], 3, axis=2) * np.array([0.9, 1.0, 1.1])


def _court():
    """A square court open to the sky (four walls and a floor, symmetric about x = 0 and y = 0)
    with a block in its middle: light from the map's sun and sky falls on parts of it."""
    v = np.array([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0],
                  [-2, -2, 2], [2, -2, 2], [2, 2, 2], [-2, 2, 2]], float)
    faces = [(0, 1, 2, 3), (0, 4, 5, 1), (1, 5, 6, 2), (2, 6, 7, 3), (3, 7, 4, 0)]   # facing in
    court = MeshInput.from_faces(v, faces, rho=(0.7,) * 3, name="court")
    return [court, scenes.box((-0.4, -0.4, 0.0), (0.4, 0.4, 0.8), bottom=False, name="block")]


@needs_embree
def test_an_environment_map_made_brighter_relights_without_a_ray(monkeypatch):
    """A world's Strength changed: its map's light is kept for the map at unit mean luminance
    (lamp_cache._unit_map), and what shines is ranked to 9 digits (output/shine.py), so the
    relight casts no ray, toward the map or from what it lights, and equals a fresh bake of
    the brighter world."""
    from hemicube_radiosity.core.light.environment import EnvironmentLight
    from hemicube_radiosity.core.output import shine

    px = _sky()
    s = BakeSettings(patch_size=0.5, element_size=0.25, sky_rays=16)
    cache = FormFactorCache()

    def world(k):
        env = EnvironmentLight(px * k, rays=64)
        return dict(lights=[env], world=env.base())
    calls = []
    for mod, name in ((lamp_cache, "light_irradiance"), (shine, "emitter_transport")):
        real = getattr(mod, name)
        monkeypatch.setattr(mod, name, lambda *x, _r=real, _n=name, **k: calls.append(_n) or _r(*x, **k))
    first = bake(_court(), s, cache=cache, **world(1.0))
    a = np.asarray(first.corner_values())
    assert a.max() > 3 * np.median(a) > 0                        # lit unevenly, by direction
    assert "emitter_transport" in calls                          # the sunlit floor shines
    calls.clear()
    again = np.asarray(bake(_court(), s, cache=cache, **world(1.5)).corner_values())
    assert calls == []
    # (to rounding: the map's light is kept at unit mean luminance and scaled back; rays drawn
    # anew would differ by per cent)
    np.testing.assert_allclose(again, 1.5 * a, rtol=1e-7, atol=1e-12 * a.max())
    fresh = np.asarray(bake(_court(), s, **world(1.5)).corner_values())
    np.testing.assert_allclose(again, fresh, rtol=1e-7, atol=1e-12 * a.max())


@needs_embree
def test_an_environment_map_turned_or_resized_is_lit_anew(monkeypatch):
    """The kept light of a map (lamp_cache._unit_map) is its shape's: the same map turned about
    the vertical (the key holds the rotation: without it this fails), or the same sky drawn at
    twice the resolution, casts its rays again and bakes as a fresh bake of that world does."""
    from hemicube_radiosity.core.light.environment import EnvironmentLight

    s = BakeSettings(patch_size=0.5, element_size=0.25, sky_rays=16)
    px = _sky()
    c, sn = np.cos(np.radians(90.0)), np.sin(np.radians(90.0))
    turned = np.array([[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]])
    worlds = {"turned": EnvironmentLight(px, rotation=turned, rays=64),
              "resized": EnvironmentLight(_sky(256, 128), rays=64)}
    cache = FormFactorCache()
    env = EnvironmentLight(px, rays=64)
    first = np.asarray(bake(_court(), s, cache=cache, lights=[env], world=env.base()).corner_values())
    calls = []
    real = lamp_cache.light_irradiance
    monkeypatch.setattr(lamp_cache, "light_irradiance", lambda *x, **k: calls.append(1) or real(*x, **k))
    for name, other in worlds.items():
        calls.clear()
        again = np.asarray(bake(_court(), s, cache=cache, lights=[other], world=other.base()).corner_values())
        assert calls, name                                         # its light found anew
        assert np.abs(again - first).max() > 0.05 * first.max(), name      # the court lit otherwise
        fresh = np.asarray(bake(_court(), s, lights=[other], world=other.base()).corner_values())
        np.testing.assert_allclose(again, fresh, rtol=1e-7, atol=1e-12 * first.max(), err_msg=name)
