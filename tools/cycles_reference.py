# SPDX-License-Identifier: GPL-3.0-or-later
"""Cycles reference bakes: outgoing diffuse radiance per vertex, as NumPy arrays (dev-only).

Not shipped with the add-on; tests and benchmarks use it to compare our radiosities with Cycles.

What is baked
-------------
``bake_vertex_radiance`` runs ``bpy.ops.object.bake(type='COMBINED', target='VERTEX_COLORS')``
with the pass filter {EMIT, DIRECT, INDIRECT, DIFFUSE} on CPU into a FLOAT_COLOR CORNER attribute
(made active, removed again afterwards), samples fixed, adaptive sampling, denoising, clamping
and the light threshold off, seed fixed. For Lambertian materials that is exactly the radiosity
quantity in radiance units,

    B = E + rho * H / pi          (W m^-2 sr^-1, scene linear)

Conventions established by experiment with bpy 5.0.1 (tests/blender/test_cycles_reference.py keeps them
true; numbers are exact to float precision where no sampling is involved):

* An emissive face of Emission strength 1 (white) bakes to 1.0 in COMBINED (the EMIT pass).
  ``type='DIFFUSE'`` with {DIRECT, INDIRECT, COLOR} gives rho * H / pi only: no emission.
  So DIFFUSE equals COMBINED minus emission for diffuse materials, and COMBINED is what the
  radiosity B is compared with. (GLOSSY/TRANSMISSION are left out of the filter, so the specular
  layer of a Principled BSDF does not leak into the reference.)
* Sun of strength S (W/m^2) at normal incidence on a rho = 0.8 Diffuse BSDF: 0.8 S / pi
  (S = 3: 0.763944). The sun strength is the irradiance on a perpendicular surface.
* Point light of power P (W), radius 0, at distance d: H = P cos(theta) / (4 pi d^2), i.e.
  radiant intensity P / (4 pi) W/sr; the plane bakes rho P cos / (4 pi^2 d^2) (ratio to that
  closed form 1.0000 +- 2e-4 over a 21x21 grid). With a radius r and ``use_soft_falloff`` off
  the lamp is a uniform sphere emitting P (same inverse square outside it); with soft falloff on
  (the default) a r = 0.1 lamp 1 m over a plane reads 0.3% lower on average.
* Spot light: the point light's intensity P / (4 pi) inside the cone, *no* extra cosine about
  the axis, times smoothstep(0, 1, (cos a - cos(size/2)) / ((1 - cos(size/2)) * blend)) where a
  is the angle from the axis (measured: 0.783 at 36 deg and 0.143 at 42.1 deg for size 90 deg,
  blend 0.5; the formula gives 0.779 / 0.143).
* Area light of power P (normalize on), any shape and size: a one-sided Lambertian emitter of
  radiance L = P / (pi A), emitting P W in total; the intensity along the axis is P / pi W/sr
  whatever the shape (square and disk of the same size bake the same). normalize off:
  L = P / pi, so the lamp emits P x A (its area in m^2) W. A spread below 180 deg narrows the beam (90 deg:
  2.7x brighter below the lamp); Cycles normalises it to keep the power.
* Light colour x energy x 2**exposure (exposure 1: x2.000), times ``temperature_color`` when
  ``use_temperature`` (3000 K: (1.771, 0.844, 0.272)). ``diffuse_factor`` is ignored by Cycles
  (EEVEE only). The light *object*'s ``visible_diffuse = False`` removes its light from diffuse
  surfaces entirely (bakes 0).
* World Background colour C x strength s: radiance C s from every direction that sees no surface
  (an open plane reads rho C s to 1e-6).
* The vertex value is the radiance at the corner position itself (Cycles places the bake sample
  on the corner), the POINT value is the mean of a vertex's corners.
* Light/World/Emission strengths are scene linear; no view transform is applied to bakes.

Cache
-----
``cached_bake(objects, cache_dir, **settings)``: key = SHA-256 of the scene's arrays (mesh
positions and loops in world space, material and light and world node values, visibility flags)
plus the settings; stored as ``<key>.npz`` with per-object ``point``/``corner`` arrays and the time
the original bake took.
"""
from __future__ import annotations

import hashlib
import json
import os
import time
import sys
from dataclasses import dataclass, field

