# SPDX-License-Identifier: GPL-3.0-or-later
"""bench/real_scenes.py leaves out a corner that Cycles never lights only where the geometry says
why (``bench/dark_corners.py``): another face passes through its bake point (a duplicated face,
two faces back to back: Cycles' rays meet it at a distance of about 0), or no ray from it reaches
light (a cube buried inside another). A never-lit corner in the open is compared: if we light it
and Cycles does not, that counts. Cycles bakes the scene here; its zeros are checked first."""
from __future__ import annotations

import os
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.support import ROOT  # noqa: E402

for _p in (os.path.join(ROOT, "bench"), os.path.join(ROOT, "tools")):
    if _p not in sys.path:
        sys.path.insert(0, _p)

import dark_corners  # noqa: E402
import real_scenes  # noqa: E402
from tools import cycles_reference as cr  # noqa: E402

pytestmark = [pytest.mark.blender, pytest.mark.cycles]

LUMA = np.array([0.2126, 0.7152, 0.0722])


def _cube(centre, half, material, name):
    c = np.asarray(centre, float)
    v = [c + half * np.array(p) for p in [(-1, -1, -1), (1, -1, -1), (1, 1, -1), (-1, 1, -1),
                                          (-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1)]]
    f = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
    return cr.mesh_object(v, f, material, name)


def _scene():
    """A 4 m floor of 4 x 4 quads under the bench's sun and sky; on it a quad over one floor cell
    facing up ("same"), one over another cell facing down ("back"), a closed box ("box"), a cube
    inside it ("inner") and a strip from inside the box out through its top ("fin")."""
    cr.new_empty_scene()
    v, f = cr.grid_arrays(4, 4, -2.0, 2.0, -2.0, 2.0, 0.0)
    floor = cr.mesh_object(v, f, cr.diffuse_material((0.5,) * 3), "floor")
    m = cr.diffuse_material((0.8,) * 3)
    same = cr.mesh_object([(-1, -1, 0), (0, -1, 0), (0, 0, 0), (-1, 0, 0)], [[0, 1, 2, 3]], m, "same")
    back = cr.mesh_object([(0, 0, 0), (0, 1, 0), (1, 1, 0), (1, 0, 0)], [[0, 1, 2, 3]], m, "back")
    box = _cube((1.2, -1.2, 0.5), 0.4, m, "box")
    inner = _cube((1.2, -1.2, 0.5), 0.1, m, "inner")
    # a 5 cm strip facing the inner cube's +x side, out through the box's top into the light
    fin = cr.mesh_object([(1.4, -1.175, 0.4), (1.4, -1.225, 0.4), (1.4, -1.225, 1.2), (1.4, -1.175, 1.2)],
                         [[0, 1, 2, 3]], m, "fin")
    real_scenes.add_sun(bpy.context.scene)
    cr.set_world(real_scenes.SKY)
    return [floor, same, back, box, inner, fin]


def test_never_lit_corners_left_out_only_where_the_geometry_explains_them(tmp_path):
    objs = _scene()
    pos, centroid, normal, area, own, face, _ = real_scenes.corner_geometry(objs)
    R = np.concatenate([cr.bake_vertex_radiance(objs, samples=16, seed=1).corner[o.name] for o in objs])
    P = np.concatenate([cr.bake_vertex_radiance(objs, samples=1, mode="POSITION").corner[o.name]
                        for o in objs])
    Y = R @ LUMA
    # Cycles: where the quads lie on the floor (both facing ways) and inside the box, nothing
    under = (own == 0) & (np.all(np.abs(centroid[:, :2] + 0.5) < 0.1, 1)      # the floor cells
                          | np.all(np.abs(centroid[:, :2] - 0.5) < 0.1, 1))    # under the quads
    zero = np.isin(own, (1, 2, 4)) | under | ((own == 5) & (pos[:, 2] < 0.9))   # the fin's foot in the box
    assert zero.sum() == 4 + 4 + 24 + 4 + 4 + 2
    assert np.all(Y[zero] == 0)
    assert np.all(Y[~zero] > 0.04)        # the open floor 0.58, the box 0.15-0.94, under it 0.05
    np.testing.assert_allclose(np.abs(P - pos).max(), 0, atol=2e-3)   # Cycles shades at the corner

    z = dict(pos=pos, centroid=centroid, normal=normal, owner=own, face=face, point=P)
    never = Y <= 1e-4 * np.median(Y)
    np.testing.assert_array_equal(never, zero)
    cov, seal = dark_corners.explained(z, never, ~never)
    np.testing.assert_array_equal(cov, zero & (own < 4))       # faces through the point
    np.testing.assert_array_equal(seal, zero & (own >= 4))     # the buried cube, the fin's foot
    # ... whose +x side sees the strip's front, lit where it leaves the box: more than LEAK of
    # its rays meet that lit face; inside all the same, as most of them meet the box's backs
    leak = dark_corners.INSIDE
    try:
        dark_corners.INSIDE = 2.0
        _, seal_leak = dark_corners.explained(z, never, ~never)
    finally:
        dark_corners.INSIDE = leak
    assert 0 < (seal & ~seal_leak & (own == 4)).sum() < (own == 4).sum()

    # a corner in the open that the reference does not light is not explained: it is compared
    open_corner = int(np.flatnonzero((own == 0) & ~zero & (Y > 0.5))[0])
    never2 = never.copy()
    never2[open_corner] = True
    cov2, seal2 = dark_corners.explained(z, never2, ~never2)
    assert not cov2[open_corner] and not seal2[open_corner]

    # the bench: those 42 left out; the open corner still compared when Cycles gives it nothing
    ours = R.copy()
    ours[zero] = 0.5                                           # what we light there does not count
    Rz = R.copy()
    Rz[open_corner] = 0.0
    arrays = dict(pos=pos, centroid=centroid, normal=normal, owner=own, face=face, point=P,
                  area=area, emit=np.zeros_like(R), cand=R)
    np.savez(tmp_path / "ref.npz", ref=R, **arrays)
    np.savez(tmp_path / "zeroed.npz", ref=Rz, **arrays)
    err, _, n = real_scenes.compare(tmp_path / "ref.npz", ours)
    assert n == len(Y) - 42 and err["rms_raw"] < 1e-12
    _, counts = real_scenes.compared_corners(tmp_path / "ref.npz")
    assert counts == {"covered": 16, "sealed": 26, "counted": 0}
    err, _, n = real_scenes.compare(tmp_path / "zeroed.npz", ours)
    assert n == len(Y) - 42 and err["rms_raw"] > 0.05
