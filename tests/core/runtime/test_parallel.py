"""Both cores: form factors, the emitters' transport, the final gather and the whole bake
are bit-identical with one worker and with two, and cancelling stops the workers.

Form factors run on forked worker processes where :func:`forked.processes_available` (Linux),
on threads elsewhere; both paths are checked here (``forked.PROCESSES`` switched off for the
threads). Batches are made small (module constants and chunk sizes) so that two workers really
share many batches of these small scenes. No timings are asserted: bench/bench_parallel.py
measures.
"""
import multiprocessing
import os
import sys
import threading
import time

import numpy as np
import pytest

from hemicube_radiosity.core.form_factors import embree as embree_ff, hemicube
from hemicube_radiosity.core.runtime import background, forked, native, parallel
from hemicube_radiosity.core import builtin_scenes as scenes
from hemicube_radiosity.core.mesh.clusters import group_pieces
from hemicube_radiosity.core.light.emitters import emitter_transport, vertex_frames
from hemicube_radiosity.core.output.gather import gather_matrix
from hemicube_radiosity.core.form_factors.hemicube import hemicube_form_factors
from hemicube_radiosity.core.runtime.forked import processes_available
from hemicube_radiosity.core.runtime.native import one_blas_thread
from hemicube_radiosity.core.runtime.parallel import cpu_count, ordered_map, resolve_workers, shares
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.pipeline import bake
from hemicube_radiosity.core.runtime.progress import Cancelled, Ticker
from hemicube_radiosity.core.rays import embree_available, embree_scene
from tests.support import ROOT
from tests.support.markers import needs_embree
from hemicube_radiosity.core.settings import BakeSettings
needs_fork = pytest.mark.skipif(not processes_available(), reason="no 'fork' worker processes here")


@pytest.fixture(params=["processes", "threads"])
def pool_kind(request, monkeypatch):
    """Run a test with worker processes (where there are any) and with threads only."""
    if request.param == "processes" and not processes_available():
        pytest.skip("no 'fork' worker processes here")
    monkeypatch.setattr(forked, "PROCESSES", request.param == "processes")
    return request.param


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


def test_shares_run_the_first_in_the_caller_and_the_others_on_threads():
    me = threading.current_thread().name
    names = {}

    def f(i):
        names[i] = threading.current_thread().name
        return i * i

    before = threading.active_count()
    assert shares(f, 3) == [0, 1, 4]
    assert names[0] == me and me not in (names[1], names[2])
    assert threading.active_count() == before                  # nothing outlives the call
    names.clear()
    assert shares(f, 1) == [0] and names == {0: me}
    assert shares(f, 0) == []


@pytest.mark.parametrize("bad", [0, 1])
def test_shares_raise_once_every_started_share_stopped(bad):
    done = []

    def f(i):
        if i == bad:
            raise ValueError(f"share {i}")
        done.append(i)
        return i

    before = threading.active_count()
    with pytest.raises(ValueError, match=f"share {bad}"):
        shares(f, 2)
    assert threading.active_count() == before
    assert done == [1 - bad]                                   # the other share ran to its end


def test_a_bake_runs_on_one_blas_thread_and_puts_the_count_back(monkeypatch):
    """OpenBLAS's second thread spins for 0.1 s after each call it takes part in (a relight's
    luminance products): the stages run with one BLAS thread, overlapping bakes share the
    setting, and what was set before is back afterwards, also when a stage fails."""
    from hemicube_radiosity.core import pipeline
    if not native.openblas():
        pytest.skip("NumPy's BLAS here is not OpenBLAS")
    set_threads, get_threads = native.openblas()[0]
    before = get_threads()
    seen = []
    try:
        set_threads(2)
        with one_blas_thread():
            assert get_threads() == 1
            with one_blas_thread():                 # a second bake (the CLI's jobs)
                assert get_threads() == 1
            assert get_threads() == 1               # the first still runs
        assert get_threads() == 2
        monkeypatch.setattr(pipeline, "STAGES", pipeline.STAGES[:1] + (
            ("spy", lambda ctx: seen.append(get_threads())),))
        pipeline.bake(scenes.cornell_box(), BakeSettings())
        assert seen == [1] and get_threads() == 2

        def fails(ctx):
            raise RuntimeError("a stage failed")
        monkeypatch.setattr(pipeline, "STAGES", (("fails", fails),))
        with pytest.raises(RuntimeError):
            pipeline.bake(scenes.cornell_box(), BakeSettings())
        assert get_threads() == 2
    finally:
        set_threads(before)


