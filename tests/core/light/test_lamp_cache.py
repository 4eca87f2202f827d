"""Lamps' light kept for a relight (core/light/lamp_cache.py): the same light as
direct_irradiance gives, and a relight of a lamp's strength or colour casts no ray again."""
from dataclasses import replace

import numpy as np

from hemicube_radiosity.core import builtin_scenes as scenes
from hemicube_radiosity.core.light import lamp_cache
from hemicube_radiosity.core.light.lamps import AreaLight, PointLight, SpotLight, SunLight, direct_irradiance
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
