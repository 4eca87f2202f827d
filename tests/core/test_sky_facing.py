"""The sky's rays limited to one side of a plane (``facing``, a leaning corner's own triangle):
only the rays on that side are cast, the others count as blocked."""
import numpy as np
import pytest

from hemicube_radiosity.core import builtin_scenes as scenes
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.rays import embree_available, embree_scene
from hemicube_radiosity.core.hemisphere import sky_fraction


class Counted:
    """A scene that counts the rays it is asked about; ``blocked(o, d)`` says which are."""

    def __init__(self, blocked):
        self.blocked, self.rays = blocked, 0

    def occluded(self, o, d):
        self.rays += len(o)
        return self.blocked(np.asarray(o, np.float64), np.asarray(d, np.float64))


def _tilted(n_points, seed=3):
    rng = np.random.default_rng(seed)
    x = rng.uniform(-1, 1, (n_points, 3))
    tilt = np.radians(rng.uniform(5, 80, n_points))
    az = rng.uniform(0, 2 * np.pi, n_points)
    f = np.stack([np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), np.cos(tilt)], 1)
    n = np.tile([0.0, 0.0, 1.0], (n_points, 1))
    return x, n, f


def test_open_sky_below_a_plane_is_the_lunes_cosine_share_and_casts_only_the_rays_above_it():
    x, n, f = _tilted(200)
    open_sky = Counted(lambda o, d: np.zeros(len(o), bool))
    got = sky_fraction(open_sky, x, n, 256, eps=np.zeros(len(x)), facing=f)
    # the cosine-weighted share of the hemisphere about n above the plane of normal f: (1 + n.f) / 2
    want = (1 + np.einsum("ij,ij->i", n, f)) / 2
    np.testing.assert_allclose(got, want, atol=0.02)          # 256 rays: a sliver is a few rays
    assert np.abs(got - want).mean() < 0.005
    # every ray on the plane's side is cast, none below it: the rays cast are the sky found
    assert open_sky.rays == pytest.approx(got.sum() * 256, abs=0.5)
    assert open_sky.rays < 0.9 * 256 * len(x)


def test_blocked_rays_above_the_plane_still_count():
    x, n, f = _tilted(100, seed=5)
    half = Counted(lambda o, d: d[:, 0] > 0)          # a wall on the +x side, infinitely far
    got = sky_fraction(half, x, n, 256, eps=np.zeros(len(x)), facing=f)
    # the open part: the lune above the plane of f on the -x side. Closed form per point as
    # the same lattice in a fine Monte Carlo of the cosine hemisphere
    rng = np.random.default_rng(0)
    u = rng.uniform(size=(200_000, 2))
    r, phi = np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]
    d = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - u[:, 0])], 1)     # about +z
    want = np.array([np.mean((d[:, 0] <= 0) & (d @ fi > 0)) for fi in f])
    np.testing.assert_allclose(got, want, atol=0.02)


@pytest.mark.skipif(not embree_available(), reason="Embree (embreex) is not installed")
def test_casting_only_the_rays_above_the_plane_matches_casting_them_all_in_the_cornell_box():
    p = build_patches(scenes.cornell_box(), 0.25)
    scene = embree_scene(p)
    lo, hi = p.verts.min(axis=0), p.verts.max(axis=0)
    rng = np.random.default_rng(11)
    x = lo + rng.uniform(0.1, 0.9, (300, 3)) * (hi - lo)
    n = rng.normal(size=(300, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    f = n + rng.normal(scale=0.6, size=n.shape)
    f /= np.linalg.norm(f, axis=1, keepdims=True)
    # each ray on its own: blocked as Embree says, and every ray below the plane blocked
    everything = Counted(lambda o, d: np.asarray(scene.occluded(o, d)))
    kept = sky_fraction(everything, x, n, 64, eps=np.zeros(len(x)), facing=f)
    whole = sky_fraction(everything, x, n, 64, eps=np.zeros(len(x)))
    assert (kept <= whole + 1e-12).all() and (kept < whole).any() and (kept > 0).any()
    from hemicube_radiosity.core.hemisphere import cosine_lattice
    from hemicube_radiosity.core.util.geometry import in_frames, tangent_frames
    d = in_frames(cosine_lattice(64, 0), tangent_frames(n)).reshape(-1, 3)
    below = np.einsum("ij,ij->i", d, np.repeat(f, 64, axis=0)) <= 0
    hit = np.asarray(scene.occluded(np.repeat(x, 64, axis=0), d)) | below
    np.testing.assert_array_equal(kept, 1.0 - hit.reshape(len(x), 64).mean(axis=1))


@pytest.mark.skipif(not embree_available(), reason="Embree (embreex) is not installed")
@pytest.mark.parametrize("split", [1, 4])
def test_points_whose_facing_is_their_normal_or_a_hair_off_it_cast_every_ray_as_without_one(split):
    """A point whose facing lies within half the pattern's lowest ray's height of its unit
    normal has no ray below it (d . f >= z - |f - n|): it is cast as without ``facing``, in
    float32 from the start; the others as before. Each point against every ray on its own:
    Embree's answer, and below the plane blocked (an independent per-ray loop), bit for bit,
    whatever the points beside it in a chunk."""
    from hemicube_radiosity.core.hemisphere import cosine_lattice
    from hemicube_radiosity.core.util.geometry import tangent_frames
    p = build_patches(scenes.cornell_box(), 0.25)
    scene = embree_scene(p)
    lo, hi = p.verts.min(axis=0), p.verts.max(axis=0)
    rng = np.random.default_rng(5)
    m = 240
    x = lo + rng.uniform(0.1, 0.9, (m, 3)) * (hi - lo)
    n = rng.normal(size=(m, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    f = n.copy()
    kind = np.arange(m) % 6                  # 0 equal, 1 a hair off, 2 tilted, 3 tilted far,
    f[kind == 1] += 1e-3 * rng.normal(size=((kind == 1).sum(), 3))               # 4 a zero normal,
    f[kind == 2] += 0.3 * rng.normal(size=((kind == 2).sum(), 3))                # 5 twice as long
    f[kind == 3] = -n[kind == 3] + 0.2 * rng.normal(size=((kind == 3).sum(), 3))
    n[kind == 4] = f[kind == 4] = 0.0
    n[kind == 5] *= 2.0
    f[kind == 5] = n[kind == 5]
    rays = 64
    part = rng.integers(0, split, m)
    got = sky_fraction(scene, x, n, rays, eps=np.full(m, 1e-4), facing=f, split=split, part=part,
                       chunk_rays=rays // split * 7)
    local, frames = cosine_lattice(rays, 0), tangent_frames(n)
    assert local[:, 2].min() > 0.05                 # what "a hair off" is measured against
    want = np.empty(m)
    for i in range(m):
        d = local[part[i]::split] @ frames[i]                       # (R, 3), world
        below = d @ f[i] <= 0
        o = np.repeat((x[i] + 1e-4 * n[i])[None], len(d), axis=0)
        hit = np.asarray(scene.occluded(o, d)) | below
        want[i] = 1.0 - hit.mean()
    np.testing.assert_array_equal(got, want)
    # a hair off (within the clearance) or equal: as without facing, bit for bit
    plain = sky_fraction(scene, x, n, rays, eps=np.full(m, 1e-4), split=split, part=part)
    same = (kind == 0) | (kind == 1)
    np.testing.assert_array_equal(got[same], plain[same])
    assert (got[kind == 4] == 0).all() and (got[kind == 3] < plain[kind == 3]).any()
