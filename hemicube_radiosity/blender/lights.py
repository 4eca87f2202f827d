# SPDX-License-Identifier: GPL-3.0-or-later
"""Blender lamps and world -> core lights, in Cycles' units.

``read_lights(depsgraph_or_scene) -> (lights, world, notes)``

Every light object that Cycles would render is turned into a :mod:`..core.lights` object; the
world's constant Background colour x strength becomes ``world`` (3,) radiance (or None). Nothing
is modified in the scene. What is approximated or left out is said in ``notes``, one short line
per thing.

Units (Blender hands Cycles ``color x energy x 2**exposure``, times the black-body colour when
``use_temperature``, times the light's Emission node colour x strength when it has nodes;
the numbers below are checked against Cycles bakes in tests/test_cycles_reference.py and
tests/test_lighting_cycles.py):

============  =====================================================================
POINT         radiant intensity P / (4 pi) W/sr; ``shadow_soft_size`` is the radius,
              ``use_soft_falloff`` chooses disk-facing-receiver (on) or sphere (off).
SPOT          the same, limited by the cone: ``spot_size`` (full angle), ``spot_blend``
              (smoothstep over the outer ``blend`` part of 1 - cos(size/2)); no
              cosine fall-off about the axis. Direction: the object's -Z.
SUN           ``energy`` is the irradiance (W/m^2) at normal incidence; ``angle`` its
              angular diameter (soft shadows). Direction: the object's -Z.
AREA          one-sided Lambertian emitter facing the object's -Z: radiance
              P / (pi A) with ``normalize`` on (A includes the object's scale), P / pi
              with it off (mapped as power P x A). SQUARE/RECTANGLE/DISK/ELLIPSE.
World         Background node Color x Strength (unlinked inputs), seen wherever a
              hemi-cube sees no surface.
============  =====================================================================

Visibility switches honoured: the object's ``hide_render`` (and the depsgraph's own
visibility), the light object's ``visible_diffuse`` (off: no diffuse light at all in Cycles),
the world's ``cycles_visibility.diffuse``. ``diffuse_factor`` is not used by Cycles (EEVEE
only) and is ignored here too, with a note when it is not 1.
"""
from __future__ import annotations

import numpy as np

from ..core.lights import AreaLight, PointLight, SpotLight, SunLight
from .read import _follow

__all__ = ["read_lights", "light_from_object", "world_radiance"]


def _rgb(v):
    return np.array([float(v[0]), float(v[1]), float(v[2])])


def _output_node(nt, kind):
    outs = [n for n in nt.nodes if n.type == kind and getattr(n, "target", "ALL") in ("ALL", "CYCLES")]
    return next((n for n in outs if n.is_active_output), outs[0] if outs else None)


def _input_value(node, name, notes, what, default):
    s = node.inputs.get(name)
    if s is None:
        return default
    if s.is_linked:
        src, out = _follow(s)
        if src is not None and src.type in ("RGB", "VALUE"):
            v = out.default_value
            return _rgb(v) if s.type == "RGBA" else float(v)
        notes.append(f"{what}: '{name}' of '{node.name}' is driven by nodes; its unlinked value was used")
    v = s.default_value
    return _rgb(v) if s.type == "RGBA" else float(v)


def _light_node_factor(data, notes, what):
    """Colour factor of a light's own node tree (Cycles multiplies the lamp by it)."""
    if not getattr(data, "use_nodes", False) or data.node_tree is None:
        return np.ones(3)
    out = _output_node(data.node_tree, "OUTPUT_LIGHT")
    if out is None:
        return np.zeros(3)
    node, _ = _follow(out.inputs.get("Surface"))
    if node is None:
        return np.zeros(3)
    if node.type != "EMISSION":
        notes.append(f"{what}: light nodes other than Emission ('{node.name}'); used strength 1")
        return np.ones(3)
    return (_input_value(node, "Color", notes, what, np.ones(3))
            * _input_value(node, "Strength", notes, what, 1.0))


def light_from_object(ob, matrix_world, notes):
    """One light object (evaluated or original) -> core light, or None when it adds no light.

    ``matrix_world``: (4, 4) world matrix (for instances, the instance's). Appends to ``notes``.
    """
    data = ob.data
    what = f"light '{ob.name}'"
    M = np.array(matrix_world, dtype=np.float64).reshape(4, 4)
    if not getattr(ob, "visible_diffuse", True):
        notes.append(f"{what}: not visible to diffuse rays; left out (as Cycles does)")
        return None
    if data.type == "AREA" and data.cycles.is_portal:
        notes.append(f"{what}: a portal, not a light; left out")
        return None
    color = _rgb(data.color)
    if getattr(data, "use_temperature", False):
        color = color * _rgb(data.temperature_color)
    color = color * _light_node_factor(data, notes, what)
    energy = float(data.energy) * 2.0 ** float(getattr(data, "exposure", 0.0))
    if energy < 0 or np.any(color < 0):
        notes.append(f"{what}: negative power is not supported; left out")
        return None
    if energy == 0 or not np.any(color > 0):
        return None
    if abs(float(getattr(data, "diffuse_factor", 1.0)) - 1.0) > 1e-6:
        notes.append(f"{what}: diffuse factor {data.diffuse_factor:g} ignored (EEVEE only; Cycles ignores it too)")
    ll = getattr(ob, "light_linking", None)
    if ll is not None and (ll.receiver_collection is not None or ll.blocker_collection is not None):
        notes.append(f"{what}: light linking ignored (it lights and is blocked by everything)")
    pos = M[:3, 3].copy()
    down = -M[:3, 2]
    t = data.type
    if t == "POINT":
        return PointLight(pos, color, energy, float(data.shadow_soft_size),
                          bool(getattr(data, "use_soft_falloff", True)))
    if t == "SPOT":
        sx, sy = np.linalg.norm(M[:3, 0]), np.linalg.norm(M[:3, 1])
        if abs(sx - sy) > 1e-6 * max(sx, sy):
            notes.append(f"{what}: non-uniform scale (elliptic cone in Cycles) taken as a round cone")
        return SpotLight(pos, down, color, energy, float(data.shadow_soft_size), float(data.spot_size),
                         float(data.spot_blend), bool(getattr(data, "use_soft_falloff", True)))
    if t == "SUN":
        return SunLight(down, color, energy, float(data.angle))
    if t == "AREA":
        if float(data.spread) < np.pi - 1e-6:
            notes.append(f"{what}: spread {np.degrees(data.spread):.0f} deg ignored (taken as 180 deg, "
                         "a Lambertian emitter of the same power)")
        light = AreaLight(M, data.shape, float(data.size), float(data.size_y), color, energy)
        if not getattr(data, "normalize", True):
            light.power_w = energy * light.area          # Cycles: radiance P / pi, not P / (pi A)
        return light
    notes.append(f"{what}: type {t} not supported; left out")
    return None


