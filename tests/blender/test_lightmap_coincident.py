# SPDX-License-Identifier: GPL-3.0-or-later
"""Texels on a face with a duplicate lying on it (coincident faces, one mesh): Cycles' bake
has them black, ours has them lit, as the light there is.

The scene: a 2 m ground quad and a 1.2 m quad modelled onto it (same plane, same orientation,
another face of the same mesh), a sun and a grey sky. Away from the duplicate, our lightmap and
Cycles' image bake (DIFFUSE: direct, indirect, colour, through the same lightmap UVs) agree to
0.1% (measured: 0.9553 both). Where the faces coincide Cycles' rays start on one face and hit
the other at once: Cycles is black (measured 0.000 on the duplicate, 0.03 on the ground under
it, 16 or 64 samples alike), ours 0.9553 on both: the sun and the sky reach a surface however
many copies of it lie there. ``bench/lightmap_real.py``'s ``coincident_texels`` flags exactly
the texels Cycles has dark (the living room's roof and door strips are such faces: a bevel's
twisted quads lie in the roof's plane, a self-overlapping six-sided face over the strips)."""
from __future__ import annotations

import os
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tools import cycles_reference as cr  # noqa: E402
from hemicube_radiosity.blender import lightmap as blm  # noqa: E402
from hemicube_radiosity.core.output import lightmap as core_lightmap  # noqa: E402
from tests.support.lightmap_scenes import beside_cycles  # noqa: E402
from tests.support import ROOT  # noqa: E402

sys.path.insert(0, os.path.join(ROOT, "bench"))
import lightmap_real  # noqa: E402

pytestmark = [pytest.mark.blender, pytest.mark.cycles]
LUMA = np.array([0.2126, 0.7152, 0.0722])


def ground_with_a_duplicate():
    cr.new_empty_scene()
    cr.set_world((1.0, 1.0, 1.0), 0.3)
    verts = np.array([(0, 0, 0), (2, 0, 0), (2, 2, 0), (0, 2, 0),
                      (0.4, 0.4, 0), (1.6, 0.4, 0), (1.6, 1.6, 0), (0.4, 1.6, 0)], float)
    ob = cr.mesh_object(verts, [(0, 1, 2, 3), (4, 5, 6, 7)], cr.diffuse_material((0.8, 0.8, 0.8), name="Grey"),
                        "Ground")
    cr.add_light("SUN", (0, 0, 5), (0.3, 0.2, 0.0), name="Sun", energy=3.0)
    return ob


def test_coincident_faces_are_black_in_cycles_and_lit_in_ours(tmp_path):
    ob = ground_with_a_duplicate()
    ours, cyc, uv, size = beside_cycles(ob, 24.0, tmp_path)
    ours, cyc = ours @ LUMA, cyc @ LUMA
    world = blm._world_triangles(ob.data, np.array(ob.matrix_world))
    faces = blm._triangle_faces(ob.data)
    tl = np.empty(len(ob.data.loop_triangles) * 3, np.int64)
    ob.data.loop_triangles.foreach_get("loops", tl)
    tris = uv[tl].reshape(-1, 3, 2)
    tri, _, inside = core_lightmap.rasterize(tris, size, size)
    coincident = lightmap_real.coincident_texels(world, faces, tris, tri) & inside
    open_ = inside & ~coincident
    assert coincident.sum() > 1000 and open_.sum() > 500
    lit = np.median(cyc[open_])
    print(f"\nopen: Cycles {lit:.4f}, ours {np.median(ours[open_]):.4f}; coincident ({int(coincident.sum())} "
          f"texels): Cycles {cyc[coincident].mean():.4f}, ours {ours[coincident].mean():.4f}")
    # away from the duplicate both agree
    assert np.allclose(ours[open_], cyc[open_], rtol=0.01)
    # on it Cycles is black (its rays hit the other face at once), ours is the open ground's light
    assert cyc[coincident].mean() < 0.1 * lit
    assert np.allclose(ours[coincident], lit, rtol=0.01)
    # the bench's flag is where Cycles is dark: every texel Cycles has below half the light
    dark = inside & (cyc < 0.5 * lit)
    assert not (dark & ~coincident).any() and (dark & coincident).sum() > 0.95 * coincident.sum()
