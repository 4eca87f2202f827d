"""A sun's shadow rays a few first (:func:`.lamps.sun_first`): a point whose first four of its
16 rays all reach the sun (or none does) takes that for the other twelve uncast; the others
cast every ray. Checked against the closed form of a sun disk cut by a roof's straight edge."""
import numpy as np
import pytest

from hemicube_radiosity.core.builtin_scenes import quad
from hemicube_radiosity.core.light import lamps
from hemicube_radiosity.core.light.lamps import SunLight, light_irradiance, sun_first
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.rays import embree_available, embree_scene, ray_offsets
from tests.support.patching import CountingScene

pytestmark = pytest.mark.skipif(not embree_available(), reason="Embree (embreex) is not installed")


def test_the_first_samples_are_the_disks_rim_one_a_sector():
    for samples, m, c in ((16, 4, 4), (32, 5, 6), (64, 8, 8)):
        f = sun_first(samples)
        np.testing.assert_array_equal(f, (m - 1) * c + np.arange(c))  # the outer row, every column
    assert sun_first(8) is None and sun_first(4) is None


@pytest.mark.parametrize("seed", [0, 3])
def test_a_row_across_a_roofs_shadow_edge_keeps_the_closed_form_penumbra(monkeypatch, seed):
    """A 10-degree sun straight overhead, a roof 1 m up over x < 0, floor points along x from
    the umbra through the penumbra (|x| < tan 5 deg) into full sun. The lit share of the
    sun's disk at x (seen from the point, a disk of radius R = tan 5 deg at unit distance, cut
    by the roof's edge at x) is (acos a - a sqrt(1 - a^2)) / pi with a = -x / R. With the
    rim's four rays first: the umbra exactly 0 and the sun exactly its unshadowed light, at 4
    rays a point; where the four part, the 16-ray value bit for bit; over the penumbra the lit
    share within 0.08 RMS of the closed form and 1.3 times the RMS of 16 rays everywhere
    (measured 0.068 and 0.071 against 0.057 and 0.060: a fifth of the penumbra's points, whose
    four rays agree, read 0 or 1), at 44% of the rays on this row (most of it penumbra)."""
    roof = quad([(-5, -5, 1), (-5, 5, 1), (0, 5, 1), (0, -5, 1)], name="Roof")
    floor = quad([(-5, -5, 0), (5, -5, 0), (5, 5, 0), (-5, 5, 0)], name="Floor")
    ps = build_patches([roof, floor], 1.0)
    R = np.tan(np.radians(5.0))
    xs = np.linspace(-3 * R, 3 * R, 601)
    pts = np.column_stack([xs, np.zeros_like(xs), np.zeros_like(xs)])
    up = np.tile([0.0, 0.0, 1.0], (len(xs), 1))
    eps = ray_offsets(ps, pts, up)
    sun = SunLight((0.0, 0.0, -1.0), strength=1.0, angle=np.radians(10.0))
    a = np.clip(-xs / R, -1, 1)
    truth = (np.arccos(a) - a * np.sqrt(1 - a * a)) / np.pi

    def lit(first):
        if not first:
            monkeypatch.setattr(lamps, "SUN_FIRST", 100)              # every ray cast
        scene = CountingScene(embree_scene(ps))
        E = light_irradiance(ps, sun, points=pts, normals=up, eps=eps, samples=16, seed=seed, _occ=scene)
        monkeypatch.undo()
        return E, scene.rays
    E, rays = lit(True)
    full, all_rays = lit(False)
    assert all_rays == 16 * len(xs)
    E0 = light_irradiance(ps, sun, points=pts, normals=up, eps=eps, samples=16, seed=seed, shadows="none")
    np.testing.assert_allclose(E0, 1.0, rtol=0.01)      # the disk's light overhead: its strength
    umbra, sunny = xs < -1.001 * R, xs > 1.001 * R
    np.testing.assert_array_equal(E[umbra], 0.0)
    np.testing.assert_array_equal(E[sunny], full[sunny])
    np.testing.assert_array_equal(full[sunny], E0[sunny])
    share = E / E0
    stopped = (share == 0.0) | (share == 1.0)
    mixed = ~stopped
    np.testing.assert_array_equal(E[mixed], full[mixed])
    assert rays == 4 * len(xs) + 12 * int(mixed.sum())
    assert rays < 0.5 * all_rays
    pen = ~(umbra | sunny)
    assert pen.sum() > 150 and mixed.sum() > 0.5 * pen.sum()
    err = np.sqrt(np.mean((share[pen] - truth[pen]) ** 2))
    assert err < 0.08 and err < 1.3 * np.sqrt(np.mean((full[pen] / E0[pen] - truth[pen]) ** 2)) + 0.01
    # what the rim's four rays missed is a sliver of the disk (measured at most 0.25 and 0.31)
    assert np.abs(share - truth)[stopped].max() < 0.35
