"""Reference bakes for tests/core/test_reference_bakes.py: run once on the code a refactor starts from,
so that the test can prove the refactored code gives the same numbers. Written first on cfa6419
(before the settings schema and the stage list); written again when the solver began to stop on
an error bound (96b8da5: results moved by at most 6e-5 of the maximum), when the final gather
began to read the output mesh instead of the patches (the two gathered cases), and when patches
began to be split where the direct light changes abruptly and weighted by the part the scene
sees, with the gather reading exact light where it lands on such elements, the world's light
exact at every point, and 128 gather rays by default (issue 11), and when the hemi-cube began to
snap vertices to a sub-pixel grid and give a pixel centre on a shared edge to one polygon by a
fill rule, not to whichever depth rounded nearer (issue 12: scale invariance), and when each chunk
of an emitter transport began to draw its penumbra rays from its own random stream (so chunks can
run on worker processes), and when the vertex stage began to read abrupt elements on a grid, let
bright areas shine, judge both on the light arriving, and cast the lattice ray pattern (issue 11),
and when patches and output elements began to be cut along contact lines, buried corners to take
the open side's limit, the gather to run once more at the elements' level, the hemi-cube to sample
pixels a hair off their centres and element vertices to be located in the patch they lie in
(issues 11 and 12), and when contact segments began to be clipped to the face they cut (issue 9:
the short block's top is no longer cut along the tall block's line beside it), and when the
penumbra's extra shadow rays began to aim at targets shared by every point instead of drawn
per chunk of the transport (issue 9: the chunks are cut to share the work between workers, and T
no longer depends on how they are cut), and when the patches cut from one emitting face began to
shine as one unit, with shadow rays spread over a group in compact strata and weighted by their
part of the form factor (issue 9: a lamp cut into 100 patches cost every point 100 contours and
400 rays), and when that weight began to take each target's own normal, 0 where it faces away
(a group of shining pieces on two surfaces, a curved lamp's far side).

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
# that every case keeps meaning what it meant (one-sided emitters, direct light at patch centres).
PINNED = {"two_sided_emission": False, "patch_light_points": 1}

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
