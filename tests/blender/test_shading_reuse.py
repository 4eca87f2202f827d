# SPDX-License-Identifier: GPL-3.0-or-later
"""A relight asks Cycles again only for the objects whose material evaluation changed
(``blender/read/shading.py`` ``_evaluated``, keyed per object by ``shading_key.object_keys``),
each with the objects it was joined with, and gets exactly the values a whole evaluation gives:
an emitter's strength changed, a vertex moved, a colour changed."""
from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from hemicube_radiosity.blender.read import shading  # noqa: E402
from tests.blender.test_shading_batches import _grid, _image, _scene, _textured  # noqa: E402

pytestmark = [pytest.mark.blender, pytest.mark.cycles]


def _glowing(name, img, strength):
    """A textured material that emits its texture at ``strength``."""
    m = _textured(name, img)
    nt = m.node_tree
    p = next(n for n in nt.nodes if n.type == "BSDF_PRINCIPLED")
    tex = next(n for n in nt.nodes if n.type == "TEX_IMAGE")
    nt.links.new(tex.outputs["Color"], p.inputs["Emission Color"])
    p.inputs["Emission Strength"].default_value = strength
    return m, p


def _same(a, b):
    assert a.failed is None and b.failed is None
    assert sorted(a.corners) == sorted(b.corners)
    for n in a.corners:
        for x, y in zip(a.corners[n], b.corners[n]):
            np.testing.assert_array_equal(x, y, err_msg=n)
    assert sorted(a.face_emission) == sorted(b.face_emission)
    for n in a.face_emission:
        np.testing.assert_array_equal(a.face_emission[n], b.face_emission[n], err_msg=n)
    assert sorted(a.materials) == sorted(b.materials)
    for n in a.materials:
        for x, y in zip(a.materials[n], b.materials[n]):
            np.testing.assert_array_equal(x, y, err_msg=n)


def _count_evaluations(monkeypatch):
    """The list each call of ``shading.evaluate`` appends its objects' sorted names to."""
    asked = []
    real = shading.evaluate

    def counting(objects, *a, **k):
        asked.append(sorted(o.name for o in objects))
        return real(objects, *a, **k)
    monkeypatch.setattr(shading, "evaluate", counting)
    return asked


def test_only_what_changed_is_evaluated_again(monkeypatch):
    obs = _scene()
    glow, p = _glowing("Glow", _image("glow", seed=9), 2.0)
    obs += [_grid("glow", 3, [glow], seed=10), _grid("glow_too", 2, [glow], seed=11)]
    bpy.context.view_layer.update()
    asked = _count_evaluations(monkeypatch)

    def shade():
        return shading.shade(obs, bpy.context.evaluated_depsgraph_get())

    def fresh():
        shading._EVALUATED.clear()
        return shade()
    names = sorted(o.name for o in obs)
    first = fresh()
    assert asked[-1] == names
    assert "glow" in first.face_emission and np.ptp(first.corners["glow"][1][:, 0]) > 0.2
    again = shade()                                  # nothing changed: Cycles is not asked
    assert len(asked) == 1
    _same(again, first)

    p.inputs["Emission Strength"].default_value = 3.0              # a relight of the emitter
    warm = shade()
    assert "glow" in asked[-1] and "glow_too" in asked[-1]
    assert "object_coords" not in asked[-1] and len(asked[-1]) < len(names), asked[-1]
    np.testing.assert_allclose(warm.corners["glow"][1], 1.5 * first.corners["glow"][1], rtol=1e-6)
    _same(warm, fresh())

    # a vertex moved: that object (and what it is joined with) asked again, the same values
    obs[3].data.vertices[0].co.z += 0.3
    obs[3].data.update()
    warm = shade()
    assert "renamed_uv" in asked[-1] and len(asked[-1]) < len(names), asked[-1]
    _same(warm, fresh())

    # a colour changed in a material of one object
    obs[4].data.materials[0].node_tree.nodes["Principled BSDF"].inputs["Metallic"].default_value = 0.5
    warm = shade()
    assert asked[-1] == ["object_coords"], asked[-1]
    _same(warm, fresh())


def test_a_cache_folder_keeps_the_evaluations_for_a_new_process(monkeypatch, tmp_path):
    from hemicube_radiosity.core.runtime.cache import FormFactorCache

    obs = _scene()
    glow, p = _glowing("Glow", _image("glow", seed=9), 2.0)
    obs += [_grid("glow", 3, [glow], seed=10)]
    bpy.context.view_layer.update()
    asked = _count_evaluations(monkeypatch)

    def shade(cache=None):
        return shading.shade(obs, bpy.context.evaluated_depsgraph_get(), cache)
    shading._EVALUATED.clear()
    cache = FormFactorCache(tmp_path)
    first = shade(cache)
    assert len(asked) == 1 and not cache._mem          # on disk only: the form factors stay
    shading._EVALUATED.clear()                         # a new process: only the folder
    again = shade(FormFactorCache(tmp_path))
    assert len(asked) == 1
    _same(again, first)
    p.inputs["Emission Strength"].default_value = 3.0
    shading._EVALUATED.clear()
    warm = shade(FormFactorCache(tmp_path))
    assert len(asked) == 2 and "glow" in asked[-1] and len(asked[-1]) < len(obs), asked[-1]
    shading._EVALUATED.clear()
    _same(warm, shade())                               # a fresh evaluation, nothing kept
