"""A mesh's geometry into a hash: what tests that prove a bake leaves the user's data alone
compare before and after (needs bpy)."""
import numpy as np


def hash_mesh(h, me):
    """Feed mesh ``me``'s name, vertex positions, loops, polygon starts and material indices to
    hash ``h`` (a hashlib object)."""
    h.update(me.name.encode())
    for coll, prop, n in ((me.vertices, "co", 3), (me.loops, "vertex_index", 1),
                          (me.polygons, "loop_start", 1), (me.polygons, "material_index", 1)):
        a = np.empty(len(coll) * n, np.float64)
        coll.foreach_get(prop, a)
        h.update(a.tobytes())


def hash_user_mesh(h, me):
    """:func:`hash_mesh`, and mesh ``me``'s UV maps (names and values), the active one, its
    attributes (names, domains, types) and its material slots, into hash ``h``."""
    hash_mesh(h, me)
    for layer in me.uv_layers:
        a = np.empty(len(me.loops) * 2, np.float64)
        layer.data.foreach_get("uv", a)
        h.update(layer.name.encode() + a.tobytes())
    h.update(repr(sorted((a.name, a.domain, a.data_type) for a in me.attributes)).encode())
    h.update(repr([m.name if m else None for m in me.materials]).encode())
    h.update(repr(me.uv_layers.active.name if me.uv_layers.active else None).encode())
