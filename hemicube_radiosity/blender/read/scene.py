# SPDX-License-Identifier: GPL-3.0-or-later
"""Blender scene -> core input: depsgraph-evaluated meshes in world space, materials -> rho/emission.

Nothing here modifies the scene: meshes are evaluated with ``evaluated_get(depsgraph).to_mesh()``
and freed again.

Vertex welding rule (the core shares a patch vertex exactly where two faces share a source
vertex, and averages radiosity there). Every face corner starts as its own vertex; corners of two
faces that share an edge are welded at both ends of that edge when the faces use the same
material and either

* both faces are smooth-shaded and the edge is not marked sharp, or
* the faces are coplanar (normals within 1e-3 rad), so a wall cut into several faces stays one
  surface even when it is flat-shaded or its edges are marked sharp.

Everything else (flat-shaded corners of a box, sharp edges between smooth faces, material
borders) is a hard edge: each side gets its own vertex copies and colours do not bleed across.
Faces of an object with a negative-determinant matrix are reversed so they stay counter-clockwise
seen from the front in world space.

What the render sees: ``render_visible_objects(view_layer)`` lists the objects a
render shows (not ``hide_render``, in a collection neither excluded nor disabled in renders),
whatever the viewport shows; an object disabled in viewports is not evaluated by the viewport
depsgraph, so it is read without modifiers and placed by ``world_matrix`` (noted). Viewport and
render modifier settings that differ are noted. An emission colour at strength 0 and negative
emission are no light, each with a note naming the material. Strength 0 is no light in Cycles too;
negative light is not modelled (the solve needs emission >= 0): Cycles subtracts light for an
Emission node's negative strength, and for a Principled BSDF's before Blender 5.0 (5.0 clamps that
one to no light, as here).

Materials: plain colour values are read from the nodes (:func:`material_rho_emission`). Where
that is not what Cycles renders (colours from textures, colour attributes or other nodes; a
Principled BSDF, whose specular layer, metallic and transmission take light from its diffuse
lobe), ``shading.shade`` has Cycles bake its diffuse albedo and emission, per corner or per
material, on temporary copies. :class:`ObjectSource` carries ``corner_rho`` / ``corner_emission``
for every corner of ``mesh.face_indices``; the mesh's ``face_rho`` / ``face_emission`` are their
per-face means.

:class:`SceneInput` carries ``lights`` and ``world`` that ``blender.read.lights.read_lights``
fills; the bake passes them on to ``core.pipeline.bake(lights=, world=)``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...core.mesh.patches import MeshInput
from ...core.runtime.errors import RadiosityError
from . import shading

__all__ = ["ReadError", "ObjectSource", "SceneInput", "material_rho_emission", "read_object",
           "read_scene", "weld_corners", "RHO_MAX", "render_visible_objects", "is_render_visible",
           "world_matrix", "GEOMETRY_TYPES", "check_writable"]

RHO_MAX = 0.999          # the core needs reflectivity < 1 in every band
COPLANAR_COS = float(np.cos(1e-3))
DEFAULT_RHO = (0.8, 0.8, 0.8)

# Object types a render draws as surfaces: meshes, and text, curves, surfaces and metaballs, which
# are read as the mesh Blender evaluates them to (a text object is geometry to an artist). A curve
# without bevel, extrusion or fill (a guide), or a metaball whose surface belongs to its family's
# base object, has no faces: it is left out with a note.
GEOMETRY_TYPES = frozenset({"MESH", "FONT", "CURVE", "SURFACE", "META"})
_TYPE_NAMES = {"FONT": "text", "CURVE": "curve", "SURFACE": "surface", "META": "metaball"}
# attribute names Blender keeps for itself (fixed type and domain) on every mesh
_RESERVED_ATTRIBUTES = frozenset({"position", "material_index", "sharp_face", "sharp_edge"})


class ReadError(RadiosityError, ValueError):
    """The scene cannot be baked; the message names the object."""


@dataclass
class ObjectSource:
    """One object as the core sees it, plus what the writer needs to map results back."""

    name: str                 # object name (unique in the file)
    mesh: MeshInput           # world space, split at hard edges
    corner_loop: np.ndarray   # (L,) evaluated-mesh loop index of every mesh.face_indices entry
    matrix_world: np.ndarray  # (4, 4)
    flipped: bool             # negative determinant: face rings were reversed
    bake: bool                # False: occluder/emitter only, nothing is written for it
    eval_counts: tuple        # (vertices, loops, polygons) of the evaluated mesh
    notes: list = field(default_factory=list)   # what was approximated, one short line each
    corner_rho: np.ndarray = None       # (L, 3) reflectance at every mesh.face_indices corner
    corner_emission: np.ndarray = None  # (L, 3) emitted radiance there (mesh.face_rho/_emission
                                        # are their per-face means)


@dataclass
class SceneInput:
    objects: list
    lights: tuple = ()        # core.light.lamps objects, filled by blender.read.lights.read_lights
    world: object = None
    skipped: list = field(default_factory=list)   # notes of objects left out ("name: why")

    @property
    def meshes(self):
        return [o.mesh for o in self.objects]

    def notes(self):
        return list(self.skipped) + [f"{o.name}: {n}" for o in self.objects for n in o.notes]


# ----------------------------------------------------------------------------- materials
def rgb(v):
    """(3,) float64 of a colour value (a socket's default, a light's colour) or of a float."""
    try:
        return np.array([float(v[0]), float(v[1]), float(v[2])])
    except TypeError:  # a float socket
        return np.array([float(v)] * 3)


def _input(node, *names):
    for n in names:
        s = node.inputs.get(n)
        if s is not None:
            return s
    return None


def _value(node, notes, *names, default=0.0, color=True):
    s = _input(node, *names)
    if s is None:
        return np.full(3, default) if color else default
    if s.is_linked:
        notes.append(f"{node.name} '{s.name}' is linked (texture/nodes); used its unlinked value")
    if color:
        return rgb(s.default_value)
    return float(s.default_value)


def follow(socket):
    """The node and output socket feeding ``socket``, skipping reroutes; (None, None) if unlinked
    (or the link or the node feeding it is muted)."""
    while socket is not None and socket.is_linked:
        link = socket.links[0]
        if not link.is_valid or link.is_muted:
            return None, None
        node = link.from_node
        if node.type == "REROUTE":
            socket = node.inputs[0]
            continue
        if getattr(node, "mute", False):
            return None, None
        return node, link.from_socket
    return None, None


def _note_unlit(node, em, strength, color_name, strength_name, notes):
    """An emission colour with strength 0 is no light in Cycles; say so (Blender 4.2's OBJ
    importer turns an .mtl ``Ke`` into exactly that: the colour, strength 0)."""
    if strength == 0 and np.any(em > 0):
        s = node.inputs.get(strength_name)
        if s is not None and s.is_linked:
            return                       # already noted as linked
        notes.append(f"{node.name} has {color_name} ({em[0]:.3g}, {em[1]:.3g}, {em[2]:.3g}) but "
                     f"{strength_name} 0: no light (as in Cycles); raise the strength to make it glow")


def _principled_clamps_negative_emission():
    """Whether this Blender's Cycles renders a Principled BSDF's negative Emission Strength as no
    light (5.0) rather than as negative light (4.2, 4.5)."""
    import bpy

    return bpy.app.version >= (5, 0, 0)


def _principled(node, notes):
    """(rho, emission) of a Principled BSDF read from its values (the fast path; Cycles' own
    albedo replaces rho when :mod:`.shading` can bake it)."""
    rho = _value(node, notes, "Base Color")
    for name in ("Metallic", "Transmission Weight", "Transmission"):
        s = node.inputs.get(name)
        if s is not None and (s.is_linked or float(s.default_value) > 0):
            notes.append(f"{node.name} '{name}' ignored (diffuse only)")
            break
    em = _value(node, notes, "Emission Color", "Emission")
    strength = _value(node, notes, "Emission Strength", default=1.0, color=False)
    if strength < 0 and np.any(em > 0):
        if _principled_clamps_negative_emission():
            # Cycles 5.0 clamps a Principled BSDF's emission at 0 (measured: no light, bakes 0)
            notes.append(f"{node.name} Emission Strength {strength:g} is negative: no light "
                         "(as in Cycles)")
        else:
            # Cycles 4.x emits negative light there, as from an Emission node (measured on
            # 4.2.23 and 4.5.15: a strength -2 panel bakes -2 x its colour and takes from the
            # floor exactly what strength +2 adds); the solve needs emission >= 0
            notes.append(f"{node.name} Emission Strength {strength:g} is negative: Cycles "
                         "subtracts light there, this bake takes it as no light")
        return rho, np.zeros(3)
    _note_unlit(node, em, strength, "Emission Color", "Emission Strength", notes)
    return rho, em * strength


def _shader(node, out_socket, mat, notes, depth=0):
    """(rho, emission) of the shader that ``node`` outputs."""
    zero = np.zeros(3)
    if depth > 16:
        notes.append("shader tree too deep; treated as black")
        return zero, zero
    t = node.type
    if t == "BSDF_PRINCIPLED":
        return _principled(node, notes)
    if t == "BSDF_DIFFUSE":
        return _value(node, notes, "Color"), zero
    if t == "EMISSION":
        em = _value(node, notes, "Color")
        strength = _value(node, notes, "Strength", default=1.0, color=False)
        if strength < 0 and np.any(em > 0):
            # Cycles really emits negative light from an Emission node (it darkens what it sees);
            # the solve needs emission >= 0
            notes.append(f"{node.name} Strength {strength:g} is negative: Cycles subtracts light there, "
                         "this bake takes it as no light")
            return zero, zero
        _note_unlit(node, em, strength, "Color", "Strength", notes)
        return zero, em * strength
    if t in ("MIX_SHADER", "ADD_SHADER"):
        shaders = [s for s in node.inputs if s.type == "SHADER"]
        parts = []
        for s in shaders[:2]:
            n2, o2 = follow(s)
            parts.append(_shader(n2, o2, mat, notes, depth + 1) if n2 is not None else (zero, zero))
        while len(parts) < 2:
            parts.append((zero, zero))
        if t == "ADD_SHADER":
            return parts[0][0] + parts[1][0], parts[0][1] + parts[1][1]
        fac = float(np.clip(_value(node, notes, "Fac", "Factor", color=False), 0.0, 1.0))
        return ((1 - fac) * parts[0][0] + fac * parts[1][0], (1 - fac) * parts[0][1] + fac * parts[1][1])
    if out_socket is not None and out_socket.type in ("RGBA", "VECTOR", "VALUE") and t in ("RGB", "VALUE"):
        # A colour wired straight into the output renders as emission of that colour.
        v = out_socket.default_value
        c = np.array([float(v[0]), float(v[1]), float(v[2])]) if out_socket.type != "VALUE" else np.full(3, float(v))
        return zero, c
    notes.append(f"shader '{node.name}' ({node.bl_idname}) approximated by the viewport colour")
    return np.array(mat.diffuse_color[:3], float), zero


def _uses_nodes(mat):
    """Blender 5 materials always use their node tree (``use_nodes`` is deprecated there)."""
    import bpy

    if bpy.app.version >= (5, 0, 0):
        return mat.node_tree is not None
    return bool(mat.use_nodes) and mat.node_tree is not None


def material_rho_emission(mat):
    """(rho (3,), emission (3,), notes) of a material, in scene-linear radiance units.

    Principled BSDF: Base Color; Emission Color x Emission Strength. Diffuse BSDF: Color.
    Emission: Color x Strength. Mix/Add shader: mixed/added. Unlinked inputs only (a linked
    input contributes its unlinked value, noted). No material: grey 0.8. Material without a node
    tree: its viewport colour. Reflectivity is clipped to [0, 0.999] (noted).
    """
    notes = []
    zero = np.zeros(3)
    if mat is None:
        notes.append("no material; grey 0.8")
        rho, em = np.array(DEFAULT_RHO), zero
    else:
        nt = mat.node_tree if _uses_nodes(mat) else None
        if nt is None:
            notes.append(f"material '{mat.name}' has no nodes; used its viewport colour")
            rho, em = np.array(mat.diffuse_color[:3], float), zero
        else:
            outs = [n for n in nt.nodes if n.type == "OUTPUT_MATERIAL" and n.target in ("ALL", "CYCLES")]
            out = next((n for n in outs if n.is_active_output), outs[0] if outs else None)
            if out is None:
                notes.append(f"material '{mat.name}' has no output node; used its viewport colour")
                rho, em = np.array(mat.diffuse_color[:3], float), zero
            else:
                node, sock = follow(out.inputs["Surface"])
                if node is None:
                    notes.append(f"material '{mat.name}' has nothing connected to Surface; black")
                    rho, em = zero, zero
                else:
                    sub = []
                    rho, em = _shader(node, sock, mat, sub)
                    notes += [f"material '{mat.name}': {s}" for s in sub]
    rho = np.asarray(rho, float)
    em = np.asarray(em, float)
    where = f" in '{mat.name}'" if mat is not None else ""
    for what, v in (("reflectivity", rho), ("emission", em)):
        if not np.all(np.isfinite(v)):
            notes.append(f"{what} {_fmt(v)} is not a number{where}: taken as 0 there, as Cycles "
                         "does; fix the value")
    rho = np.where(np.isfinite(rho), rho, 0.0)
    em = np.where(np.isfinite(em), em, 0.0)
    if np.any(em < 0):
        notes.append(f"negative emission {tuple(np.round(em, 3))} taken as no light"
                     + (f" in '{mat.name}'" if mat is not None else ""))
        em = np.maximum(em, 0.0)
    if np.any(rho > RHO_MAX) or np.any(rho < 0):
        notes.append(f"reflectivity {tuple(np.round(rho, 3))} clipped to [0, {RHO_MAX}]"
                     + (f" in '{mat.name}'" if mat is not None else ""))
        rho = np.clip(rho, 0.0, RHO_MAX)
    return rho, em, notes


# notes of material_rho_emission that a Cycles evaluation makes moot (it reads what they name)
_FIXED_BY_CYCLES = ("is linked (texture/nodes)", "by the viewport colour", "ignored (diffuse only)",
                    "has no nodes; used its viewport colour")


def _corner_materials(name, mats, corner_mat, corner_loop, shaded, used):
    """(corner_rho (L,3), corner_emission (L,3), notes) in the order of ``corner_loop``.

    Plain materials give their :func:`material_rho_emission` value at every corner; a material
    that :func:`.shading.classify` sends to Cycles gives Cycles' value: one per material
    ('constant'), or the object's baked corners ('corners')."""
    L = corner_loop.size
    corner_rho, corner_em = np.empty((L, 3)), np.empty((L, 3))
    baked = shaded.corners.get(name)
    notes = []
    if baked is not None and baked[0].shape[0] != L:
        notes.append("Cycles' corner colours did not match the mesh read; used per-material values")
        baked = None
    for k, m in enumerate(mats):
        sel = corner_mat == k
        rho, em, n = material_rho_emission(m)
        kind, why = shaded.kinds.get(m.original.name_full if m is not None else None, ("plain", []))
        label = f"material '{m.name}'" if m is not None else ""
        if kind != "plain" and shaded.failed:
            n.append(f"{label}: {shaded.failed}; its unlinked values used")
        elif kind == "constant" and m.original.name_full in shaded.materials:
            n = [s for s in n if not any(f in s for f in _FIXED_BY_CYCLES)]
            c_rho, c_em = shaded.materials[m.original.name_full]
            n += [f"{label}: {w}" for w in why]
            if np.any(np.abs(c_rho - rho) > 0.005 * np.maximum(rho, 1e-3)):
                n.append(f"{label}: diffuse reflectance {_fmt(c_rho)} as Cycles evaluates it (its "
                         f"colour {_fmt(rho)}; the specular layer, metallic or transmission reflect "
                         "the rest, which is not baked)")
            rho, em = _clean(c_rho, c_em, label, n)
        elif kind == "corners" and baked is not None:
            n = [s for s in n if not any(f in s for f in _FIXED_BY_CYCLES)]
            n += [f"{label}: {w}, evaluated by Cycles at the corners" for w in why]
            r, e = _clean(baked[0][corner_loop[sel]], baked[1][corner_loop[sel]], label, n)
            corner_rho[sel], corner_em[sel] = r, e
            if k in used:
                notes += [s for s in n if s not in notes]
            continue
        elif kind == "corners":
            n.append(f"{label}: not evaluated by Cycles; its unlinked values used")
        corner_rho[sel], corner_em[sel] = rho, em
        if k in used:
            notes += [s for s in n if s not in notes]
    return corner_rho, corner_em, notes


