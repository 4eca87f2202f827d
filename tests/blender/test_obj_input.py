# SPDX-License-Identifier: GPL-3.0-or-later
"""An .obj input's faces are the same on every load: of the faces that use the same vertices (a
thin wall modelled as two faces back to back, of two materials), the first in the file is kept.
Blender's importer validates with an unstable parallel sort and kept either (sauer_pandora: about
one load in twelve kept other faces)."""
from __future__ import annotations

import numpy as np
import pytest

from tests.support.addon import sub

pytestmark = pytest.mark.blender

N = 30                                   # a wall of N x N unit quads (enough for a parallel sort)
PAIRS = range(0, N * N, 23)              # the quads that have a second face behind them


def write_wall(tmp_path):
    """``wall.obj``: N x N quads facing +z of material 'front', then (later in the file) the same
    vertices of some of them in reverse order, facing -z, of material 'back'."""
    (tmp_path / "wall.mtl").write_text("newmtl front\nKd 0.5 0.5 0.5\nnewmtl back\nKd 0.2 0.2 0.2\n")
    vid = [[i * (N + 1) + j + 1 for j in range(N + 1)] for i in range(N + 1)]
    quads = [(vid[i][j], vid[i + 1][j], vid[i + 1][j + 1], vid[i][j + 1]) for i in range(N) for j in range(N)]
    lines = ["mtllib wall.mtl", "o Wall"] + [f"v {i} {j} 0" for i in range(N + 1) for j in range(N + 1)]
    lines += ["usemtl front"] + ["f " + " ".join(map(str, q)) for q in quads]
    lines += ["usemtl back"] + ["f " + " ".join(map(str, quads[k][::-1])) for k in PAIRS]
    (tmp_path / "wall.obj").write_text("\n".join(lines) + "\n")
    return str(tmp_path / "wall.obj")


def faces_of(bpy):
    me = bpy.data.objects["Wall"].data
    mi = np.empty(len(me.polygons), np.int32)
    me.polygons.foreach_get("material_index", mi)
    normals = np.empty(3 * len(me.polygons))
    me.polygons.foreach_get("normal", normals)
    lv = np.empty(len(me.loops), np.int32)
    me.loops.foreach_get("vertex_index", lv)
    return np.array([m.name for m in me.materials])[mi], normals.reshape(-1, 3), lv


def test_an_obj_keeps_the_first_of_faces_on_the_same_vertices(addon, tmp_path):
    import bpy

    path = write_wall(tmp_path)
    load = sub(addon, "blender.cli.main").load_input
    load(path)
    names, normals, lv = faces_of(bpy)
    # every quad once, as its first face: material 'front', facing +z (Blender's own validation
    # kept the second, 'back' and facing -z, for 20 of the 40 pairs of this file)
    assert len(names) == N * N and set(names) == {"front"}
    np.testing.assert_allclose(normals, [[0.0, 0.0, 1.0]] * (N * N), atol=1e-6)
    load(path)
    again = faces_of(bpy)
    assert np.array_equal(again[0], names) and np.array_equal(again[2], lv)
