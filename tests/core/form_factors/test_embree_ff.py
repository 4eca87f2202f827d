"""Embree form factors against closed forms, the enclosure identity and the NumPy rasteriser."""
import sys

import numpy as np
import pytest

from hemicube_radiosity.core import builtin_scenes as scenes
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.form_factors import embree as embree_ff
from tests.support.analytic import object_factor, parallel_rectangles, perpendicular_rectangles
from hemicube_radiosity.core.form_factors.embree import (
    embree_hemicube_form_factors, embree_stochastic_form_factors
)
from hemicube_radiosity.core.runtime.progress import Cancelled
from hemicube_radiosity.core.rays import EmbreeUnavailable, embree_available
from tests.support.markers import needs_embree


def test_closed_forms_are_the_catalogue_values():
    assert parallel_rectangles() == pytest.approx(0.1998, abs=5e-5)
    assert perpendicular_rectangles() == pytest.approx(0.2000, abs=5e-5)


# 10 x 10 patches per square: the centre-point rule itself is within 3.5e-4 of the area-to-area
# closed form here (0.20013 vs 0.19982 for the parallel squares), pixel aliasing with rotated
# R = 64 hemi-cubes adds a few 1e-4.
CASES = [("parallel", scenes.parallel_squares, parallel_rectangles()),
         ("perpendicular", scenes.perpendicular_squares, perpendicular_rectangles())]


@needs_embree
@pytest.mark.parametrize("name,scene,exact", CASES, ids=[c[0] for c in CASES])
def test_hemicube_rays_match_closed_form(name, scene, exact):
    p = build_patches(scene(), 0.1)
    F = embree_hemicube_form_factors(p, 64, rotate_seed=3)
    assert object_factor(p, F) == pytest.approx(exact, abs=1e-3)
    # reciprocity of the object factors (equal areas): F_ab = F_ba
    assert object_factor(p, F, 1, 0) == pytest.approx(exact, abs=1e-3)
    # the two squares see nothing else: the rest of every row is sky
    np.testing.assert_allclose(F.row_sums() + F.sky, 1.0, atol=1e-6)
    assert np.all(F.to_dense().diagonal() == 0)
    assert F.data.dtype == np.float32 and F.meta["method"] == "embree" and F.meta["resolution"] == 64


@needs_embree
@pytest.mark.parametrize("name,scene,exact", CASES, ids=[c[0] for c in CASES])
def test_stochastic_rays_match_closed_form(name, scene, exact):
    p = build_patches(scene(), 0.1)
    k = 1024
    F = embree_stochastic_form_factors(p, k, seed=7)
    # 100 receivers x k rays estimate a fraction near 0.2: the standard error of the object factor
    # is at most sqrt(0.2 * 0.8 / (100 k)) = 0.00125 (stratification only lowers it); allow
    # 4 standard errors plus the centre-point discretisation (< 3.5e-4).
    sigma = np.sqrt(0.2 * 0.8 / (100 * k))
    assert object_factor(p, F) == pytest.approx(exact, abs=4 * sigma + 4e-4)
    np.testing.assert_allclose(F.row_sums() + F.sky, 1.0, atol=1e-6)
    assert np.all(F.to_dense().diagonal() == 0)
    assert F.meta["method"] == "embree_stochastic" and F.meta["rays_per_patch"] == k


@needs_embree
@pytest.mark.parametrize("method", ["hemicube", "stochastic"])
def test_rows_sum_to_one_in_a_closed_box(method):
    p = build_patches(scenes.closed_box((1.0, 1.4, 0.8)), 0.25)
    if method == "hemicube":
        F = embree_hemicube_form_factors(p, 32)
    else:
        F = embree_stochastic_form_factors(p, 256, seed=1)
    np.testing.assert_allclose(F.row_sums(), 1.0, atol=1e-5)
    assert F.sky.max() < 1e-5


@needs_embree
def test_back_faces_block_but_count_for_nothing():
    # bottom square facing up; a second square above it facing up too (its back to the bottom)
    m = scenes.parallel_squares()
    m[1] = scenes.quad([(0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)], name="top_backwards")
    p = build_patches(m, 0.5)
    F = embree_hemicube_form_factors(p, 32)
    bottom = np.flatnonzero(p.owner == 0)
    assert F.to_dense()[bottom].sum() == 0
    # what the bottom patches see of the square is neither F nor sky
    expected_open = 1 - parallel_rectangles()
    assert F.sky[bottom] @ p.areas[bottom] / p.areas[bottom].sum() == pytest.approx(expected_open, abs=0.02)


@needs_embree
def test_receivers_subset_and_determinism():
    p = build_patches(scenes.cornell_box(), 0.5)
    full = embree_stochastic_form_factors(p, 64, seed=5)
    some = np.array([3, 17, 40])
    sub = embree_stochastic_form_factors(p, 64, seed=5, receivers=some)
    Df, Ds = full.to_dense(), sub.to_dense()
    np.testing.assert_array_equal(Ds[some], Df[some])
    others = np.setdiff1d(np.arange(len(p)), some)
    assert np.all(Ds[others] == 0) and np.all(sub.sky[others] == 0)
    np.testing.assert_array_equal(sub.sky[some], full.sky[some])
    H = embree_hemicube_form_factors(p, 16, receivers=some)
    Hf = embree_hemicube_form_factors(p, 16)
    np.testing.assert_array_equal(H.to_dense()[some], Hf.to_dense()[some])


