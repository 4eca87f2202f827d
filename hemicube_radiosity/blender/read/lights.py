# SPDX-License-Identifier: GPL-3.0-or-later
"""Blender lamps and world -> core lights, in Cycles' units.

``read_lights(depsgraph_or_scene) -> (lights, world, notes)``

Every light object that Cycles would render is turned into a :mod:`..core.light.lamps` object; the
world's constant Background colour x strength becomes ``world`` (3,) radiance (or None). Nothing
is modified in the scene. What is approximated or left out is said in ``notes``, one short line
per thing.

Units (Blender hands Cycles ``color x energy x 2**exposure``, times the black-body colour when
``use_temperature``, times the light's Emission node colour x strength when it has nodes;
the numbers below are checked against Cycles bakes in tests/blender/test_cycles_reference.py and
tests/blender/test_lighting_cycles.py):

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
World         the active World Output's Background (or Emission) Color x Strength, Mix
              and Add shaders of them followed; seen wherever a hemi-cube sees no surface.
              A 4.x world with "Use Nodes" off arrives in Blender 5 as a new active output
              fed by its old colour; before 5.0 it is ``world.color``. No world: black.
============  =====================================================================

Lights are taken by *render* visibility, as Cycles renders them, not the viewport's: a light
hidden with H, disabled in viewports or in a collection hidden in the viewport still lights;
``hide_render``, a collection disabled in renders or excluded from the view layer, does not
(``visibility.render_visible_objects``). Also honoured: the light object's ``visible_diffuse``
(off: no diffuse light at all in Cycles), the world's ``cycles_visibility.diffuse``.
``diffuse_factor`` is not used by Cycles (EEVEE only) and is ignored here too, with a note when
it is not 1.
"""
from __future__ import annotations

import numpy as np

from ...core.light.lamps import AreaLight, EnvironmentLight, PointLight, SpotLight, SunLight
from ...core.runtime.notes import warning
from .materials import follow, image_pixels, rgb
from .visibility import is_render_visible, render_visible_objects, unevaluated_note, world_matrix

__all__ = ["read_lights", "light_from_object", "world_radiance"]


def _output_node(nt, kind):
    outs = [n for n in nt.nodes if n.type == kind and n.target in ("ALL", "CYCLES")]
    return next((n for n in outs if n.is_active_output), outs[0] if outs else None)


def _input_value(node, name, notes, what, default):
    s = node.inputs.get(name)
    if s is None:
        return default
    if s.is_linked:
        src, out = follow(s)
        if src is not None and src.type in ("RGB", "VALUE"):
            v = out.default_value
            return rgb(v) if s.type == "RGBA" else float(v)
        notes.append(f"{what}: '{name}' of '{node.name}' is driven by nodes; its unlinked value was used")
    v = s.default_value
    return rgb(v) if s.type == "RGBA" else float(v)


