"""The lightmap's direct light, exact only where the light needs it (``core/output/texels.py``).

A 96 x 64 texel island on one flat face (texels 2 cm), lit by two sources given in closed form:

* a lamp (probed: one shadow ray stands for it) whose light falls off smoothly over the floor,
  cut by a hard shadow whose edge runs at a slant across the texel grid and by a thin shadow
  strip 1.5 texels wide, narrower than the anchors' spacing, falling between them;
* the world (not probed), smooth: a quadratic in position.

The interpolated texels must read each source within 2% of its exact value (the agreement
bound, :data:`texels.AGREE`), every texel of either shadow must be exact, far fewer texels than
the island's are lit exactly, and the choice is deterministic and the same when a source's
strength changes (a relight finds the same points).
"""
from __future__ import annotations

import numpy as np

from hemicube_radiosity.core.output import texels
from hemicube_radiosity.core.util.colour import LUMA

H, W, PITCH = 64, 96, 0.02


def island():
    """(covered (H, W), points (n, 3), normals (n, 3), faces (n,), pitch (n,)) of a flat face."""
    covered = np.ones((H, W), bool)
    rows, cols = np.nonzero(covered)
    points = np.stack([(cols + 0.5) * PITCH, (rows + 0.5) * PITCH, np.zeros(rows.size)], 1)
    normals = np.tile([0.0, 0.0, 1.0], (rows.size, 1))
    return covered, points, normals, np.zeros(rows.size, np.int64), np.full(rows.size, PITCH)


def shadowed(p):
    """(n,) bool: behind the slanted hard edge, or in the thin strip 1.5 texels wide."""
    x, y = p[:, 0], p[:, 1]
    edge = x + 0.37 * y > 1.3
    strip = np.abs(x - 0.5 - 0.05 * y) < 0.75 * PITCH
    return edge | strip


def light(p, lamp=1.0, world=1.0):
    """(n, 2, 3) the exact light of the two sources at points ``p``."""
    x, y = p[:, 0], p[:, 1]
    out = np.zeros((len(p), 2, 3))
    out[:, 0] = (lamp / (1.0 + (x - 0.6) ** 2 + (y - 0.4) ** 2) * ~shadowed(p))[:, None] * [1.0, 0.9, 0.8]
    out[:, 1] = (world * (0.3 + 0.2 * x * y + 0.1 * x * x))[:, None] * [0.5, 0.6, 0.9]
    return out


def run(lamp=1.0, world=1.0, probes=None):
    """(value (n, 2, 3), exact (n, 2), points, lit: [(ids, which)] of every exact call)."""
    covered, points, normals, faces, pitch = island()
    lit = []

    def split(ids, samples, which=None):
        if samples is None:
            lit.append((ids, np.ones(2, bool) if which is None else np.asarray(which, bool)))
        elif probes is not None:
            probes.append(which)
        out = light(points[ids], lamp, world)          # a point lamp: one ray is exact
        if which is not None:
            out[:, ~np.asarray(which, bool)] = 0.0
        return out
    value, exact = texels.by_source(split, covered, points, normals, faces, pitch,
                                    probed=np.array([True, False]))
    return value, exact, points, lit


def test_the_probe_casts_toward_the_probed_sources_only():
    """The one-ray probe at every texel asks for the lamp alone: the world's rays (hundreds a
    point) are not cast at every texel, and the result is the same as with them."""
    probes = []
    value = run(probes=probes)[0]
    assert len(probes) == 1 and probes[0].tolist() == [True, False]
    covered, points, normals, faces, pitch = island()
    every = texels.by_source(lambda ids, samples, which=None: light(points[ids]), covered, points, normals,
                             faces, pitch, probed=np.array([True, False]))[0]
    np.testing.assert_array_equal(value, every)


def test_interpolated_where_smooth_exact_at_every_shadow_texel():
    value, exact, points, lit = run()
    want = light(points)
    # every texel lit once at most in each source, and those are the exact ones
    for k in range(2):
        ids = np.concatenate([i for i, which in lit if which[k]])
        assert np.unique(ids).size == ids.size and np.array_equal(np.sort(ids), np.flatnonzero(exact[:, k]))
    np.testing.assert_array_equal(value[exact], want[exact])
    # every shadowed texel dark (the strip's found by the probe), every texel at an edge exact
    s = shadowed(points)
    assert np.all(value[s, 0] == 0)
    img = s.reshape(H, W)
    pad = np.pad(img, 1, mode="edge")
    mixed = np.zeros((H, W), bool)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            mixed |= pad[1 + dr:1 + dr + H, 1 + dc:1 + dc + W] != img
    assert mixed.sum() > 300 and exact[mixed.ravel(), 0].all()
    # the interpolated texels within the agreement bound of the exact light, each source apart
    Y, Yw = value @ LUMA, want @ LUMA
    err = np.abs(Y - Yw)[~exact] / np.maximum(Yw[~exact], 1e-12)
    assert err.max() <= texels.AGREE, err.max()
    # and far fewer texels lit than the island has (measured: 21% in the lamp's light, the
    # strip and the edge with their neighbours; the grids' last cells cut at the island's last
    # row and column), the smooth world's at its anchors only (measured: 3.5%), not at the
    # lamp's shadows (18% of the texels lit in the lamp's alone)
    assert exact[:, 0].mean() < 0.45, exact[:, 0].mean()
    assert exact[:, 1].mean() < 0.15, exact[:, 1].mean()
    assert (exact[:, 0] & ~exact[:, 1]).mean() > 0.12