def _fmt(c):
    return "(" + ", ".join(f"{x:.3g}" for x in c) + ")"


def _clean(rho, em, label, notes):
    """Cycles' values made what the solve needs: finite, emission >= 0, reflectance in [0, RHO_MAX]."""
    if not (np.all(np.isfinite(rho)) and np.all(np.isfinite(em))):
        notes.append(f"{label}: Cycles evaluates it to a value that is not a number at some corners; "
                     "taken as 0 there")
        rho = np.where(np.isfinite(rho), rho, 0.0)
        em = np.where(np.isfinite(em), em, 0.0)
    if np.any(em < 0):
        # the node reader has already named the negative strength (an Emission node's, or a
        # Principled BSDF's before 5.0, whose negative light Cycles bakes too): one note, not two
        if not any(s.startswith(f"{label}: ") and "is negative" in s for s in notes):
            notes.append(f"{label}: negative emission (an Emission node of negative strength): Cycles "
                         "subtracts light there, this bake takes it as no light")
        em = np.maximum(em, 0.0)
    if np.any(rho > RHO_MAX + 1e-6) or np.any(rho < 0):
        notes[:] = [s for s in notes if not (s.startswith("reflectivity (") and "clipped to" in s)]
        notes.append(f"{label}: reflectivity up to {float(np.max(rho)):.3g} clipped to [0, {RHO_MAX}]")
    return np.clip(rho, 0.0, RHO_MAX), em


