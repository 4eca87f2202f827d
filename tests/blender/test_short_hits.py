# SPDX-License-Identifier: GPL-3.0-or-later
"""A moulding's back, close in front of a wall of large faces, reads the wall in its own shadow
(core/output/short_hits.py), compared with Cycles at its own face corners.

../shared/scenes' staircase hall, too dense for output elements (its faces gather,
:func:`hemicube_radiosity.core.output.indirect.gathers_faces`): panel mouldings stand 1.7 cm in
front of walls of triangles 0.8 m across whose corners are out in the lit room. The backs'
gather rays land 2 to 5 cm away, in the mouldings' shadow, and read the wall's corners' light
interpolated: the room's. Here: a box 60 x 20 x 2 cm, its back (12 x 4 quads) 1.7 cm in front of
a wall of 2 x 2 faces 1.5 m x 1 m, a floor of 30 x 30 faces (the scene too dense for
elements), an emissive panel overhead in front of the wall. Run
``python -m tests.blender.test_short_hits`` to print the figures."""
from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tools import cycles_reference as cr  # noqa: E402
from hemicube_radiosity.blender.read import scene as reader  # noqa: E402
from hemicube_radiosity.blender.read.lights import read_lights  # noqa: E402
from hemicube_radiosity.core.pipeline import BakeSettings, bake  # noqa: E402
from tests.support.cycles_scenes import face_corner_values  # noqa: E402

pytestmark = [pytest.mark.blender, pytest.mark.cycles]

RHO = 0.8
# the 'auto' detail size with an elements' limit the scene's faces exceed at any detail size
SETTINGS = dict(patch_size=1.0, element_size="auto", max_elements=1000, light_samples=64, light_seed=1)
GAP = 0.017                     # m between the wall and the moulding's back


def _yz_grid(ny, nz, y0, y1, z0, z1, x, facing):
    """(verts, faces) of a grid in the plane at ``x``, facing +x (``facing`` > 0) or -x."""
    v, f = cr.grid_arrays(ny, nz, y0, y1, z0, z1, 0.0)
    v = np.stack([np.full(len(v), x), v[:, 0], v[:, 1]], 1)
    return v, (f if facing > 0 else f[:, ::-1])


def _moulding(x0, x1, y0, y1, z0, z1):
    """A closed box, its -x face (toward the wall) as 12 x 4 quads."""
    parts = [_yz_grid(12, 4, y0, y1, z0, z1, x0, -1), _yz_grid(1, 1, y0, y1, z0, z1, x1, +1)]
    c = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]])
    parts.append((c, np.array([(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (2, 3, 7, 6)])))
    off = np.cumsum([0] + [len(v) for v, _ in parts])
    return np.concatenate([v for v, _ in parts]), np.concatenate([np.asarray(f) + o for (_, f), o in zip(parts, off)])


def scene():
    """The moulding, the floor, the wall and the lamp (objects in that order)."""
    cr.new_empty_scene()
    m = cr.diffuse_material((RHO,) * 3)
    mould = cr.mesh_object(*_moulding(GAP, GAP + 0.02, -0.3, 0.3, 0.8, 1.0), m, "moulding")
    floor = cr.mesh_object(*cr.grid_arrays(30, 30, 0.0, 3.0, -1.5, 1.5, 0.0), m, "floor")
    wall = cr.mesh_object(*_yz_grid(2, 2, -1.5, 1.5, 0.0, 2.0, 0.0, +1), m, "wall")
    v, f = cr.grid_arrays(1, 1, 1.0, 2.0, -0.5, 0.5, 2.0)
    lamp = cr.mesh_object(v, f[:, ::-1], cr.diffuse_material((RHO,) * 3, emission=20.0), "lamp")
    return [mould, floor, wall, lamp]


def _ours(objs):
    dg = bpy.context.evaluated_depsgraph_get()
    si = reader.read_scene(dg, objs)
    lights, world, _ = read_lights(dg)
    return bake(si.meshes, BakeSettings(**SETTINGS), lights=lights, world=world)


def compare(samples=256):
    """{'back': (ours, Cycles), 'front': (ours, Cycles)}: the moulding's faces toward the wall
    and away from it, their corners' mean value; and our result."""
    objs = scene()
    ref = cr.bake_vertex_radiance(objs[:1], samples=samples, seed=3)
    r = _ours(objs)
    me = objs[0].data
    ours, theirs = face_corner_values(r, 0, me), ref.corner["moulding"]
    nx = np.array([p.normal[0] for p in me.polygons for _ in p.vertices])
    return {k: (float(ours[s].mean()), float(theirs[s].mean())) for k, s in (("back", nx < -0.5),
                                                                            ("front", nx > 0.5))}, r


@pytest.fixture(scope="module")
def case():
    return compare()


def test_the_faces_are_the_output(case):
    r = case[1]
    assert r.settings.element_size is None and len(r.elements) == len(r.patches)


def test_the_moulding_s_back_reads_the_wall_in_its_shadow(case):
    """Cycles: the back 0.208, the front 0.902. Ours 0.362 and 0.907; the back 0.695 when its
    rays read the wall's corners' direct light (the room's: 0.81 interpolated where the exact
    light at the hits is 0.20). What is left over is mostly the wall's light reflected more than
    once, read from its cluster's one value (0.21 of the 0.36 the back's rays bring)."""
    (back, back_ref), (front, front_ref) = case[0]["back"], case[0]["front"]
    assert back_ref < 0.3 * front_ref
    assert front == pytest.approx(front_ref, rel=0.05)
    assert abs(back - back_ref) < 0.2 * front_ref


if __name__ == "__main__":
    means, _ = compare()
    for side, (o, t) in means.items():
        print(f"the moulding's {side}: ours {o:.4f} Cycles {t:.4f}")
