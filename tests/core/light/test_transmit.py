"""Shadow and sky rays through see-through faces (core/light/transmit.py), against closed forms:
a sun straight down through a plane of uniform transmittance and through a checker of alpha
cut-outs, the world's light under a half-transparent roof, and a bake whose opaque twin is
bit-identical to the bake without any see-through data."""
from __future__ import annotations

import numpy as np
import pytest

from hemicube_radiosity.core.light.lamps import SunLight, direct_irradiance
from hemicube_radiosity.core.light.transmit import AlphaImage, Transmit, see_through
from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.pipeline import BakeSettings, bake
from hemicube_radiosity.core.rays import embree_available, occluder
from hemicube_radiosity.core.hemisphere import sky_fraction

pytestmark = pytest.mark.skipif(not embree_available(), reason="see-through faces need embreex")


def _grid(n, half, z, flip=False):
    xs = np.linspace(-half, half, n + 1)
    X, Y = np.meshgrid(xs, xs, indexing="xy")
    v = np.stack([X.ravel(), Y.ravel(), np.full(X.size, z)], 1)
    i = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    f = np.stack([i[:-1, :-1], i[:-1, 1:], i[1:, 1:], i[1:, :-1]], -1).reshape(-1, 4)
    return v, (f[:, ::-1] if flip else f)


def _scene(transmit, leaf_half=1.0):
    v, f = _grid(40, 2.0, 0.0)
    floor = MeshInput.from_faces(v, f, rho=(0.5,) * 3, name="floor")
    v, f = _grid(1, leaf_half, 1.0)
    leaf = MeshInput.from_faces(v, f, rho=(0.3,) * 3, name="leaf")
    leaf.transmit = transmit
    return floor, leaf


def _floor_points(P):
    sel = np.flatnonzero(P.owner == 0)
    return sel, P.centers[sel]


def test_a_sun_passes_a_uniform_share_through_a_plane():
    floor, leaf = _scene(Transmit(np.array([0.3])))
    P = build_patches([floor, leaf], None)
    assert P.see_through is not None and P.see_through.patch_mask(P).sum() == 1
    sun = SunLight(direction=(0, 0, -1), strength=2.0)
    H = direct_irradiance(P, [sun])[:, 0]
    sel, x = _floor_points(P)
    under = (np.abs(x[:, 0]) < 1.0) & (np.abs(x[:, 1]) < 1.0)
    assert np.allclose(H[sel][under], 0.6) and np.allclose(H[sel][~under], 2.0)
    leaf.transmit = None                                  # opaque: the full shadow, as before
    H0 = direct_irradiance(build_patches([floor, leaf], None), [sun])[:, 0]
    assert np.allclose(H0[sel][under], 0.0)


def test_a_sun_passes_the_holes_of_an_alpha_checker():
    """A 4 x 4 checker of transmittance 1 / 0 (alpha 0 / 1) on a 2 x 2 m leaf: under each hole
    the full sun, under each solid cell none; the floor's cells are 0.1 m, so none straddles."""
    pix = (np.indices((4, 4)).sum(axis=0) % 2).astype(np.float32)     # row 0 at v = 0
    corner_uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)     # the quad's corners, CCW
    floor, leaf = _scene(Transmit(np.zeros(1), np.zeros(1, np.int64), corner_uv,
                                  [AlphaImage(pix, closest=True)]))
    P = build_patches([floor, leaf], None)
    H = direct_irradiance(P, [SunLight(direction=(0, 0, -1), strength=2.0)])[:, 0]
    sel, x = _floor_points(P)
    under = (np.abs(x[:, 0]) < 1.0) & (np.abs(x[:, 1]) < 1.0)
    cell = np.floor((x[:, :2] + 1.0) / 0.5).astype(int)               # the leaf's texel above
    hole = under & (pix[np.clip(cell[:, 1], 0, 3), np.clip(cell[:, 0], 0, 3)] > 0.5)
    assert hole.sum() == under.sum() // 2
    assert np.allclose(H[sel][hole], 2.0) and np.allclose(H[sel][under & ~hole], 0.0)
    assert np.allclose(H[sel][~under], 2.0)


def test_bilinear_reads_between_texels_and_repeat_wraps():
    img = AlphaImage(np.array([[0.0, 1.0]], np.float32))
    assert img.at(np.array([[0.5, 0.5], [0.25, 0.5], [1.25, 0.5]])) == pytest.approx([0.5, 0.0, 0.0])
    assert AlphaImage(img.pixels, closest=True).at(np.array([[0.74, 0.1]])) == pytest.approx([1.0])


