"""Both cores (issue 9): form factors, the emitters' transport, the final gather and the whole bake
are bit-identical with one worker and with two, and cancelling stops the workers.

Batches are made small here (module constants and chunk sizes) so that two workers really share
many batches of these small scenes. No timings are asserted: bench/bench_parallel.py measures.
"""
import threading

import numpy as np
import pytest

from hemicube_radiosity.core import embree_ff, hemicube, scenes
from hemicube_radiosity.core.clusters import group_pieces
from hemicube_radiosity.core.direct import emitter_transport, vertex_frames
from hemicube_radiosity.core.gather import gather_matrix
from hemicube_radiosity.core.hemicube import hemicube_form_factors
from hemicube_radiosity.core.parallel import cpu_count, ordered_map, resolve_workers
from hemicube_radiosity.core.patches import build_patches
from hemicube_radiosity.core.pipeline import bake
from hemicube_radiosity.core.progress import Cancelled, Ticker
from hemicube_radiosity.core.rays import embree_available, embree_scene
from hemicube_radiosity.core.settings import BakeSettings

needs_embree = pytest.mark.skipif(not embree_available(), reason="embreex is not installed")


def same_csr(a, b):
    return (np.array_equal(a.indptr, b.indptr) and np.array_equal(a.indices, b.indices)
            and np.array_equal(a.data, b.data) and np.array_equal(a.sky, b.sky))


@pytest.fixture(scope="module")
def box():
    return build_patches(scenes.cornell_box(), 0.25)


# ------------------------------------------------------------------ the driver

def test_workers_setting_resolves_to_the_cores():
    assert resolve_workers(0) == cpu_count() >= 1
    assert resolve_workers(1) == 1 and resolve_workers(3) == 3 and resolve_workers(None) == 1
    with pytest.raises(ValueError):
        resolve_workers(-1)
    assert BakeSettings().workers == 0
    BakeSettings(workers=2).validate()


def test_ordered_map_keeps_order_and_uses_threads():
    names = set()

    def f(i):
        names.add(threading.current_thread().name)
        return i * i

    assert list(ordered_map(f, range(50), 1)) == [i * i for i in range(50)]
    assert names == {threading.current_thread().name}          # serial: the caller's thread
    names.clear()
    assert list(ordered_map(f, range(50), 2)) == [i * i for i in range(50)]
    assert threading.current_thread().name not in names


def test_ordered_map_stops_its_threads_when_the_consumer_stops():
    before = threading.active_count()
    started = []

    def f(i):
        started.append(i)
        return i

    with pytest.raises(Cancelled):
        for i in ordered_map(f, range(1000), 2):
            if i == 3:
                raise Cancelled("cancelled")
    assert threading.active_count() == before
    assert len(started) < 20                                   # at most a few batches ahead


# ------------------------------------------------------------------ form factors

@pytest.mark.parametrize("rotate", [None, 5])
def test_hemicube_identical_with_two_workers(box, rotate):
    kw = dict(rotate_seed=rotate, batch=3)
    F1 = hemicube_form_factors(box, 16, workers=1, **kw)
    F2 = hemicube_form_factors(box, 16, workers=2, **kw)
    assert same_csr(F1, F2) and F1.nnz > 0


def test_hemicube_clusters_and_receivers_identical_with_two_workers():
    p = build_patches(scenes.tessellate(scenes.cornell_box(), 4), None)
    c = group_pieces(p, 0.5, 30.0)
    recv = np.arange(0, len(c), 2)
    F1 = hemicube_form_factors(p, 16, clusters=c, receivers=recv, batch=2, workers=1)
    F2 = hemicube_form_factors(p, 16, clusters=c, receivers=recv, batch=2, workers=2)
    assert same_csr(F1, F2)


@needs_embree
def test_embree_identical_with_two_workers(box, monkeypatch):
    monkeypatch.setattr(embree_ff, "RAYS_PER_BATCH", 3 * 16 * 16 * 4)    # 4 receivers a batch
    for fn, arg in ((embree_ff.embree_hemicube_form_factors, 16),
                    (embree_ff.embree_stochastic_form_factors, 64)):
        F1 = fn(box, arg, workers=1)
        F2 = fn(box, arg, workers=2)
        assert same_csr(F1, F2) and F1.nnz > 0


