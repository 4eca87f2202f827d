"""The final gather's rays find the world at the element vertices (core/output/indirect.py
gather_finds_world): no sky rays of their own, the same light as sky rays of the same count."""
from dataclasses import replace

import numpy as np
import pytest

from hemicube_radiosity.core import builtin_scenes as scenes
from hemicube_radiosity.core.light import direct as light_direct
from hemicube_radiosity.core.output import indirect, stage as output_stage
from hemicube_radiosity.core.pipeline import bake
from hemicube_radiosity.core.rays import embree_available
from hemicube_radiosity.core.settings import BakeSettings
from tests.support.patching import counted_points

pytestmark = pytest.mark.skipif(not embree_available(), reason="the gather needs Embree")

WORLD = (0.3, 0.4, 0.5)


def _scene():
    """A floor with a block standing on it and a plate over it: the sky is partly hidden."""
    floor = scenes.quad([(0, 0, 0), (4, 0, 0), (4, 4, 0), (0, 4, 0)], (0.5, 0.5, 0.5), name="Floor")
    block = scenes.box((1.0, 1.0, 0.0), (2.0, 2.0, 0.8), (0.7, 0.6, 0.5), bottom=False, name="Block")
    plate = scenes.quad([(2.5, 2.5, 0.6), (2.5, 3.5, 0.6), (3.5, 3.5, 0.6), (3.5, 2.5, 0.6)], (0.4, 0.4, 0.4),
                        name="Plate")
    return [floor, block, plate]


def test_the_gathers_rays_light_the_vertices_as_their_own_sky_rays_of_the_same_count(monkeypatch):
    s = BakeSettings(patch_size=0.5, element_size=0.25, gather_rays=64, sky_rays=128, workers=1)
    calls = counted_points(monkeypatch, light_direct, "sky_fraction")
    new = bake(_scene(), s, world=WORLD)
    cast_new = sum(calls)
    calls.clear()
    # the former way: the vertices' own sky rays, beside a gather of as many rays
    for module in (indirect, output_stage):
        monkeypatch.setattr(module, "gather_finds_world", lambda ctx: False)
    monkeypatch.setattr(light_direct, "SKY_FIRST", 1)   # every sky ray at every vertex, as the gather's
    old = bake(_scene(), replace(s, gather_rays=128), world=WORLD)
    V = len(new.elements.verts)
    assert len(old.elements.verts) == V
    assert sum(calls) - cast_new == V                   # only the vertices' sky rays are saved
    np.testing.assert_allclose(new.vertex_radiosity, old.vertex_radiosity, rtol=1e-12, atol=1e-12)


def test_the_gather_casts_the_skys_count_where_it_finds_the_world():
    class Direct:
        world = np.array(WORLD)

    class Ctx:
        settings = BakeSettings(patch_size=0.5, element_size=0.25, gather_rays=64, sky_rays=128)
        direct = Direct()
    ctx = Ctx()
    assert indirect.gather_finds_world(ctx) and indirect.gather_count(ctx) == 128
    ctx.settings = replace(ctx.settings, sky_rays=32)            # fewer: the gather's own count
    assert indirect.gather_finds_world(ctx) and indirect.gather_count(ctx) == 64
    # far more sky rays than gather rays: the sky casts its own (the gather's matrix would grow)
    ctx.settings = replace(ctx.settings, sky_rays=64 * indirect.SKY_PER_GATHER + 1)
    assert not indirect.gather_finds_world(ctx) and indirect.gather_count(ctx) == 64
    ctx.settings = replace(ctx.settings, sky_rays=128)

    class F:
        sky = np.full(10, 0.5)
    ctx.form_factors = F()
    assert indirect.gather_finds_world(ctx)                     # half the sky seen: shared
    F.sky = np.full(10, 0.9 * indirect.SKY_SHARE_OPEN)          # closed rooms: hits to read, not sky
    assert not indirect.gather_finds_world(ctx) and indirect.gather_count(ctx) == 64
    F.sky = np.full(10, 0.5)
    ctx.direct.world = None                                     # a black world: nothing to find
    assert not indirect.gather_finds_world(ctx) and indirect.gather_count(ctx) == 64