def test_deterministic_and_the_same_texels_after_a_relight():
    v1, e1, _, _ = run()
    v2, e2, _, _ = run()
    np.testing.assert_array_equal(v1, v2)
    np.testing.assert_array_equal(e1, e2)
    v3, e3, _, _ = run(lamp=7.0, world=0.25)
    np.testing.assert_array_equal(e1, e3)
    np.testing.assert_allclose(v3[:, 0], 7.0 * v1[:, 0], rtol=1e-12)
    np.testing.assert_allclose(v3[:, 1], 0.25 * v1[:, 1], rtol=1e-12)


# small islands, each a face of its own, as Lightmap Pack lays out a detailed mesh (the living
# room's 1,961 faces: half of them 42 texels or fewer): (first row, first column, rows, columns,
# where in the lamp's and the world's light its first texel lies)
ISLANDS = ((1, 1, 6, 6, (0.10, 0.10)), (1, 9, 5, 7, (0.30, 0.60)), (1, 18, 9, 1, (0.70, 0.20)),
           (1, 21, 1, 9, (0.20, 0.90)), (8, 1, 3, 3, (0.90, 0.50)), (8, 6, 10, 12, (1.05, 0.55)),
           (12, 20, 7, 7, (0.45, 0.30)), (20, 1, 6, 6, (1.20, 0.20)), (20, 9, 12, 14, (0.40, 0.05)))


def atlas():
    """(covered (h, w), points, normals, faces, pitch) of :data:`ISLANDS` in one image."""
    covered = np.zeros((34, 34), bool)
    face = np.full(covered.shape, -1)
    origin = np.zeros(covered.shape + (2,))
    for k, (r0, c0, h, w, xy) in enumerate(ISLANDS):
        covered[r0:r0 + h, c0:c0 + w] = True
        face[r0:r0 + h, c0:c0 + w] = k
        origin[r0:r0 + h, c0:c0 + w] = np.array(xy) - (np.array([c0, r0]) - 0.5) * PITCH
    rows, cols = np.nonzero(covered)
    xy = origin[rows, cols] + np.stack([cols, rows], 1) * PITCH
    points = np.column_stack([xy, np.zeros(rows.size)])
    normals = np.tile([0.0, 0.0, 1.0], (rows.size, 1))
    return covered, points, normals, face[rows, cols], np.full(rows.size, PITCH)


def test_small_islands_are_interpolated_on_cells_laid_from_their_own_first_texel():
    """Each island's grid starts at its first row and column and its last cells end at its
    last ones (narrower), so a small island's smooth light is read at a few anchors, its last
    row and column interpolated too: every texel within the agreement bound of the exact
    light, every texel of an island beside a shadow's edge within it exact, and the smooth
    world lit at an eighth of the texels (measured: 12%; the image's fixed grid lit 54%: its
    cells crossed the islands' borders, so every last row and column and the 2-texel grid's
    anchors were exact)."""
    covered, points, normals, faces, pitch = atlas()
    want = light(points)

    def split(ids, samples, which=None):
        out = light(points[ids])
        if which is not None:
            out[:, ~np.asarray(which, bool)] = 0.0
        return out
    value, exact = texels.by_source(split, covered, points, normals, faces, pitch, probed=np.array([True, False]))
    np.testing.assert_array_equal(value[exact], want[exact])
    Y, Yw = value @ LUMA, want @ LUMA
    err = np.abs(Y - Yw)[~exact] / np.maximum(Yw[~exact], 1e-12)
    assert err.max() <= texels.AGREE, err.max()
    # a texel whose 8 neighbours on its island are not all lit or all shadowed as it is: exact
    s = shadowed(points)
    img, fimg = np.zeros(covered.shape, bool), np.full(covered.shape, -1)
    img[covered], fimg[covered] = s, faces
    rows, cols = np.nonzero(covered)
    mixed = np.zeros(rows.size, bool)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            r, c = np.clip(rows + dr, 0, 33), np.clip(cols + dc, 0, 33)
            mixed |= (fimg[r, c] == faces) & (img[r, c] != s)
    assert mixed.sum() > 20 and exact[mixed, 0].all()
    assert np.all(value[s, 0] == 0)
    assert exact[:, 1].mean() < 0.25, exact[:, 1].mean()
    # the 1-texel strips (9 x 1, 1 x 9) interpolated along their length
    for k in (2, 3):
        assert not exact[faces == k, 1].all()
