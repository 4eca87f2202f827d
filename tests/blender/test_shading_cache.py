# SPDX-License-Identifier: GPL-3.0-or-later
"""Cycles' evaluation of the materials is kept for the session and reused while nothing it
depends on changed (``blender/read/shading_key.py``): a relight of new lamp strengths asks
Cycles nothing, while a change to a node's value, a colour ramp, an image, the mesh's UVs or
the object's place asks again and reads the new colours."""
from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tools import cycles_reference as cr  # noqa: E402
from hemicube_radiosity.blender.read import shading  # noqa: E402
from tests.blender.test_cycles_textures import floor, material, pattern_image  # noqa: E402

pytestmark = [pytest.mark.blender, pytest.mark.cycles]


@pytest.fixture
def counted(monkeypatch):
    """A fresh session's kept evaluations, and a list that grows by one per Cycles evaluation."""
    monkeypatch.setattr(shading, "_EVALUATED", type(shading._EVALUATED)())
    calls, real = [], shading.evaluate
    monkeypatch.setattr(shading, "evaluate", lambda *a, **k: calls.append(1) or real(*a, **k))
    return calls


def scene():
    """A floor whose Base Color is a checker through a colour ramp, and one with an image."""
    cr.new_empty_scene()
    m, nt, p = material("checker")
    checker = nt.nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 2.5         # corners inside squares, not on their edges
    ramp = nt.nodes.new("ShaderNodeValToRGB")
    nt.links.new(checker.outputs["Fac"], ramp.inputs["Fac"])
    nt.links.new(ramp.outputs["Color"], p.inputs["Base Color"])
    a = floor(6, m, "checkered")
    m2, nt2, p2 = material("imaged")
    tex = nt2.nodes.new("ShaderNodeTexImage")
    tex.image = pattern_image()
    nt2.links.new(tex.outputs["Color"], p2.inputs["Base Color"])
    b = floor(6, m2, "imaged")
    b.location.x = 3.0
    return a, b, checker, ramp, tex


def rho(objects):
    s = shading.shade(objects, bpy.context.evaluated_depsgraph_get())
    assert s.failed is None
    return {k: v[0].copy() for k, v in s.corners.items()}


def test_the_same_scene_is_evaluated_once_and_reads_the_same(counted):
    a, b, *_ = scene()
    first = rho([a, b])
    again = rho([a, b])
    assert len(counted) == 1
    for k in first:
        np.testing.assert_array_equal(first[k], again[k])
    again["checkered"][:] = 0                      # what a reader holds is its own
    np.testing.assert_array_equal(rho([a, b])["checkered"], first["checkered"])
    assert len(counted) == 1


@pytest.mark.parametrize("change", ["input", "ramp", "image", "uv", "move", "material"])
def test_a_change_that_can_move_a_colour_asks_cycles_again(counted, change):
    a, b, checker, ramp, tex = scene()
    first = rho([a, b])
    if change == "input":
        checker.inputs["Scale"].default_value = 1.5
    elif change == "ramp":
        ramp.color_ramp.elements[0].color = (0.6, 0.1, 0.1, 1.0)
    elif change == "image":
        px = np.full(32 * 32 * 4, 0.25, np.float32)
        tex.image.pixels.foreach_set(px)
        tex.image.pack()                            # saved into the file: not dirty, its size changed
    elif change == "uv":
        uv = b.data.uv_layers["UVMap"]
        v = np.empty(len(b.data.loops) * 2, np.float32)
        uv.data.foreach_get("uv", v)
        uv.data.foreach_set("uv", (v * 0.5).astype(np.float32))
        b.data.update()                             # as an edit in the UV editor tags it (4.2 needs it)
    elif change == "move":
        a.location.z = 0.5
    elif change == "material":
        a.data.materials[0] = b.data.materials[0]
    bpy.context.view_layer.update()
    second = rho([a, b])
    assert len(counted) == 2
    moved = "imaged" if change in ("image", "uv") else "checkered"
    if change != "move":                           # (a checker in object space: a move may not show)
        assert not np.allclose(second[moved], first[moved])


def test_an_image_with_unsaved_edits_is_always_evaluated(counted):
    a, b, checker, ramp, tex = scene()
    tex.image.pixels.foreach_set(np.full(32 * 32 * 4, 0.5, np.float32))
    assert tex.image.is_dirty
    rho([a, b])
    rho([a, b])
    assert len(counted) == 2