import numpy as np

__all__ = ["CyclesBake", "configure_cycles", "bake_vertex_radiance", "bake_seconds",
           "scene_fingerprint", "cache_key", "cached_bake", "PASS_FILTERS", "new_empty_scene",
           "diffuse_material", "mesh_object", "grid_arrays", "add_light", "set_world"]

# Outgoing diffuse radiance B = E + rho H / pi (COMBINED) or rho H / pi only (DIFFUSE).
# LIGHTING: the Diffuse bake without Color: the light arriving, irradiance / pi.
PASS_FILTERS = {
    "COMBINED": {"EMIT", "DIRECT", "INDIRECT", "DIFFUSE"},
    "DIFFUSE": {"DIRECT", "INDIRECT", "COLOR"},
    "LIGHTING": {"DIRECT", "INDIRECT"},
    "POSITION": set(),      # where Cycles shades each corner (world space), not light
}
BAKE_TYPES = {"LIGHTING": "DIFFUSE"}
ATTRIBUTE = "_cycles_reference_bake"


@dataclass
class CyclesBake:
    """Per-object radiance arrays from one Cycles bake.

    point:  name -> (V, 3) float64 radiance per mesh vertex (mean of the vertex's corners).
    corner: name -> (L, 3) float64 radiance per face corner (mesh loop order).
    seconds: wall time of ``bpy.ops.object.bake`` alone.
    settings: what made it (samples, seed, mode, bounces).
    """

    point: dict
    corner: dict
    seconds: float
    settings: dict = field(default_factory=dict)
    cached: bool = False


def configure_cycles(scene, samples=256, seed=0, bounces=32, threads=2, glossy=0, filter_glossy=None):
    """Cycles on CPU, fixed samples and seed, no denoising/adaptivity/clamping/light threshold.
    ``glossy`` 0: no glossy bounces and no caustics (light reaches a surface only off diffuse
    ones: the paper's model); n > 0: n glossy bounces and reflective caustics, as a user's render
    has them (Blender's defaults: 4, on), so light off metal and glossy layers reaches the walls.
    ``filter_glossy``: Cycles' Filter Glossy (None: Blender's default, 1.0; 0: off, unbiased).
    It blurs glossy surfaces met after a diffuse bounce, and loses light doing so: the walls of
    a room with a metal floor (tests/blender/test_specular_bounce.py) show 0.53 with it, 0.68
    without, as an independent path tracer gives (docs/lighting.md)."""
    scene.render.engine = "CYCLES"
    cy = scene.cycles
    cy.device = "CPU"
    cy.samples = int(samples)
    cy.seed = int(seed)
    cy.use_animated_seed = False
    cy.use_denoising = False
    cy.use_adaptive_sampling = False
    cy.sample_clamp_direct = 0.0
    cy.sample_clamp_indirect = 0.0
    cy.light_sampling_threshold = 0.0
    cy.max_bounces = int(bounces)
    cy.diffuse_bounces = int(bounces)
    cy.glossy_bounces = int(glossy)
    cy.transmission_bounces = 0
    cy.volume_bounces = 0
    cy.transparent_max_bounces = 8
    cy.min_light_bounces = 0
    cy.caustics_reflective = glossy > 0
    if filter_glossy is not None:
        cy.blur_glossy = float(filter_glossy)
    cy.caustics_refractive = False
    if threads:
        scene.render.threads_mode = "FIXED"
        scene.render.threads = int(threads)
    scene.render.bake.target = "VERTEX_COLORS"
    scene.render.bake.use_selected_to_active = False
    scene.render.bake.use_clear = True


def _read_corner(attr, n):
    a = np.empty(n * 4, np.float32)
    attr.data.foreach_get("color", a)
    return a.reshape(-1, 4)[:, :3].astype(np.float64)


def _point_from_corner(me, corner):
    lv = np.empty(len(me.loops), np.int64)
    me.loops.foreach_get("vertex_index", lv)
    V = len(me.vertices)
    cnt = np.maximum(np.bincount(lv, minlength=V), 1).astype(np.float64)
    return np.stack([np.bincount(lv, weights=corner[:, k], minlength=V) for k in range(3)], 1) / cnt[:, None]