@needs_embree
def test_progress_and_cancel(monkeypatch):
    p = build_patches(scenes.cornell_box(), 0.5)
    monkeypatch.setattr(embree_ff, "RAYS_PER_BATCH", 3 * 16 * 16 * 4)  # 4 receivers per batch
    seen = []
    embree_hemicube_form_factors(p, 16, progress=seen.append)
    assert seen[0] == 0.0 and seen[-1] == 1.0 and all(0 <= f <= 1 for f in seen)
    calls = []

    def cancel():
        calls.append(1)
        return len(calls) > 2

    monkeypatch.setattr(embree_ff, "RAYS_PER_BATCH", 16 * 4)
    with pytest.raises(Cancelled):
        embree_stochastic_form_factors(p, 16, cancelled=cancel)
    assert len(calls) == 3


def test_clear_error_without_embreex(monkeypatch):
    # a None entry in sys.modules makes `import embreex...` raise ImportError
    for mod in ("embreex", "embreex.rtcore_scene", "embreex.mesh_construction"):
        monkeypatch.setitem(sys.modules, mod, None)
    assert embree_available() is False
    p = build_patches(scenes.parallel_squares(), None)
    for fn in (embree_hemicube_form_factors, embree_stochastic_form_factors):
        with pytest.raises(EmbreeUnavailable, match="embreex is not installed; use method='hemicube'"):
            fn(p)
    assert issubclass(EmbreeUnavailable, RuntimeError)


def turned(meshes, angles=(0.3, -0.2, 0.7)):
    """The meshes turned by a generic rotation (no patch edge parallel to a world axis)."""
    a, b, c = angles
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
    rot = rz @ ry @ rx
    for m in meshes:
        m.verts = m.verts @ rot.T
    return meshes


@needs_embree
@pytest.mark.parametrize("turn,seed", [(False, 11), (True, None), (True, 5)],
                         ids=["axis-aligned,rotated-hemicubes", "turned,fixed-frames", "turned,rotated"])
def test_rasteriser_and_embree_agree_on_the_same_pixels(turn, seed):
    hemicube = pytest.importorskip("hemicube_radiosity.core.form_factors.hemicube",
                                   reason="core/form_factors/hemicube.py (the NumPy rasteriser) is not there yet")
    # a room with blocks: occlusion, neighbours sharing edges, patches at grazing angles.
    # Not axis-aligned geometry with unrotated hemi-cubes: there the top-face diagonal pixel
    # centres fall exactly on wall-patch edges and the two methods break those ties differently
    # (both right; up to 5e-3 per entry at R = 32).
    meshes = scenes.cornell_box()
    p = build_patches(turned(meshes) if turn else meshes, 0.5)
    R = hemicube.hemicube_form_factors(p, 32, rotate_seed=seed)
    E = embree_hemicube_form_factors(p, 32, rotate_seed=seed)
    diff = np.abs(R.to_dense() - E.to_dense())
    assert diff.max() < 1e-3, f"max |F_rast - F_embree| = {diff.max():.2e}"
    np.testing.assert_allclose(R.sky, E.sky, atol=1e-3)
    np.testing.assert_allclose(R.row_sums(), E.row_sums(), atol=1e-3)


@needs_embree
def test_auto_method_casts_rays_where_a_hemicube_would_draw_many_polygons(monkeypatch):
    """'auto' (the default) draws hemi-cubes where they are cheap and casts Embree's rays
    through the same pixels where a hemi-cube would draw many polygons (the forecast's own
    rates, :mod:`.forecast`); the F is the chosen method's, bit for bit, the result says which,
    and without Embree it is always the rasteriser."""
    from hemicube_radiosity.core.form_factors import stage
    from hemicube_radiosity.core.pipeline import bake
    from hemicube_radiosity.core.runtime.forecast import hemicube_seconds, ray_seconds
    from hemicube_radiosity.core.settings import BakeSettings

    from tests.support.shapes import sphere

    base = dict(patch_size=0.25, element_size=None, direct="hemicube")
    box = scenes.cornell_box()
    # a curved mesh of many small faces: no flat cluster to draw as an outline
    dense = scenes.cornell_box() + [sphere(80, 0.5, (1.0, 1.0, 0.6))]
    # where the choice falls: seen polygons at which a hemi-cube costs what its rays cost
    assert ray_seconds(64) > hemicube_seconds(1000) and ray_seconds(32) < hemicube_seconds(3000)
    picked = {}
    for name, meshes, res in (("box", box, 64), ("dense", dense, 32)):
        auto = bake(meshes, BakeSettings(resolution=res, **base))
        picked[name] = auto.settings.method
        same = bake(meshes, BakeSettings(resolution=res, method=picked[name], **base))
        assert auto.form_factors.nnz == same.form_factors.nnz
        np.testing.assert_array_equal(auto.form_factors.data, same.form_factors.data)
        np.testing.assert_array_equal(auto.solution.B, same.solution.B)
    assert picked == {"box": "hemicube", "dense": "embree"}
    monkeypatch.setattr(stage, "embree_available", lambda: False)
    assert bake(dense, BakeSettings(resolution=32, **base)).settings.method == "hemicube"
