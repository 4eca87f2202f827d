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
from hemicube_radiosity.core.pipeline import BakeSettings, bake
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