@needs_fork
def test_a_worker_forked_by_a_bake_starts_no_blas_thread():
    """OpenBLAS stops its threads at a fork and starts them again in the child whenever its thread
    count is set there, even to the one it has; a new one spins for 0.1 s. A worker forked inside
    a bake (one BLAS thread already) leaves the count alone: it runs on its one thread."""
    if not native.openblas():
        pytest.skip("NumPy's BLAS here is not OpenBLAS")
    with one_blas_thread():
        got = list(ordered_map(lambda i: (len(os.listdir("/proc/self/task")), native.openblas()[0][1]()),
                               range(4), 2, processes=True))
    assert got == [(1, 1)] * 4


def test_processes_on_linux_only_where_fork_is():
    if sys.platform.startswith("linux"):
        assert processes_available()                # the form-factor tests below fork here
    else:                                           # macOS, Windows: threads (no fork of Blender)
        assert not processes_available()


@needs_fork
def test_ordered_map_processes_keep_order_and_inherit_fn():
    big = np.arange(200_000, dtype=np.int64)            # held by the closure, never pickled

    def f(i):
        return os.getpid(), int(big[i * 1000]), forked.in_worker()

    out = list(ordered_map(f, range(60), 2, processes=True))
    assert [v for _, v, _ in out] == [i * 1000 for i in range(60)]
    pids = {p for p, _, _ in out}
    assert os.getpid() not in pids and 1 <= len(pids) <= 2
    assert all(w for _, _, w in out)                    # nested maps there run serially
    assert multiprocessing.active_children() == []     # the workers were joined
    # one worker: no process, the caller's own loop
    assert {p for p, _, _ in ordered_map(f, range(5), 1, processes=True)} == {os.getpid()}


@needs_fork
def test_started_map_forks_before_it_returns_and_collects_on_another_thread():
    """:func:`.parallel.started_map`: the workers exist when the call returns (forked on the
    calling thread), the results come in order to whichever thread reads them, and closing
    early terminates the workers."""
    def f(i):
        return os.getpid(), i * i

    results = parallel.started_map(f, range(40), 2, processes=True)
    assert len(multiprocessing.active_children()) == 2           # forked already, nothing read yet
    got = []
    t = threading.Thread(target=lambda: got.extend(results))
    t.start()
    t.join()
    assert [v for _, v in got] == [i * i for i in range(40)] and os.getpid() not in {p for p, _ in got}
    assert multiprocessing.active_children() == []
    results = parallel.started_map(f, range(40), 2, processes=True)
    next(results)
    results.close()
    assert multiprocessing.active_children() == []
    # threads, or one worker: an ordinary ordered_map
    assert [v for _, v in parallel.started_map(f, range(5), 1, processes=True)] == [0, 1, 4, 9, 16]


@needs_fork
def test_ordered_map_processes_raise_the_error_at_its_turn():
    seen = []

    def f(i):
        if i == 7:
            raise ValueError(f"bad item {i}")
        return i

    with pytest.raises(ValueError, match="bad item 7"):
        for i in ordered_map(f, range(40), 2, processes=True):
            seen.append(i)
    assert seen == list(range(7))
    assert multiprocessing.active_children() == []


