"""A shadow inside an output element that reaches none of its corners (core/output/abrupt.py,
:func:`shadowed_inside`).

A 2 m plate 0.3 m over a 12 m floor in an overhead sun: its shadow lies in the middle of the
floor's middle 4 m element, whose corners are all sunlit. The final gather from the plate's
underside reads the floor; interpolated from the corners, the floor under the plate read as
sunlit (as under the racetrack's bridges of the truck town, 3x Cycles' light). Truth: the same
scene with the floor modelled as 0.25 m faces.
"""
from __future__ import annotations

import numpy as np

from hemicube_radiosity.core import builtin_scenes as scenes
from hemicube_radiosity.core.light.lamps import SunLight
from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.output import indirect
from hemicube_radiosity.core.output.abrupt import AbruptGrid
from hemicube_radiosity.core.pipeline import BakeSettings, bake
from tests.support.analytic import point_under_rectangle_corner
from tests.support.markers import needs_embree


def _floor(cells):
    t = np.linspace(0, 12, cells + 1)
    verts = [(x, y, 0.0) for y in t for x in t]
    faces = [[j * (cells + 1) + i, j * (cells + 1) + i + 1, (j + 1) * (cells + 1) + i + 1, (j + 1) * (cells + 1) + i]
             for j in range(cells) for i in range(cells)]
    return MeshInput.from_faces(verts, faces, (0.5,) * 3, name="floor")


def _underside(cells):
    plate = scenes.quad([(5, 5, 0.3), (5, 7, 0.3), (7, 7, 0.3), (7, 5, 0.3)], (0.5,) * 3, name="plate")  # faces down
    r = bake([_floor(cells), plate], BakeSettings(patch_size=12.0, element_size=4.0),
             lights=[SunLight((0.0, 0.0, -1.0), strength=3.0)])
    el = r.elements
    down = (el.owner == el.object_names.index("plate")) & (el.normals[:, 2] < -0.9)
    v = np.unique(el.polys[down])
    return float(r.vertex_radiosity[v[v >= 0]].mean(axis=0)[0])


@needs_embree
def test_a_shadow_inside_an_element_darkens_what_sees_it(monkeypatch):
    truth = _underside(48)
    got = _underside(1)
    # measured at the plate's corners: 0.183 against 0.195
    assert abs(got / truth - 1) < 0.1
    monkeypatch.setattr(indirect, "shadowed_inside", lambda *a, **k: np.zeros(len(a[1]), bool))
    before = _underside(1)
    assert before / truth - 1 > 0.15           # 0.239: the floor under the plate read as sunlit


def _rectangle(x1, x2, y1, y2, c):
    """Form factor from a point facing a parallel rectangle [x1, x2] x [y1, y2] (relative to
    the point) a distance c away (closed form: corner rectangles added and subtracted)."""
    def corner(a, b):
        return np.sign(a) * np.sign(b) * point_under_rectangle_corner(np.abs(a), np.abs(b), c)
    return corner(x2, y2) - corner(x1, y2) - corner(x2, y1) + corner(x1, y1)


@needs_embree
def test_a_narrow_shadow_on_a_huge_grounds_long_elements_darkens_what_sees_it(monkeypatch):
    """A 6 m x 0.8 m bridge 0.3 m over a 200 m ground in an overhead sun. The ground is a huge
    object (:mod:`..mesh.sizes`): cut at ten times the detail size, 5 m elements, all four
    corners of the two under the bridge sunlit. Its shadow, found inside them
    (:func:`shadowed_inside`), is read by the gather on the elements' grid (:class:`AbruptGrid`),
    whose cells on a huge object are half the scene's detail size (:func:`grid_sides`): capped
    at 4 x 4 cells an element, 1.25 m, no grid point fell in the shadow and the bridge's underside read the
    ground under it as sunlit (the truck town's racetrack 0.88 m over its ground, 68 m x 11 m
    elements: 2.4x Cycles' light). Truth, closed form: the light arriving at the underside is
    the ground's sunlit radiance times the share of its hemisphere that does not see the
    shadow, the bridge's own footprint (the bridge reflects 5%: what it sends back is under 1%)."""
    E, rho, h, x0, x1, y0, y1 = 3.0, 0.5, 0.3, -3.0, 3.0, 1.5, 2.3
    ground = scenes.quad([(-100, -100, 0), (100, -100, 0), (100, 100, 0), (-100, 100, 0)], (rho,) * 3,
                         name="ground")
    plate = scenes.quad([(x0, y0, h), (x0, y1, h), (x1, y1, h), (x1, y0, h)], (0.05,) * 3, name="plate")

    def underside():
        r = bake([ground, plate], BakeSettings(patch_size=2.0, element_size=0.5),
                 lights=[SunLight((0.0, 0.0, -1.0), strength=E)])
        el = r.elements
        g = el.owner == el.object_names.index("ground")
        assert np.sqrt(el.areas[g].max()) > 4.0             # the ground's elements: 5 m
        down = (el.owner == el.object_names.index("plate")) & (el.normals[:, 2] < -0.9)
        v = np.unique(el.polys[down])
        v = v[v >= 0]
        x, y = el.verts[v, 0], el.verts[v, 1]
        inner = np.abs(x) < 2.5                             # away from the bridge's ends
        truth = rho * E / np.pi * (1 - _rectangle(x0 - x, x1 - x, y0 - y, y1 - y, h))
        return float(np.mean(r.vertex_indirect[v[inner], 0] / truth[inner] - 1))
    got = underside()
    assert abs(got) < 0.05                                  # measured: +2.8%
    monkeypatch.setattr(AbruptGrid, "MOST", 16)             # at most 4 x 4 cells an element, as before
    before = underside()
    assert before > 0.5                                     # measured: +190%
