"""An HDR environment map lights the scene by direction, as in Cycles (core/light/environment.py,
blender/read/lights.py).

The world is an equirectangular float image made here: a blue sky, a dark ground and a small
bright sun spot 30 degrees up, from -y (as ``cycles_scenes.case_sun``'s sun). Over a floor, a box
throws the spot's shadow toward +y. Cycles' DIFFUSE-with-colour bake (COMBINED: rho H / pi at
every floor corner, 1,024 samples) is compared with ours at the same corners: the lit floor,
the floor in the spot's shadow, and the shadow's place. Measured: lit 0.719 against Cycles' 0.718, in the shadow 0.310
against 0.310. Before, the world was the map's mean: 0.374 in the sun and 0.366 in the shadow
(no shadow, the lit floor 48% dark). A Mapping node turning the map 90 degrees about Z moves the
shadow with it. A Sky Texture world, which no image holds, is rendered by Cycles into a map
first: lit 0.378 against 0.378, in the shadow 0.0613 against 0.0606.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tools import cycles_reference as cr  # noqa: E402
from hemicube_radiosity.core.light.environment import EnvironmentLight, equirect_uv  # noqa: E402
from tests.support.cycles_scenes import (  # noqa: E402
    BOX_HI, BOX_LO, RHO, SUN_ELEVATION, Comparison, box_arrays, environment_world, floor_object, shadowed)

pytestmark = [pytest.mark.blender, pytest.mark.cycles]

W, H = 256, 128
SKY, GROUND, SPOT = (0.25, 0.35, 0.6), (0.05, 0.05, 0.05), 1500.0
ZEN = math.pi / 2 - SUN_ELEVATION
TO_SUN = np.array([0.0, -math.sin(ZEN), math.cos(ZEN)])


def hdri_pixels():
    """(H, W, 3) rows bottom-up: sky above the horizon, ground below, a 2 x 2-pixel sun spot
    (about 1.4 degrees a pixel) where ``TO_SUN`` points."""
    px = np.empty((H, W, 3), np.float32)
    px[H // 2:], px[:H // 2] = SKY, GROUND
    u, v = equirect_uv(TO_SUN)
    i, j = int(v * H), int(u * W)
    px[i - 1:i + 1, j - 1:j + 1] = SPOT
    return px


def hdri_world(rotation_z=0.0):
    w, nt, tex = environment_world(hdri_pixels(), "sky")
    if rotation_z:
        m = nt.nodes.new("ShaderNodeMapping")
        co = nt.nodes.new("ShaderNodeTexCoord")
        m.inputs["Rotation"].default_value = (0.0, 0.0, rotation_z)
        nt.links.new(co.outputs["Generated"], m.inputs["Vector"])
        nt.links.new(m.outputs["Vector"], tex.inputs["Vector"])
    bpy.context.scene.world = w
    return w


def case(rotation_z=0.0):
    cr.new_empty_scene()
    fl = floor_object(16, 2.0)
    v, f = box_arrays(BOX_LO, BOX_HI, 4)
    bx = cr.mesh_object(v, f, cr.diffuse_material((RHO,) * 3), "box")
    hdri_world(rotation_z)
    return Comparison([fl, bx], samples=1024)


def regions(c, to_sun, step=0.25):
    """(lit, deep) floor corners, away from the shadow's edge and the box's foot."""
    lo, hi = np.array(BOX_LO), np.array(BOX_HI)
    floor = np.flatnonzero(c.owner == 0)
    p = c.pos[floor]
    offs = np.array([(dx, dy, 0) for dx in (-step, 0, step) for dy in (-step, 0, step)])
    vis = np.stack([shadowed(p + o, to_sun, lo, hi) for o in offs], 1)
    foot = np.all((p[:, :2] > lo[:2] - step) & (p[:, :2] < hi[:2] + step), axis=1)
    lit, deep = np.zeros(len(c.pos), bool), np.zeros(len(c.pos), bool)
    lit[floor[~vis.any(axis=1) & ~foot]] = True
    deep[floor[vis.all(axis=1) & ~foot]] = True
    return lit, deep


def test_the_map_is_a_light_and_its_mean_the_world():
    c = case()
    env = [li for li in c.lights if isinstance(li, EnvironmentLight)]
    assert len(env) == 1 and not any("replaced by its average" in n for n in c.notes), c.notes
    np.testing.assert_allclose(c.world, env[0].base(), rtol=1e-9)   # the constant the map varies about
    # the sun spot is where it was put: the brightest direction of the map read
    np.testing.assert_allclose(env[0].radiance(TO_SUN), SPOT, rtol=1e-6)


def test_hdri_sun_casts_the_box_shadow_as_in_cycles():
    c = case()
    lit, deep = regions(c, TO_SUN)
    assert lit.sum() > 400 and deep.sum() > 15
    y_lit, y_deep = c.cycles[lit].mean(), c.cycles[deep].mean()
    assert y_lit > 2.0 * y_deep                        # the spot's shadow is real in Cycles
    assert c.ours[lit].mean() == pytest.approx(y_lit, rel=0.03)
    assert c.ours[deep].mean() == pytest.approx(y_deep, rel=0.06)
    assert c.error(lit) < 0.04


def test_a_mapping_rotation_turns_the_shadow_with_the_map():
    """Rotation Z = 90 degrees: the map's direction d is looked up at R d, so the spot now
    shines from R^T TO_SUN, from +x instead of -y."""
    c = case(rotation_z=math.pi / 2)
    Rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    to_sun = Rz.T @ TO_SUN
    lit, deep = regions(c, to_sun)
    assert lit.sum() > 400 and deep.sum() > 15
    assert c.cycles[lit].mean() > 2.0 * c.cycles[deep].mean()      # Cycles agrees on where
    assert c.ours[deep].mean() == pytest.approx(c.cycles[deep].mean(), rel=0.06)
    assert c.ours[lit].mean() == pytest.approx(c.cycles[lit].mean(), rel=0.03)


def sky_scene():
    """The same floor and box under a Sky Texture (its default model, sun disc on) with its sun
    30 degrees up from -y, at strength 0.02: the world varies with direction, and no
    Environment Texture holds it."""
    cr.new_empty_scene()
    fl = floor_object(16, 2.0)
    v, f = box_arrays(BOX_LO, BOX_HI, 4)
    bx = cr.mesh_object(v, f, cr.diffuse_material((RHO,) * 3), "box")
    w = bpy.data.worlds.new("sky")
    nt = cr.node_tree(w)
    bg = next(n for n in nt.nodes if n.type == "BACKGROUND")
    sky = nt.nodes.new("ShaderNodeTexSky")
    sky.sun_elevation, sky.sun_rotation = SUN_ELEVATION, math.pi    # from -y, as TO_SUN
    nt.links.new(sky.outputs["Color"], bg.inputs["Color"])
    bg.inputs["Strength"].default_value = 0.02
    bpy.context.scene.world = w
    return [fl, bx]


def test_a_sky_texture_is_rendered_by_cycles_into_a_map_that_lights():
    """Cycles renders the world alone into an equirectangular map (blender/read/world_map.py):
    its sun a third of a pixel, found; the map lights as an HDRI does. Nothing is left behind
    in the file (no scene, camera, image or Render Result)."""
    objects = sky_scene()

    def blocks():
        return [sorted(c.keys()) for c in (bpy.data.scenes, bpy.data.images, bpy.data.cameras,
                                           bpy.data.objects, bpy.data.worlds)]
    before = blocks()
    c = Comparison(objects, samples=1024)
    assert blocks() == before
    env = [li for li in c.lights if isinstance(li, EnvironmentLight)]
    assert len(env) == 1 and not any("not read" in n for n in c.notes), c.notes
    Y = env[0].pixels @ [0.2126, 0.7152, 0.0722]
    i, j = np.unravel_index(Y.argmax(), Y.shape)
    h, w = Y.shape
    lat, lon = ((i + 0.5) / h - 0.5) * np.pi, 2 * np.pi * (0.5 - (j + 0.5) / w)
    sun = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
    assert sun @ TO_SUN > np.cos(np.radians(2.0))                  # the sun is where it was set
    lit, deep = regions(c, TO_SUN)
    assert lit.sum() > 400 and deep.sum() > 15
    assert c.cycles[lit].mean() > 3.0 * c.cycles[deep].mean()
    assert c.ours[lit].mean() == pytest.approx(c.cycles[lit].mean(), rel=0.03)
    assert c.ours[deep].mean() == pytest.approx(c.cycles[deep].mean(), rel=0.05)