@needs_fork
def test_ordered_map_processes_are_terminated_when_the_consumer_stops():
    """A cancelled map does not wait for the batches that are running: here they would sleep for
    ten minutes, so the test returns only because the workers were terminated."""
    import time

    def f(i):
        if i >= 3:
            time.sleep(600)
        return os.getpid()

    pids = set()
    with pytest.raises(Cancelled):
        for k, pid in enumerate(ordered_map(f, range(1000), 2, processes=True)):
            pids.add(pid)
            if k == 2:
                raise Cancelled("cancelled")
    assert pids and multiprocessing.active_children() == []
    for pid in pids:                                    # gone, and reaped
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)


@pytest.mark.blender
@needs_fork
def test_form_factor_workers_start_nothing_inside_blender(box, monkeypatch):
    """Inside Blender ``sys.executable`` is the Blender binary and the modal operator bakes in a
    thread: the workers are forks of the caller (nothing is executed, not even a resource
    tracker), so a bake from a worker thread with an executable that does not exist still works."""
    import bpy  # noqa: F401  (the add-on's process has it loaded; the workers never touch it)
    monkeypatch.setattr(sys, "executable", "/nonexistent/blender")
    F1 = hemicube_form_factors(box, 16, batch=3, workers=1)
    out = {}

    def bake_in_thread():
        out["F"] = hemicube_form_factors(box, 16, batch=3, workers=2)

    t = threading.Thread(target=bake_in_thread)
    t.start()
    t.join()
    assert same_csr(F1, out["F"])
    assert multiprocessing.active_children() == []


_ORPHAN_SCRIPT = """
import os, sys, time
sys.path.insert(0, sys.argv[1])
from hemicube_radiosity.core.runtime.parallel import ordered_map

def f(i):
    os.write(1, f"{os.getpid()}\\n".encode())   # one write: two workers' lines never interleave
    time.sleep(600)

list(ordered_map(f, range(4), 2, processes=True))
"""


