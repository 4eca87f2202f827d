"""A generated terrain for bench/real_scenes.py: 1 km of rolling ground as 128 x 128 quads with
five buildings on it (issue 32: "the terrain of 128 x 128 faces under Cycles 64 spp's time").

The file is made here, not read: no third-party scene is a large lit terrain of even faces, and
that is where a bake must not refine everywhere. Deterministic (the Cycles cache key holds):

* ``Ground``: a ``SIZE`` m square of ``N`` x ``N`` quads, smooth-shaded, heights a sum of three
  sine waves (about 25 m from trough to crest over 1 km), one material of grey 0.35;
* five box buildings (``BUILDINGS``: centre x, y, width, depth, height in metres above their
  base), flat-shaded, one material of grey 0.6, each standing on the ground everywhere under it:
  its base 1 m below the lowest ground under its footprint (a base at the ground's height under
  its centre left caves up to 1.1 m high under the buildings' downhill sides, which the bake
  lit through its coarse elements where Cycles has them dark: 45% of the squared error, on
  ground nobody sees).

The sun and the sky are real_scenes.py's ``sun_sky``.
"""
from __future__ import annotations

import numpy as np

N = 128
SIZE = 1000.0
BUILDINGS = ((-180.0, 120.0, 40.0, 25.0, 30.0), (60.0, -90.0, 30.0, 30.0, 55.0),
             (210.0, 200.0, 60.0, 20.0, 18.0), (-60.0, -260.0, 25.0, 45.0, 24.0),
             (320.0, -220.0, 35.0, 35.0, 40.0))


def height(x, y):
    """Ground height (m) at ``x``, ``y`` (m)."""
    return (8.0 * np.sin(x / 97.0) * np.cos(y / 131.0) + 4.0 * np.sin((x + 2 * y) / 53.0)
            + 1.5 * np.cos((3 * x - y) / 23.0))


def _material(bpy, name, grey):
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (grey, grey, grey, 1.0)
    bsdf.inputs["Roughness"].default_value = 1.0
    return mat


def _object(bpy, name, verts, faces, mat, smooth):
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(map(float, v)) for v in verts], [], [tuple(map(int, f)) for f in faces])
    me.update()
    me.polygons.foreach_set("use_smooth", [smooth] * len(me.polygons))
    me.materials.append(mat)
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def build():
    """Replace the current file with the terrain and its buildings; returns a line saying what."""
    import bpy

    bpy.ops.wm.read_homefile(use_empty=True)
    t = np.linspace(-SIZE / 2, SIZE / 2, N + 1)
    x, y = np.meshgrid(t, t, indexing="xy")
    verts = np.stack([x.ravel(), y.ravel(), height(x, y).ravel()], 1)
    i, j = np.meshgrid(np.arange(N), np.arange(N), indexing="xy")
    a = (j * (N + 1) + i).ravel()
    faces = np.stack([a, a + 1, a + N + 2, a + N + 1], 1)
    _object(bpy, "Ground", verts, faces, _material(bpy, "Ground", 0.35), True)
    wall = _material(bpy, "Building", 0.6)
    for k, (cx, cy, w, d, h) in enumerate(BUILDINGS):
        fx, fy = np.meshgrid(np.linspace(cx - w / 2, cx + w / 2, 65), np.linspace(cy - d / 2, cy + d / 2, 65))
        z0 = float(height(fx, fy).min()) - 1.0
        lo, hi = np.array([cx - w / 2, cy - d / 2, z0]), np.array([cx + w / 2, cy + d / 2, z0 + h])
        corners = np.array([[(lo, hi)[b >> 0 & 1][0], (lo, hi)[b >> 1 & 1][1], (lo, hi)[b >> 2 & 1][2]]
                            for b in range(8)])
        quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
        _object(bpy, f"Building{k}", corners, quads, wall, False)
    bpy.context.view_layer.update()
    return f"generated: {N} x {N} quads over {SIZE:g} m, {len(BUILDINGS)} buildings"