def bake_vertex_radiance(objects, *, samples=256, seed=0, mode="COMBINED", bounces=32, threads=2,
                         scene=None, glossy=0, filter_glossy=None) -> CyclesBake:
    """Bake Cycles radiance at the corners/vertices of mesh ``objects`` (all in one bake call).

    Objects must be mesh objects linked to ``scene`` (default: the context scene). Their meshes
    get a temporary FLOAT_COLOR CORNER attribute that is removed again; the previously active
    colour attribute is restored. ``mode``: 'COMBINED' (B = E + rho H / pi), 'DIFFUSE'
    (rho H / pi), 'LIGHTING' (H / pi), 'POSITION' (where Cycles shades each corner, world space,
    metres) or another key of ``PASS_FILTERS``. Returns a :class:`CyclesBake`.
    """
    import bpy

    if mode not in PASS_FILTERS:
        raise ValueError(f"mode must be one of {sorted(PASS_FILTERS)}")
    scene = scene or bpy.context.scene
    configure_cycles(scene, samples, seed, bounces, threads, glossy, filter_glossy)
    objects = list(objects)
    if not objects:
        raise ValueError("no objects to bake")
    view_layer = bpy.context.view_layer
    previous = []
    for ob in objects:
        if ob.type != "MESH":
            raise ValueError(f"{ob.name!r} is not a mesh")
        me = ob.data
        old = me.color_attributes.active_color_name if me.color_attributes.active_color else None
        if ATTRIBUTE in me.color_attributes:
            me.color_attributes.remove(me.color_attributes[ATTRIBUTE])
        attr = me.color_attributes.new(ATTRIBUTE, "FLOAT_COLOR", "CORNER")
        me.color_attributes.active_color = attr
        previous.append(old)
    for ob in view_layer.objects:
        if ob is not None:
            ob.select_set(False)
    for ob in objects:
        ob.select_set(True)
    view_layer.objects.active = objects[0]
    t = time.perf_counter()
    with bpy.context.temp_override(scene=scene, view_layer=view_layer,
                                   active_object=objects[0], object=objects[0],
                                   selected_objects=objects, selected_editable_objects=objects):
        res = bpy.ops.object.bake(type=BAKE_TYPES.get(mode, mode), pass_filter=PASS_FILTERS[mode],
                                  target="VERTEX_COLORS",
                                  use_clear=True)
    seconds = time.perf_counter() - t
    if "FINISHED" not in res:
        raise RuntimeError(f"Cycles bake failed: {res}")
    point, corner = {}, {}
    for ob, old in zip(objects, previous):
        me = ob.data
        attr = me.color_attributes[ATTRIBUTE]
        c = _read_corner(attr, len(me.loops))
        corner[ob.name] = c
        point[ob.name] = _point_from_corner(me, c)
        me.color_attributes.remove(attr)
        if old is not None and old in me.color_attributes:
            me.color_attributes.active_color = me.color_attributes[old]
    settings = dict(samples=int(samples), seed=int(seed), mode=mode, bounces=int(bounces))
    if glossy:                  # keys of the references baked without glossy bounces unchanged
        settings["glossy"] = int(glossy)
    if filter_glossy is not None:
        settings["filter_glossy"] = float(filter_glossy)
    return CyclesBake(point, corner, seconds, settings)