@needs_fork
def test_workers_die_with_a_killed_baking_process(tmp_path):
    """A Blender killed outright (a crash, a batch timeout) leaves no worker behind: they would
    otherwise wait for batches forever, holding its memory."""
    import signal
    import subprocess
    import time

    script = tmp_path / "orphan.py"
    script.write_text(_ORPHAN_SCRIPT)
    p = subprocess.Popen([sys.executable, str(script), ROOT], stdout=subprocess.PIPE, text=True)
    try:
        pids = [int(p.stdout.readline()) for _ in range(2)]      # both workers are drawing
    finally:
        p.send_signal(signal.SIGKILL)
        p.wait()

    def alive(pid):
        try:
            with open(f"/proc/{pid}/status") as fh:
                return "\nState:\tZ" not in fh.read()             # a zombie has ended
        except FileNotFoundError:
            return False

    deadline = time.monotonic() + 30                             # a bound on waiting, not a speed
    while any(alive(q) for q in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(alive(q) for q in pids)


def test_ordered_map_processes_fall_back_to_threads(monkeypatch):
    monkeypatch.setattr(forked, "PROCESSES", False)
    assert not processes_available()
    names = set()

    def f(i):
        names.add((os.getpid(), threading.current_thread().name))
        return -i

    assert list(ordered_map(f, range(30), 2, processes=True)) == [-i for i in range(30)]
    assert {p for p, _ in names} == {os.getpid()}
    assert threading.current_thread().name not in {n for _, n in names}


# ------------------------------------------------------------------ form factors

@pytest.mark.parametrize("rotate", [None, 5])
def test_hemicube_identical_with_two_workers(box, rotate, pool_kind):
    kw = dict(rotate_seed=rotate, batch=3)
    F1 = hemicube_form_factors(box, 16, workers=1, **kw)
    F2 = hemicube_form_factors(box, 16, workers=2, **kw)
    assert same_csr(F1, F2) and F1.nnz > 0


def test_hemicube_clusters_and_receivers_identical_with_two_workers(pool_kind):
    p = build_patches(scenes.tessellate(scenes.cornell_box(), 4), None)
    c = group_pieces(p, 0.5, 30.0)
    recv = np.arange(0, len(c), 2)
    F1 = hemicube_form_factors(p, 16, clusters=c, receivers=recv, batch=2, workers=1)
    F2 = hemicube_form_factors(p, 16, clusters=c, receivers=recv, batch=2, workers=2)
    assert same_csr(F1, F2)


@needs_embree
def test_embree_identical_with_two_workers(box, monkeypatch, pool_kind):
    monkeypatch.setattr(embree_ff, "RAYS_PER_BATCH", 3 * 16 * 16 * 4)    # 4 receivers a batch
    for fn, arg in ((embree_ff.embree_hemicube_form_factors, 16),
                    (embree_ff.embree_stochastic_form_factors, 64)):
        F1 = fn(box, arg, workers=1)
        F2 = fn(box, arg, workers=2)
        assert same_csr(F1, F2) and F1.nnz > 0


@pytest.mark.parametrize("method", ["hemicube", pytest.param("embree", marks=needs_embree)])
def test_cancel_mid_way_stops_with_two_workers(box, method, monkeypatch, pool_kind):
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
    assert multiprocessing.active_children() == []             # no worker outlives the cancel
    assert seen and seen[-1] < 1.0                               # progress came, then it stopped


def test_progress_reaches_one_with_two_workers(box, pool_kind):
    seen = []
    hemicube_form_factors(box, 16, batch=2, workers=2, progress=seen.append)
    assert seen[0] == 0.0 and seen[-1] == 1.0 and seen == sorted(seen)


# ------------------------------------------------------------------ per-point light

@pytest.mark.parametrize("shadows", ["numpy", pytest.param("embree", marks=needs_embree)])
def test_emitter_transport_identical_with_two_workers(box, shadows, pool_kind, monkeypatch):
    from hemicube_radiosity.core.light import emitters as direct
    from hemicube_radiosity.core.rays import occluder
    monkeypatch.setattr(direct, "PROCESS_RAYS", 0)                     # fork even for this small box
    scene = occluder(box, shadows)
    x, n, _ = vertex_frames(box)
    em = np.flatnonzero(box.emission.max(axis=1) > 0)
    kw = dict(scene=scene, samples=4, chunk_rays=len(em) * 4 * 7)    # 7 points a chunk
    T1 = emitter_transport(box, x, n, em, workers=1, **kw)
    T2 = emitter_transport(box, x, n, em, workers=2, **kw)
    assert np.array_equal(T1, T2) and T1.any()
    # penumbrae were refined (their extra rays aim at targets shared by every chunk) ...
    assert ((T1 > 0) & (T1 < emitter_transport(box, x, n, em, scene=None, samples=4))).any()
    # ... so the chunks' size does not matter: T is the same cut into 7 points or 40
    T3 = emitter_transport(box, x, n, em, workers=1, **{**kw, "chunk_rays": len(em) * 4 * 40})
    assert np.array_equal(T1, T3)


@needs_embree
def test_grouped_transport_is_the_same_for_any_chunk_size(box):
    """Grouped emitters with shadows (what shines, :func:`.output.shine.shine`, with its larger
    chunks): the contours run only for the pairs some first ray reaches, per chunk, and the
    penumbrae are refined; T is the same cut into 7 points a chunk or 40 or all at once."""
    from hemicube_radiosity.core.rays import occluder
    x, n, _ = vertex_frames(box)
    em = np.flatnonzero(box.emission.max(axis=1) > 0)
    groups = np.arange(em.size) // 2
    kw = dict(scene=occluder(box, "embree"), samples=4, groups=groups)
    runs = [emitter_transport(box, x, n, em, chunk_rays=(groups.max() + 1) * 4 * c, **kw) for c in (7, 40, 10 ** 6)]
    assert runs[0].any() and ((runs[0] > 0) & (runs[0] < emitter_transport(box, x, n, em, samples=4, groups=groups))).any()
    assert all(np.array_equal(runs[0], r) for r in runs[1:])


@needs_fork
def test_grouped_emitters_shine_on_threads_and_patches_on_forks(box, monkeypatch):
    """A transport of grouped emitters (mostly rays: embreex lets go of the GIL) runs on threads,
    one of emitter patches shining one by one (NumPy form factors) on forked processes; both
    equal one worker's."""
    from hemicube_radiosity.core.light import emitters as direct
    monkeypatch.setattr(direct, "PROCESS_RAYS", 0)                     # large enough for both
    forked = []
    real = parallel._process_map
    monkeypatch.setattr(parallel, "_process_map", lambda *a, **k: forked.append(1) or real(*a, **k))
    x, n, _ = vertex_frames(box)
    em = np.flatnonzero(box.emission.max(axis=1) > 0)
    assert em.size > 1
    for groups, forks in ((np.zeros(em.size, np.int64), False), (None, True)):
        forked.clear()
        kw = dict(scene=None, samples=4, chunk_rays=em.size * 4 * 7, groups=groups)
        T2 = emitter_transport(box, x, n, em, workers=2, **kw)
        assert bool(forked) == forks
        assert np.array_equal(T2, emitter_transport(box, x, n, em, workers=1, **kw)) and T2.any()


def test_emitter_transport_cancel_with_two_workers(box, pool_kind, monkeypatch):
    from hemicube_radiosity.core.light import emitters as direct
    monkeypatch.setattr(direct, "PROCESS_RAYS", 0)
    x, n, _ = vertex_frames(box)
    em = np.flatnonzero(box.emission.max(axis=1) > 0)
    polls = []
    with pytest.raises(Cancelled):
        emitter_transport(box, x, n, em, samples=4, chunk_rays=len(em) * 4 * 7, workers=2,
                          ticker=Ticker(None, lambda: polls.append(1) or len(polls) > 2))
    assert multiprocessing.active_children() == []             # no worker outlives the cancel


@needs_embree
def test_gather_identical_with_two_workers(box, pool_kind, monkeypatch):
    from hemicube_radiosity.core.output import gather
    monkeypatch.setattr(gather, "PROCESS_RAYS", 0)                     # fork even for this small box
    x, n, _ = vertex_frames(box)
    G1, s1, H1 = gather_matrix(box, x, n, embree_scene(box), rays=16, chunk_rays=16 * 9, workers=1, hits=True)
    G2, s2, H2 = gather_matrix(box, x, n, embree_scene(box), rays=16, chunk_rays=16 * 9, workers=2, hits=True)
    assert np.array_equal(G1.indptr, G2.indptr) and np.array_equal(G1.indices, G2.indices)
    assert np.array_equal(G1.data, G2.data) and np.array_equal(s1, s2) and np.array_equal(H1, H2)
    # the chunking (smaller with two workers) does not change G: rows never span chunks
    G3, s3 = gather_matrix(box, x, n, embree_scene(box), rays=16, workers=1)
    assert np.array_equal(G3.indptr, G1.indptr) and np.array_equal(G3.data, G1.data)
    assert np.array_equal(G3.indices, G1.indices) and np.array_equal(s3, s1)
    # started in the background (collected on a thread while the caller goes on): the same
    before = threading.active_count()
    pending = gather_matrix(box, x, n, embree_scene(box), rays=16, chunk_rays=16 * 9, workers=2, hits=True,
                            background=True)
    assert isinstance(pending, background.Background)
    G4, s4, H4 = pending.result()
    assert np.array_equal(G4.indptr, G1.indptr) and np.array_equal(G4.indices, G1.indices)
    assert np.array_equal(G4.data, G1.data) and np.array_equal(s4, s1) and np.array_equal(H4, H1)
    assert threading.active_count() == before and multiprocessing.active_children() == []


@needs_fork
def test_forked_workers_write_into_a_shared_array():
    """:func:`.forked.shared_array`: what forked workers write in place is what the caller
    reads; each writes its own rows, and only counts travel back through the pipe."""
    out = forked.shared_array((6, 3), np.float64)
    assert out.shape == (6, 3) and not out.any()

    def fill(i):
        out[2 * i:2 * i + 2] = np.arange(6).reshape(2, 3) + 10 * i
        return os.getpid()
    pids = list(ordered_map(fill, range(3), 2, processes=True))
    assert os.getpid() not in pids                                  # written by the workers
    assert np.array_equal(out, np.vstack([np.arange(6).reshape(2, 3) + 10 * i for i in range(3)]))
    assert forked.shared_array(0, np.int32).shape == (0,)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="MADV_REMOVE is Linux's")