# ----------------------------------------------------------------------------- welding
def _union(n, i, j):
    """Connected-component labels of n nodes joined by pairs (i, j): hook + pointer jumping."""
    lab = np.arange(n)
    if i.size == 0:
        return lab
    while True:
        li, lj = lab[i], lab[j]
        if np.array_equal(li, lj):
            return lab
        m = np.minimum(li, lj)
        np.minimum.at(lab, li, m)
        np.minimum.at(lab, lj, m)
        while True:
            nl = lab[lab]
            if np.array_equal(nl, lab):
                break
            lab = nl


def weld_corners(loop_vert, loop_edge, poly_start, poly_total, face_material, face_smooth,
                 edge_sharp, face_normal):
    """Vertex id per loop (corner) following the welding rule in the module docstring.

    Returns (corner_vertex (L,), source_vertex (V',)): new vertex ids and the original vertex each
    one copies.
    """
    L = loop_vert.size
    F = poly_start.size
    loop_face = np.repeat(np.arange(F), poly_total)
    pos = np.arange(L) - poly_start[loop_face]
    nxt = np.where(pos == poly_total[loop_face] - 1, poly_start[loop_face], np.arange(L) + 1)
    order = np.argsort(loop_edge, kind="stable")
    es = loop_edge[order]
    first = order[np.searchsorted(es, es, side="left")]
    l1, l2 = first, order
    keep = l1 != l2
    l1, l2 = l1[keep], l2[keep]
    f1, f2 = loop_face[l1], loop_face[l2]
    e = loop_edge[l2]
    coplanar = np.einsum("ij,ij->i", face_normal[f1], face_normal[f2]) > COPLANAR_COS
    smooth = face_smooth[f1] & face_smooth[f2] & ~edge_sharp[e]
    weld = (face_material[f1] == face_material[f2]) & (smooth | coplanar)
    l1, l2 = l1[weld], l2[weld]
    same = loop_vert[l1] == loop_vert[l2]
    i = np.concatenate([l1, nxt[l1]])
    j = np.concatenate([np.where(same, l2, nxt[l2]), np.where(same, nxt[l2], l2)])
    ok = loop_vert[i] == loop_vert[j]          # guards degenerate faces
    lab = _union(L, i[ok], j[ok])
    uniq, first_loop, corner_vertex = np.unique(lab, return_index=True, return_inverse=True)
    return corner_vertex.reshape(-1), loop_vert[first_loop]


