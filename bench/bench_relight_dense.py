"""Relight of a dense room against a Cycles re-bake, in one run (issue 9's relight target).

    .venv/bin/python bench/bench_relight_dense.py [--n 11] [--samples 64] [--repeat 5]

The Cornell box modelled as ``2 n^2`` triangles per quad (n = 11: 3,872 faces). Ours: a bake with
a form-factor cache, then a relight (the lamp 30% brighter and the red wall's colour changed: only
reflectance and emission differ, so form factors, the emitters' transport and the gather rays are
reused). Cycles: a vertex bake of the same objects at ``--samples`` spp (COMBINED, as the bench's
references), which a relight has to repeat whole. Prints both times and the ratio; the machine's
load (os.getloadavg) is printed too, as this machine is shared. The relight is timed ``--repeat``
times (each a new lamp strength and wall colour, so each is a relight, not a repeat): the ratio
is taken on the median, the fastest is printed too. Results go to bench/out/relight_dense.json.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))
sys.path.insert(0, os.path.join(os.path.dirname(HERE), "tools"))

import numpy as np  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=11)
    ap.add_argument("--samples", type=int, default=64)
    ap.add_argument("--repeat", type=int, default=5, help="relights timed (median and fastest)")
    ap.add_argument("--quick", action="store_true", help="n = 6, 16 samples")
    a = ap.parse_args(argv)
    if a.quick:
        a.n, a.samples = 6, 16
    import bpy
    import cycles_reference as cr
    from hemicube_radiosity.blender.demo import object_from_mesh_input
    from hemicube_radiosity.core import builtin_scenes as scenes
    from hemicube_radiosity.core.runtime.cache import FormFactorCache
    from hemicube_radiosity.core.mesh.patches import MeshInput
    from hemicube_radiosity.core.pipeline import BakeSettings, bake

    meshes = scenes.tessellate(scenes.cornell_box(), a.n)
    faces = sum(len(m.face_offsets) - 1 for m in meshes)
    cache = FormFactorCache()
    s = BakeSettings()
    t = time.perf_counter()
    first = bake(meshes, s, cache=cache)
    cold = time.perf_counter() - t

    def relit(m, i):
        em = np.asarray(m.face_emission) * (1.3 + 0.01 * i)
        rho = np.asarray(m.face_rho).copy()
        if m.name == "RedWall":
            rho[:] = (0.2, 0.5 - 0.01 * i, 0.6)
        return MeshInput(m.verts, m.face_offsets, m.face_indices, rho, em, m.name)

    runs = []
    for i in range(max(1, a.repeat)):
        new = [relit(m, i) for m in meshes]
        t = time.perf_counter()
        again = bake(new, s, cache=cache)
        runs.append((time.perf_counter() - t, again.timings))
        assert again.form_factor_source == "cached"
    runs.sort(key=lambda r: r[0])
    warm, timings = runs[len(runs) // 2]
    cr.new_empty_scene()
    coll = bpy.context.scene.collection
    objects = [object_from_mesh_input(m, coll) for m in meshes]
    cycles = cr.bake_seconds(objects, samples=a.samples)
    load = os.getloadavg()[0]
    print(f"faces {faces}, patches {first.unknowns}, output vertices {len(first.elements.verts)}")
    print(f"ours: cold bake {cold:.2f} s, relight {warm:.3f} s (median of {len(runs)}, fastest "
          f"{runs[0][0]:.3f} s; the median's {' '.join(f'{k} {v:.3f}' for k, v in timings.items())})")
    print(f"Cycles {a.samples} spp re-bake: {cycles:.2f} s -> relight {cycles / warm:.0f}x faster "
          f"(load average {load:.1f} on {os.cpu_count()} cores)")
    os.makedirs(os.path.join(HERE, "out"), exist_ok=True)
    with open(os.path.join(HERE, "out", "relight_dense.json"), "w") as f:
        json.dump({"quick": a.quick, "n": a.n, "faces": faces, "patches": int(first.unknowns),
                   "output_vertices": len(first.elements.verts), "cold_seconds": cold, "relight_seconds": warm,
                   "fastest_seconds": runs[0][0], "repeat": len(runs), "stages": dict(timings),
                   "spp": a.samples, "cycles_seconds": cycles, "ratio": cycles / warm, "load": load,
                   "cpus": os.cpu_count()}, f, indent=1, default=float)
    return 0


if __name__ == "__main__":
    sys.exit(main())