def world_radiance(world, notes):
    """(3,) constant radiance of ``world`` or None (no world / black / invisible to diffuse)."""
    if world is None:
        return None
    vis = getattr(world, "cycles_visibility", None)
    if vis is not None and not vis.diffuse:
        notes.append("world: not visible to diffuse rays; no sky light")
        return None
    nt = world.node_tree             # Blender 5 always renders worlds with their node tree
    if nt is None:
        c = _rgb(world.color)
        return c if np.any(c > 0) else None
    out = _output_node(nt, "OUTPUT_WORLD")
    if out is None:
        return None
    node, _ = _follow(out.inputs.get("Surface"))
    if node is None:
        return None
    if node.type != "BACKGROUND":
        bg = [n for n in nt.nodes if n.type == "BACKGROUND"]
        if not bg:
            notes.append(f"world: surface '{node.name}' is not a Background node; no sky light")
            return None
        notes.append(f"world: '{node.name}' mixes shaders; used Background '{bg[0].name}' alone")
        node = bg[0]
    strength = _input_value(node, "Strength", notes, "world", 1.0)
    cs = node.inputs["Color"]
    src, _ = _follow(cs)
    if src is not None and src.type == "TEX_ENVIRONMENT" and src.image is not None:
        c = _image_mean(src.image, src.projection)
        notes.append(f"world: environment texture '{src.image.name}' replaced by its average colour "
                     f"({c[0]:.3g}, {c[1]:.3g}, {c[2]:.3g}); only a constant world is modelled")
    elif src is not None and src.type not in ("RGB",):
        c = _rgb(cs.default_value)
        notes.append(f"world: colour comes from '{src.name}' ({src.type}); used the socket's unlinked "
                     "value as a constant colour")
    else:
        c = _input_value(node, "Color", notes, "world", np.zeros(3))
    c = np.maximum(np.asarray(c, float) * float(strength), 0.0)
    return c if np.any(c > 0) else None


def _image_mean(image, projection="EQUIRECTANGULAR"):
    """Solid-angle-weighted mean colour of an environment image (rows weighted by cos(latitude)
    for equirectangular maps; a plain mean otherwise)."""
    w, h = image.size
    if w == 0 or h == 0:
        return np.zeros(3)
    px = np.empty(w * h * image.channels, np.float32)
    image.pixels.foreach_get(px)
    px = px.reshape(h, w, image.channels)[..., :3].astype(np.float64)
    if projection == "EQUIRECTANGULAR":
        lat = (np.arange(h) + 0.5) / h * np.pi - np.pi / 2
        wt = np.cos(lat)
        return (px.mean(axis=1) * wt[:, None]).sum(axis=0) / wt.sum()
    return px.reshape(-1, 3).mean(axis=0)


def read_lights(depsgraph_or_scene):
    """(lights, world, notes) for a depsgraph (evaluated, instances included) or a scene.

    ``lights``: list of core light objects; ``world``: (3,) radiance or None; ``notes``: what was
    approximated or left out.
    """
    notes, lights = [], []
    if hasattr(depsgraph_or_scene, "object_instances"):
        dg = depsgraph_or_scene
        scene = dg.scene_eval if hasattr(dg, "scene_eval") else dg.scene
        items = []
        for inst in dg.object_instances:
            ob = inst.instance_object if inst.is_instance else inst.object
            if ob is None or ob.type != "LIGHT":
                continue
            if getattr(ob.original, "hide_render", False):
                continue
            items.append((ob, np.array(inst.matrix_world, dtype=np.float64)))
    else:
        scene = depsgraph_or_scene
        items = [(ob, np.array(ob.matrix_world, dtype=np.float64)) for ob in scene.objects
                 if ob.type == "LIGHT" and not ob.hide_render]
    for ob, M in items:
        light = light_from_object(ob, M, notes)
        if light is not None:
            light.cast_shadows = bool(getattr(ob.data, "use_shadow", True))   # Blender's Shadow switch
            lights.append(light)
    world = world_radiance(scene.world, notes)
    return lights, world, notes