# ----------------------------------------------------------------------------- render visibility
def _render_collections(view_layer):
    """Collections whose objects the render sees in ``view_layer``: the layer-collection tree
    without excluded layer collections and collections disabled in renders (and everything under
    them). The viewport's switches (eye, monitor) do not matter to a render."""
    out, stack = [], [view_layer.layer_collection]
    while stack:
        lc = stack.pop()
        if lc.exclude or lc.collection.hide_render:
            continue
        out.append(lc.collection)
        stack.extend(lc.children)
    return out


def render_visible_objects(view_layer, types=None):
    """Original objects that a render of ``view_layer`` shows, in view-layer order: in a
    collection the render sees (not excluded, not disabled in renders up the tree) and not
    ``hide_render`` themselves, whatever their viewport visibility (hidden with H, disabled in
    viewports). ``types``: e.g. {'MESH'} or {'LIGHT'} (default: all). Instances made by
    instancers are not listed (the depsgraph has them)."""
    names = set()
    for coll in _render_collections(view_layer):
        names.update(o.name for o in coll.objects)
    return [o for o in view_layer.objects
            if o.name in names and not o.hide_render and (types is None or o.type in types)]


def is_render_visible(ob, view_layer):
    """True when a render of ``view_layer`` shows the original object ``ob``."""
    ob = getattr(ob, "original", ob)
    if ob.hide_render or view_layer.objects.get(ob.name) is None:
        return False
    return any(c.objects.get(ob.name) is not None for c in _render_collections(view_layer))


