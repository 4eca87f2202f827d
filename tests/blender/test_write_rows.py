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
