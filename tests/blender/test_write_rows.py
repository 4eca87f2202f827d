# SPDX-License-Identifier: GPL-3.0-or-later
"""``write.rows_of``: the rows of some owners, from the rows grouped by owner once (the writer
asks for each of hundreds of objects), equal to scanning every element each time."""
from __future__ import annotations

import types

import numpy as np
import pytest

pytest.importorskip("bpy")

from hemicube_radiosity.blender import write  # noqa: E402

pytestmark = pytest.mark.blender


def test_rows_of_equals_a_scan():
    rng = np.random.default_rng(1)
    for _ in range(200):
        owner = rng.integers(0, rng.integers(1, 20), rng.integers(0, 300)).astype(np.int32)
        P = types.SimpleNamespace(owner=owner)
        for o in (0, 3, [1, 2], [5, 0], [7, 7], 19, 25):
            np.testing.assert_array_equal(write.rows_of(P, o), np.flatnonzero(np.isin(owner, np.atleast_1d(o))))


def test_element_layout_is_kept_per_geometry_and_follows_an_edit():
    """``write._element_layout`` is kept per elements' arrays (a relight writes the same layouts):
    the same arrays give the same (read-only) layout; moved vertices (new arrays, an edit) give
    the moved vertices in the object's local space (truth: the inverse matrix applied by hand)."""
    verts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0]], float)
    polys = np.array([[0, 1, 2, 3], [1, 4, 5, -1]], np.int64)
    owner = np.array([0, 1], np.int32)
    M = np.eye(4)
    M[:3, 3] = (1.0, 2.0, 3.0)
    P = types.SimpleNamespace(verts=verts, polys=polys, owner=owner)
    a = write._element_layout(P, 1, M, False)
    assert write._element_layout(P, 1, M, False) is a and not a[0].flags.writeable
    np.testing.assert_array_equal(a[0], verts[[1, 4, 5]] - (1.0, 2.0, 3.0))
    np.testing.assert_array_equal(a[1], [0, 1, 2])
    np.testing.assert_array_equal(a[4], [1])
    moved = types.SimpleNamespace(verts=verts + (0.0, 0.0, 0.5), polys=polys, owner=owner)
    b = write._element_layout(moved, 1, M, False)
    np.testing.assert_array_equal(b[0], verts[[1, 4, 5]] + (0.0, 0.0, 0.5) - (1.0, 2.0, 3.0))
    M2 = M.copy()
    M2[:3, 3] = 0.0                                  # a moved object: another layout
    np.testing.assert_array_equal(write._element_layout(P, 1, M2, False)[0], verts[[1, 4, 5]])
