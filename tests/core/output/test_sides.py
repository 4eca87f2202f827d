"""Each side of a surface crossing the output mesh its own vertices (core/output/sides.py).

A house's base and a ground that slopes through it at 30 degrees, folded under the house (as a
terrain's faces are): the ground parts the base into a cavity above it, which sees only the
ground, and a part below it, which the world lights from beneath (Cycles' world lights every
direction). The contact cut parts the vertices along each of the ground's faces, but not where
two of them meet (a segment's end parts nothing); there the sides are told apart by a segment
between points a hair inside each element, lifted off the base. Lifted by the insets' whole
length, that segment passed under a surface crossing at less than 45 degrees, and the cavity's
corner there took the world's light from below and spread it over the cavity's ceiling.
"""
from __future__ import annotations

import numpy as np

from hemicube_radiosity.core import builtin_scenes as scenes
from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.pipeline import BakeSettings, bake
from tests.support.markers import needs_embree

LUMA = np.array([0.2126, 0.7152, 0.0722])


def _ground_z(x, y):
    return 0.58 * (x - 1.0) + np.where(y > 1.0, 0.4 * (y - 1.0), 0.0)


def _scene():
    xs, ys = np.array([-1.0, 3.0]), np.array([-1.0, 1.0, 3.0])
    verts = [(x, y, float(_ground_z(x, y))) for y in ys for x in xs]
    ground = MeshInput.from_faces(verts, [[0, 1, 3, 2], [2, 3, 5, 4]], (0.5,) * 3, name="ground")
    return [ground, scenes.box((0, 0, 0), (2, 2, 1.5), (0.6,) * 3, name="house")]


@needs_embree
def test_a_ground_crossing_a_base_at_a_grazing_angle_parts_its_vertices():
    r = bake(_scene(), BakeSettings(patch_size=0.5, element_size=0.25), world=np.ones(3))
    el = r.elements
    base = (el.owner == el.object_names.index("house")) & (el.normals[:, 2] < -0.99)
    c = el.centers
    cavity = base & (c[:, 2] > _ground_z(c[:, 0], c[:, 1]))
    below = base & ~cavity
    assert cavity.sum() > 20 and below.sum() > 20

    def verts(sel):
        v = np.unique(el.polys[sel])
        return v[v >= 0]
    vc, vb = verts(cavity), verts(below)
    assert len(np.intersect1d(vc, vb)) == 0          # before: 3, at the fold (1, 1, 0) and the line's ends
    B = r.vertex_radiosity @ LUMA
    # every cavity vertex, those on the line included, darker than any vertex below the ground,
    # which the world lights from beneath (0.56 and more; the cavity 0.32 at most, at its mouth)
    assert B[vc].max() < 0.6 * B[vb].min()
