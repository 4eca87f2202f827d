"""The bake gives the numbers it gave before a refactor: ``tests/data/reference_bakes.npz`` was written
by ``tools/reference_bakes.py`` on the code before the settings schema and the stage list (cfa6419),
and again when the solver began to stop on an error bound (moves of at most 6e-5 of the maximum),
and when rays began to start off their own object's surface by its size, not the scene's (moves of
at most 5e-5 of the maximum in the Cornell box, whose blocks and light are smaller than the room,
and a refinement that adds 3 patches to cornell_embree_lamps; the plain boxes are unchanged),
and when the abrupt grid's points and cells began to share the sky's rays out (cornell_embree_lamps'
vertices, the only case with a world and abrupt elements: moves of at most 1.2e-4 of the maximum,
3.4e-5 of the mean; its patch solution unchanged), and when elements with a shadow inside them
that reaches none of their corners got the abrupt grid too (core/output/abrupt.py shadowed_inside:
cornell_embree_lamps' vertices again, at most 2.4e-5 of the maximum, 2e-6 of the mean), and
when each lamp's light at the refinement's and the abrupt test's points began to draw its own
random stream, in the units of the other sources (cornell_embree_lamps: 1,623 patches instead of
1,656, its vertices moved by at most 2.1e-4 of the maximum, 4.6e-5 of the mean), and when a
corner whose sun ray passes under a lip beside it began to be lit at its own point
(core/output/covered.py: cornell_embree_lamps' 12 vertices on the open front's top edge, 3% to
34% darker; the mean of all its vertices 0.07% lower; not compared with Cycles there), and when
a boundary vertex's fit began to reach no further than its samples' range widened by its width
(core/output/vertex.py _sample_bounds; cornell_interp: 3 of 4,673 vertices, at most 1.8e-4 of the
maximum; cornell_defaults: at most 1.6e-5 of the maximum, through the gather; patch solutions
unchanged), and when a corner whose sun ray and its vertex's disagree (a shadow's edge through
the vertex) began to be lit at its own point (core/output/covered.py: cornell_embree_lamps' 8
vertices on the ceiling's front-edge shadow at y = 0.4 on the floor and at the front corners,
their lit side's corners now with the sun, up to 0.92% of the maximum; the mean of all its
vertices 0.04% higher; patch solutions unchanged), and when the sky's rays began to be cast a
quarter first where points are lit one by one (core/hemisphere.py SKY_FIRST), shared out among
the points a patch or a cluster averages (core/light/points.py SKY_SHARE) and among 4 x 4 blocks
of the abrupt grid (cornell_embree_lamps: its patch solution moved by at most 3.1e-4 of the
maximum, its vertices by at most 7.7e-4, 2.5e-4 of the mean; the other cases unchanged), and
when the gather's element-level bounce took three passes instead of one (core/output/indirect.py
GATHER_PASSES: cornell_defaults' vertices by at most 5.3e-4 of the maximum, cornell_embree_lamps'
by 4.6e-3, 4.7e-3 of the mean; patch solutions unchanged), and when a covered corner began to take
the direct light of the near faces' fronts its rays meet (core/output/near.py: cornell_embree_lamps'
14 of its 912 vertices, 13 of them brighter, by at most 6.6e-3 of the maximum (10.7% of that
vertex's own), its mean 2.1e-4 higher; patch solutions unchanged), and when a gather ray landing
in a spiky cell of the abrupt grid began to read the point of the stratum it lands in, not the
cell's mean (core/output/abrupt.py: cornell_defaults' vertices by at most 1.2e-3 of the maximum,
1.2e-4 of the mean, cornell_embree_lamps' by at most 3.9e-3, 5.9e-4 of the mean; their means
0.007% and 0.035% lower; patch solutions unchanged), and when each shining group began to draw its
shadow rays' targets from a key of where it is (core/output/shine.py _group_keys:
cornell_defaults' vertices by at most 4.1e-5 of the maximum, cornell_embree_lamps' by at most
5.4e-4, their means -0.0004% and +0.064%; patch solutions unchanged), and when the strata of a
spiky cell at its element's edge began to be graded toward it (core/output/abrupt.py
stratum_edges: cornell_defaults' vertices by at most 4.0e-3 of the maximum, 8.1e-5 of the mean,
cornell_embree_lamps' by at most 1.2e-2, 9.7e-4 of the mean; their means 0.008% and 0.065% lower;
patch solutions unchanged).
A change that is meant to alter results regenerates the file in the same commit and says why."""
import os

import numpy as np
import pytest

from hemicube_radiosity.core.pipeline import BakeSettings
from tests.support import ROOT
from tools import reference_bakes

REF = np.load(os.path.join(ROOT, "tests", "data", "reference_bakes.npz"))


@pytest.mark.parametrize("name", sorted(reference_bakes.CASES))
def test_same_numbers_as_before(name):
    got = reference_bakes.run_case(name, lambda d: BakeSettings(**{**reference_bakes.PINNED, **d}))
    for key, value in got.items():
        ref = REF[f"{name}/{key}"]
        assert value.shape == ref.shape, key
        scale = float(np.max(np.abs(ref)))
        assert scale > 0
        np.testing.assert_allclose(value, ref, rtol=0, atol=1e-6 * scale, err_msg=f"{name}/{key}")
