"""The direct stage's points averaged into a patch or a cluster share the sky's rays out
(:data:`.light.points.SKY_SHARE`): a cluster's stand-ins and a patch's grid points each cast a
share of the pattern, the mean the whole pattern once. Checked against the closed-form sky
view of a floor half under a roof, and the ray counts."""
import numpy as np
import pytest

from hemicube_radiosity.core import builtin_scenes as scenes
from hemicube_radiosity.core.light import points as light_points
from hemicube_radiosity.core.light.direct import DirectLight
from hemicube_radiosity.core.light.points import SKY_SHARE, shared_parts
from hemicube_radiosity.core.light.polygon_ff import polygon_form_factors
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.pipeline import BakeSettings, bake
from hemicube_radiosity.core.rays import embree_available


def test_shared_parts_give_each_big_cluster_every_share():
    groups = np.array([3, 1, 3, 3, 1, 3, 7, 3, 1, 1, 1, 3])      # 3: six points, 1: five, 7: one
    full, part = shared_parts(groups)
    np.testing.assert_array_equal(full, groups != 7)
    for g in (1, 3):
        assert set(part[groups == g]) == set(range(SKY_SHARE))
        # in the given order: ranks 0, 1, 2, ... modulo SKY_SHARE
        np.testing.assert_array_equal(part[groups == g], np.arange((groups == g).sum()) % SKY_SHARE)


@pytest.mark.skipif(not embree_available(), reason="Embree (embreex) is not installed")
def test_a_floor_half_under_a_roof_keeps_its_closed_form_sky_with_the_rays_shared(monkeypatch):
    """A 2 m floor of 20,000 triangles (clusters of hundreds of pieces, 32 stand-ins each) with a
    1 m x 2 m roof 0.4 m over one half, lit by a white world alone: each floor cluster's direct
    source is rho times the mean over its faces of 1 - F (F the roof's closed-form form factor
    at each face centre), the stand-ins casting a quarter of the sky's rays each: within 3.5%
    and an RMS under 1.2%, relative (measured: at most 2.4%, RMS 0.79%; with every stand-in
    casting all of them, 1.6% and 0.57%), and under 1.6 times the RMS of all the rays at
    every stand-in."""
    floor = scenes.tessellate([scenes.quad([(0, 0, 0), (2, 0, 0), (2, 2, 0), (0, 2, 0)], rho=(0.6,) * 3,
                                           name="Floor")], 100)
    roof = scenes.quad([(0, 0, 0.4), (0, 2, 0.4), (1, 2, 0.4), (1, 0, 0.4)], name="Roof")      # faces down
    world = np.array([1.0, 1.0, 1.0])
    asked = []
    world_at = DirectLight.world_at

    def counting(self, x, n, where, *a, **kw):
        asked.append((where, len(x), kw.get("split", 1)))
        return world_at(self, x, n, where, *a, **kw)
    monkeypatch.setattr(DirectLight, "world_at", counting)

    def run():
        asked.clear()
        r = bake(floor + [roof], BakeSettings(patch_size=0.25), world=world)
        c, p = r.clusters, r.patches
        on_floor = c.owner == p.object_names.index("Floor")
        lp = build_patches([roof], None)
        F = polygon_form_factors(p.centers, p.normals, lp.corners(), lp.normals).sum(1)
        truth = np.bincount(c.of, weights=p.areas * (1 - F), minlength=len(c)) / c.areas
        return r.source[on_floor, 0] / 0.6, truth[on_floor], on_floor, c, list(asked)

    got, truth, on_floor, c, calls = run()
    assert on_floor.sum() == 64 and c.sizes[on_floor].min() > 250
    np.testing.assert_allclose(got, truth, rtol=0.035)
    assert ("grouped-centres", 32 * 64, SKY_SHARE) in calls          # the floor's stand-ins, shared
    assert not any(w == "grouped-centres" and s == 1 for w, _, s in calls)
    assert any(w == "patch-points-2" and s == SKY_SHARE for w, _, s in calls)   # the roof's grids
    shared = np.sqrt(np.mean((got / truth - 1) ** 2))
    monkeypatch.setattr(light_points, "SKY_SHARE", 10 ** 6)            # every point all the rays
    monkeypatch.setattr(DirectLight, "world_at", lambda self, x, n, where, *a, **kw:
                        counting(self, x, n, where, *a, **{**kw, "first": 1}))
    alone, truth2, *_ , calls2 = run()
    assert ("grouped-centres", 32 * 64, 1) in calls2
    np.testing.assert_array_equal(truth, truth2)
    assert shared < 0.012 and shared < 1.6 * np.sqrt(np.mean((alone / truth - 1) ** 2))
