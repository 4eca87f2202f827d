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

How: three vertex-colour bakes (``bpy.ops.object.bake(target='VERTEX_COLORS')``) into a
FLOAT_COLOR CORNER attribute: type DIFFUSE with only the COLOR filter (Cycles' diffuse albedo: the
weight of its diffuse closures, specular layering, metallic, transmission and alpha included),
type GLOSSY with only the COLOR filter (the albedo of the specular and metallic layers: 0.037 for
Blender's default material, 0.80 for a metal of Base Color 0.8 and roughness 0.3; the solve
bounces it, :mod:`core.mesh.specular`) and type EMIT. Albedo and emission do not depend on light, so one sample is exact (measured: 1 and 4
samples give identical bits) and the scene needs no world or lamps. The bake runs on TEMPORARY
copies in a temporary scene: each object's evaluated mesh is copied with all its attributes
(``bpy.data.meshes.new_from_object``, UVs and colour attributes kept), placed at the object's
world matrix with the object's materials, baked, read with ``foreach_get`` and removed with the
scene; the user's objects, meshes, materials and scenes are never written.

Blender's bake operator runs Cycles once per selected object, and each run syncs the whole
temporary scene (every copy, every image): baking N objects one by one costs N times the scene.
So the copies are **joined** into one mesh per group (:func:`_batches`) and baked in one run: an
INT corner attribute numbers every corner before the join, and maps the baked values back to
each object's loops after it. A material's albedo does not depend on where its object is, except
through object-space inputs (Generated or Object coordinates, Object Info, box-projected images,
procedural textures with their default coordinates, object-space normal maps): objects with such
a material are baked as themselves, one run each (:func:`object_independent`). The groups share
their render UV map and the colour attributes their materials name, so a texture reads the same
layer on the joined mesh as on the object (measured on bitterli_wooden_staircase, 349 textured
objects of 775: 698 Cycles runs of 0.43 s each, 6 min, before; 2 runs after).

An image texture whose image cannot be read (its file is missing, or no image is set) renders
magenta in Cycles, an alarm colour: baked, it would make every such surface reflect 0.999 of its
red and blue light (sauer_pandora ships without its 206 textures). Such a material is baked as a
temporary copy with those textures unlinked, so the sockets' own values are used, and a note
names the image (:func:`missing_images`).