def world_matrix(obj, depsgraph):
    """(4, 4) world matrix of ``obj`` as the render places it. Objects disabled in viewports are
    not evaluated by the viewport depsgraph and their stored ``matrix_world`` may be stale (never
    computed for an object made by a script), so theirs is rebuilt from location/rotation/scale
    and the parent chain (constraints and parent bones/vertices are not applied)."""
    ob_eval = obj.evaluated_get(depsgraph)
    if getattr(ob_eval, "is_evaluated", True):
        return np.array(ob_eval.matrix_world, dtype=np.float64)
    obj = getattr(obj, "original", obj)
    M = np.array(obj.matrix_basis, dtype=np.float64)
    if obj.parent is not None:
        P = world_matrix(obj.parent, depsgraph)
        M = P @ np.array(obj.matrix_parent_inverse, dtype=np.float64) @ M
    return M


def unevaluated_note(obj):
    """Why the matrix of an object the viewport does not evaluate may differ from the render's."""
    what = [w for w, on in (("constraints", len(obj.constraints) > 0),
                            ("animation", obj.animation_data is not None),
                            ("parent " + obj.parent_type.lower(),
                             obj.parent is not None and obj.parent_type != "OBJECT")) if on]
    if what:
        return (f"disabled in viewports, so not evaluated; placed by its location/rotation/scale "
                f"and parent only ({', '.join(what)} not applied)")
    return None


