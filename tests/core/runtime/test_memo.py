"""The in-process memos (``core/runtime/cache.py``): the bytes a :class:`Memo` holds are counted
as entries come and go (not summed again on every put) and stay within ``max_bytes``, the oldest
dropped first; a scene of hundreds of meshes keeps every mesh's entry (:data:`PER_MESH`);
:func:`inverse` is ``np.linalg.inv``, made once per matrix value; :func:`frozen` makes what a
memo keeps read-only, and no module hand-writes that loop again."""
from __future__ import annotations

import os
import re

import numpy as np
import pytest

from hemicube_radiosity.core.runtime.cache import PER_MESH, Memo, _nbytes_of, frozen, inverse

PKG = os.path.join(os.path.dirname(__file__), "..", "..", "..", "hemicube_radiosity")


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


def test_frozen_makes_every_array_read_only_and_passes_the_rest_through():
    a, b = np.arange(3.0), np.zeros((2, 2), np.int64)
    view = a[1:]
    out = frozen(a, None, b, (1, 2), view)
    assert out[0] is a and out[1] is None and out[2] is b and out[3] == (1, 2) and out[4] is view
    assert not a.flags.writeable and not b.flags.writeable and not view.flags.writeable
    with pytest.raises(ValueError):
        a[0] = 1.0
    np.testing.assert_array_equal(a, [0.0, 1.0, 2.0])        # values untouched
    c = np.ones(2)
    assert frozen(c) is c and not c.flags.writeable        # one array: itself, not a tuple
    assert frozen(None) is None and frozen() == ()


def test_no_module_freezes_by_hand():
    """Every memoised product is frozen through :func:`frozen` (one place to read and change)."""
    found = []
    for folder, _, files in os.walk(PKG):
        for f in files:
            path = os.path.join(folder, f)
            if f.endswith(".py") and not path.endswith(os.path.join("runtime", "cache.py")):
                text = open(path, encoding="utf-8").read()
                found += [f"{path}: {m.group(0)}" for m in re.finditer(r"flags\.writeable\s*=\s*False", text)]
    assert not found, found