def _light_node_factor(data, notes, what):
    """Colour factor of a light's own node tree (Cycles multiplies the lamp by it)."""
    if not data.use_nodes or data.node_tree is None:
        return np.ones(3)
    out = _output_node(data.node_tree, "OUTPUT_LIGHT")
    if out is None:
        return np.zeros(3)
    node, _ = follow(out.inputs.get("Surface"))
    if node is None:
        return np.zeros(3)
    if node.type != "EMISSION":
        notes.append(warning(f"light nodes other than Emission ('{node.name}'); used strength 1", what,
                             topic="scene"))
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
    if not ob.visible_diffuse:
        notes.append(f"{what}: not visible to diffuse rays; left out (as Cycles does)")
        return None
    if data.type == "AREA" and data.cycles.is_portal:
        notes.append(f"{what}: a portal, not a light; left out")
        return None
    color = rgb(data.color)
    if getattr(data, "use_temperature", False):          # Blender 4.5 on
        color = color * rgb(data.temperature_color)
    color = color * _light_node_factor(data, notes, what)
    energy = float(data.energy) * 2.0 ** float(getattr(data, "exposure", 0.0))   # exposure: 4.5 on
    if energy < 0 or np.any(color < 0):
        notes.append(warning("negative power is not supported; left out", what, topic="scene"))
        return None
    if energy == 0 or not np.any(color > 0):
        return None
    if abs(float(data.diffuse_factor) - 1.0) > 1e-6:
        notes.append(f"{what}: diffuse factor {data.diffuse_factor:g} ignored (EEVEE only; Cycles ignores it too)")
    ll = ob.light_linking
    if ll.receiver_collection is not None or ll.blocker_collection is not None:
        notes.append(f"{what}: light linking ignored (it lights and is blocked by everything)")
    pos = M[:3, 3].copy()
    down = -M[:3, 2]
    t = data.type
    if t == "POINT":
        return PointLight(pos, color, energy, float(data.shadow_soft_size),
                          bool(data.use_soft_falloff))
    if t == "SPOT":
        sx, sy = np.linalg.norm(M[:3, 0]), np.linalg.norm(M[:3, 1])
        if abs(sx - sy) > 1e-6 * max(sx, sy):
            notes.append(f"{what}: non-uniform scale (elliptic cone in Cycles) taken as a round cone")
        return SpotLight(pos, down, color, energy, float(data.shadow_soft_size), float(data.spot_size),
                         float(data.spot_blend), bool(data.use_soft_falloff))
    if t == "SUN":
        return SunLight(down, color, energy, float(data.angle))
    if t == "AREA":
        if float(data.spread) < np.pi - 1e-6:
            notes.append(f"{what}: spread {np.degrees(data.spread):.0f} deg ignored (taken as 180 deg, "
                         "a Lambertian emitter of the same power)")
        light = AreaLight(M, data.shape, float(data.size), float(data.size_y), color, energy)
        if not getattr(data, "normalize", True):        # Blender 4.5 on
            light.power_w = energy * light.area          # Cycles: radiance P / pi, not P / (pi A)
        return light
    notes.append(warning(f"type {t} not supported; left out", what, topic="scene"))
    return None


def _world_tree(world):
    """The node tree a render of ``world`` uses, or None for a plain ``world.color`` world.

    Blender 5 always renders a world's nodes (``use_nodes`` is deprecated and always on); a 4.x
    file whose world had "Use Nodes" off is converted on load into a new active World Output fed by
    a Background of the old ``world.color``, which the active-output rule below follows. Before
    5.0, "Use Nodes" off renders ``world.color`` as a uniform background."""
    import bpy

    nt = world.node_tree
    if bpy.app.version < (5, 0, 0) and not world.use_nodes:
        return None
    return nt


def _world_color(node, notes, envs=None, scale=1.0):
    """Constant Color x Strength of a Background (or Emission) node in a world. An
    equirectangular environment texture gives its mean, and (into ``envs``) an
    :class:`EnvironmentLight` of its variation, scaled as the node tree scales it (``scale``:
    the Mix factors above this node)."""
    strength = _input_value(node, "Strength", notes, "world", 1.0)
    cs = node.inputs["Color"]
    src, _ = follow(cs)
    if src is not None and src.type == "TEX_ENVIRONMENT" and src.image is not None:
        env = _environment(src, notes) if envs is not None and src.projection == "EQUIRECTANGULAR" else None
        if env is not None:
            env.pixels = env.pixels * float(strength) * float(scale)
            envs.append(env)
            return env.base() / float(scale) if scale else np.zeros(3)
        c = _image_mean(src.image, src.projection)
        notes.append(warning(f"environment texture '{src.image.name}' replaced by its average colour "
                             f"({c[0]:.3g}, {c[1]:.3g}, {c[2]:.3g}); only an equirectangular map "
                             "lights by direction", "world", topic="scene"))
    elif src is not None and src.type not in ("RGB",):
        c = rgb(cs.default_value)
        notes.append(warning(f"colour of '{node.name}' comes from '{src.name}' ({src.type}), which "
                             f"is not read; used the socket's own colour ({c[0]:.3g}, {c[1]:.3g}, "
                             f"{c[2]:.3g}) as a constant sky", "world", topic="scene"))
    else:
        c = _input_value(node, "Color", notes, "world", np.zeros(3))
    return np.asarray(c, float) * float(strength)