def test_release_tail_hands_back_the_pages_past_what_is_kept():
    """:func:`.forked.release_tail`: the items kept, and the rest of their page, are untouched;
    the pages after are handed back (shared memory reads zeros where its pages are gone), so a
    compacted gather keeps only the memory its rows use."""
    import mmap
    page = mmap.PAGESIZE // 8
    a = forked.shared_array(10 * page, np.float64)
    a[:] = 1.0
    keep = 3 * page + 5
    forked.release_tail(a, keep)
    assert (a[:4 * page] == 1.0).all()               # the kept items and the rest of their page
    assert not a[4 * page:].any()                    # the pages after: gone (zeros)
    forked.release_tail(a, 10 * page)              # nothing past the end: nothing happens
    assert (a[:4 * page] == 1.0).all()


def test_background_returns_raises_and_stops():
    """:class:`.background.Background`: the value made on its thread, the error raised on the
    caller's, and a stop asked for (cancelled while waiting) reaches the thread's loop."""
    assert background.Background(lambda stop: 42).result() == 42
    assert background.Background.ready("made").result() == "made"

    def fails(stop):
        raise ValueError("in the thread")
    with pytest.raises(ValueError, match="in the thread"):
        background.Background(fails).result()
    steps = []

    def loop(stop):
        while not stop.is_set():
            steps.append(1)
            time.sleep(0.01)
        return "stopped"
    before = threading.active_count()
    b = background.Background(loop)
    polls = []
    with pytest.raises(Cancelled):
        b.result(cancelled=lambda: polls.append(1) or len(polls) > 2, poll=0.01)
    assert steps and threading.active_count() == before        # the thread saw the stop and ended


