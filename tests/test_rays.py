"""Ray back-ends: the Embree scene cache and its clearing, Embree vs the NumPy BVH."""
import numpy as np

from hemicube_radiosity.core import scenes
from hemicube_radiosity.core.patches import build_patches
from hemicube_radiosity.core.rays import (NumpyOccluder, clear_ray_cache, embree_scene, occluder,
                                          patch_triangles)


def cornell():
    return build_patches(scenes.cornell_box(), 0.25)


def test_clear_ray_cache_empties_the_embree_scene_cache():
    a, b = cornell(), build_patches(scenes.parallel_squares(), None)
    clear_ray_cache()
    sa, sb = embree_scene(a), embree_scene(b)
    # cached: the same objects again, also for a PatchSet rebuilt with the same geometry
    assert embree_scene(a) is sa and embree_scene(cornell()) is sa and embree_scene(b) is sb
    assert occluder(a, "auto") is sa
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
