# SPDX-License-Identifier: GPL-3.0-or-later
"""Lightmap texels under a face nearer than our rays start (``core/output/texel_cover.py``):
dark, as Cycles' image bake has them.

The scene: a 10 m ground quad (its rays start 1e-5 of the diagonal off it: 0.14 mm) and a 4 m lid
quad of the same mesh 0.05 mm over its middle, facing up as the ground does, a sun and a grey
sky. Cycles' bake starts a texel's rays on the ground, and they meet the lid: the ground under it
is black (the living room's floor strips 0.13 mm under the slab over them: 0.000 in Cycles).
Ours started its rays 0.14 mm up, over the lid, and read the open sun and sky there (measured
before the cover: 0.955, as the open ground). The truth is Cycles' own bake through the same
lightmap UVs, texel by texel."""
from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tools import cycles_reference as cr  # noqa: E402
from hemicube_radiosity.blender import lightmap as blm  # noqa: E402
from hemicube_radiosity.core.output import lightmap as core_lightmap  # noqa: E402
from tests.support.lightmap_scenes import beside_cycles  # noqa: E402

pytestmark = [pytest.mark.blender, pytest.mark.cycles]
LUMA = np.array([0.2126, 0.7152, 0.0722])
GAP = 5e-5          # the lid over the ground, world units: under our 0.14 mm ray offset
LID = (3.0, 7.0)    # the lid's extent along x and y


def ground_under_a_lid():
    cr.new_empty_scene()
    cr.set_world((1.0, 1.0, 1.0), 0.3)
    a, b = LID
    verts = np.array([(0, 0, 0), (10, 0, 0), (10, 10, 0), (0, 10, 0),
                      (a, a, GAP), (b, a, GAP), (b, b, GAP), (a, b, GAP)], float)
    ob = cr.mesh_object(verts, [(0, 1, 2, 3), (4, 5, 6, 7)], cr.diffuse_material((0.8, 0.8, 0.8), name="Grey"),
                        "Ground")
    cr.add_light("SUN", (0, 0, 5), (0.3, 0.2, 0.0), name="Sun", energy=3.0)
    return ob


def test_texels_under_a_lid_nearer_than_our_rays_start_are_dark_as_in_cycles(tmp_path):
    ob = ground_under_a_lid()
    ours, cyc, uv, size = beside_cycles(ob, 6.0, tmp_path)
    ours, cyc = ours @ LUMA, cyc @ LUMA
    world = blm._world_triangles(ob.data, np.array(ob.matrix_world))
    tl = np.empty(len(ob.data.loop_triangles) * 3, np.int64)
    ob.data.loop_triangles.foreach_get("loops", tl)
    tris = uv[tl].reshape(-1, 3, 2)
    tri, bary, inside = core_lightmap.rasterize(tris, size, size)
    points = np.zeros(tri.shape + (3,))
    points[tri >= 0] = core_lightmap.texel_points(world, tri[tri >= 0], bary[tri >= 0])[0]
    on_ground = inside & (np.abs(points[..., 2]) < 0.5 * GAP)
    pitch = 10.0 / size * 2                       # two texels of the ground, at least, in world units
    x, y = points[..., 0], points[..., 1]
    a, b = LID
    under = on_ground & (x > a + pitch) & (x < b - pitch) & (y > a + pitch) & (y < b - pitch)
    clear = on_ground & ~((x > a - pitch) & (x < b + pitch) & (y > a - pitch) & (y < b + pitch))
    lid = inside & (points[..., 2] > 0.5 * GAP)
    assert under.sum() > 50 and clear.sum() > 500 and lid.sum() > 50
    lit = np.median(cyc[clear])
    print(f"\nclear ground: Cycles {lit:.4f}, ours {np.median(ours[clear]):.4f}; under the lid ({int(under.sum())} "
          f"texels): Cycles {cyc[under].mean():.4f}, ours {ours[under].mean():.4f}; lid: Cycles "
          f"{np.median(cyc[lid]):.4f}, ours {np.median(ours[lid]):.4f}")
    # Cycles' rays from the ground meet the lid 0.05 mm up: black under it
    assert cyc[under].max() < 0.02 * lit
    # ours too (before the cover: the open ground's light, 0.955)
    assert ours[under].max() < 0.02 * lit
    # the open ground and the lid's top as they were: both agree with Cycles
    assert np.allclose(ours[clear], cyc[clear], rtol=0.02)
    assert np.allclose(ours[lid], cyc[lid], rtol=0.02)
