# SPDX-License-Identifier: GPL-3.0-or-later
"""What Cycles' evaluation of the materials depends on, as a key: a relight asks Cycles again
only when it changed (Blender glue only).

:func:`.shading.evaluate` bakes albedo, glossy albedo and emission at the corners of the objects
whose materials need Cycles (textures, node trees), about half a second on the truck town for
every bake, a relight of new lamp strengths included. Its result depends on the evaluated
meshes (positions, corners, every attribute: UVs, colour attributes, named layers), the
objects' world matrices (object-space texture coordinates), the materials' node trees (every
node's inputs and settings, node groups within, colour ramps and curves), the images they read,
and which materials stand in for others. :func:`evaluation_key` hashes all of that; the
reader keeps the last few evaluations in the session under it (:data:`KEPT`).

Where it cannot be sure, it gives None and Cycles is asked: an image edited in Blender and not
saved (``is_dirty``: its pixels are not hashed), or an image whose file changed on disk since
(its modification time is in the key). A relight in a new process asks Cycles again, unless
the bake's cache folder kept the evaluations (:func:`.shading._evaluated`).
"""
from __future__ import annotations

import hashlib
import os

import numpy as np

from .materials import uses_nodes

__all__ = ["evaluation_key", "object_keys", "KEPT"]

#: Evaluations kept in the session, the most recent ones (each holds per-corner arrays).
KEPT = 2

# node and struct properties that change no colour (the node editor's layout)
_LAYOUT = {"rna_type", "name", "label", "location", "location_absolute", "width", "width_hidden", "height",
           "dimensions", "select", "show_options", "show_preview", "show_texture", "hide", "mute_ui",
           "parent", "use_custom_color", "color", "color_tag", "internal_links", "inputs", "outputs",
           "bl_idname", "bl_label", "bl_description", "bl_icon", "bl_static_type", "bl_width_default",
           "bl_width_min", "bl_width_max", "bl_height_default", "bl_height_min", "bl_height_max",
           "id_data", "is_active_output", "warning_propagation", "interface"}
# per-type property names a mesh attribute's values sit under
_VALUE = {"FLOAT_VECTOR": "vector", "FLOAT2": "vector", "FLOAT_COLOR": "color", "BYTE_COLOR": "color"}
_WIDTH = {"FLOAT_VECTOR": 3, "FLOAT2": 2, "FLOAT_COLOR": 4, "BYTE_COLOR": 4, "QUATERNION": 4,
          "FLOAT4X4": 16, "INT32_2D": 2, "INT16_2D": 2, "INT8": 1}


class _Unsure(Exception):
    """Something the key cannot stand for (an unsaved image edit): ask Cycles."""


def evaluation_key(objects, depsgraph, constants, emit, stand_ins, sampled):
    """A hex digest of what :func:`.shading.evaluate` of these arguments depends on, or None
    where that cannot be told (module docstring)."""
    h = hashlib.blake2b(digest_size=20)
    seen = set()
    try:
        # a stand-in (a copy without its missing images) is made afresh from its material each
        # time: the material and the fact that it stands in say what it is
        h.update(repr((bool(emit), sorted(sampled), sorted(stand_ins or ()))).encode())
        for obj in objects:
            ob = obj.evaluated_get(depsgraph)
            h.update(obj.name_full.encode())
            h.update(np.asarray(ob.matrix_world, dtype=np.float64).tobytes())
            _mesh(h, ob.data)
            for s in ob.material_slots:
                _material(h, getattr(s.material, "original", s.material), seen)
        for m in constants:
            _material(h, m, seen)
    except _Unsure:
        return None
    return h.hexdigest()


def object_keys(objects, depsgraph, constants, emit, stand_ins, sampled):
    """(one key per object of ``objects``, one per material of ``constants``): what the
    evaluation of each alone depends on (as :func:`evaluation_key`: its evaluated mesh, world
    matrix and materials, and the arguments that shape every run: whether anything may emit, the
    stand-ins, the materials sampled), each material hashed once; or None where that cannot be
    told. A relight that changed one emitter's strength asks Cycles again for the objects of
    that material only (:func:`.shading._evaluated`)."""
    common = repr((bool(emit), sorted(sampled), sorted(stand_ins or ()))).encode()
    digests = {}

    def material(m):
        name = None if m is None else m.name_full
        if name not in digests:
            h = hashlib.blake2b(digest_size=20)
            _material(h, m, set())
            digests[name] = h.digest()
        return digests[name]
    try:
        keys = []
        for obj in objects:
            ob = obj.evaluated_get(depsgraph)
            h = hashlib.blake2b(common, digest_size=20)
            h.update(obj.name_full.encode())
            h.update(np.asarray(ob.matrix_world, dtype=np.float64).tobytes())
            _mesh(h, ob.data)
            for s in ob.material_slots:
                h.update(material(getattr(s.material, "original", s.material)))
            keys.append("o" + h.hexdigest())
        consts = ["m" + hashlib.blake2b(common + material(m), digest_size=20).hexdigest() for m in constants]
    except _Unsure:
        return None
    return keys, consts