def bake_image(ob, size, *, kind="DIFFUSE", samples=4, uv_layer="", threads=2, seed=0, color=True, glossy=0,
               filter_glossy=None):
    """((size, size, 3) float64, seconds): Cycles' bake of mesh object ``ob`` into an image
    through UV map ``uv_layer`` ('' the active one): 'DIFFUSE' (direct + indirect + colour:
    what a render shows of a diffuse surface; ``color=False``: without the colour, the light
    arriving as radiance, irradiance / pi) or 'EMIT' (a baked copy's own look), with noise
    seed ``seed``; ``glossy``, ``filter_glossy`` as :func:`configure_cycles`. An image node is added to each of its materials for the bake and removed
    again; rows bottom-up."""
    import bpy

    img = bpy.data.images.new(f"{ob.name}.{kind}{samples}", size, size, float_buffer=True)
    added = []
    for slot in ob.material_slots:
        nt = slot.material.node_tree
        node = nt.nodes.new("ShaderNodeTexImage")
        node.image = img
        nt.nodes.active = node
        added.append((nt, node))
    sc = bpy.context.scene
    configure_cycles(sc, samples=samples, seed=seed, threads=threads, glossy=glossy, filter_glossy=filter_glossy)
    sc.render.bake.target = "IMAGE_TEXTURES"
    sc.render.bake.margin = 0
    vl = bpy.context.view_layer
    for o in vl.objects:
        o.select_set(o == ob)
    vl.objects.active = ob
    kw = dict(pass_filter={"DIRECT", "INDIRECT"} | ({"COLOR"} if color else set())) if kind == "DIFFUSE" else {}
    t = time.perf_counter()
    with bpy.context.temp_override(scene=sc, view_layer=vl, active_object=ob, object=ob,
                                   selected_objects=[ob], selected_editable_objects=[ob]):
        bpy.ops.object.bake(type=kind, target="IMAGE_TEXTURES", margin=0, use_clear=True,
                            uv_layer=uv_layer, **kw)
    seconds = time.perf_counter() - t
    for nt, node in added:
        nt.nodes.remove(node)
    rgb = image_rgb(img)
    bpy.data.images.remove(img)
    return rgb, seconds


def image_rgb(img) -> np.ndarray:
    """(H, W, 3) float64 the colour of a Blender image (RGBA), rows bottom-up."""
    w, h = img.size
    px = np.empty(w * h * 4, np.float32)
    img.pixels.foreach_get(px)
    return px.reshape(h, w, 4)[..., :3].astype(np.float64)


def bake_seconds(objects, **kw) -> float:
    """Run :func:`bake_vertex_radiance` and return only the time the bake call took (s)."""
    return bake_vertex_radiance(objects, **kw).seconds


# ----------------------------------------------------------------------------- cache
_SIMPLE = {"BOOLEAN", "INT", "FLOAT", "ENUM", "STRING"}


def _rna_values(struct, skip=("name", "name_full", "session_uid", "users", "is_evaluated",
                              "original", "tag", "preview", "select", "location", "width",
                              "height", "label", "dimensions", "bl_idname")):
    out = {}
    for p in struct.bl_rna.properties:
        k = p.identifier
        if k in skip or k == "rna_type" or p.type not in _SIMPLE:
            continue
        try:
            v = getattr(struct, k)
        except Exception:  # noqa: BLE001 - some properties raise in background mode
            continue
        if hasattr(v, "__len__") and not isinstance(v, str):
            v = [round(float(x), 7) if isinstance(x, float) else x for x in v]
            v = [x for x in v] if not isinstance(v, set) else sorted(v)
        elif isinstance(v, float):
            v = round(v, 7)
        elif isinstance(v, set):
            v = sorted(v)
        out[k] = v
    return out


def _tree(nt):
    if nt is None:
        return None
    nodes = []
    for n in sorted(nt.nodes, key=lambda n: n.name):
        ins = []
        for s in n.inputs:
            v = getattr(s, "default_value", None)
            if v is not None and hasattr(v, "__len__") and not isinstance(v, str):
                v = [round(float(x), 7) for x in v]
            elif isinstance(v, float):
                v = round(v, 7)
            ins.append((s.identifier, v if isinstance(v, (int, float, list, str, bool)) else None))
        nodes.append((n.bl_idname, n.name, _rna_values(n), ins))
    links = sorted((l.from_node.name, l.from_socket.identifier, l.to_node.name, l.to_socket.identifier,
                    bool(l.is_muted)) for l in nt.links)
    return nodes, links


