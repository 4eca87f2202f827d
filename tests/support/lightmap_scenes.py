"""A low-poly room for lightmap tests: walls, floor and ceiling as single quads (one object), a
block on the floor (one object) and an emitting panel under the ceiling (not baked), each mesh
with a texture-style UV map ``UVMap`` (every face the whole square: overlapping, no use as a
lightmap)."""
from __future__ import annotations

import numpy as np

from tools import cycles_reference as cr

# corner i of a box is (x, y, z) bits of i; faces wound to face out of the box
_OUT = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
SIZE = (4.0, 3.0, 2.5)       # the room, metres
LAMP_Z = SIZE[2] - 0.05


def box(lo, hi, inward, material, name):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    bits = np.array([[(i >> k) & 1 for k in range(3)] for i in range(8)], float)
    verts = lo + bits * (hi - lo)
    faces = [f[::-1] if inward else f for f in _OUT]
    ob = cr.mesh_object(verts, faces, material, name)
    square_uvs(ob)
    return ob


def square_uvs(ob, name="UVMap"):
    """Every face of ``ob`` the whole UV square (a tiled texture's UVs)."""
    me = ob.data
    total = np.empty(len(me.polygons), np.int64)
    me.polygons.foreach_get("loop_total", total)
    corners = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    uv = np.concatenate([corners[:n] for n in total])
    me.uv_layers.new(name=name).data.foreach_set("uv", uv.ravel())


def room():
    """(room, block, lamp), in a new empty scene, no world light."""
    cr.new_empty_scene()
    cr.set_world((0.0, 0.0, 0.0), 0.0)
    r = box((0, 0, 0), SIZE, True, cr.diffuse_material((0.7, 0.65, 0.6), name="Walls"), "Room")
    b = box((2.3, 0.8, 0.0), (3.1, 1.6, 0.9), False, cr.diffuse_material((0.4, 0.5, 0.7), name="Paint"),
            "Block")
    v, f = cr.grid_arrays(1, 1, 1.5, 2.5, 1.0, 2.0, LAMP_Z)
    lamp = cr.mesh_object(v, f[:, ::-1], cr.diffuse_material((0.0,) * 3, emission=10.0, name="Panel"), "Lamp")
    return r, b, lamp


def beside_cycles(ob, density, folder, samples=16):
    """``ob`` (one mesh object, the scene set up) baked to a lightmap by ours with defaults
    (``lightmap_density`` texels a metre, files in ``folder``) and by Cycles through the same
    UVs: (ours (S, S, 3), Cycles' (S, S, 3) DIFFUSE bake at ``samples``, the lightmap UVs (L, 2)
    per loop of ``ob``, S). The baked copy is removed before Cycles bakes (it would shade ``ob``)."""
    import bpy

    from hemicube_radiosity.blender import bake, write

    job = bake.BakeJob.prepare(bpy.context, [ob], bake.BakeSettings(target="lightmap", lightmap_density=density,
                                                                      lightmap_dir=str(folder)))
    job.run()
    copy = job.write(bpy.context)[0]
    rec = job.lightmaps[0]
    size = rec["size"][0]
    ours = cr.image_rgb(bpy.data.images[f"{ob.name}.lightmap.exr"])
    uv = np.empty(len(copy.data.loops) * 2)
    copy.data.uv_layers[rec["uv_map"]].data.foreach_get("uv", uv)
    uv = uv.reshape(-1, 2)
    write.remove_bakes([ob.name], unhide=True)
    ob.data.uv_layers.new(name="LM").data.foreach_set("uv", uv.astype(np.float32).ravel())
    cyc = cr.bake_image(ob, size, samples=samples, uv_layer="LM")[0]
    return ours, cyc, uv, size
