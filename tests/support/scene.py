"""Reading and fingerprinting Blender data in tests: a material's or world's node tree on every
Blender, the baked colour at every face corner, and sha256 fingerprints of the scene and of files
(for "a failed or cancelled bake leaves the scene unchanged", "the input file is byte-identical")."""
from __future__ import annotations

import hashlib

import numpy as np


def node_tree(idblock):
    """The node tree of a material or world: Blender 4.x makes new ones with ``use_nodes`` off and
    no tree; 5.0 always has one (and deprecates ``use_nodes``, so it is not touched there)."""
    if idblock.node_tree is None:
        idblock.use_nodes = True
    return idblock.node_tree


def corner_data(ob, attr="Radiosity"):
    """World positions and RGB of every face corner of a baked object."""
    me = ob.data
    co = np.empty(len(me.vertices) * 3, np.float32)
    me.vertices.foreach_get("co", co)
    lv = np.empty(len(me.loops), np.int32)
    me.loops.foreach_get("vertex_index", lv)
    col = np.empty(len(me.loops) * 4, np.float32)
    me.color_attributes[attr].data.foreach_get("color", col)
    M = np.array(ob.matrix_world)
    pos = co.reshape(-1, 3)[lv] @ M[:3, :3].T + M[:3, 3]
    return pos, col.reshape(-1, 4)[:, :3].astype(np.float64)


# ----------------------------------------------------------------------------- scene fingerprint
_ATTRIBUTE_PROPS = {"FLOAT_VECTOR": ("vector", 3), "FLOAT2": ("vector", 2), "FLOAT_COLOR": ("color", 4),
                    "BYTE_COLOR": ("color", 4), "INT32_2D": ("value", 2), "INT16_2D": ("value", 2),
                    "INT8_2D": ("value", 2), "QUATERNION": ("value", 4), "FLOAT4X4": ("value", 16)}


def _attribute_bytes(attr):
    n = len(attr.data)
    if attr.data_type == "STRING":
        return "\0".join(d.value for d in attr.data).encode("utf-8", "surrogateescape")
    prop, k = _ATTRIBUTE_PROPS.get(attr.data_type, ("value", 1))
    a = np.empty(n * k, np.float64)
    attr.data.foreach_get(prop, a)
    return a.tobytes()


def scene_hash(bpy):
    """sha256 hex of everything a bake must not change when it fails or is cancelled: every mesh
    datablock (vertex positions, edges, face corners and sizes, every attribute with its name,
    domain, type and values, materials, users) and every object (name, type, data, matrix,
    hide_render/hide_viewport/view-layer visibility, library), plus the collection names."""
    h = hashlib.sha256()
    for me in sorted(bpy.data.meshes, key=lambda m: m.name_full):
        h.update(f"mesh {me.name_full} {me.users} {len(me.vertices)} {len(me.edges)} "
                 f"{len(me.loops)} {len(me.polygons)}".encode())
        for coll, prop, k in ((me.vertices, "co", 3), (me.edges, "vertices", 2),
                              (me.loops, "vertex_index", 1), (me.polygons, "loop_start", 1),
                              (me.polygons, "loop_total", 1)):
            a = np.empty(len(coll) * k, np.float64)
            coll.foreach_get(prop, a)
            h.update(a.tobytes())
        for attr in sorted(me.attributes, key=lambda a: a.name):
            h.update(f"attr {attr.name} {attr.domain} {attr.data_type}".encode())
            h.update(_attribute_bytes(attr))
        h.update(repr([m.name_full if m else None for m in me.materials]).encode())
    vl = bpy.context.view_layer
    vl.update()   # objects linked by a script join the view layer at its next sync: not a change
    for ob in sorted(bpy.data.objects, key=lambda o: o.name_full):
        shown = vl.objects.get(ob.name) is not None and not ob.hide_get(view_layer=vl)
        h.update(f"object {ob.name_full} {ob.type} {ob.data.name_full if ob.data else None} "
                 f"{ob.hide_render} {ob.hide_viewport} {shown} {ob.library is not None}".encode())
        h.update(np.array(ob.matrix_world, np.float64).tobytes())
    h.update(repr(sorted(c.name_full for c in bpy.data.collections)).encode())
    return h.hexdigest()


def file_sha256(path):
    """sha256 hex of a file's bytes."""
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()
