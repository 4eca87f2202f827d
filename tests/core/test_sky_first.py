"""The sky's rays a share first (:func:`.hemisphere.sky_fraction`'s ``first``): a point whose first
share of the pattern is all blocked or all open takes 0 or 1 without casting the rest; the
others cast every ray. Checked against closed forms: a point in a closed box (0), floor points
along a row from under a plate's middle out past its edge (1 minus the plate's form factor)."""
import numpy as np
import pytest

from tests.support.analytic import point_under_rectangle_corner
from hemicube_radiosity.core.builtin_scenes import box, quad
from hemicube_radiosity.core.hemisphere import SKY_FIRST, sky_fraction
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.rays import embree_available, embree_scene, ray_offsets
from tests.support.patching import CountingScene

pytestmark = pytest.mark.skipif(not embree_available(), reason="Embree (embreex) is not installed")


def _rectangle_above(x1, x2, y1, y2, c):
    """Form factor from an upward point at the origin to the parallel rectangle [x1, x2] x
    [y1, y2] a height c above it (corner rectangles added and subtracted: closed form)."""
    def corner(a, b):
        return np.sign(a) * np.sign(b) * point_under_rectangle_corner(np.abs(a), np.abs(b), c)
    return corner(x2, y2) - corner(x1, y2) - corner(x2, y1) + corner(x1, y1)


def test_points_in_a_closed_box_see_no_sky_and_cast_only_the_first_share():
    ps = build_patches([box((0, 0, 0), (2.0, 1.0, 1.5), inward=True)], 0.25)
    rng = np.random.default_rng(1)
    x = rng.uniform([0.1, 0.1, 0.1], [1.9, 0.9, 1.4], (300, 3))
    n = rng.normal(size=(300, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    scene = CountingScene(embree_scene(ps))
    got = sky_fraction(scene, x, n, 256, eps=np.zeros(len(x)), first=SKY_FIRST)
    np.testing.assert_array_equal(got, 0.0)                      # truth: no sky at all
    assert scene.rays == len(x) * 256 // SKY_FIRST               # the first share only
    # the box without its floor: points under its ceiling looking down see the opening (mixed:
    # every ray cast), and their fraction is the full pattern's, bit for bit
    bottomless = build_patches([box((0, 0, 0), (2.0, 1.0, 1.5), inward=True, bottom=False)], 0.25)
    down = np.tile([0.0, 0.0, -1.0], (50, 1))
    y = np.column_stack([rng.uniform(0.3, 1.7, 50), rng.uniform(0.3, 0.7, 50), np.full(50, 1.45)])
    s2 = CountingScene(embree_scene(bottomless))
    early = sky_fraction(s2, y, down, 256, eps=np.zeros(50), first=SKY_FIRST)
    assert s2.rays == 50 * 256                                   # none stopped early
    np.testing.assert_array_equal(early, sky_fraction(embree_scene(bottomless), y, down, 256, eps=np.zeros(50)))
    assert np.all((early > 0.05) & (early < 0.95))


@pytest.mark.parametrize("seed", [0, 1])
def test_a_floor_row_from_under_a_plate_to_far_beside_it_keeps_the_closed_form(seed):
    """Floor points on a row from under the middle of a 10 m plate 0.1 m up to 4 m beside it:
    under the plate every ray of the first share is blocked, far out every one is open (the
    plate then a few rays' worth of the hemisphere at most), near its edge they are mixed.
    The sky fraction against 1 - F (closed form): where the first share was mixed, the full
    pattern's value bit for bit; where it was not, within 0.015 of the truth (measured at most
    0.0055 and 0.0098 for the two seeds); over the row an RMS error under 0.004 (measured
    0.0019 and 0.0022; the full pattern's 0.0019 and 0.0018), and both paths taken."""
    plate = quad([(0, -5, 0.1), (0, 5, 0.1), (10, 5, 0.1), (10, -5, 0.1)], name="Plate")     # faces down
    floor = quad([(-1, -6, 0), (15, -6, 0), (15, 6, 0), (-1, 6, 0)], name="Floor")
    ps = build_patches([plate, floor], 1.0)
    xs = np.linspace(5.0, 14.0, 241)
    pts = np.column_stack([xs, np.full_like(xs, 0.3), np.zeros_like(xs)])
    up = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    truth = 1 - _rectangle_above(-xs, 10 - xs, -5.3, 4.7, 0.1)
    scene = CountingScene(embree_scene(ps))
    eps = ray_offsets(ps, pts, up)
    got = sky_fraction(scene, pts, up, 256, seed=seed, eps=eps, first=SKY_FIRST)
    full = sky_fraction(embree_scene(ps), pts, up, 256, seed=seed, eps=eps)
    stopped = (got == 0.0) | (got == 1.0)
    mixed = ~stopped
    assert (got[stopped] == 0.0).any() and (got[stopped] == 1.0).any() and mixed.sum() >= 10
    np.testing.assert_array_equal(got[mixed], full[mixed])
    assert np.abs(got - truth)[stopped].max() < 0.015
    assert np.sqrt(np.mean((got - truth) ** 2)) < 0.004
    # the rays: the first share everywhere, the rest only at the mixed points
    assert scene.rays == len(pts) * 64 + int(mixed.sum()) * 192
    # the same for any chunking and any number of workers (each point's rays are its own)
    for kw in ({"chunk_rays": 256 * 7}, {"workers": 2, "chunk_rays": 256 * 16}):
        np.testing.assert_array_equal(sky_fraction(embree_scene(ps), pts, up, 256, seed=seed, eps=eps,
                                                   first=SKY_FIRST, **kw), got)