def _corner_ff(X, Y):
    """Form factor from a point to a parallel X x Y rectangle 1 above it, one corner overhead."""
    a, b = np.hypot(1.0, X), np.hypot(1.0, Y)
    return (X / a * np.arctan(Y / a) + Y / b * np.arctan(X / b)) / (2 * np.pi)


def test_the_world_under_a_half_transparent_roof():
    """A roof of transmittance 0.5 20 m across, 1 m over the floor's centre,
    covering 0.993 of its cosine-weighted sky: the sky rays find 1 - 0.5 x 0.990 of the world there,
    and the bake's floor reflects that (a roof over an open floor keeps no back: it adds none)."""
    floor, roof = _scene(Transmit(np.array([0.5])), leaf_half=10.0)
    P = build_patches([floor, roof], None)
    sel, x = _floor_points(P)
    i = sel[np.argmin(np.linalg.norm(x, axis=1))]
    covered = sum(_corner_ff(10.0 - sx * P.centers[i, 0], 10.0 - sy * P.centers[i, 1])
                  for sx in (-1, 1) for sy in (-1, 1))
    f = sky_fraction(occluder(P), P.centers[i:i + 1], P.normals[i:i + 1], rays=4096, eps=1e-6)
    assert f[0] == pytest.approx(1 - 0.5 * covered, abs=0.004)
    r = bake([floor, roof], BakeSettings(patch_size=None, element_size=None, method="hemicube",
                                        resolution=32), world=np.ones(3))
    B = r.patch_radiosity[i].mean()
    assert 0.5 * f[0] * (1 - 1e-9) < B < 0.5 * f[0] * 1.05


def test_see_through_data_of_a_back_follows_its_front():
    floor, leaf = _scene(Transmit(np.array([0.3])))
    back = MeshInput(leaf.verts, leaf.face_offsets, leaf.face_indices[::-1].copy(), leaf.face_rho,
                     leaf.face_emission, "leaf back", back_of=1, back_faces=np.array([0]))
    st = see_through([floor, leaf, back])
    assert [f.tolist() for f in st.faces] == [[False] * 1600, [True], [True]]
    assert len(st.tris) == 2                             # the front only: a ray passes once


def test_a_relight_with_a_new_alpha_casts_its_rays_again():
    """The cache keeps shadow and sky rays by geometry and by what passes: a roof made more
    transparent on a relight (same geometry, cache shared) lets more of the world through."""
    from hemicube_radiosity.core.runtime.cache import FormFactorCache

    cache = FormFactorCache()
    s = BakeSettings(patch_size=None, element_size=None, method="hemicube", resolution=16, sky_rays=256)
    floor, roof = _scene(Transmit(np.array([0.2])), leaf_half=10.0)
    first = bake([floor, roof], s, world=np.ones(3), cache=cache)
    roof.transmit = Transmit(np.array([0.8]))
    second = bake([floor, roof], s, world=np.ones(3), cache=cache)
    fresh = bake([floor, roof], s, world=np.ones(3))
    on_floor = first.patches.owner == 0
    assert second.patch_radiosity[on_floor].mean() > 1.5 * first.patch_radiosity[on_floor].mean()
    np.testing.assert_allclose(second.patch_radiosity, fresh.patch_radiosity, rtol=1e-6)


def test_sky_fraction_on_threads_and_in_float32_is_the_serial_float64_cast():
    """The sky rays cast in chunks on two threads, their origins and directions rounded to
    float32 once (Embree's precision) instead of cast from float64 arrays: the same fractions,
    bit for bit, as the serial cast of the float64 rays it replaced (written out here)."""
    from hemicube_radiosity.core.rays import ray_offsets
    from hemicube_radiosity.core.hemisphere import cosine_lattice
    from hemicube_radiosity.core.util.geometry import in_frames, tangent_frames
    floor, roof = _scene(None, leaf_half=1.0)
    P = build_patches([floor, roof], None)
    sel = np.flatnonzero(P.owner == 0)
    x, n = P.centers[sel], P.normals[sel]
    eps = ray_offsets(P, x, n)
    occ = occluder(P)
    local = cosine_lattice(64, 0)
    d = in_frames(local, tangent_frames(n)).reshape(-1, 3)
    o = np.repeat(x + eps[:, None] * n, 64, axis=0)
    ref = 1.0 - np.asarray(occ.occluded(o, d)).reshape(len(x), 64).mean(axis=1)
    assert 0.05 < ref.min() < 0.9 < ref.max()
    for workers, chunk in ((1, 1 << 16), (2, 1 << 16), (2, 640)):
        f = sky_fraction(occ, x, n, 64, eps=eps, workers=workers, chunk_rays=chunk)
        np.testing.assert_array_equal(f, ref)
