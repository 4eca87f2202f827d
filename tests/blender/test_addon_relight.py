"""Relighting in Blender: a new material colour, emission strength or lamp re-solves only."""
from __future__ import annotations

import importlib

import numpy as np
import pytest

from tests.support.addon import lit_cornell_box, select
from tests.support.scene import corner_data

pytestmark = pytest.mark.blender

BAKE = dict(patch_size=0.25, resolution=32)


@pytest.mark.slow
def test_relight_in_the_session_reuses_form_factors(addon, empty_scene, monkeypatch, tmp_path):
    bpy = empty_scene
    bake_mod = importlib.import_module(f"{addon.__name__}.blender.bake")
    form_factors = importlib.import_module(f"{addon.__name__}.core.form_factors.stage")
    write = importlib.import_module(f"{addon.__name__}.blender.write")
    objs, lamp, names = lit_cornell_box(addon, bpy)
    calls = []
    real = form_factors.compute_form_factors
    monkeypatch.setattr(form_factors, "compute_form_factors", lambda *a, **k: calls.append(1) or real(*a, **k))

    def bake(**kw):
        # after a bake the originals are hidden and the user selects the baked copies
        copies = write.copies_of(names)
        select(bpy, copies if copies else [bpy.data.objects[n] for n in names])
        assert bpy.ops.object.radiosity_bake(**BAKE, **kw) == {"FINISHED"}
        return {n: corner_data(write.copies_of([n])[0]) for n in names}

    first = bake()
    assert len(calls) == 1
    # relight: lamp colour, the red wall's paint, the ceiling light's strength
    lamp.data.color = (0.2, 0.4, 1.0)
    red = bpy.data.objects["RedWall"].active_material
    red.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.1, 0.6, 0.1, 1)
    glow = bpy.data.objects["Light"].active_material.node_tree.nodes["Principled BSDF"]
    glow.inputs["Emission Strength"].default_value *= 0.5
    warm = bake()
    assert len(calls) == 1, "a relight must not recompute form factors"
    # the same changed scene baked cold (fresh cache) gives the same colours
    bake_mod.clear_session_cache()
    cold = bake()
    assert len(calls) == 2
    for n in names:
        np.testing.assert_allclose(warm[n][1], cold[n][1], rtol=1e-5, atol=1e-7)
    # and the relight did change the picture: the floor near the (now green) left wall turns green
    floor_first, floor_warm = first["Floor"], warm["Floor"]
    near = floor_first[0][:, 0] < 0.3
    assert (floor_warm[1][near, 1] / floor_warm[1][near, 0]).mean() > 1.5 * (
        floor_first[1][near, 1] / floor_first[1][near, 0]).mean()
    # moving geometry recomputes
    bpy.data.objects["TallBlock"].location.x += 0.1
    bake()
    assert len(calls) == 3
    # a cache folder keeps form factors across sessions (here: after the memory cache is cleared)
    bpy.context.scene.hemicube_radiosity.cache_dir = str(tmp_path)
    bake()
    assert len(calls) == 4 and list(tmp_path.glob("*.npz"))
    bake_mod.clear_session_cache()
    bake()
    assert len(calls) == 4, "form factors must come from the cache folder"