def _world_shader(node, notes, depth=0, envs=None, scale=1.0):
    """(3,) radiance of the world shader ``node`` outputs (Background/Emission, Mix, Add);
    environment maps into ``envs`` (:func:`_world_color`), ``scale`` the Mix factors above."""
    if node is None or depth > 16:
        return np.zeros(3)
    t = node.type
    if t in ("BACKGROUND", "EMISSION"):
        return _world_color(node, notes, envs, scale)
    if t in ("MIX_SHADER", "ADD_SHADER"):
        shaders = [s for s in node.inputs if s.type == "SHADER"][:2]
        fac = 0.5 if t == "ADD_SHADER" else float(np.clip(_input_value(node, "Fac", notes, "world", 0.5), 0.0, 1.0))
        weights = (1.0, 1.0) if t == "ADD_SHADER" else (1 - fac, fac)
        parts = [_world_shader(follow(s)[0], notes, depth + 1, envs, scale * w)
                 for s, w in zip(shaders, weights)]
        while len(parts) < 2:
            parts.append(np.zeros(3))
        return weights[0] * parts[0] + weights[1] * parts[1]
    notes.append(warning(f"shader '{node.name}' ({node.type}) is not a Background; it gives no sky "
                         "light here", "world", topic="scene"))
    return np.zeros(3)


# what the node reader says of a world it cannot read as constant (then Cycles renders it)
_NOT_CONSTANT = ("colour of '", "shader '", "environment texture '")


def world_radiance(world, notes, envs=None):
    """(3,) constant radiance of ``world`` or None (no world / black / invisible to diffuse);
    with a list ``envs``, its environment maps are added there as lights of their variation
    (their means are in the constant)."""
    if world is None:
        return None                  # Cycles renders a scene without a world black, too
    vis = getattr(world, "cycles_visibility", None)   # registered by the Cycles add-on
    if vis is not None and not vis.diffuse:
        notes.append("world: not visible to diffuse rays; no sky light")
        return None
    nt = _world_tree(world)
    if nt is None:
        c = rgb(world.color)
        return c if np.any(c > 0) else None
    out = _output_node(nt, "OUTPUT_WORLD")
    if out is None:
        notes.append("world: no World Output node; no sky light")
        return None
    node, _ = follow(out.inputs.get("Surface"))
    if node is None:
        return None
    said = []
    c = _world_shader(node, said, envs=envs)
    if envs is not None and any(getattr(n, "kind", "").startswith(_NOT_CONSTANT) for n in said):
        # a Sky Texture, a gradient...: Cycles renders the world by direction, and that map lights
        from .world_map import render_world_map

        px = render_world_map(world, notes)
        if px is not None:
            env = EnvironmentLight(px, name="world")
            envs[:] = [env]
            said = [n for n in said if not getattr(n, "warning", False)]   # read as Cycles sees it
            c = env.base()
    notes += said
    if np.any(c < 0):
        notes.append(f"world: negative radiance ({c[0]:.3g}, {c[1]:.3g}, {c[2]:.3g}) taken as 0")
    c = np.maximum(c, 0.0)
    return c if np.any(c > 0) else None


def _environment(tex, notes):
    """An :class:`EnvironmentLight` of an equirectangular Environment Texture node's image (its
    pixels at strength 1, rotated as the Mapping node on its Vector input says), or None when it
    cannot be read (then the mean stands alone, with a warning from the caller)."""
    img = tex.image
    w, h = img.size
    if w == 0 or h == 0 or img.channels < 3:
        return None
    rotation = _mapping_rotation(tex, notes)
    return EnvironmentLight(image_pixels(img)[..., :3], rotation, name=f"world '{img.name}'")


def _mapping_rotation(tex, notes):
    """(3, 3) world -> map rotation of what feeds an Environment Texture's Vector: nothing (the
    identity) or a Mapping node's Rotation (Euler XYZ; 'TEXTURE' mapping turns the other way)."""
    sock = tex.inputs.get("Vector")
    src, _ = follow(sock) if sock is not None else (None, None)
    if src is None or src.type == "TEX_COORD":
        return np.eye(3)
    if src.type != "MAPPING":
        notes.append(f"world: the environment map's Vector comes from '{src.name}' ({src.type}); "
                     "used the map unrotated")
        return np.eye(3)
    r = src.inputs.get("Rotation")
    ex, ey, ez = (float(a) for a in (r.default_value if r is not None else (0, 0, 0)))
    cx, sx, cy, sy, cz, sz = np.cos(ex), np.sin(ex), np.cos(ey), np.sin(ey), np.cos(ez), np.sin(ez)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    R = Rz @ Ry @ Rx                         # Euler XYZ: a point's coordinates, rotated
    if src.vector_type == "TEXTURE":
        R = R.T
    elif src.vector_type not in ("POINT", "VECTOR", "NORMAL"):
        notes.append(f"world: mapping '{src.name}' of type {src.vector_type}; used its rotation")
    return R


