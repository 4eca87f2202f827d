"""bench/real_scenes.py reads our result at Cycles' corners: a corner is read on its own face's
element even where another face lies on top of it (a face folded over its neighbour, a face
modelled on a wall), where the nearest element belongs to the other face."""
import os
import sys

import numpy as np

from hemicube_radiosity.core.mesh.patches import PatchSet
from tests.support import ROOT

sys.path.insert(0, os.path.join(ROOT, "bench"))
sys.path.insert(0, os.path.join(ROOT, "tools"))
import real_scenes  # noqa: E402


def two_faces_on_each_other():
    """Face 0: the unit square; face 1: [0.5, 1.5] x [0, 1], both at z = 0 facing up."""
    verts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                      [0.5, 0, 0], [1.5, 0, 0], [1.5, 1, 0], [0.5, 1, 0]], float)
    polys = np.array([[0, 1, 2, 3], [4, 5, 6, 7]])
    c = verts[polys].mean(axis=1)
    n = np.tile([0.0, 0.0, 1.0], (2, 1))
    return PatchSet(verts, polys, c, n, np.ones(2), np.full((2, 3), 0.5), np.zeros((2, 3)),
                    np.zeros(2, np.int32), np.array([0, 1], np.int32), ["obj"])


def test_a_corner_is_read_on_its_own_face():
    E = two_faces_on_each_other()
    values = np.stack([np.full((4, 3), 1.0), np.full((4, 3), 2.0)])       # face 0 reads 1, face 1 reads 2
    # a corner of face 1 at (0.6, 0.5): inside both faces, nearer face 0's centre
    pos, centroid = np.array([[0.6, 0.5, 0.0]]), np.array([[1.0, 0.5, 0.0]])
    normal, owner = np.array([[0.0, 0.0, 1.0]]), np.array([0])
    found, ok = real_scenes.values_at_corners(E, values, pos, centroid, normal, owner)
    assert ok[0] and found[0, 0] == 1.0                        # by position alone: the other face's
    found, ok = real_scenes.values_at_corners(E, values, pos, centroid, normal, owner, face=np.array([1]))
    assert ok[0] and found[0, 0] == 2.0
    # a corner of face 0 stays on face 0
    found, ok = real_scenes.values_at_corners(E, values, np.array([[0.9, 0.5, 0.0]]), np.array([[0.5, 0.5, 0.0]]),
                                              normal, owner, face=np.array([0]))
    assert ok[0] and found[0, 0] == 1.0


def a_bent_face():
    """One face (0) of two triangles meeting at the origin: one in z = 0 facing up, the other in
    y = 0 facing +y (a bent n-gon as Blender's loop triangles: the living room's wall corner
    7281, whose first triangle is a sliver turned up under a bevel)."""
    verts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [-1, 0, 1]], float)
    polys = np.array([[0, 1, 2, -1], [0, 3, 4, -1]])
    c = np.array([verts[p[:3]].mean(axis=0) for p in polys])
    n = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])
    return PatchSet(verts, polys, c, n, np.array([0.5, 0.5]), np.full((2, 3), 0.5), np.zeros((2, 3)),
                    np.zeros(2, np.int32), np.array([0, 0], np.int32), ["obj"])


def test_a_corner_of_a_bent_face_is_read_where_cycles_baked_it():
    E = a_bent_face()
    # triangle 0 reads 1, triangle 1 reads 2, each plus a linear function of the position, which
    # the interpolation in a triangle gives exactly: a value read at the wrong place shows
    grad = np.array([10.0, 20.0, 30.0])
    f = E.verts[np.where(E.polys < 0, E.polys[:, 2:3], E.polys)] @ grad   # (2, 4): a triangle's 4th is its 3rd
    values = np.repeat((np.array([[1.0], [2.0]]) + f)[:, :, None], 3, axis=2)
    pos, centroid = np.zeros((1, 3)), np.array([[0.3, 0.3, 0.0]])          # the nudge lands on triangle 0
    normal, owner, face = np.array([[0.0, 0.0, 1.0]]), np.array([0]), np.array([0])
    found, ok = real_scenes.values_at_corners(E, values, pos, centroid, normal, owner, face)
    assert ok[0] and 1.0 <= found[0, 0] < 1.0 + 1e-2                     # by the origin, on triangle 0
    # Cycles baked it on triangle 1, a hair toward its centre: read there, though it faces +y
    on_other = np.array([[-2e-4, 0.0, 1e-4]])
    found, ok = real_scenes.values_at_corners(E, values, pos, centroid, normal, owner, face, point=on_other)
    assert ok[0] and np.isclose(found[0, 0], 2.0 + on_other[0] @ grad, rtol=0, atol=1e-12)
    # Cycles' point on triangle 0 (to float32 rounding): as without it, bit for bit
    on_own = np.array([[2e-4, 1e-4, 1e-7]])
    again, ok2 = real_scenes.values_at_corners(E, values, pos, centroid, normal, owner, face, point=on_own)
    first, _ = real_scenes.values_at_corners(E, values, pos, centroid, normal, owner, face)
    assert ok2[0] and again[0, 0] == first[0, 0]
    # a point off every element of its face (nearer none by 4x) is not moved
    off = np.array([[2e-4, 1e-4, 5e-3]])
    found, ok = real_scenes.values_at_corners(E, values, pos, centroid, normal, owner, face, point=off)
    assert ok[0] and found[0, 0] == first[0, 0]
