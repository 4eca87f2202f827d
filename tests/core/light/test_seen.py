"""The choice of clusters whose receivers see their parts (``core/light/seen.py``) keeps its
answer when the light is made brighter, as a relight must (its result exactly the first times
the factor), also for a cluster that sits on the threshold: two equal triangles, one lit and one
dark, vary by a coefficient of variation of exactly 1 = :data:`seen.VARIES`, where the
floating-point rounding of the light's scale decided (truck town's relight x1.5 came out 1.7e-4
off the first bake's, zdm2's 1.3e-3)."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from hemicube_radiosity.core.light import seen
from hemicube_radiosity.core.mesh.clusters import make_clusters
from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.util.colour import LUMA


def _square(side=2.71):
    """Two equal triangles of a square whose area is no power of two (truck town's pair: 7.34 m^2
    each), so that the variance's sums round."""
    verts = side * np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    p = build_patches([MeshInput.from_faces(verts, [[0, 1, 2], [0, 2, 3]], rho=(0.7,) * 3, name="sq")], 10.0)
    assert len(p) == 2 and np.isclose(p.areas[0], p.areas[1])
    return p


def test_a_cluster_on_the_threshold_is_chosen_whatever_the_lights_scale():
    p = _square()
    c = make_clusters(p, np.zeros(len(p), np.int64))              # both triangles one unknown
    lit = p.centers[:, 0] > p.centers[:, 1]                       # the triangle under y = x
    answers = []
    for scale in np.linspace(0.05, 10.0, 200):
        def at(x, normals, where, samples=None, eps=None, scale=scale):
            return np.repeat(scale * (x[:, :1] > x[:, 1:2]), 3, axis=1).astype(float)
        ctx = SimpleNamespace(patches=p, clusters=c, direct=SimpleNamespace(at=at))
        y = (p.rho * at(seen.spread_points(p, np.arange(2)), p.normals, "")) @ LUMA
        assert np.array_equal(y > 0, lit)                          # one lit, one dark: CV exactly 1
        answers.append(bool(seen._varying(ctx, np.array([0]), np.arange(len(p)))[0]))
    assert answers == [True] * len(answers), answers