def _render_notes(obj, ob_eval):
    """What the render sees differently from the viewport-evaluated mesh we read."""
    notes = []
    mods = [m for m in obj.modifiers]
    if not getattr(ob_eval, "is_evaluated", True):
        n = unevaluated_note(obj)
        if n:
            notes.append(n)
        if any(m.show_render for m in mods):
            notes.append("disabled in viewports (not evaluated there): read without its modifiers; "
                         "enable it in viewports for an exact bake")
            return notes
    for m in mods:
        if m.show_render != m.show_viewport:
            notes.append(f"modifier '{m.name}' is {'on' if m.show_render else 'off'} in renders but "
                         f"{'on' if m.show_viewport else 'off'} in the viewport; the viewport's mesh was used")
        elif m.show_render and m.type in ("SUBSURF", "MULTIRES") and m.levels != m.render_levels:
            notes.append(f"modifier '{m.name}': viewport level {m.levels} used (renders use {m.render_levels})")
    off = [k for k in ("diffuse", "shadow") if not getattr(obj, f"visible_{k}", True)]
    if off:
        notes.append(f"not visible to {' and '.join(off)} rays in Cycles; here it still reflects and "
                     "casts shadows like any surface")
    return notes


# ----------------------------------------------------------------------------- objects
def _mesh_arrays(me):
    nv, nl, nf, ne = len(me.vertices), len(me.loops), len(me.polygons), len(me.edges)
    co = np.empty(nv * 3, np.float32)
    me.vertices.foreach_get("co", co)
    lv = np.empty(nl, np.int32)
    me.loops.foreach_get("vertex_index", lv)
    le = np.empty(nl, np.int32)
    me.loops.foreach_get("edge_index", le)
    ps = np.empty(nf, np.int32)
    me.polygons.foreach_get("loop_start", ps)
    pt = np.empty(nf, np.int32)
    me.polygons.foreach_get("loop_total", pt)
    mi = np.empty(nf, np.int32)
    me.polygons.foreach_get("material_index", mi)
    sm = np.empty(nf, bool)
    me.polygons.foreach_get("use_smooth", sm)
    sh = np.zeros(ne, bool)
    if ne:
        me.edges.foreach_get("use_edge_sharp", sh)
    return (co.reshape(-1, 3).astype(np.float64), lv.astype(np.int64), le.astype(np.int64),
            ps.astype(np.int64), pt.astype(np.int64), mi.astype(np.int64), sm, sh)


