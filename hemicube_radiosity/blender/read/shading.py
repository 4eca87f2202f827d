# SPDX-License-Identifier: GPL-3.0-or-later
"""Reflectance and emission as Cycles evaluates them, by Cycles itself (Blender glue only).

The material reader (``materials.py``) takes plain colour values straight from the nodes. Where
that is not what Cycles renders, Cycles is asked instead:

* **corners**: a material whose Base Color / Color / Emission / Strength / Fac / Metallic / ...
  comes from nodes (image textures through the mesh's UVs, procedural textures, colour
  attributes, mix nodes, node groups): the object is baked by Cycles at every face corner;
* **constant**: a Principled BSDF with plain values: Cycles darkens its diffuse lobe by the
  specular layer above it (default material, roughness 0.5, IOR 1.5: 0.770 for Base Color 0.8),
  and metallic / transmissive parts reflect no diffuse light. One small quad per material is
  baked, and its value used for every face;
* **plain**: Diffuse BSDF, Emission, Mix / Add of them with plain values: the reader's own
  values are exact, Cycles is not asked.

How: two vertex-colour bakes (``bpy.ops.object.bake(target='VERTEX_COLORS')``) into a FLOAT_COLOR
CORNER attribute: type DIFFUSE with only the COLOR filter (Cycles' diffuse albedo: the weight of
its diffuse closures, specular layering, metallic, transmission and alpha included) and type
EMIT. Albedo and emission do not depend on light, so one sample is exact (measured: 1 and 4
samples give identical bits) and the scene needs no world or lamps. The bake runs on TEMPORARY
copies in a temporary scene: each object's evaluated mesh is copied with all its attributes
(``bpy.data.meshes.new_from_object``, UVs and colour attributes kept), placed at the object's
world matrix with the object's materials, baked, read with ``foreach_get`` and removed with the
scene; the user's objects, meshes, materials and scenes are never written.

Cycles places a vertex bake's sample on the corner itself with the view along the normal, so the
values are those at the corner's UV / position, for a view straight onto the surface (the
specular layer's darkening varies with the view angle in a render; the bake, and Cycles' own
DIFFUSE bake we compare with, use normal incidence).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .materials import follow, uses_nodes
from .visibility import world_matrix

__all__ = ["Shaded", "classify", "may_emit", "shade", "evaluate"]

ATTRIBUTE = "_hr_shading"
SCENE = "_hr_shading"
# inputs that change no colour (bump and normal maps, tangents): a link there needs no Cycles
_GEOMETRY_INPUTS = {"Normal", "Coat Normal", "Clearcoat Normal", "Tangent"}
_KNOWN = {"BSDF_PRINCIPLED", "BSDF_DIFFUSE", "EMISSION", "MIX_SHADER", "ADD_SHADER"}


@dataclass
class Shaded:
    """One batch of Cycles evaluations.

    kinds:     material name_full -> ('plain' | 'constant' | 'corners', [note, ...])
    materials: material name_full -> (rho (3,), emission (3,)) for 'constant' materials
    corners:   object name -> (rho (nloops, 3), emission (nloops, 3)) in evaluated-mesh loop order
    failed:    why Cycles could not be asked (the reader's own values are used), or None
    seconds:   time of the Cycles bake calls
    """

    kinds: dict = field(default_factory=dict)
    materials: dict = field(default_factory=dict)
    corners: dict = field(default_factory=dict)
    failed: str | None = None
    seconds: float = 0.0


# ----------------------------------------------------------------------------- which materials
def _output_node(mat):
    if not uses_nodes(mat):
        return None
    nt = mat.node_tree
    outs = [n for n in nt.nodes if n.type == "OUTPUT_MATERIAL" and n.target in ("ALL", "CYCLES")]
    return next((n for n in outs if n.is_active_output), outs[0] if outs else None)


def describe(node, socket=None):
    """What feeds an input, in words: 'an image texture 'wood.png'', 'colour attribute 'Col''..."""
    t = node.type
    if t == "TEX_IMAGE":
        img = node.image
        return f"an image texture '{img.name}'" if img is not None else "an image texture without an image"
    if t in ("VERTEX_COLOR",):
        return f"colour attribute '{node.layer_name}'" if node.layer_name else "the default colour attribute"
    if t == "ATTRIBUTE":
        return f"attribute '{node.attribute_name}'"
    if t.startswith("TEX_"):
        label = node.bl_label if node.bl_label.endswith("Texture") else node.bl_label + " texture"
        return f"a {label}"
    if t == "GROUP":
        return f"node group '{node.node_tree.name if node.node_tree else node.name}'"
    return f"nodes ({node.bl_label})"


_RANK = {"plain": 0, "constant": 1, "corners": 2}


def _shader_nodes(out):
    """Every node feeding the Surface of material output ``out``, once each, depth first, as
    (node, the output socket it feeds through). The walk follows the SHADER inputs of shader
    nodes; it does not enter a node group, nor a node whose colour or value feeds a shader input
    (the Surface itself)."""
    stack, seen = [out.inputs["Surface"]], set()
    while stack:
        node, sock = follow(stack.pop())
        if node is None or node.name in seen:
            continue
        seen.add(node.name)
        yield node, sock
        if (sock is None or sock.type == "SHADER") and node.type != "GROUP":
            stack += [s for s in node.inputs if s.type == "SHADER"]


def classify(mat):
    """('plain' | 'constant' | 'corners', notes) of a material: whether and how Cycles must
    evaluate it (module docstring). ``notes`` say what is read from Cycles and why."""
    if mat is None:
        return "plain", []
    out = _output_node(mat)
    if out is None:
        if not uses_nodes(mat):
            # Blender < 5 without nodes: Cycles renders a Principled BSDF of the viewport colour
            return "constant", []
        return "plain", []
    kind, notes, unknown = "plain", [], []

    def need(k):
        nonlocal kind
        kind = k if _RANK[k] > _RANK[kind] else kind

    for node, sock in _shader_nodes(out):
        if sock is not None and sock.type != "SHADER":
            if node.type not in ("RGB", "VALUE"):       # a colour wired into the output: emission
                need("corners")
                notes.append(f"Surface colour from {describe(node)}")
            continue
        if node.type == "GROUP":
            need("corners")
            notes.append(f"shader from {describe(node)}")
            continue
        if node.type == "BSDF_PRINCIPLED":
            need("constant")
        for s in node.inputs:
            if s.type == "SHADER" or not s.is_linked or s.name in _GEOMETRY_INPUTS or not s.enabled:
                continue
            src, _ = follow(s)
            if src is None:
                continue
            if src.type in ("RGB", "VALUE"):            # a constant, but not the socket's own value
                need("constant")
                continue
            need("corners")
            notes.append(f"{node.name} '{s.name}' from {describe(src)}")
        if node.type not in _KNOWN:
            unknown.append(node)
    if kind != "plain":
        notes += [f"'{n.name}' is not a Diffuse or Principled BSDF: only what Cycles' diffuse pass "
                  "takes from it is baked" for n in unknown]
    return kind, notes


def may_emit(mat):
    """False when no shader of ``mat`` can emit (no Emission node, Principled Emission Strength
    0 and unlinked, no node group, no colour wired into the output): its EMIT bake is all zero."""
    out = _output_node(mat) if mat is not None else None
    if out is None:
        return False
    for node, sock in _shader_nodes(out):
        if (sock is not None and sock.type != "SHADER") or node.type in ("EMISSION", "GROUP"):
            return True
        if node.type == "BSDF_PRINCIPLED":
            st = node.inputs.get("Emission Strength")
            if st is not None and (st.is_linked or st.default_value != 0):
                return True
    return False


# ----------------------------------------------------------------------------- Cycles bakes
def _configure(scene):
    scene.render.engine = "CYCLES"
    cy = scene.cycles
    cy.device = "CPU"
    cy.samples = 1                      # albedo and emission: every sample is the same value
    cy.seed = 0
    cy.use_denoising = False
    cy.use_adaptive_sampling = False
    scene.render.bake.target = "VERTEX_COLORS"
    scene.render.bake.use_selected_to_active = False


def _bake(scene, objects, kind, pass_filter):
    import bpy

    vl = scene.view_layers[0]
    with bpy.context.temp_override(scene=scene, view_layer=vl, active_object=objects[0],
                                   object=objects[0], selected_objects=objects,
                                   selected_editable_objects=objects):
        res = bpy.ops.object.bake(type=kind, pass_filter=pass_filter, target="VERTEX_COLORS",
                                  use_clear=True)
    if "FINISHED" not in res:
        raise RuntimeError(f"Cycles {kind} bake: {res}")
    out = []
    for ob in objects:
        me = ob.data
        a = np.empty(len(me.loops) * 4, np.float32)
        me.color_attributes[ATTRIBUTE].data.foreach_get("color", a)
        out.append(a.reshape(-1, 4)[:, :3].astype(np.float64))
    return out


def _original(m):
    return m.original if m is not None else None


def _assign_materials(me, materials):
    """Make ``materials`` the material slots of mesh ``me``, in order (slot k: material index k)."""
    me.materials.clear()
    for m in materials:
        me.materials.append(m)


def _quad_mesh(materials):
    """One unit quad per material (material index k on face k), 1 m apart."""
    import bpy

    n = len(materials)
    verts = [(2.0 * k + x, y, 0.0) for k in range(n) for x, y in ((0, 0), (1, 0), (1, 1), (0, 1))]
    faces = [tuple(range(4 * k, 4 * k + 4)) for k in range(n)]
    me = bpy.data.meshes.new(SCENE)
    me.from_pydata(verts, [], faces)
    _assign_materials(me, materials)
    me.polygons.foreach_set("material_index", np.arange(n, dtype=np.int32))
    me.update()
    return me


def _copy_objects(objects, depsgraph, made_obs, made_meshes):
    """A temporary object per object of ``objects``: a copy of its evaluated mesh with all its
    attributes, the original materials of its slots, at its world matrix. Appends each mesh to
    ``made_meshes`` as soon as it exists and (object name, copy) to ``made_obs``, so that the
    caller removes whatever was made even when a later copy fails."""
    import bpy

    for obj in objects:
        ob_eval = obj.evaluated_get(depsgraph)
        me = bpy.data.meshes.new_from_object(ob_eval, preserve_all_data_layers=True,
                                             depsgraph=depsgraph)
        made_meshes.append(me)
        _assign_materials(me, [_original(s.material) for s in ob_eval.material_slots])
        ob = bpy.data.objects.new(SCENE, me)
        ob.matrix_world = _matrix(world_matrix(obj, depsgraph))
        made_obs.append((obj.name, ob))


def _prepare_bake(scene, obs):
    """Link ``obs`` into ``scene``, give each mesh the FLOAT_COLOR corner attribute the bakes
    write (active for baking, the render colour attribute unchanged), select them all and make
    the first one active."""
    for ob in obs:
        scene.collection.objects.link(ob)
        me = ob.data
        render = me.color_attributes.default_color_name
        attr = me.color_attributes.new(ATTRIBUTE, "FLOAT_COLOR", "CORNER")
        me.color_attributes.active_color = attr
        if render:                 # an unnamed Color Attribute node keeps reading its layer
            me.color_attributes.default_color_name = render
    vl = scene.view_layers[0]
    for ob in obs:
        ob.select_set(True, view_layer=vl)
    vl.objects.active = obs[0]


def _split_results(made_obs, rho, em, constants):
    """The baked corner values by owner: ({object name: (rho, em)}, {material name_full: (rho,
    em)}); a material's values are the mean over the four corners of its quad."""
    corners, materials = {}, {}
    for (name, _), r, e in zip(made_obs, rho, em):
        if name is not None:
            corners[name] = (r, e)
        else:
            for k, m in enumerate(constants):
                materials[m.name_full] = (r[4 * k:4 * k + 4].mean(axis=0), e[4 * k:4 * k + 4].mean(axis=0))
    return corners, materials


def _remove(scene, made_obs, made_meshes):
    """Remove the temporary objects, then their meshes, then the temporary scene."""
    import bpy

    for _, ob in made_obs:
        bpy.data.objects.remove(ob)
    for me in made_meshes:
        bpy.data.meshes.remove(me)
    bpy.data.scenes.remove(scene)


def evaluate(objects, depsgraph, constants=(), emit=True):
    """Bake albedo and emission of ``objects`` (original mesh objects) at every corner of their
    evaluated meshes, and of the ``constants`` materials on a quad each, in one temporary scene.
    ``emit`` False: no material can emit, the EMIT bake is skipped (zeros).

    Returns ({object name: (rho (L,3), emission (L,3))}, {material name_full: (rho, em)}, seconds).
    Raises RuntimeError when Cycles cannot bake (no Cycles, a bake error).
    """
    import bpy

    scene = bpy.data.scenes.new(SCENE)
    made_obs, made_meshes = [], []
    try:
        _configure(scene)
        _copy_objects(objects, depsgraph, made_obs, made_meshes)
        constants = list(constants)
        if constants:
            me = _quad_mesh(constants)
            made_meshes.append(me)
            made_obs.append((None, bpy.data.objects.new(SCENE, me)))
        obs = [ob for _, ob in made_obs]
        if not obs:
            return {}, {}, 0.0
        _prepare_bake(scene, obs)
        t = time.perf_counter()
        rho = _bake(scene, obs, "DIFFUSE", {"COLOR"})
        em = _bake(scene, obs, "EMIT", set()) if emit else [np.zeros_like(r) for r in rho]
        seconds = time.perf_counter() - t
        return (*_split_results(made_obs, rho, em, constants), seconds)
    finally:
        _remove(scene, made_obs, made_meshes)


def _matrix(M):
    from mathutils import Matrix

    return Matrix([list(map(float, row)) for row in M])


def shade(objects, depsgraph) -> Shaded:
    """Classify the materials of ``objects`` (original mesh objects) and let Cycles evaluate the
    ones that need it, in one batch. Never raises for a Cycles problem: ``failed`` says why."""
    out = Shaded()
    need, constants, emit = [], {}, False
    for obj in objects:
        if obj.type != "MESH":
            continue
        ob_eval = obj.evaluated_get(depsgraph)
        if len(ob_eval.data.polygons) == 0:
            continue                     # the reader refuses it (or skips it as an occluder)
        corners = False
        for s in ob_eval.material_slots:
            m = _original(s.material)
            if m is None:
                continue
            if m.name_full not in out.kinds:
                out.kinds[m.name_full] = classify(m)
            kind = out.kinds[m.name_full][0]
            emit |= kind != "plain" and may_emit(m)
            corners |= kind == "corners"
            if kind == "constant":
                constants[m.name_full] = m
        if corners:
            need.append(obj)
    if not need and not constants:
        return out
    try:
        out.corners, out.materials, out.seconds = evaluate(need, depsgraph, constants.values(), emit)
    except (RuntimeError, AttributeError, TypeError) as ex:   # no Cycles, a bake refused
        out.failed = f"Cycles could not evaluate the materials ({str(ex).splitlines()[0]})"
    return out