@needs_fork
def test_ahead_makes_its_value_on_a_forked_process_and_is_terminated_when_stopped():
    """:class:`.background.Ahead`: forked when made (on the calling thread), the value made in the
    other process, its error raised on the caller's thread; closed early, or cancelled while
    the caller waits, the process is terminated at once (here it would sleep ten minutes)."""
    a = background.Ahead.start(lambda: (os.getpid(), np.arange(5) ** 2))
    assert len(multiprocessing.active_children()) == 1          # forked already
    pid, value = a.result()
    assert pid != os.getpid() and value.tolist() == [0, 1, 4, 9, 16]
    assert multiprocessing.active_children() == []
    a.close()                                                   # again: nothing

    def fails():
        raise ValueError("in the process")
    with pytest.raises(ValueError, match="in the process"):
        background.Ahead.start(fails).result()
    slow = background.Ahead.start(lambda: time.sleep(600))
    t = time.perf_counter()
    slow.close()
    assert multiprocessing.active_children() == [] and time.perf_counter() - t < 60
    slow = background.Ahead.start(lambda: time.sleep(600))
    polls = []
    with pytest.raises(Cancelled):
        slow.result(cancelled=lambda: polls.append(1) or len(polls) > 2, poll=0.01)
    assert multiprocessing.active_children() == []