def _mesh(h, me):
    """Positions, corners, faces and every attribute of mesh ``me`` (UVs and colours included)."""
    for coll, prop, n, dt in ((me.vertices, "co", 3, np.float32), (me.loops, "vertex_index", 1, np.int32),
                              (me.polygons, "loop_start", 1, np.int32), (me.polygons, "loop_total", 1, np.int32),
                              (me.polygons, "material_index", 1, np.int32)):
        a = np.empty(len(coll) * n, dt)
        coll.foreach_get(prop, a)
        h.update(a.tobytes())
    for a in sorted(me.attributes, key=lambda a: a.name):
        h.update(repr((a.name, a.domain, a.data_type)).encode())
        if a.data_type == "STRING" or not len(a.data):
            continue
        w = _WIDTH.get(a.data_type, 1)
        v = np.empty(len(a.data) * w, np.float64)
        try:
            a.data.foreach_get(_VALUE.get(a.data_type, "value"), v)
        except (TypeError, RuntimeError, AttributeError):
            raise _Unsure from None
        h.update(v.tobytes())
    h.update(repr((me.uv_layers.active.name if me.uv_layers.active else None,
                   [l.name for l in me.uv_layers if l.active_render],
                   me.color_attributes.default_color_name, me.color_attributes.active_color_name)).encode())


def _material(h, mat, seen):
    if mat is None:
        h.update(b"none")
        return
    h.update(mat.name_full.encode())
    _struct(h, mat, seen, depth=0, skip={"node_tree", "preview", "grease_pencil", "lineart", "cycles", "eevee",
                                           "texture_paint_images", "texture_paint_slots", "use_nodes"})
    if uses_nodes(mat):
        _tree(h, mat.node_tree, seen)


def _tree(h, tree, seen):
    """Every node (its type, inputs' values and links, settings) and link of node tree ``tree``,
    node groups within once each."""
    key = tree.as_pointer()
    h.update(tree.name_full.encode())
    if key in seen:
        return
    seen.add(key)
    for node in sorted(tree.nodes, key=lambda n: n.name):
        h.update(repr((node.name, node.bl_idname, getattr(node, "mute", False))).encode())
        for sock in list(node.inputs) + list(node.outputs):
            h.update(repr((sock.identifier, sock.is_linked, getattr(sock, "enabled", True))).encode())
            if hasattr(sock, "default_value"):
                h.update(repr(_plain(sock.default_value)).encode())
        _struct(h, node, seen, depth=0)
    for link in tree.links:
        h.update(repr((link.from_node.name, link.from_socket.identifier, link.to_node.name,
                       link.to_socket.identifier, link.is_muted, link.is_valid)).encode())


def _struct(h, s, seen, depth, skip=()):
    """The properties of RNA struct ``s`` that may change a colour: values, nested structs (a
    colour ramp, a curve mapping) to depth 3, images and node trees by what they hold."""
    for p in s.bl_rna.properties:
        k = p.identifier
        if k in skip or k == "rna_type" or (depth == 0 and k in _LAYOUT):   # a ramp's 'color' counts
            continue
        try:
            v = getattr(s, k)
        except (AttributeError, RuntimeError):
            continue
        if p.type == "POINTER":
            if v is None:
                h.update(f"{k}=None".encode())
            elif v.bl_rna.identifier == "Image":
                _image(h, v)
            elif v.bl_rna.identifier.endswith("NodeTree"):
                _tree(h, v, seen)
            elif v.bl_rna.identifier == "Object":           # a Texture Coordinate node's object
                h.update(v.name_full.encode() + np.asarray(v.matrix_world, dtype=np.float64).tobytes())
            elif hasattr(v, "name_full"):
                h.update(f"{k}={v.name_full}".encode())
            elif depth < 3 and v.as_pointer() not in seen:
                seen.add(v.as_pointer())
                _struct(h, v, seen, depth + 1)
        elif p.type == "COLLECTION":
            if depth < 3:
                for item in v:
                    if hasattr(item, "bl_rna") and not hasattr(item, "name_full"):
                        _struct(h, item, seen, depth + 1)
        else:
            h.update(f"{k}={_plain(v)!r}".encode())


def _image(h, img):
    """An image by its name, file (and its time on disk), source, size, colour space and
    settings; an image with unsaved edits cannot be told by these: :class:`_Unsure`."""
    if img.is_dirty:
        raise _Unsure
    path = img.filepath_raw or img.filepath
    try:
        stamp = os.path.getmtime(_abspath(path)) if path and not img.packed_file else None
    except OSError:
        stamp = None
    h.update(repr((img.name_full, path, stamp, img.source, tuple(img.size), img.colorspace_settings.name,
                   img.alpha_mode, getattr(img, "generated_type", None), tuple(getattr(img, "generated_color", ())),
                   img.packed_file.size if img.packed_file else None)).encode())


def _abspath(path):
    import bpy

    return bpy.path.abspath(path)


def _plain(v):
    """A property's value as plain Python (bpy arrays and vectors as tuples)."""
    if isinstance(v, (bool, int, float, str)) or v is None:
        return v
    try:
        return tuple(_plain(x) for x in v)
    except TypeError:
        return repr(v)