def _newell(verts, corner_vertex, poly_start, poly_total):
    """Unit face normals (F,3) from world-space corners."""
    L = corner_vertex.size
    loop_face = np.repeat(np.arange(poly_start.size), poly_total)
    pos = np.arange(L) - poly_start[loop_face]
    nxt = np.where(pos == poly_total[loop_face] - 1, poly_start[loop_face], np.arange(L) + 1)
    a, b = verts[corner_vertex], verts[corner_vertex[nxt]]
    n = np.zeros((poly_start.size, 3))
    np.add.at(n, loop_face, np.cross(a, b))
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, ln, out=np.zeros_like(n), where=ln > 0)


def _within_faces(corner, offsets, per_face):
    """``corner`` where it varies within a face (a texture), else None (the faces say it all)."""
    if corner is None or not len(per_face):
        return None
    spread = np.abs(corner - np.repeat(per_face, np.diff(offsets), axis=0)).max()
    return corner if spread > 1e-6 else None


def read_object(obj, depsgraph, bake=True, shaded=None) -> ObjectSource:
    """One mesh object, evaluated (modifiers applied), in world space. ``shaded``: the
    :func:`.shading.shade` batch that holds this object's Cycles evaluations (None: evaluate this
    object alone)."""
    if obj.type not in GEOMETRY_TYPES:
        raise ReadError(f"'{obj.name}' is not a mesh object (it is a {obj.type.lower()})")
    ob_eval = obj.evaluated_get(depsgraph)
    me = ob_eval.to_mesh()
    if me is None:
        raise ReadError(f"'{obj.name}' has no faces: Blender gives no mesh for this "
                        f"{_TYPE_NAMES.get(obj.type, 'object')}")
    try:
        co, lv, le, ps, pt, mi, sm, sh = _mesh_arrays(me)
        counts = (len(me.vertices), len(me.loops), len(me.polygons))
        mats = [s.material for s in ob_eval.material_slots] or [None]
    finally:
        ob_eval.to_mesh_clear()
    if ps.size == 0:
        raise ReadError(f"'{obj.name}' has no faces" + _no_faces_why(obj))
    used = np.zeros(len(co), bool)
    used[lv] = True
    bad = np.flatnonzero(used & ~np.all(np.isfinite(co), axis=1))
    if bad.size:
        raise ReadError(f"'{obj.name}': {bad.size} vertex position(s) are not finite (NaN or "
                        f"infinity), first vertex {int(bad[0])}: fix or delete them")
    M = world_matrix(obj, depsgraph)
    if not np.all(np.isfinite(M)):
        raise ReadError(f"'{obj.name}': its transform is not finite (NaN or infinity in location, "
                        "rotation or scale)")
    co[~used] = 0.0      # loose vertices are not read; a NaN there must not spread
    verts_w = co @ M[:3, :3].T + M[:3, 3]
    det = float(np.linalg.det(M[:3, :3]))
    if abs(det) < 1e-300:
        raise ReadError(f"'{obj.name}' has a zero scale; nothing to bake")
    flipped = det < 0
    mi = np.clip(mi, 0, len(mats) - 1)
    normals = _newell(verts_w, lv, ps, pt) * (-1.0 if flipped else 1.0)
    corner_vertex, src_vertex = weld_corners(lv, le, ps, pt, mi, sm, sh, normals)
    # face rings in face order; reversed per face when the matrix mirrors
    F = ps.size
    loop_face = np.repeat(np.arange(F), pt)
    pos = np.arange(lv.size) - ps[loop_face]
    corner_loop = ps[loop_face] + (pt[loop_face] - 1 - pos if flipped else pos)
    offsets = np.concatenate([[0], np.cumsum(pt)])
    if shaded is None:
        shaded = shading.shade([obj], depsgraph)
    notes = _render_notes(obj, ob_eval)
    corner_rho, corner_em, mat_notes = _corner_materials(obj.name, mats, mi[loop_face], corner_loop,
                                                          shaded, set(np.unique(mi).tolist()))
    notes += [s for s in mat_notes if s not in notes]
    rho = np.add.reduceat(corner_rho, offsets[:-1], axis=0) / pt[:, None]
    em = np.add.reduceat(corner_em, offsets[:-1], axis=0) / pt[:, None]
    mesh = MeshInput(verts_w[src_vertex], offsets, corner_vertex[corner_loop], rho, em, obj.name,
                     _within_faces(corner_rho, offsets, rho), _within_faces(corner_em, offsets, em))
    return ObjectSource(obj.name, mesh, corner_loop, M, flipped, bake, counts, notes,
                        corner_rho, corner_em)


