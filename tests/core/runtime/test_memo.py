"""The in-process memos (``core/runtime/cache.py``): the bytes a :class:`Memo` holds are counted
as entries come and go (not summed again on every put) and stay within ``max_bytes``, the oldest
dropped first; a scene of hundreds of meshes keeps every mesh's entry (:data:`PER_MESH`);
:func:`inverse` is ``np.linalg.inv``, made once per matrix value."""
from __future__ import annotations

import numpy as np

from hemicube_radiosity.core.runtime.cache import PER_MESH, Memo, _nbytes_of, inverse


def _held(m):
    return sum(_nbytes_of(objs) for objs, _ in m._store.values())


def test_bytes_held_are_counted_and_bounded():
    rng = np.random.default_rng(0)
    m = Memo(50, max_bytes=10_000)
    arrays = [np.zeros(int(n)) for n in rng.integers(1, 400, 300)]      # 8 .. 3,200 bytes each
    for i, a in enumerate(arrays):
        assert m.of((a,), lambda i=i: i) == i
        assert m._held == _held(m) <= 10_000
        if i % 7 == 0:                                     # again: a hit, nothing added
            assert m.of((a,), lambda: -1) == i and m._held == _held(m)
    kept = sorted(v for _, v in m._store.values())
    assert kept and kept == list(range(kept[0], len(arrays)))             # the newest, in a run
    m.clear()
    assert m._held == 0 and len(m) == 0


def test_refreshed_entries_keep_their_count():
    m = Memo(3, max_bytes=1_000, refresh=True)
    a, b, c, d = (np.zeros(40) for _ in range(4))          # 320 bytes each: three fit
    for x in (a, b, c):
        m.of((x,), lambda: 1)
    m.of((a,), lambda: 2)                                  # a hit: a is now the newest
    m.of((d,), lambda: 3)                                  # b, the least recently used, goes
    assert m._held == _held(m) == 960
    assert m.of((b,), lambda: "again") == "again"


def test_a_scene_of_hundreds_of_meshes_keeps_them_all():
    m = Memo(PER_MESH)
    arrays = [np.zeros(3) for _ in range(800)]             # the staircase hall: 775 objects
    for i, a in enumerate(arrays):
        m.of((a,), lambda i=i: i)
    assert [m.of((a,), lambda: None) for a in arrays] == list(range(800))


def test_inverse_is_numpys_once_per_matrix():
    M = np.array([[2.0, 0.3, 0.0], [0.1, -1.5, 0.2], [0.0, 0.4, 3.0]])
    inv = inverse(M)
    np.testing.assert_array_equal(inv, np.linalg.inv(M))
    assert not inv.flags.writeable
    assert inverse(M.copy()) is inv                        # by value
    N = M.copy()
    N[0, 0] = 2.5
    np.testing.assert_array_equal(inverse(N), np.linalg.inv(N))
