# SPDX-License-Identifier: GPL-3.0-or-later
"""A scene too dense for output elements still gathers the light reflected more than once at
its faces' own vertices (:func:`hemicube_radiosity.core.output.indirect.gathers_faces`),
compared with Cycles at its own face corners.

Where the 'auto' detail size finds the faces finer than any detail size the elements' limit
allows (../shared/scenes' staircase hall: 262,663 triangles), the faces themselves are the
output and the solve groups them into clusters of one value each. Without a gather every face
of a cluster showed that one value of the light it reflects more than once: the staircase's
candle tops, flame bases and the rails' backs a few centimetres from a wall read the mean of
what their cluster sees.

Here: a strip 0.4 m x 6 cm modelled as 20 x 3 quads (one cluster), facing down 3 cm over a
floor, passes under a wall standing on the line x = 0 with a gap of 8 cm below it. An emissive
panel overhead lights the floor on the x > 0 side only: the strip's half over it sees lit floor,
the other half dark floor. Run ``python -m tests.blender.test_dense_gather`` to print the
figures."""
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
X0, X1, Y, Z = -0.2, 0.2, 0.03, 0.03            # the strip


def _grid(nx, ny, x0, x1, y0, y1, z, down=False, name="grid"):
    v, f = cr.grid_arrays(nx, ny, x0, x1, y0, y1, z)
    return cr.mesh_object(v, f[:, ::-1] if down else f, cr.diffuse_material((RHO,) * 3), name)


def scene():
    """The strip, the floor, the wall and the lamp (objects in that order)."""
    cr.new_empty_scene()
    strip = _grid(20, 3, X0, X1, -Y, Y, Z, down=True, name="strip")
    floor = _grid(60, 60, -1.5, 1.5, -1.5, 1.5, 0.0, name="floor")
    # the wall: the plane x = 0 from 8 cm to 1.2 m high, facing -x and +x (two faces)
    v = np.array([[0.0, -1.5, 0.08], [0.0, 1.5, 0.08], [0.0, 1.5, 1.2], [0.0, -1.5, 1.2]])
    wall = cr.mesh_object(v, [(0, 1, 2, 3)], cr.diffuse_material((RHO,) * 3), "wall")
    v, f = cr.grid_arrays(1, 1, 0.05, 0.65, -0.3, 0.3, 1.2)
    lamp = cr.mesh_object(v, f[:, ::-1], cr.diffuse_material((RHO,) * 3, emission=20.0), "lamp")
    return [strip, floor, wall, lamp]


def _ours(objs, settings=SETTINGS):
    dg = bpy.context.evaluated_depsgraph_get()
    si = reader.read_scene(dg, objs)
    lights, world, _ = read_lights(dg)
    return bake(si.meshes, BakeSettings(**settings), lights=lights, world=world)


def strip_corners(strip, result):
    """(ours (L, 3), x (L,)) at every face corner of ``strip`` (object 0), in its loop order:
    the output is the faces themselves; a corner takes its face's element's value there."""
    me = strip.data
    x = [me.vertices[vi].co[0] for p in me.polygons for vi in p.vertices]
    return face_corner_values(result, 0, me), np.array(x)


def halves(values, x, edge=0.05):
    """Mean luminance of the strip's corners over the dark floor (x < -``edge``) and over the
    lit floor (x > ``edge``)."""
    y = values.mean(axis=1)
    return float(y[x < -edge].mean()), float(y[x > edge].mean())


def compare(settings=SETTINGS, samples=512):
    """({'dark': (ours, Cycles), 'lit': (ours, Cycles)} the strip's halves' means, our result)."""
    objs = scene()
    ref = cr.bake_vertex_radiance(objs[:1], samples=samples, seed=3)
    r = _ours(objs, settings)
    ours, x = strip_corners(objs[0], r)
    a, b = halves(ours, x), halves(ref.corner["strip"], x)
    return {"dark": (a[0], b[0]), "lit": (a[1], b[1])}, r


@pytest.fixture(scope="module")
def case():
    return compare()


