"""Ray back-ends: the Embree scene cache and its clearing, Embree vs the NumPy BVH."""
import numpy as np
import pytest

from hemicube_radiosity.core import builtin_scenes as scenes
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.rays import (NumpyOccluder, clear_ray_cache, embree_available, embree_scene, occluder,
                                          patch_triangles)


def cornell():
    return build_patches(scenes.cornell_box(), 0.25)


def test_clear_ray_cache_empties_the_embree_scene_cache():
    a, b = cornell(), build_patches(scenes.parallel_squares(), None)
    clear_ray_cache()
    sa, sb = embree_scene(a), embree_scene(b)
    # cached: the same objects again, also for a PatchSet rebuilt with the same geometry
    assert embree_scene(a) is sa and embree_scene(cornell()) is sa and embree_scene(b) is sb
    # shadow rays test the planar regions' outlines (drawn.plane_outlines), a scene of their own
    assert occluder(a, "auto") is occluder(cornell(), "auto") is not sa
    clear_ray_cache()
    # every cached geometry is gone: both are built anew
    sa2, sb2 = embree_scene(a), embree_scene(b)
    assert sa2 is not sa and sb2 is not sb
    assert embree_scene(a) is sa2
    clear_ray_cache()
    clear_ray_cache()  # clearing an empty cache is fine
    assert embree_scene(a) is not sa2


def test_numpy_bvh_and_embree_agree_on_occlusion_in_the_cornell_box():
    p = cornell()
    clear_ray_cache()
    em, bvh = embree_scene(p), NumpyOccluder(p)
    tris, owner, scale = patch_triangles(p)
    assert em.scale == bvh.scale == scale and np.array_equal(em.tri_patch, owner)
    lo, hi = p.verts.min(axis=0), p.verts.max(axis=0)
    rng = np.random.default_rng(7)
    M = 600
    o = lo + rng.uniform(0.05, 0.95, (M, 3)) * (hi - lo)
    d = rng.normal(size=(M, 3))
    tf = rng.uniform(0.05, 1.0, M) * scale / np.linalg.norm(d, axis=1)
    # segments of random length: some blocked, some not
    e_seg, n_seg = em.occluded(o, d, tf), bvh.occluded(o, d, tf)
    np.testing.assert_array_equal(e_seg, n_seg)
    assert 0.15 * M < n_seg.sum() < 0.85 * M
    # unbounded rays
    np.testing.assert_array_equal(em.occluded(o, d), bvh.occluded(o, d))
    # Embree's nearest hit is where the BVH starts to see a blocker
    pid, t = em.intersect(o, d)
    hit = pid >= 0
    assert 0.5 * M < hit.sum() < M          # the box is open at the front
    t = np.asarray(t, np.float64)[hit]
    assert not bvh.occluded(o[hit], d[hit], t * (1 - 1e-4)).any()
    assert bvh.occluded(o[hit], d[hit], t * (1 + 1e-4)).all()


def test_shadow_rays_see_the_same_surfaces_as_planar_outlines():
    """A dense box's shadow rays test 32 triangles (each wall, block face and the lamp as its
    outline) instead of 14,112, and every ray is blocked exactly as by the triangles."""
    from hemicube_radiosity.core.form_factors.drawn import plane_outlines

    p = build_patches(scenes.tessellate(scenes.cornell_box(), 21), None)
    q = plane_outlines(p)
    assert len(p) == 14112 and len(q) == 32
    assert q.areas.sum() == pytest.approx(p.areas.sum(), rel=1e-12)
    rng = np.random.default_rng(5)
    lo, hi = p.verts.min(0), p.verts.max(0)
    o = rng.uniform(lo - 0.5, hi + 0.5, (20000, 3))
    e = rng.uniform(lo - 0.5, hi + 0.5, (20000, 3))
    want = NumpyOccluder(p).occluded(o, e - o, np.ones(len(o)))
    assert 0.2 < want.mean() < 0.9
    assert np.array_equal(NumpyOccluder(q).occluded(o, e - o, np.ones(len(o))), want)
    if embree_available():
        clear_ray_cache()
        assert np.array_equal(embree_scene(q).occluded(o, e - o, np.ones(len(o))),
                              embree_scene(p).occluded(o, e - o, np.ones(len(o))))
