"""bench/lightmap_real.py leaves texels on coincident surfaces apart (``coincident_texels``): a
texel is flagged when a point of the square Cycles' bake jitters its samples over (half a texel
wide, the core's sub-texel points) lies on another face's triangle in its plane, either facing;
not for a face beside it sharing an edge, nor for one a centimetre above it. Checked against
the squares' geometry, worked out by hand."""
import os
import sys

import numpy as np

from hemicube_radiosity.core.output import lightmap as core_lightmap
from tests.support import ROOT

sys.path.insert(0, os.path.join(ROOT, "bench"))
sys.path.insert(0, os.path.join(ROOT, "tools"))
import lightmap_real  # noqa: E402


def quad(x0, x1, y0, y1, z=0.0, up=True):
    """Two triangles of the rectangle [x0, x1] x [y0, y1] at height z, facing up (or down)."""
    a, b, c, d = [x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]
    tris = [[a, b, c], [a, c, d]] if up else [[a, c, b], [a, d, c]]
    return np.array(tris, float)


def test_texels_on_a_coincident_face_are_found_and_no_others():
    size = 16
    room = quad(0, 1, 0, 1)                                  # face 0, mapped onto the whole image
    others = [room,
              quad(0.5, 1, 0, 0.5),                          # face 1: on it, facing the same way
              quad(1, 2, 0, 1),                              # face 2: beside it, one edge shared
              quad(0, 0.5, 0.5, 1, z=0.01),                  # face 3: a centimetre above it
              quad(0, 0.5, 0, 0.5, z=5e-5, up=False)]        # face 4: on it (within 0.1 mm), facing down
    world = np.concatenate(others)
    faces = np.repeat(np.arange(len(others)), 2)
    uv = room[..., :2]
    tri, _, inside = core_lightmap.rasterize(uv, size, size)
    assert inside.all()
    got = lightmap_real.coincident_texels(room, faces[:2], uv, tri, world, faces)
    # the footprint's points lie within 3/16 texel of the centre: rows 0..7 (y < 0.5) reach faces 1
    # and 4 (x >= 0.5: columns 8..15; x <= 0.5: columns 0..7), row 8's points start at 8.3125 texels
    want = np.zeros((size, size), bool)
    want[:8] = True
    assert np.array_equal(got, want), np.argwhere(got != want)
    # nothing on it: nothing found (the face beside it and the one above do not count)
    alone = lightmap_real.coincident_texels(room, faces[:2], uv, tri, np.concatenate(others[:1] + others[2:4]),
                                            np.concatenate([faces[:2], faces[4:8]]))
    assert not alone.any()


def test_never_lit_texels_count_unless_on_a_coincident_surface():
    """The verdict's texels: one the reference never lights counts (ours lights it: error), unless
    it lies on a coincident surface, where Cycles' rays hit the other face at once."""
    H = W = 8
    ref = np.full((H, W, 3), 0.5)
    ours = ref.copy()
    ref[0, 0] = ref[0, 1] = 0.0                 # never lit by the reference; ours 0.5 there
    inside = np.ones((H, W), bool)
    material = np.zeros((H, W), int)
    coincident = np.zeros((H, W), bool)
    coincident[0, 0] = True                     # only the first on a coincident surface
    rows = lightmap_real.texel_errors(ours, ref, ref, inside, material, ["m"], 1024, 64, coincident)
    every = {r["part"]: r for r in rows}["all"]
    assert every["texels"] == H * W - 1         # (0, 1) compared, (0, 0) left out
    mean = (H * W - 2) * 0.5 / (H * W - 1)
    assert np.isclose(every["ours"]["rms_raw"], np.sqrt(0.25 / (H * W - 1)) / mean)
