"""A dense curved mesh as artists make them: Suzanne with a Subdivision Surface in the Cornell box.

    .venv/bin/python bench/bench_curved.py [--level 3] [--spp 64] [--quick]

Issue 9 opened with "a Suzanne with a level-3 Subdivision Surface (31.7k faces) cannot be baked at
all". This bench builds one (``bmesh.ops.create_monkey``, a SUBSURF modifier of ``--level``,
evaluated into a plain mesh as an applied modifier leaves it), scaled to 0.55 m and set on the
floor of the coarse Cornell box (``core.builtin_scenes.cornell_box``, 16 quads) beside the blocks. Ours:
``pipeline.bake`` with ``BakeSettings()`` as shipped (every stage timed); Cycles: a COMBINED
vertex bake of the same objects at ``--spp`` samples, 32 bounces, 2 threads
(``tools/cycles_reference.py``), in the same run. Both are read at Suzanne's vertices: ours
with ``interpolate_at`` on our output, Cycles' as the mean of each vertex's corners. The mean
luminance over Suzanne's vertices (Cycles' noise averages out over 30k of them) compares the
two; the per-vertex RMS difference is mostly Cycles' own noise at
64 spp and is reported as such. Prints the row and saves it to bench/out/curved.json.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(ROOT, "tools"))

import numpy as np  # noqa: E402

LUMA = np.array([0.2126, 0.7152, 0.0722])
WHITE = (0.725, 0.71, 0.68)


def suzanne(level, scale=0.2, at=(0.45, 1.5, 0.0)):
    """MeshInput of Suzanne subdivided ``level`` times (Catmull-Clark, as the modifier's default),
    resting on z = 0 at ``at``, facing -y; and its per-vertex normals (V, 3)."""
    import bmesh
    import bpy

    from hemicube_radiosity.core.mesh.patches import MeshInput

    bm = bmesh.new()
    bmesh.ops.create_monkey(bm)
    me = bpy.data.meshes.new("SuzanneSrc")
    bm.to_mesh(me)
    bm.free()
    ob = bpy.data.objects.new("SuzanneSrc", me)
    bpy.context.scene.collection.objects.link(ob)
    mod = ob.modifiers.new("Subdivision", "SUBSURF")
    mod.levels = mod.render_levels = level
    dg = bpy.context.evaluated_depsgraph_get()
    ev = ob.evaluated_get(dg).to_mesh()
    v = np.empty((len(ev.vertices), 3))
    ev.vertices.foreach_get("co", v.ravel())
    n = np.empty((len(ev.vertices), 3))
    ev.vertices.foreach_get("normal", n.ravel())
    loops = np.empty(len(ev.loops), np.int64)
    ev.loops.foreach_get("vertex_index", loops)
    start = np.empty(len(ev.polygons), np.int64)
    ev.polygons.foreach_get("loop_start", start)
    total = np.empty(len(ev.polygons), np.int64)
    ev.polygons.foreach_get("loop_total", total)
    ob.evaluated_get(dg).to_mesh_clear()
    bpy.data.objects.remove(ob)
    bpy.data.meshes.remove(me)
    # Suzanne faces -y with her top up (+z) in Blender: scaled, set on the floor
    v = v * scale
    v += np.asarray(at, float) - np.array([v[:, 0].mean(), v[:, 1].mean(), v[:, 2].min()])
    offsets = np.r_[0, np.cumsum(total)]
    F = len(total)
    m = MeshInput(v, offsets, loops[np.concatenate([np.arange(s, s + t) for s, t in zip(start, total)])],
                  np.tile(WHITE, (F, 1)), np.zeros((F, 3)), "Suzanne")
    return m, n


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--level", type=int, default=3)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--quick", action="store_true", help="level 2, 16 samples")
    a = ap.parse_args(argv)
    if a.quick:
        a.level, a.spp = 2, 16
    import bpy  # noqa: F401
    import cycles_reference as cr
    from bench_dense import _Scene, build_scene
    from hemicube_radiosity.core import pipeline, builtin_scenes as scenes
    from hemicube_radiosity.core.output.interpolate import interpolate_at

    box = scenes.cornell_box()
    suz, normals = suzanne(a.level)
    meshes = box + [suz]
    load0 = os.getloadavg()
    t = time.perf_counter()
    res = pipeline.bake(meshes, pipeline.BakeSettings(), world=None, lights=())
    ours = time.perf_counter() - t
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    owner = len(meshes) - 1
    V = len(suz.verts)
    mine = interpolate_at(res.elements, res.vertex_radiosity, suz.verts, np.full(V, owner), normals)
    scene, objs = build_scene(_Scene(meshes))
    b = cr.bake_vertex_radiance(objs, samples=a.spp, seed=1, bounces=32, threads=2)
    ref = b.point["Suzanne"]
    lit = (ref @ LUMA) > 1e-3 * (ref @ LUMA).max()
    y_ours, y_ref = mine[lit] @ LUMA, ref[lit] @ LUMA
    st = res.timings
    faces = len(suz.face_offsets) - 1
    print(f"\nload {load0[0]:.2f} -> {os.getloadavg()[0]:.2f}; Suzanne level {a.level}: {faces:,} faces, "
          f"{V:,} vertices; pieces {len(res.patches):,}, patches {int(res.unknowns):,}, output vertices "
          f"{len(res.elements.verts):,}\n")
    print("| Suzanne faces | pieces | patches | output vertices | patches stage | form factors | direct | solve | "
          "vertices | bake total | peak (MB) | Cycles " + f"{a.spp} spp (s) | Cycles / ours | Suzanne mean luminance, "
          "ours / Cycles | per-vertex RMS vs Cycles (its noise included) |")
    print("|" + "---|" * 14)
    rms = float(np.sqrt(np.mean((y_ours - y_ref) ** 2)) / y_ref.mean())
    print(f"| {faces:,} | {len(res.patches):,} | {int(res.unknowns):,} | {len(res.elements.verts):,} | "
          f"{st['patches']:.2f} | {st['form_factors']:.2f} | {st['direct']:.2f} | {st['solve']:.2f} | "
          f"{st['vertices']:.2f} | {ours:.1f} | {peak:.0f} | {b.seconds:.1f} | {b.seconds / ours:.2f}x | "
          f"{y_ours.mean() / y_ref.mean():.3f} | {100 * rms:.1f}% |")
    os.makedirs(os.path.join(HERE, "out"), exist_ok=True)
    with open(os.path.join(HERE, "out", "curved.json"), "w") as f:
        json.dump({"quick": a.quick, "level": a.level, "faces": faces, "vertices": V, "pieces": len(res.patches),
                   "patches": int(res.unknowns), "output_vertices": len(res.elements.verts), "stages": dict(st),
                   "seconds": ours, "peak_mb": peak, "spp": a.spp, "cycles_seconds": b.seconds,
                   "ratio": b.seconds / ours, "luminance_ratio": float(y_ours.mean() / y_ref.mean()), "rms": rms,
                   "load": [load0[0], os.getloadavg()[0]]}, f, indent=1, default=float)


if __name__ == "__main__":
    main()
