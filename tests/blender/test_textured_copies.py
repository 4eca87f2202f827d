# SPDX-License-Identifier: GPL-3.0-or-later
"""A textured floor seen through its baked copy (``blender/textures.py``), against Cycles.

A 2 x 2 m floor whose default Principled BSDF takes its Base Color from an image through UVs, under
a sun of angle 0 and a uniform world (deterministic light: Cycles' bake has no noise). Cycles bakes
the original to an image through its UV map (DIFFUSE: direct, indirect and colour); then we bake
and write the copy, and Cycles bakes the copy's own look (EMIT: the copy's material is its light)
to an image of the same size. Texel by texel the two agree where the copy shows the texture times
the light (``keep_textures``, default), whether the copy keeps the user's quad or is an element
mesh that got the user's UVs; the radiosity attribute alone (the texture at the corners only)
is far off between the corners.
"""
from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tools import cycles_reference as cr  # noqa: E402
from hemicube_radiosity.blender import bake  # noqa: E402
from hemicube_radiosity.blender.textures import LIGHT_SUFFIX  # noqa: E402
from tests.support.cycles_scenes import textured_floor as scene  # noqa: E402

pytestmark = [pytest.mark.blender, pytest.mark.cycles]

SIZE = 32                      # texels along a side of the baked images


def bake_image(ob, kind):
    """(SIZE, SIZE, 3) Cycles' bake of ``ob`` through its UV map: 'DIFFUSE' (what a render shows
    of the surface) or 'EMIT' (a baked copy's own look)."""
    return cr.bake_image(ob, SIZE, kind=kind)[0]


def error(a, b):
    """Mean relative error of the bands' mean, over every texel."""
    return float(np.mean(np.abs(a.mean(-1) - b.mean(-1)) / b.mean(-1)))


@pytest.mark.parametrize("cuts, patch_size, element_size, kind",
                         [(2, 1.0, None, "source"), (1, 1.0, 0.4, "elements")])
def test_copy_shows_the_texture_times_the_light(cuts, patch_size, element_size, kind):
    ob = scene(cuts)
    ref = bake_image(ob, "DIFFUSE")
    s = dict(element_size=element_size, patch_size=patch_size, resolution=32, gather_rays=64)
    job = bake.BakeJob.prepare(bpy.context, [ob], bake.BakeSettings(**s))
    job.run()
    copy, = job.write(bpy.context)
    assert copy["radiosity_mesh"] == kind
    me = copy.data
    light = "Radiosity" + LIGHT_SUFFIX
    assert me.color_attributes.active_color.name == light and "Radiosity" in me.color_attributes
    assert [m.name for m in me.materials] == [f"Radiosity Bake ({light} x Floor)"]
    assert "UVMap" in me.uv_layers
    ours = bake_image(copy, "EMIT")
    assert error(ours, ref) < 0.01
    # the radiosity attribute alone: the texture at the corners only
    job = bake.BakeJob.prepare(bpy.context, [ob], bake.BakeSettings(**s, keep_textures=False))
    job.run()
    plain, = job.write(bpy.context)
    assert [m.name for m in plain.data.materials] == ["Radiosity Bake (Radiosity)"] * len(plain.data.materials)
    assert "UVMap" in plain.data.uv_layers           # an element mesh gets the user's UVs too
    assert error(bake_image(plain, "EMIT"), ref) > 0.1


@pytest.mark.parametrize("settings, kind", [
    (dict(element_size=0.4, patch_size=1.0), "elements"),        # the window's back too: both sides
    (dict(element_size=None, patch_size=3.0, two_sided_reflection=False), "source")])
def test_glass_keeps_its_own_material_in_the_copy(settings, kind):
    """A window (Principled, Transmission 1) beside a floor in one object: the copy shows the bake
    on the floor and keeps the user's glass material (shared, unchanged) on the window, so it stays
    see-through, where the bake's own colour there (near black) would be an opaque slab."""
    cr.new_empty_scene()
    floor_mat = cr.diffuse_material((0.6, 0.6, 0.6), name="FloorMat")
    glass = bpy.data.materials.new("Glass")
    nt, out = cr.bare_node_tree(glass)
    p = nt.nodes.new("ShaderNodeBsdfPrincipled")
    p.inputs["Transmission Weight"].default_value = 1.0
    nt.links.new(p.outputs[0], out.inputs["Surface"])
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0],
                  [-1, 0, 0.1], [1, 0, 0.1], [1, 0, 1.1], [-1, 0, 1.1]], float)
    ob = cr.mesh_object(v, np.array([[0, 1, 2, 3], [4, 5, 6, 7]]), floor_mat, "room")
    ob.data.materials.append(glass)
    ob.data.polygons[1].material_index = 1
    cr.add_light("SUN", (0, 0, 3), (0.4, 0.2, 0.0), energy=2.0, angle=0.0)
    job = bake.BakeJob.prepare(bpy.context, [ob], bake.BakeSettings(**settings, resolution=16, gather_rays=16))
    job.run()
    copy, = job.write(bpy.context)
    assert copy["radiosity_mesh"] == kind
    me = copy.data
    slot = np.empty(len(me.polygons), np.int64)
    me.polygons.foreach_get("material_index", slot)
    centre = np.array([list(f.center) for f in me.polygons])
    upright = centre[:, 2] > 0.05
    assert upright.any() and (~upright).any()
    assert {me.materials[i].name for i in slot[upright]} == {"Glass"}
    assert {me.materials[i].name for i in slot[~upright]} == {
        "Radiosity Bake (Radiosity" + (", two-sided)" if kind == "elements" else ")")}
    assert me.materials[int(slot[upright][0])] is glass and glass.node_tree.nodes.get("Principled BSDF") is not None