@needs_fork
def test_a_worker_killed_half_way_through_its_result_does_not_hang_the_stop():
    """A worker terminated while it writes its result leaves half a message in the pool's
    results pipe; the pool's reading thread waited for the rest for ever, and so did the stop
    that terminated it (the background gather's cancel test hung so). Here the worker writes
    a header for 1,000 bytes and only 10, then sleeps: stopping it must return."""
    import struct
    holder = {}

    class Spy(background.Ahead):
        def __init__(self, fn):
            holder["self"] = self
            super().__init__(fn)

    def half_a_result():
        writer = holder["self"]._pool._result_queue._writer
        writer._send(struct.pack("!i", 1000))
        writer._send(b"x" * 10)
        time.sleep(600)
    before = threading.active_count()
    a = Spy(half_a_result)
    time.sleep(1.0)                                   # the pool's thread now waits for 990 bytes
    stopper = threading.Thread(target=a.close, daemon=True)
    stopper.start()
    stopper.join(60)
    assert not stopper.is_alive(), "the stop hung"
    assert multiprocessing.active_children() == [] and threading.active_count() == before


def test_ahead_is_not_started_where_processes_are_not(monkeypatch):
    monkeypatch.setattr(forked, "PROCESSES", False)
    assert background.Ahead.start(lambda: 1) is None


@needs_embree
def test_the_element_cut_made_ahead_is_the_one_made_in_place(monkeypatch, pool_kind):
    """On two workers the output elements' cut along contacts starts on a process of its own
    when the bake starts (:func:`.elements.start_elements`) and the vertex stage takes it: the
    bake's own process cuts nothing, and the bake is the one-worker bake, bit for bit. On one
    worker, or with threads only, it is cut in place, as before. A bake stopped early leaves no
    process behind."""
    from hemicube_radiosity.core.mesh import elements as output
    calls = []
    real = output.cut_along_contacts
    monkeypatch.setattr(output, "cut_along_contacts", lambda *a, **k: calls.append(os.getpid()) or real(*a, **k))
    s = dict(patch_size=0.5, element_size=0.2, resolution=16, gather_rays=16)
    r1 = bake(scenes.cornell_box(), BakeSettings(workers=1, **s))
    assert calls == [os.getpid()]
    calls.clear()
    r2 = bake(scenes.cornell_box(), BakeSettings(workers=2, **s))
    assert calls == ([] if pool_kind == "processes" else [os.getpid()])
    assert multiprocessing.active_children() == []
    for a in ("verts", "polys"):
        assert np.array_equal(getattr(r1.elements, a), getattr(r2.elements, a))
    assert np.array_equal(r1.vertex_radiosity, r2.vertex_radiosity)
    # a relight (the same geometry, the lamp brighter) finds the elements in the cache: no fork
    from hemicube_radiosity.core.runtime.cache import FormFactorCache
    # (the box as modelled: its elements are cut; tessellated finer than the detail size: its
    # faces are the elements, and nothing is cut)
    started = []
    start = background.Ahead.start
    monkeypatch.setattr(background.Ahead, "start", classmethod(lambda cls, fn: started.append(1) or start(fn)))
    for meshes in (scenes.cornell_box(), scenes.tessellate(scenes.cornell_box(), 8)):
        cache = FormFactorCache()
        started.clear()
        bake(meshes, BakeSettings(workers=2, **s), cache=cache)
        assert started == [1]                 # (None where nothing is forked: threads only)
        started.clear()
        brighter = [scenes.MeshInput(m.verts, m.face_offsets, m.face_indices, m.face_rho,
                                     1.3 * np.asarray(m.face_emission), m.name) for m in meshes]
        again = bake(brighter, BakeSettings(workers=2, **s), cache=cache)
        assert again.form_factor_source == "cached" and started == []
    if pool_kind == "processes":              # cancelled while the cut runs on its process
        with pytest.raises(Cancelled):
            bake(scenes.cornell_box(), BakeSettings(workers=2, **s),
                 cancelled=lambda: len(multiprocessing.active_children()) > 0)
        assert multiprocessing.active_children() == []


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's heap settings")
def test_a_bake_keeps_its_freed_heap_and_hands_it_back_after(tmp_path):
    """:func:`.native.kept_heap` (around every bake): temporaries of 20 MB made and dropped
    again and again fault their pages in once, not every time; after the block the next free
    hands the heap kept back to the system. In a fresh process, whose glibc has moved its own
    threshold to 30 MB (as a NumPy program does), ten rounds of ten such arrays."""
    import subprocess
    script = tmp_path / "heap.py"
    script.write_text("""
import resource, sys, numpy as np
from hemicube_radiosity.core.runtime.native import kept_heap
def rss():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 >> 20
def rounds():
    f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(10):
        a = [np.ones(20 << 17) for _ in range(10)]
        del a
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0
b = np.ones(30 << 17)
del b
out = rounds()
with kept_heap():
    inside = rounds()
    held = rss()
c = np.ones(1 << 17)
del c
print(out, inside, held, rss())
""")
    got = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONPATH": ROOT}).stdout.split()
    out, inside, held, after = map(int, got)
    assert out > 20000 and inside < out / 4          # 200 MB a round faulted in once, not ten times
    assert held > 150 and after < held - 100         # kept while the bake runs, handed back after it


