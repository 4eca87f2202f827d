"""What shines (core/output/shine.py): at most a budget of groups, elements and an abrupt grid's
hot cells counted together, the brightest kept; the rest is left to the gather."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.output import shine


def _floor(cells, size=8.0):
    t = np.linspace(0, size, cells + 1)
    verts = [(x, y, 0.0) for y in t for x in t]
    faces = [[j * (cells + 1) + i, j * (cells + 1) + i + 1, (j + 1) * (cells + 1) + i + 1, (j + 1) * (cells + 1) + i]
             for j in range(cells) for i in range(cells)]
    return build_patches([MeshInput.from_faces(verts, faces, (0.5,) * 3, name="floor")])


class _Grid:
    """The two things :func:`.shine.hot_elements` reads of an abrupt grid: ``hot`` (its cells)
    and ``hot_parts``; one cell per element ``ids``, lit ``light``."""

    def __init__(self, elements, ids, light):
        self.elements, self.ids, self.light = elements, np.asarray(ids), np.asarray(light, float)
        self.hot = np.ones(len(ids), bool)

    def hot_parts(self, cells):
        el = self.ids[cells]
        return el, self.elements.areas[el], self.light[cells]


def _groups(ctx, elements, ids, scale=1.0):
    return len(np.unique(shine._shine_groups(ctx, elements, np.asarray(ids, np.int64), scale))) if len(ids) else 0


def test_elements_and_cells_share_one_budget_the_brightest_kept():
    """An 8 m floor of 1 m elements, patch-size (1 m) cells: the left half's elements are hot
    (each its own group), and a grid's hot cells on the right half, brighter the further right.
    With a budget of 10 the ten brightest groups shine, whichever kind: the cells of the two
    brightest columns (the elements' light is below theirs) and none of the elements; the rest
    is gathered (``hot`` and ``grid.hot`` cleared). Unbudgeted, every group shines."""
    el = _floor(8)
    ctx = SimpleNamespace(settings=SimpleNamespace(patch_size=1.0, element_size=1.0), cache=None)
    x = el.centers[:, 0]
    left, right = np.flatnonzero(x < 4), np.flatnonzero(x > 4)
    light_v = np.zeros((len(el.verts), 3))
    light_v[np.unique(el.polys[left])] = 1.0              # the left half's corners: 1
    smooth = np.zeros(len(el), bool)
    smooth[left] = True
    cell_light = 2.0 + el.centers[right, 0]               # 6.5 .. 9.5: brighter than the elements
    hot, _ = shine.hot_elements(ctx, el, light_v, 0.5, smooth, budget=10 ** 6, grid=_Grid(el, right, cell_light))
    assert hot[left].all() and not hot[right].any()

    grid = _Grid(el, right, cell_light)
    hot, radiance = shine.hot_elements(ctx, el, light_v, 0.5, smooth, budget=10, grid=grid)
    assert not hot.any() and len(radiance) == 0
    kept = right[grid.hot]
    assert _groups(ctx, el, kept, 0.5) <= 10
    assert np.all(el.centers[kept, 0] > 6)                # the brightest columns
    assert grid.hot.sum() >= 10

    grid = _Grid(el, right, 0.1 + 0 * cell_light)        # cells dimmer than the elements
    hot, radiance = shine.hot_elements(ctx, el, light_v, 0.05, smooth, budget=10, grid=grid)
    assert not grid.hot.any() and hot.sum() == 10 and len(radiance) == 10