def read_scene(depsgraph, objects, others=()) -> SceneInput:
    """``objects`` are baked; ``others`` take part as occluders/emitters only. The materials that
    Cycles must evaluate are evaluated for all of them in one batch (:func:`.shading.shade`)."""
    shaded = shading.shade(list(objects) + list(others), depsgraph)
    out, skipped = [], []
    for o in objects:
        try:
            out.append(read_object(o, depsgraph, True, shaded))
        except ReadError as ex:
            if o.type == "MESH" or "has no faces" not in str(ex):
                raise
            # a guide curve, a metaball whose surface is its family's: nothing to bake here
            skipped.append(f"{ex}; left out")
    if objects and not any(s.bake for s in out):
        raise ReadError(skipped[0].rsplit(";", 1)[0] if len(skipped) == 1 else
                        "none of the selected objects has faces: "
                        + ", ".join(repr(o.name) for o in objects))
    for o in others:
        try:
            out.append(read_object(o, depsgraph, False, shaded))
        except ReadError:
            continue  # an occluder without faces simply does not occlude
    return SceneInput(out, skipped=skipped)


def _no_faces_why(obj):
    """Why a non-mesh object evaluated to no faces, for its error line or note."""
    if obj.type in ("CURVE", "FONT"):
        return " (a curve without bevel, extrusion or fill makes no surface)" if obj.type == "CURVE" else ""
    if obj.type == "META":
        return " (a metaball's surface belongs to its family's base object, the one without a number)"
    return ""


def check_writable(objects, settings):
    """Raise :class:`ReadError` naming the object when the bake's result could not be written
    the way ``settings`` asks, before any work (so a refused bake changes nothing); returns the
    notes to add (an existing colour attribute replaced in place)."""
    name = settings.attribute_name
    if not name.strip():
        raise ReadError("the attribute name is empty: give the colour attribute a name")
    if name.startswith(".") or name in _RESERVED_ATTRIBUTES:
        raise ReadError(f"the attribute name '{name}' is one Blender keeps for itself; choose another")
    notes = []
    if settings.output_mode != "in_place":
        return notes
    for ob in objects:
        if ob.type != "MESH":
            raise ReadError(f"'{ob.name}' is a {_TYPE_NAMES.get(ob.type, ob.type.lower())} object: "
                            "in place writes to a mesh; bake it as a copy (Output: Baked Copy)")
        lib = ob.library or ob.data.library
        if lib is not None or ob.override_library is not None:
            where = f" from library '{lib.name}'" if lib is not None else " (a library override)"
            raise ReadError(f"'{ob.name}' is linked{where}, read-only here: bake it as a copy "
                            "(Output: Baked Copy), or make it local to bake in place")
        me = ob.data
        attr = me.attributes.get(name)
        if attr is None:
            continue
        if me.color_attributes.get(name) is None:
            raise ReadError(f"mesh '{me.name}' of '{ob.name}' already has a non-colour attribute "
                            f"named '{name}' ({attr.data_type} on {attr.domain.lower()}s): choose "
                            "another attribute name, or rename or remove it")
        if (attr.data_type, attr.domain) != ("FLOAT_COLOR", "CORNER"):
            notes.append(f"{ob.name}: its colour attribute '{name}' ({attr.data_type} on "
                         f"{attr.domain.lower()}s) is replaced by the bake's (FLOAT_COLOR on corners)")
    return notes