def scene_fingerprint(objects, scene=None) -> bytes:
    """Bytes that change when anything a bake of ``objects`` sees changes (meshes of every
    visible object in world space, materials, lights, world, render visibility)."""
    import bpy

    scene = scene or bpy.context.scene
    dg = bpy.context.evaluated_depsgraph_get()
    h = hashlib.sha256()
    h.update(json.dumps(sorted(o.name for o in objects)).encode())
    for ob in sorted(scene.objects, key=lambda o: o.name):
        if ob.hide_render:
            continue
        h.update(ob.name.encode() + ob.type.encode())
        h.update(np.array(ob.matrix_world, np.float64).tobytes())
        h.update(json.dumps(_rna_values(ob), sort_keys=True, default=str).encode())
        if ob.type == "MESH":
            ev = ob.evaluated_get(dg)
            me = ev.to_mesh()
            try:
                co = np.empty(len(me.vertices) * 3, np.float32)
                me.vertices.foreach_get("co", co)
                lv = np.empty(len(me.loops), np.int32)
                me.loops.foreach_get("vertex_index", lv)
                ps = np.empty(len(me.polygons), np.int32)
                me.polygons.foreach_get("loop_start", ps)
                mi = np.empty(len(me.polygons), np.int32)
                me.polygons.foreach_get("material_index", mi)
                for a in (co, lv, ps, mi):
                    h.update(a.tobytes())
            finally:
                ev.to_mesh_clear()
            for slot in ob.material_slots:
                m = slot.material
                h.update(json.dumps(_tree(m.node_tree) if m is not None else None, default=str).encode())
        elif ob.type == "LIGHT":
            h.update(json.dumps(_rna_values(ob.data), sort_keys=True, default=str).encode())
            h.update(json.dumps(_rna_values(ob.data.cycles), sort_keys=True, default=str).encode())
            h.update(json.dumps(_tree(ob.data.node_tree) if ob.data.use_nodes else None, default=str).encode())
    w = scene.world
    if w is not None:
        h.update(json.dumps([_tree(w.node_tree), list(w.color), _rna_values(w.cycles_visibility)],
                            default=str).encode())
    return h.digest()


def cache_key(objects, settings: dict, scene=None) -> str:
    h = hashlib.sha256(scene_fingerprint(objects, scene))
    h.update(json.dumps(settings, sort_keys=True).encode())
    return h.hexdigest()[:32]


def cached_bake(objects, cache_dir, *, samples=256, seed=0, mode="COMBINED", bounces=32, threads=2,
                scene=None, glossy=0, filter_glossy=None) -> CyclesBake:
    """:func:`bake_vertex_radiance` through an npz cache in ``cache_dir`` (created if missing).

    A hit returns the stored arrays and the stored bake time with ``cached=True``.
    """
    settings = dict(samples=int(samples), seed=int(seed), mode=mode, bounces=int(bounces))
    if glossy:                  # keys of the references baked without glossy bounces unchanged
        settings["glossy"] = int(glossy)
    if filter_glossy is not None:   # (None: Blender's default, the keys made before it unchanged)
        settings["filter_glossy"] = float(filter_glossy)
    key = cache_key(objects, settings, scene)
    path = os.path.join(os.fspath(cache_dir), f"cycles_{key}.npz")
    if os.path.exists(path):
        with np.load(path, allow_pickle=False) as z:
            names = [str(n) for n in z["names"]]
            point = {n: z[f"point_{i}"] for i, n in enumerate(names)}
            corner = {n: z[f"corner_{i}"] for i, n in enumerate(names)}
            return CyclesBake(point, corner, float(z["seconds"]), settings, cached=True)
    res = bake_vertex_radiance(objects, samples=samples, seed=seed, mode=mode, bounces=bounces,
                               threads=threads, scene=scene, glossy=glossy, filter_glossy=filter_glossy)
    os.makedirs(os.fspath(cache_dir), exist_ok=True)
    names = list(res.point)
    arrays = {"names": np.array(names), "seconds": np.array(res.seconds)}
    for i, n in enumerate(names):
        arrays[f"point_{i}"] = res.point[n]
        arrays[f"corner_{i}"] = res.corner[n]
    tmp = path + f".{os.getpid()}.tmp.npz"
    np.savez_compressed(tmp, **arrays)
    os.replace(tmp, path)
    return res


# ----------------------------------------------------------------------------- scene helpers
# Small bpy builders shared by the Cycles comparison tests and tools/lighting_pictures.py.
def not_in_this_blender(what):
    """A case needs a property this Blender version lacks (e.g. a light's ``use_temperature``
    before 4.5): a skip under pytest, an error elsewhere."""
    import bpy

    msg = f"Blender {bpy.app.version_string}: {what}"
    if "pytest" in sys.modules:
        import pytest

        pytest.skip(msg)
    raise AttributeError(msg)


def new_empty_scene():
    """An empty scene without a world; returns the scene. (``read_homefile``, not
    ``read_factory_settings``: the latter resets the preferences and so disables the add-on and
    its extension repository for every test that runs after it.)"""
    import bpy

    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.world = None
    return scene