Cycles places a vertex bake's sample on the corner itself with the view along the normal, so the
values are those at the corner's UV / position, for a view straight onto the surface (the
specular layer's darkening varies with the view angle in a render; the bake, and Cycles' own
DIFFUSE bake we compare with, use normal incidence).
"""
from __future__ import annotations

import time
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np

from ...core.runtime.notes import warning
from .face_emission import sample_faces
from .shading_key import KEPT, object_keys
from .materials import follow, uses_nodes
from .visibility import world_matrix

__all__ = ["Shaded", "classify", "may_emit", "shade", "evaluate", "object_independent",
           "missing_images", "output_node"]

# the last evaluations of this session: {key of an object or constant material
# (:func:`.shading_key.object_keys`): its values, ('run', object name): the names it was run with}
_EVALUATED: OrderedDict = OrderedDict()

ATTRIBUTE = "_hr_shading"
SCENE = "_hr_shading"
CORNER_ID = "_hr_corner"      # INT corner attribute: the corner's index over all copies of a batch
# inputs that change no colour (bump and normal maps, tangents): a link there needs no Cycles
_GEOMETRY_INPUTS = {"Normal", "Coat Normal", "Clearcoat Normal", "Tangent"}
_KNOWN = {"BSDF_PRINCIPLED", "BSDF_DIFFUSE", "EMISSION", "MIX_SHADER", "ADD_SHADER"}


@dataclass
class Shaded:
    """One batch of Cycles evaluations.

    kinds:     material name_full -> ('plain' | 'constant' | 'corners', [note, ...])
    materials: material name_full -> (rho (3,), emission (3,), glossy (3,)) for 'constant'
               materials
    corners:   object name -> (rho (nloops, 3), emission (nloops, 3), glossy (nloops, 3)) in
               evaluated-mesh loop order; glossy: the albedo of the specular and metallic layers
    failed:    why Cycles could not be asked (the reader's own values are used), or None
    seconds:   time of the Cycles bake calls
    face_emission: object name -> (nloops, 3) the mean emission over the face of each loop's
               polygon (:mod:`.face_emission`), for objects with a material in ``sampled``
    sampled:   name_full of the 'corners' materials that may emit (their faces' emission is
               their mean over the face, not their corners')
    """

    kinds: dict = field(default_factory=dict)
    materials: dict = field(default_factory=dict)
    corners: dict = field(default_factory=dict)
    face_emission: dict = field(default_factory=dict)
    sampled: set = field(default_factory=set)
    failed: str | None = None
    seconds: float = 0.0


# ----------------------------------------------------------------------------- which materials
def output_node(mat):
    """The material output Cycles renders ``mat`` through (the active one of target All or
    Cycles), or None (no nodes, no such output)."""
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
    out = output_node(mat)
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
    out = output_node(mat) if mat is not None else None
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


# nodes whose value depends on the object they shade (its space, its bounds, its identity)
_OBJECT_NODES = {"OBJECT_INFO", "PARTICLE_INFO", "POINT_INFO", "HAIR_INFO", "CURVES_INFO", "SCRIPT",
                 "TANGENT", "UVALONGSTROKE"}
# textures whose unlinked Vector is not Generated coordinates (the image: the UV map)
_OWN_COORDINATES = {"TEX_IMAGE", "TEX_ENVIRONMENT", "TEX_SKY"}


def _tree_nodes(nt, seen=None):
    """Every node of ``nt`` and of the node groups inside it, once each."""
    seen = set() if seen is None else seen
    if nt is None or nt.name_full in seen:
        return
    seen.add(nt.name_full)
    for node in nt.nodes:
        yield node
        if node.type == "GROUP":
            yield from _tree_nodes(node.node_tree, seen)


def _object_dependent(node):
    t = node.type
    if t in _OBJECT_NODES:
        return True
    if t == "TEX_COORD":
        return any(o.is_linked for o in node.outputs if o.name != "UV")
    if t == "ATTRIBUTE":
        return node.attribute_type != "GEOMETRY"
    if t == "UVMAP":
        return node.from_instancer
    if t == "NORMAL_MAP":
        return node.space in ("OBJECT", "BLENDER_OBJECT")
    if t == "VECT_TRANSFORM":
        return "OBJECT" in (node.convert_from, node.convert_to)
    if t == "TEX_IMAGE":
        return node.projection != "FLAT"
    if t.startswith("TEX_") and t not in _OWN_COORDINATES:
        v = node.inputs.get("Vector")
        return v is not None and v.enabled and not v.is_linked     # Generated coordinates
    return False


def object_independent(mat):
    """True when ``mat`` shades the same at a corner whatever object carries it (module
    docstring): its corners may be baked on a mesh joined from several objects."""
    if mat is None or not uses_nodes(mat):
        return True
    return not any(_object_dependent(n) for n in _tree_nodes(mat.node_tree))


def _named_layers(mat):
    """Names of the mesh layers the material reads: '' for the render colour attribute."""
    names = set()
    if mat is None or not uses_nodes(mat):
        return names
    for n in _tree_nodes(mat.node_tree):
        if n.type == "VERTEX_COLOR":
            names.add(n.layer_name)
        elif n.type == "ATTRIBUTE":
            names.add(n.attribute_name)
        elif n.type in ("UVMAP", "NORMAL_MAP") and n.uv_map:
            names.add(n.uv_map)
    return names


def _batch_key(me, materials, independent):
    """Which joined batch the copy ``me`` can go in, or None (bake it as itself): copies in one
    batch have the same render UV map and the same layers (name, domain, type) under the names
    their materials read, so the joined mesh feeds each material what the object did."""
    names = set()
    for m in materials:
        if m is None:
            continue
        if m.name_full not in independent:
            independent[m.name_full] = (object_independent(m), _named_layers(m))
        ok, used = independent[m.name_full]
        if not ok:
            return None
        names |= used
    uv = next((l.name for l in me.uv_layers if l.active_render), None)
    render = me.color_attributes.default_color_name or ""
    layers = []
    for n in sorted(names):
        a = me.attributes.get(n or render) if (n or render) else None
        layers.append((n, a.name, a.domain, a.data_type) if a is not None else (n, None, None, None))
    return uv, tuple(layers)


def missing_images(mat):
    """The Image Texture nodes of ``mat`` (not inside node groups) whose image Cycles cannot read
    and renders magenta: no image set, or a file image of no pixels (``Image.size`` is 0 when
    the file cannot be loaded)."""
    if mat is None or not uses_nodes(mat):
        return []
    out = []
    for n in mat.node_tree.nodes:
        if n.type != "TEX_IMAGE" or not any(o.is_linked for o in n.outputs):
            continue
        img = n.image
        if img is None or (img.source == "FILE" and img.packed_file is None and tuple(img.size) == (0, 0)):
            out.append(n)
    return out


def _missing_note(node):
    """A warning of its own subject (the image: said once for every material that uses it)."""
    img = node.image
    if img is None:
        return f"'{node.name}' has no image (Cycles renders it magenta): the inputs it feeds use their own values"
    return warning("cannot be read (Cycles renders it magenta): the inputs it feeds use their own "
                   "values", f"image '{img.name}'", detail=img.filepath or "no file", topic="materials")


def _stand_in(mat, nodes):
    """A temporary copy of ``mat`` without the links out of ``nodes``."""
    copy = mat.copy()
    nt = copy.node_tree
    names = {n.name for n in nodes}
    for link in list(nt.links):
        if link.from_node.name in names:
            nt.links.remove(link)
    return copy


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


def _stand_in_for(m, stand_ins):
    return stand_ins.get(m.name_full, m) if m is not None else None


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


def _copy_objects(objects, depsgraph, made_obs, made_meshes, stand_ins):
    """A temporary object per object of ``objects``: a copy of its evaluated mesh with all its
    attributes, the original materials of its slots (or their ``stand_ins``, by name_full), at its
    world matrix. Appends each mesh to ``made_meshes`` as soon as it exists and (object name,
    copy) to ``made_obs``, so that the caller removes whatever was made even when a later copy
    fails."""
    import bpy

    for obj in objects:
        ob_eval = obj.evaluated_get(depsgraph)
        me = bpy.data.meshes.new_from_object(ob_eval, preserve_all_data_layers=True,
                                             depsgraph=depsgraph)
        made_meshes.append(me)
        _assign_materials(me, [_stand_in_for(_original(s.material), stand_ins)
                               for s in ob_eval.material_slots])
        ob = bpy.data.objects.new(SCENE, me)
        ob.matrix_world = _matrix(world_matrix(obj, depsgraph))
        made_obs.append((obj.name, ob))


def _prepare_bake(scene, obs):
    """Give each mesh of ``obs`` (in ``scene``) the FLOAT_COLOR corner attribute the bakes write
    (active for baking, the render colour attribute unchanged), select them all and make the
    first one active."""
    for ob in obs:
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


@dataclass
class _Run:
    """One object of the bake: a copy of its own (``names`` one name), a join of several copies
    (``ids``: the corner id of every loop, ``counts``: each name's loop count, in id order), or the
    quads of the 'constant' materials (no names)."""

    ob: object
    names: tuple = ()
    ids: np.ndarray | None = None
    counts: tuple = ()


def _join_batches(scene, copies, made_obs, made_meshes):
    """:class:`_Run` objects for ``copies`` ([(object name, copy)], linked in ``scene``): the
    copies of one :func:`_batch_key` joined into one mesh (a new object at the identity, so the
    corners keep their world positions), the others as they are. The join objects are appended
    to ``made_obs`` and their meshes to ``made_meshes``, for :func:`_remove`."""
    import bpy

    independent, groups, runs = {}, {}, []
    for name, ob in copies:
        key = _batch_key(ob.data, list(ob.data.materials), independent)
        if key is None:
            runs.append(_Run(ob, (name,)))
        else:
            groups.setdefault(key, []).append((name, ob))
    vl = scene.view_layers[0]
    for (uv, layers), members in groups.items():
        if len(members) == 1:
            runs.append(_Run(members[0][1], (members[0][0],)))
            continue
        counts, base = [], 0
        for _, ob in members:
            n = len(ob.data.loops)
            ob.data.attributes.new(CORNER_ID, "INT", "CORNER").data.foreach_set(
                "value", np.arange(base, base + n, dtype=np.int32))
            counts.append(n)
            base += n
        me = bpy.data.meshes.new(SCENE)
        made_meshes.append(me)
        target = bpy.data.objects.new(SCENE, me)
        made_obs.append((None, target))
        scene.collection.objects.link(target)
        obs = [target] + [ob for _, ob in members]
        with bpy.context.temp_override(scene=scene, view_layer=vl, active_object=target, object=target,
                                       selected_objects=obs, selected_editable_objects=obs):
            res = bpy.ops.object.join()
        if "FINISHED" not in res:
            raise RuntimeError(f"joining the copies: {res}")
        me = target.data
        if uv is not None and me.uv_layers.get(uv) is not None:
            me.uv_layers[uv].active_render = True
        render = next((a for n, a, _, _ in layers if n == "" and a), None)
        if render is not None and me.color_attributes.get(render) is not None:
            me.color_attributes.default_color_name = render
        ids = np.empty(len(me.loops), np.int32)
        me.attributes[CORNER_ID].data.foreach_get("value", ids)
        if ids.size != base or np.bincount(ids, minlength=base).max(initial=1) != 1:
            raise RuntimeError("joining the copies changed their corners")
        runs.append(_Run(target, tuple(n for n, _ in members), ids, tuple(counts)))
    return runs


def _split_results(runs, kinds, constants):
    """The baked corner values by owner: ({object name: (one array per kind)}, {material
    name_full: (one (3,) per kind)}) for ``kinds``, a list of per-run bakes (rho, emission, ...);
    a joined run's corners go back to each object's loops by their ids, a material's values are
    the mean over the four corners of its quad."""
    corners, materials = {}, {}
    for i, run in enumerate(runs):
        values = [kind[i] for kind in kinds]
        if not run.names:
            for k, m in enumerate(constants):
                materials[m.name_full] = tuple(v[4 * k:4 * k + 4].mean(axis=0) for v in values)
        elif run.ids is None:
            corners[run.names[0]] = tuple(values)
        else:
            full = [np.empty_like(v) for v in values]
            for f, v in zip(full, values):
                f[run.ids] = v
            starts = np.concatenate([[0], np.cumsum(run.counts)])
            for name, a, b in zip(run.names, starts[:-1], starts[1:]):
                corners[name] = tuple(f[a:b] for f in full)
    return corners, materials


def _remove(scene, made_obs, made_meshes):
    """Remove the temporary objects, then their meshes, then the temporary scene."""
    import bpy

    def alive(ids):
        out = []
        for i in ids:
            try:
                i.name
            except ReferenceError:      # joined into another copy: Blender removed it
                continue
            out.append(i)
        return out
    # in batches: one by one, each removal scans every object (5 s of the staircase's relight)
    bpy.data.batch_remove(alive(ob for _, ob in made_obs))
    bpy.data.batch_remove(alive(made_meshes))
    bpy.data.scenes.remove(scene)


def evaluate(objects, depsgraph, constants=(), emit=True, stand_ins=None, sampled=(), runs_out=None):
    """Bake albedo and emission of ``objects`` (original mesh objects) at every corner of their
    evaluated meshes, and of the ``constants`` materials on a quad each, in one temporary scene.
    ``emit`` False: no material can emit, the EMIT bake is skipped (zeros). ``stand_ins``:
    {material name_full: the material baked in its place}. ``sampled``: names of the materials
    (as baked: stand-ins by their own name) whose objects also get their faces' mean emission
    (:func:`.face_emission.sample_faces`).

    Returns ({object name: (rho (L,3), emission (L,3), glossy (L,3))}, {material name_full: (rho,
    em, glossy)}, seconds,
    {object name: (L, 3) each loop's face mean emission}).
    ``runs_out``: a list, given the names of the objects of each run (a join, or one object).
    Raises RuntimeError when Cycles cannot bake (no Cycles, a bake error).
    """
    import bpy

    scene = bpy.data.scenes.new(SCENE)
    made_obs, made_meshes = [], []
    try:
        _configure(scene)
        stand_ins = stand_ins or {}
        _copy_objects(objects, depsgraph, made_obs, made_meshes, stand_ins)
        for _, ob in made_obs:
            scene.collection.objects.link(ob)
        runs = _join_batches(scene, list(made_obs), made_obs, made_meshes)
        if runs_out is not None:
            runs_out += [r.names for r in runs]
        constants = list(constants)
        if constants:
            me = _quad_mesh([_stand_in_for(m, stand_ins) for m in constants])
            made_meshes.append(me)
            made_obs.append((None, bpy.data.objects.new(SCENE, me)))
            scene.collection.objects.link(made_obs[-1][1])
            runs.append(_Run(made_obs[-1][1]))
        if not runs:
            return {}, {}, 0.0, {}
        obs = [r.ob for r in runs]
        _prepare_bake(scene, obs)
        t = time.perf_counter()
        rho = _bake(scene, obs, "DIFFUSE", {"COLOR"})
        glossy = _bake(scene, obs, "GLOSSY", {"COLOR"})
        em = _bake(scene, obs, "EMIT", set()) if emit else [np.zeros_like(r) for r in rho]
        means = sample_faces(scene, runs, set(sampled), _bake, _prepare_bake, made_obs, made_meshes,
                             ATTRIBUTE) if emit and sampled else {}
        seconds = time.perf_counter() - t
        loops = [_per_loop(runs[i].ob.data, m) for i, m in means.items()]
        face_em = _split_results([runs[i] for i in means], [loops], [])[0]
        return (*_split_results(runs, [rho, em, glossy], constants), seconds,
                {name: v[0] for name, v in face_em.items()})
    finally:
        _remove(scene, made_obs, made_meshes)


def _per_loop(me, per_face):
    """(nloops, 3) each loop of mesh ``me`` given its polygon's row of ``per_face``."""
    pt = np.empty(len(me.polygons), np.int64)
    me.polygons.foreach_get("loop_total", pt)
    return per_face[np.repeat(np.arange(pt.size), pt)]


def _matrix(M):
    from mathutils import Matrix

    return Matrix([list(map(float, row)) for row in M])


def _copied(value):
    """``value`` (dicts and tuples of arrays, None) with every array copied: what is kept is
    never what a reader holds."""
    if value is None:
        return None
    if isinstance(value, dict):
        return {k: _copied(x) for k, x in value.items()}
    if isinstance(value, tuple):
        return tuple(_copied(x) for x in value)
    return np.array(value)


def _classified(objects, depsgraph, out, stand_ins):
    """Classify the materials of ``objects`` into ``out.kinds`` (a material with missing images
    through a stand-in, added to ``stand_ins``) and mark the sampled emitters in ``out.sampled``.
    Returns (objects whose materials Cycles evaluates at their corners, the constant materials
    by name, whether any may emit, the names of the materials sampled for emission)."""
    need, constants, emit, sampled = [], {}, False, set()
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
                missing = missing_images(m)
                if missing:
                    stand_ins[m.name_full] = _stand_in(m, missing)
                    kind, why = classify(stand_ins[m.name_full])
                    out.kinds[m.name_full] = (kind, [_missing_note(n) for n in missing] + why)
                else:
                    out.kinds[m.name_full] = classify(m)
            kind = out.kinds[m.name_full][0]
            emits = kind != "plain" and may_emit(_stand_in_for(m, stand_ins))
            emit |= emits
            corners |= kind == "corners"
            if kind == "corners" and emits:
                out.sampled.add(m.name_full)
                sampled.add(_stand_in_for(m, stand_ins).name_full)
            if kind == "constant":
                constants[m.name_full] = m
        if corners:
            need.append(obj)
    return need, constants, emit, sampled


def _disk_key(key) -> str:
    """The cache folder's name for an evaluation kept under ``key`` (an object's or material's,
    or ('run', object name)): this Blender's build in it (Cycles evaluates)."""
    import bpy

    from ...core.runtime.cache import cache_key
    build = f"{bpy.app.version_string} {getattr(bpy.app, 'build_hash', b'')!r}".encode()
    return cache_key(b"shading " + build, key)


def _evaluated(out, need, depsgraph, constants, emit, stand_ins, sampled, cache=None):
    """Fill ``out``'s corners, materials and face emission from Cycles, or from one of the last
    :data:`.shading_key.KEPT` evaluations where nothing they depend on changed: each object and
    constant material by its own key (:func:`.shading_key.object_keys`), so a relight that
    changed an emitter's strength asks Cycles again for that material's objects only (the
    staircase hall: 5 of 755, where every object's evaluation took 7-13 s). An object is asked
    with every object it was joined with the last time (:func:`_join_batches`), in the same
    order, so each run is the one a whole evaluation makes, and its values the same, bit for bit.
    ``cache``: a :class:`...core.runtime.cache.FormFactorCache`; with a folder the evaluations
    are kept there too (on disk only), so a relight in a new process (``--cache``) asks Cycles
    only what changed as well."""
    keys = object_keys(need, depsgraph, constants, emit, stand_ins, sampled)
    if keys is None:                                # cannot be told: ask Cycles for everything
        out.corners, out.materials, out.seconds, out.face_emission = evaluate(
            need, depsgraph, constants, emit, stand_ins, sampled)
        return
    ob_keys, mat_keys = keys
    disk = cache if cache is not None and getattr(cache, "directory", None) else None
    kept = _Kept(disk)
    names = [o.name for o in need]
    ask = {n for n, k in zip(names, ob_keys) if kept(k) is None}
    for n in list(ask):                             # with the objects of their last runs
        run = kept(("run", n))
        ask.update(run if run is not None else ())
    todo = [o for o in need if o.name in ask]
    todo_c = [m for m, k in zip(constants, mat_keys) if kept(k) is None]
    corners, materials, face_em, runs = {}, {}, {}, []
    if todo or todo_c:
        corners, materials, out.seconds, face_em = evaluate(todo, depsgraph, todo_c, emit, stand_ins, sampled, runs)
    gen = {}
    for n, k in zip(names, ob_keys):
        v = (corners.get(n), face_em.get(n)) if n in ask else kept(k)
        gen[k] = _copied(v)
        if v[0] is not None:
            out.corners[n] = v[0]
        if v[1] is not None:
            out.face_emission[n] = v[1]
    asked_c = {m.name_full for m in todo_c}
    for m, k in zip(constants, mat_keys):
        v = materials.get(m.name_full) if m.name_full in asked_c else kept(k)
        gen[k] = _copied(v)
        if v is not None:
            out.materials[m.name_full] = v
    for run in runs:
        for n in run:
            gen[("run", n)] = run
    if disk is not None:                            # what Cycles was asked, for a new process
        for k in [k for n, k in zip(names, ob_keys) if n in ask] + [("run", n) for run in runs for n in run] \
                + [k for m, k in zip(constants, mat_keys) if m.name_full in asked_c]:
            disk.put(_disk_key(k), gen[k], remember=False)
    out.corners, out.materials, out.face_emission = _copied((out.corners, out.materials, out.face_emission))
    _remember(gen, names)


class _Kept:
    """An evaluation kept under a key: the newest of the session's last :data:`.shading_key.KEPT`
    that holds it, else the cache folder's (``disk``, read once per key), else None."""

    def __init__(self, disk):
        self.disk, self.read = disk, {}

    def __call__(self, key):
        for gen in reversed(_EVALUATED.values()):
            if key in gen:
                return gen[key]
        if self.disk is None:
            return None
        if key not in self.read:
            self.read[key] = self.disk.get(_disk_key(key), remember=False)
        return self.read[key]


def _remember(gen, names):
    """Keep ``gen`` (key -> evaluation) as the session's newest evaluation, with the runs of the
    objects ``names`` not asked again carried over from the older ones; the oldest past
    :data:`.shading_key.KEPT` is dropped."""
    for old in _EVALUATED.values():
        for n in names:
            if ("run", n) not in gen and ("run", n) in old:
                gen[("run", n)] = old[("run", n)]
    _EVALUATED[object()] = gen
    while len(_EVALUATED) > KEPT:
        _EVALUATED.popitem(last=False)


def shade(objects, depsgraph, cache=None) -> Shaded:
    """Classify the materials of ``objects`` (original mesh objects) and let Cycles evaluate the
    ones that need it, in one batch, unless nothing that depends on changed since one of the
    last :data:`.shading_key.KEPT` evaluations in this session (:func:`.shading_key.evaluation_key`:
    a relight of new lamps asks Cycles nothing; ``cache``: also what a cache folder kept,
    :func:`_evaluated`). Never raises for a Cycles problem: ``failed`` says why."""
    import bpy

    out = Shaded()
    stand_ins = {}
    try:
        need, constants, emit, sampled = _classified(objects, depsgraph, out, stand_ins)
        if not need and not constants:
            return out
        try:
            _evaluated(out, need, depsgraph, list(constants.values()), emit, stand_ins, sampled, cache)
        except (RuntimeError, AttributeError, TypeError) as ex:   # no Cycles, a bake refused
            out.failed = f"Cycles could not evaluate the materials ({str(ex).splitlines()[0]})"
        return out
    finally:
        for m in stand_ins.values():
            bpy.data.materials.remove(m)