@pytest.mark.parametrize("method", ["hemicube", pytest.param("embree", marks=needs_embree)])
def test_cancel_mid_way_stops_with_two_workers(box, method, monkeypatch):
    monkeypatch.setattr(embree_ff, "RAYS_PER_BATCH", 3 * 16 * 16 * 2)
    polls = []
    seen = []

    def cancelled():
        polls.append(1)
        return len(polls) > 4

    before = threading.active_count()
    fn = (hemicube_form_factors if method == "hemicube" else embree_ff.embree_hemicube_form_factors)
    kw = dict(batch=2) if method == "hemicube" else {}
    with pytest.raises(Cancelled):
        fn(box, 16, progress=seen.append, cancelled=cancelled, workers=2, **kw)
    assert threading.active_count() == before
    assert seen and seen[-1] < 1.0                               # progress came, then it stopped


def test_progress_reaches_one_with_two_workers(box):
    seen = []
    hemicube_form_factors(box, 16, batch=2, workers=2, progress=seen.append)
    assert seen[0] == 0.0 and seen[-1] == 1.0 and seen == sorted(seen)


# ------------------------------------------------------------------ per-point light

@pytest.mark.parametrize("shadows", ["numpy", pytest.param("embree", marks=needs_embree)])
def test_emitter_transport_identical_with_two_workers(box, shadows):
    from hemicube_radiosity.core.rays import occluder
    scene = occluder(box, shadows)
    x, n, _ = vertex_frames(box)
    em = np.flatnonzero(box.emission.max(axis=1) > 0)
    kw = dict(scene=scene, samples=4, chunk_rays=len(em) * 4 * 7)    # 7 points a chunk
    T1 = emitter_transport(box, x, n, em, workers=1, **kw)
    T2 = emitter_transport(box, x, n, em, workers=2, **kw)
    assert np.array_equal(T1, T2) and T1.any()
    # penumbrae were refined (the extra rays' draws are ordered the same way)
    assert ((T1 > 0) & (T1 < emitter_transport(box, x, n, em, scene=None, samples=4))).any()


def test_emitter_transport_cancel_with_two_workers(box):
    x, n, _ = vertex_frames(box)
    em = np.flatnonzero(box.emission.max(axis=1) > 0)
    polls = []
    with pytest.raises(Cancelled):
        emitter_transport(box, x, n, em, samples=4, chunk_rays=len(em) * 4 * 7, workers=2,
                          ticker=Ticker(None, lambda: polls.append(1) or len(polls) > 2))


@needs_embree
def test_gather_identical_with_two_workers(box):
    x, n, _ = vertex_frames(box)
    G1, s1 = gather_matrix(box, x, n, embree_scene(box), rays=16, chunk_rays=16 * 9, workers=1)
    G2, s2 = gather_matrix(box, x, n, embree_scene(box), rays=16, chunk_rays=16 * 9, workers=2)
    assert np.array_equal(G1.indptr, G2.indptr) and np.array_equal(G1.indices, G2.indices)
    assert np.array_equal(G1.data, G2.data) and np.array_equal(s1, s2)


# ------------------------------------------------------------------ the whole bake

@pytest.mark.parametrize("method", ["hemicube", pytest.param("embree", marks=needs_embree)])
def test_bake_identical_with_two_workers(method, monkeypatch):
    monkeypatch.setattr(hemicube, "PATCHES_PER_BATCH", 1 << 10)       # a few receivers a batch
    monkeypatch.setattr(embree_ff, "RAYS_PER_BATCH", 1 << 13)
    s = dict(patch_size=0.5, element_size=0.25, resolution=16, method=method,
             gather_rays=16 if embree_available() else 0)
    r1 = bake(scenes.cornell_box(), BakeSettings(workers=1, **s))
    r2 = bake(scenes.cornell_box(), BakeSettings(workers=2, **s))
    assert same_csr(r1.form_factors, r2.form_factors)
    assert np.array_equal(r1.solution.B, r2.solution.B)
    assert np.array_equal(r1.vertex_radiosity, r2.vertex_radiosity)