def _image_mean(image, projection="EQUIRECTANGULAR"):
    """Solid-angle-weighted mean colour of an environment image (rows weighted by cos(latitude)
    for equirectangular maps; a plain mean otherwise)."""
    w, h = image.size
    if w == 0 or h == 0:
        return np.zeros(3)
    px = image_pixels(image)[..., :3].astype(np.float64)
    if projection == "EQUIRECTANGULAR":
        lat = (np.arange(h) + 0.5) / h * np.pi - np.pi / 2
        wt = np.cos(lat)
        return (px.mean(axis=1) * wt[:, None]).sum(axis=0) / wt.sum()
    return px.reshape(-1, 3).mean(axis=0)


def _view_layer_of(scene):
    import bpy

    ctx = getattr(bpy.context, "view_layer", None)
    if getattr(bpy.context, "scene", None) == scene and ctx is not None:
        return ctx
    return scene.view_layers[0]


def _render_light_items(dg, notes):
    """(object, matrix) of every light a render shows: what Cycles sees, not what the viewport
    shows. The viewport depsgraph gives evaluated lights and instances; lights hidden in the
    viewport but visible to renders are added from the view layer; lights the viewport shows but
    renders do not (``hide_render``, a collection disabled in renders) are dropped."""
    view_layer = dg.view_layer
    visible = {o.as_pointer(): o for o in render_visible_objects(view_layer, {"LIGHT"})}
    layer_objects = {o.as_pointer() for o in view_layer.objects}
    items, seen = [], set()
    for inst in dg.object_instances:
        ob = inst.instance_object if inst.is_instance else inst.object
        if ob is None or ob.type != "LIGHT":
            continue
        key = ob.original.as_pointer()
        if inst.is_instance:
            if ob.original.hide_render:
                continue
            parent = inst.parent
            if (parent is not None and parent.original.as_pointer() in layer_objects
                    and not is_render_visible(parent.original, view_layer)):
                continue                  # its instancer is not rendered
        else:
            if key not in visible:
                continue
            seen.add(key)
        items.append((ob, np.array(inst.matrix_world, dtype=np.float64)))
    for key, ob in visible.items():
        if key in seen:
            continue
        ev = ob.evaluated_get(dg)          # hidden with H: still evaluated; disabled: the original
        if not ev.is_evaluated:
            n = unevaluated_note(ob)
            if n or ob.data.animation_data is not None:
                notes.append(f"light '{ob.name}': {n or 'disabled in viewports; light animation not applied'}")
        items.append((ev, world_matrix(ob, dg)))
    return items


def read_lights(depsgraph_or_scene):
    """(lights, world, notes) for a depsgraph (evaluated, instances included) or a scene.

    Lights are taken by their *render* visibility, as Cycles does: a light hidden in the viewport
    (H, or disabled in viewports, or in a collection hidden there) still lights the bake; one in a
    collection that is excluded or disabled in renders, or with ``hide_render``, does not.

    ``lights``: list of core light objects; ``world``: (3,) radiance or None; ``notes``: what was
    approximated or left out.
    """
    notes, lights = [], []
    if hasattr(depsgraph_or_scene, "object_instances"):
        dg = depsgraph_or_scene
        scene = dg.scene_eval
        items = _render_light_items(dg, notes)
    else:
        scene = depsgraph_or_scene
        items = [(ob, np.array(ob.matrix_world, dtype=np.float64))
                 for ob in render_visible_objects(_view_layer_of(scene), {"LIGHT"})]
    for ob, M in items:
        light = light_from_object(ob, M, notes)
        if light is not None:
            light.cast_shadows = bool(ob.data.use_shadow)   # Blender's Shadow switch
            lights.append(light)
    envs = []
    world = world_radiance(scene.world, notes, envs)
    if world is None:
        envs = []                    # a world that gives no light gives no variation either
    return lights + envs, world, notes
