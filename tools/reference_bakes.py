"""Reference bakes for tests/core/test_reference_bakes.py: run once on the code a refactor starts from,
so that the test can prove the refactored code gives the same numbers. Written again only by a
change meant to move the numbers (a new method, a fixed error, a random stream cut otherwise);
``git log tests/data/reference_bakes.npz`` lists those changes and why each moved them.

    .venv/bin/python tools/reference_bakes.py tests/data/reference_bakes.npz

Each case is a core bake of a pure-NumPy scene (no bpy) with settings spelt out as a dict, so the
same case can be run again on any later version of the settings schema.
"""
from __future__ import annotations

import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

# Settings whose defaults changed after the references were first written (cfa6419): pinned so
# that every case keeps meaning what it meant (one-sided emitters, direct light at patch centres,
# surfaces that reflect from their front only: no backs for open surfaces).
PINNED = {"two_sided_emission": False, "patch_light_points": 1, "two_sided_reflection": False}

CASES = {
    # name: (scene, settings dict, lights, world)
    "cornell_defaults": ("cornell", {}, "none", None),
    "cornell_interp": ("cornell", {"gather_rays": 0}, "none", None),
    "cornell_paper": ("cornell", {"patch_size": 0.5, "element_size": None, "direct": "hemicube",
                                  "resolution": 64}, "none", None),
    "cornell_embree_lamps": ("cornell", {"patch_size": 0.4, "element_size": 0.2, "method": "embree",
                                         "gather_rays": 16}, "lamps", (0.05, 0.1, 0.2)),
    "box_progressive": ("box", {"patch_size": 0.25, "element_size": None, "solver": "progressive",
                                "max_iterations": 2000}, "none", None),
    "box_stochastic_jacobi": ("box", {"patch_size": 0.34, "element_size": None, "solver": "jacobi",
                                      "method": "embree_stochastic", "rays_per_patch": 64,
                                      "rotate_seed": 3}, "none", None),
}


def lights_for(kind):
    from hemicube_radiosity.core.light.lamps import AreaLight, PointLight, SpotLight, SunLight

    if kind == "none":
        return []
    area = np.eye(4)
    area[:3, 3] = (1.0, 1.0, 1.8)            # facing down (local -Z), below the ceiling
    return [PointLight((0.6, 1.2, 1.4), (1.0, 0.9, 0.8), 40.0, radius=0.05),
            SpotLight((1.4, 1.2, 1.7), (0, 0, -1), power_w=60.0, spot_size=1.0),
            SunLight((0.3, 0.2, -1.0), (1.0, 1.0, 0.9), strength=0.5),
            AreaLight(area, power_w=10.0, size_x=0.3)]


def scene(kind):
    from hemicube_radiosity.core import builtin_scenes as scenes

    if kind == "cornell":
        return scenes.cornell_box()
    return scenes.closed_box((1.0, 1.0, 1.0), rho=(0.6, 0.5, 0.4), emission=(1.0, 1.0, 1.0))


def run_case(name, make_settings):
    """Bake one case; ``make_settings(dict) -> settings`` adapts to the schema of the day."""
    kind, settings, lights, world = CASES[name]
    from hemicube_radiosity.core.pipeline import bake

    r = bake(scene(kind), make_settings(settings), lights=lights_for(lights),
             world=None if world is None else np.asarray(world))
    return {"vertex": r.vertex_radiosity, "B": r.solution.B}


def main(path):
    from hemicube_radiosity.core.pipeline import BakeSettings

    out = {}
    for name in CASES:
        res = run_case(name, lambda d: BakeSettings(**{**PINNED, **d}))
        for k, v in res.items():
            out[f"{name}/{k}"] = np.asarray(v)
        print(name, {k: v.shape for k, v in res.items()})
    np.savez_compressed(path, **out)


if __name__ == "__main__":
    main(sys.argv[1])