def node_tree(idblock):
    """The node tree of a material or world, switching nodes on where Blender made it without one
    (4.x: ``materials.new`` / ``worlds.new`` give ``use_nodes`` off and no tree; 5.0 always has
    one and deprecates ``use_nodes``, so it is left alone there)."""
    if idblock.node_tree is None:
        idblock.use_nodes = True
    return idblock.node_tree


def bare_node_tree(material):
    """(node tree, output node) of ``material`` with every node but the material output removed."""
    nt = node_tree(material)
    for n in list(nt.nodes):
        if n.type != "OUTPUT_MATERIAL":
            nt.nodes.remove(n)
    return nt, next(n for n in nt.nodes if n.type == "OUTPUT_MATERIAL")


def diffuse_material(rho=(0.8, 0.8, 0.8), emission=0.0, emission_color=(1.0, 1.0, 1.0), name="diffuse"):
    """A Diffuse BSDF of colour ``rho`` (plus an Emission of ``emission`` strength when > 0)."""
    import bpy

    m = bpy.data.materials.new(name)
    nt, out = bare_node_tree(m)
    d = nt.nodes.new("ShaderNodeBsdfDiffuse")
    d.inputs["Color"].default_value = (*rho, 1.0)
    if emission > 0:
        e = nt.nodes.new("ShaderNodeEmission")
        e.inputs["Color"].default_value = (*emission_color, 1.0)
        e.inputs["Strength"].default_value = float(emission)
        a = nt.nodes.new("ShaderNodeAddShader")
        nt.links.new(d.outputs[0], a.inputs[0])
        nt.links.new(e.outputs[0], a.inputs[1])
        nt.links.new(a.outputs[0], out.inputs["Surface"])
    else:
        nt.links.new(d.outputs[0], out.inputs["Surface"])
    return m


def mesh_object(verts, faces, material=None, name="mesh", scene=None):
    """A mesh object from world-space ``verts`` and ``faces`` (index lists), flat shaded."""
    import bpy

    scene = scene or bpy.context.scene
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(map(float, v)) for v in verts], [], [list(map(int, f)) for f in faces])
    me.update()
    if material is not None:
        me.materials.append(material)
    ob = bpy.data.objects.new(name, me)
    scene.collection.objects.link(ob)
    return ob


def grid_arrays(nx, ny, x0, x1, y0, y1, z=0.0):
    """(verts, faces) of a z-up grid of nx x ny quads over [x0,x1] x [y0,y1] at height z."""
    xs, ys = np.linspace(x0, x1, nx + 1), np.linspace(y0, y1, ny + 1)
    X, Y = np.meshgrid(xs, ys, indexing="xy")
    verts = np.stack([X.ravel(), Y.ravel(), np.full(X.size, z)], 1)
    idx = np.arange((nx + 1) * (ny + 1)).reshape(ny + 1, nx + 1)
    faces = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], -1).reshape(-1, 4)
    return verts, faces


def add_light(kind, location, rotation=(0.0, 0.0, 0.0), name=None, scene=None, **props):
    """A light object of ``kind`` (POINT/SPOT/SUN/AREA) with light-data ``props`` set."""
    import bpy

    scene = scene or bpy.context.scene
    data = bpy.data.lights.new(name or kind.lower(), kind)
    missing = sorted(k for k in props if not hasattr(data, k))
    if missing:
        not_in_this_blender(f"a {kind.lower()} light has no {', '.join(missing)}")
    for k, v in props.items():
        setattr(data, k, v)
    ob = bpy.data.objects.new(name or kind.lower(), data)
    scene.collection.objects.link(ob)
    ob.location = location
    ob.rotation_euler = rotation
    return ob


def set_world(color=(1.0, 1.0, 1.0), strength=1.0, scene=None):
    """A world whose Background node has ``color`` x ``strength`` (unlinked)."""
    import bpy

    scene = scene or bpy.context.scene
    w = bpy.data.worlds.new("world")
    bg = next(n for n in node_tree(w).nodes if n.type == "BACKGROUND")
    bg.inputs["Color"].default_value = (*color, 1.0)
    bg.inputs["Strength"].default_value = float(strength)
    scene.world = w
    return w