# ------------------------------------------------------------------ the whole bake

@pytest.mark.parametrize("method", ["hemicube", pytest.param("embree", marks=needs_embree)])
def test_bake_identical_with_two_workers(method, monkeypatch, pool_kind):
    monkeypatch.setattr(hemicube, "PATCHES_PER_BATCH", 1 << 10)       # a few receivers a batch
    monkeypatch.setattr(embree_ff, "RAYS_PER_BATCH", 1 << 13)
    s = dict(patch_size=0.5, element_size=0.25, resolution=16, method=method,
             gather_rays=16 if embree_available() else 0)
    from hemicube_radiosity.core.output import gather, stage as output
    monkeypatch.setattr(gather, "PROCESS_RAYS", 0)           # the gather forked, in the background
    started = []
    start = output.start_gather
    monkeypatch.setattr(output, "start_gather", lambda *a: started.append(start(*a)) or started[-1])
    r1 = bake(scenes.cornell_box(), BakeSettings(workers=1, **s))
    assert started == [] or started == [None]
    before = threading.active_count()
    r2 = bake(scenes.cornell_box(), BakeSettings(workers=2, **s))
    if embree_available():
        assert isinstance(started[-1], background.Background)
    assert threading.active_count() == before and multiprocessing.active_children() == []
    assert same_csr(r1.form_factors, r2.form_factors)
    assert np.array_equal(r1.solution.B, r2.solution.B)
    assert np.array_equal(r1.vertex_radiosity, r2.vertex_radiosity)


@needs_embree
def test_cancel_while_the_gather_runs_in_the_background(monkeypatch, pool_kind):
    """Cancelled after the vertex stage started its gather in the background: the bake stops,
    and neither the collecting thread nor a worker outlives it."""
    from hemicube_radiosity.core.output import gather, stage as output
    monkeypatch.setattr(gather, "PROCESS_RAYS", 0)
    started = []
    start = output.start_gather
    monkeypatch.setattr(output, "start_gather", lambda *a: started.append(start(*a)) or started[-1])
    before = threading.active_count()
    with pytest.raises(Cancelled):
        bake(scenes.cornell_box(), BakeSettings(workers=2, patch_size=0.5, element_size=0.25, resolution=16,
                                                gather_rays=16), cancelled=lambda: bool(started))
    assert isinstance(started[-1], background.Background)
    assert threading.active_count() == before and multiprocessing.active_children() == []


@needs_embree
def test_open_fraction_identical_with_two_workers(box):
    """:func:`.hemisphere.open_fraction` cast by two threads in chunks: the same fractions as one
    thread in one chunk (each point's rays do not depend on the chunk it is in)."""
    from hemicube_radiosity.core.hemisphere import open_fraction
    x, n, _ = vertex_frames(box)
    x = np.concatenate([x] * 40)                     # past one chunk of 4,096 points a worker
    n = np.concatenate([n] * 40)
    one = open_fraction(box, x, n, embree_scene(box), 0.05)
    two = open_fraction(box, x, n, embree_scene(box), 0.05, workers=2)
    assert len(x) > 2 * 4096 and np.array_equal(one, two)
    assert 0 < one.mean() < 1 and (one == 1).any()