def test_the_faces_are_the_output_and_the_strip_one_cluster(case):
    r = case[1]
    assert r.settings.element_size is None                 # the 'auto' detail size found none
    assert len(r.elements) == len(r.patches)
    strip = np.flatnonzero(r.patches.owner == 0)
    assert len(np.unique(r.clusters.of[strip])) == 1


def test_each_half_of_the_strip_shows_the_floor_it_sees(case):
    """Cycles: the half over the lit floor 0.664, over the dark floor 0.041. Ours 0.548 and
    0.102 (both 0.325 without the gather: the cluster's one value; 0.553 and 0.107 with 128
    gather rays and the floor's abrupt faces all gridded). The lit half is 17% low, not
    explained: with the exact light's grid at a quarter of the patch size on the floor's 5 cm
    faces (one cell each) instead of 4 x 4 cells (``AbruptGrid(whole=True)``), it read 0.645;
    the staircase's candles need the finer grid where something stands over a face (see the
    last test)."""
    means = case[0]
    (dark, dark_ref), (lit, lit_ref) = means["dark"], means["lit"]
    assert lit_ref > 3 * dark_ref
    assert lit == pytest.approx(lit_ref, rel=0.2)
    assert dark == pytest.approx(dark_ref, abs=0.15 * lit_ref)


def test_without_the_gather_the_strip_shows_its_cluster_s_one_value():
    """The defect, with the gather's rays off (``gather_rays`` 0): both halves of the strip
    read the cluster's one value of the light reflected more than once (they have no direct
    light), within rounding of the vertex rule."""
    objs = scene()
    r = _ours(objs, {**SETTINGS, "gather_rays": 0})
    ours, x = strip_corners(objs[0], r)
    dark, lit = halves(ours, x)
    assert lit == pytest.approx(dark, rel=0.02)


if __name__ == "__main__":
    means, r = compare()
    for half, (o, t) in means.items():
        print(f"strip over the {half} floor: ours {o:.4f} Cycles {t:.4f}")
    objs = scene()
    r0 = _ours(objs, {**SETTINGS, "gather_rays": 0})
    print("without the gather: dark %.4f lit %.4f" % halves(*strip_corners(objs[0], r0)))


def test_a_cap_over_a_fan_s_dark_centre_reads_it_dark():
    """The staircase's candle top (:mod:`tests.blender.test_seen_direct`'s disc, a fan of 32
    slivers lit at its rim and dark in the middle under a plate, with a cap 5 mm over its
    centre), a scene too dense for elements: the cap's gather rays land on the slivers' dark
    inner ends. Each sliver, 10 cm long, is one cell of the exact light's grid at a quarter of
    the patch size: the cap read the slivers' means, several times Cycles' light; the grid of
    an abrupt face at 4 x 4 cells (``AbruptGrid(whole=True)``) reads the dark centre. The
    slivers' centre corners lie under the cap, not fully seen, so they keep that grid where
    open small faces are read interpolated (``indirect._open_small_faces``)."""
    from tests.blender import test_seen_direct as sd

    objs = sd.scene(cap=True)
    ref = cr.bake_vertex_radiance(objs[1:3], samples=256, seed=3)
    r = _ours(objs, {**sd.SETTINGS, "element_size": "auto", "max_elements": 50})
    assert r.settings.element_size is None
    ours, own, w = sd.corners(objs[:3], r)
    got = {}
    for k in (1, 2):                                          # the plate, the cap
        me = objs[k].data
        area = np.repeat([p.area / len(p.vertices) for p in me.polygons], [len(p.vertices) for p in me.polygons])
        got[k] = (float(np.average(ours[own == k], weights=w[own == k], axis=0).mean()),
                  float(np.average(ref.corner[objs[k].name], weights=area, axis=0).mean()))
    mean = sd.RHO * 0.9 * sd._area_mean_reflected()          # the disc's mean, seen by the cap
    cap, theirs = got[2]
    assert theirs < 0.25 * mean
    assert abs(cap - theirs) < 0.1 * mean                    # 0.028 vs Cycles 0.033; 0.32 one cell a sliver
    plate, theirs = got[1]
    assert plate == pytest.approx(theirs, rel=0.15)           # 0.122 vs 0.120; 0.25 one cell a sliver
