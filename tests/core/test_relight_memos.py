"""What a relight asks again and only the geometry decides, kept in this process: each mesh's
bounding box (``core/mesh/sizes.py``, read by the automatic sizes and :func:`with_backs`), the
hemi-cube's forecast of polygons drawn (``core/form_factors/stage.py``), the points inside
elements where a shadow may hide (``core/output/abrupt.py``). A relight finds them (nothing
made again) and equals a fresh bake with every memo emptied, bit for bit; a moved plate
misses them (made again) and equals its own fresh bake.

The scene is that of ``tests/core/output/test_shadowed_inside.py``: a 2 m plate 0.3 m over a
12 m floor of 4 m elements, in an overhead sun (the plate's shadow inside the floor's middle
element: the inside points are asked for)."""
from __future__ import annotations

import numpy as np
import pytest

from hemicube_radiosity.core import builtin_scenes as scenes
from hemicube_radiosity.core.form_factors import stage
from hemicube_radiosity.core.light.lamps import SunLight
from hemicube_radiosity.core.mesh import sizes
from hemicube_radiosity.core.output import abrupt
from hemicube_radiosity.core.pipeline import BakeSettings, bake
from hemicube_radiosity.core.runtime import forecast
from hemicube_radiosity.core.runtime.cache import FormFactorCache
from tests.core.output.test_shadowed_inside import _floor
from tests.support.markers import needs_embree

SETTINGS = BakeSettings(patch_size=12.0, element_size=4.0)


def _plate(z):
    return scenes.quad([(5, 5, z), (5, 7, z), (7, 7, z), (7, 5, z)], (0.5,) * 3, name="plate")


def _sun(strength):
    return [SunLight((0.0, 0.0, -1.0), strength=strength)]


def _empty():
    for memo in (sizes._BOXES, stage._SEEN, abrupt._INSIDE):
        memo.clear()


def _counting(monkeypatch):
    calls = {"box": 0, "seen": 0, "inside": 0}

    def counted(name, f):
        def g(*a, **k):
            calls[name] += 1
            return f(*a, **k)
        return g
    monkeypatch.setattr(sizes, "np", _CountingMin(sizes.np, calls))
    monkeypatch.setattr(forecast, "polygons_seen", counted("seen", forecast.polygons_seen))
    monkeypatch.setattr(abrupt, "grid_sides", counted("inside", abrupt.grid_sides))
    return calls


class _CountingMin:
    """``numpy`` for :mod:`.sizes`, counting its calls of ``np.min`` (one per box made)."""

    def __init__(self, np_, calls):
        self._np, self._calls = np_, calls

    def __getattr__(self, name):
        return getattr(self._np, name)

    def min(self, *a, **k):
        self._calls["box"] += 1
        return self._np.min(*a, **k)


def _same(a, b):
    np.testing.assert_array_equal(a.corner_values(), b.corner_values())
    np.testing.assert_array_equal(a.solution.B, b.solution.B)


@needs_embree
def test_a_relight_finds_the_memos_and_an_edit_misses_them(monkeypatch):
    _empty()
    calls = _counting(monkeypatch)
    floor, cache = _floor(3), FormFactorCache()
    first = bake([floor, _plate(0.3)], SETTINGS, lights=_sun(3.0), cache=cache)
    made = dict(calls)
    assert made["box"] >= 2 and made["seen"] >= 1 and made["inside"] >= 1, made   # the scene asks
    plate = _plate(0.3)
    relit = bake([floor, plate], SETTINGS, lights=_sun(4.5), cache=cache)
    # the plate's new arrays have their boxes made; nothing else is made again
    assert calls == {**made, "box": made["box"] + 1}, calls
    assert np.abs(relit.corner_values() - 1.5 * first.corner_values()).max() \
        <= 1e-8 * np.abs(first.corner_values()).max()
    _empty()
    _same(relit, bake([floor, _plate(0.3)], SETTINGS, lights=_sun(4.5)))
    # a moved plate: its box, the forecast and the inside points made again
    _empty()
    bake([floor, plate], SETTINGS, lights=_sun(4.5), cache=cache)
    before = dict(calls)
    moved = bake([floor, _plate(0.5)], SETTINGS, lights=_sun(4.5), cache=cache)
    assert calls["box"] > before["box"] and calls["seen"] > before["seen"] \
        and calls["inside"] > before["inside"], (before, calls)
    _empty()
    fresh = bake([floor, _plate(0.5)], SETTINGS, lights=_sun(4.5))
    _same(moved, fresh)
    assert not np.array_equal(moved.corner_values(), relit.corner_values())


def test_a_mesh_s_box_follows_its_arrays():
    """Truth: ``np.min``/``np.max`` of the vertices; a new array (an edit) is measured anew."""
    _empty()
    a = _floor(2)
    lo, hi = sizes.mesh_boxes([a])
    np.testing.assert_array_equal(lo[0], a.verts.min(axis=0))
    moved = a.verts + np.array([1.0, -2.0, 0.5])
    b = type(a).from_faces(moved, [a.face_indices[s:e] for s, e in zip(a.face_offsets[:-1], a.face_offsets[1:])])
    lo2, hi2 = sizes.mesh_boxes([a, b])
    np.testing.assert_array_equal(lo2[1], moved.min(axis=0))
    np.testing.assert_array_equal(hi2[1], moved.max(axis=0))
    np.testing.assert_array_equal(hi2[0], a.verts.max(axis=0))
