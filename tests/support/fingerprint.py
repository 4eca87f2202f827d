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
