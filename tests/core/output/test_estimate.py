"""The report's estimated error (core/output/estimate.py) against the error it estimates.

Truth here is the same bake converged: output elements a third the size and 512 gather rays,
interpolated to the default bake's vertices (Cycles' version of this check, on the bench scenes,
is in ``bench/speed_vs_error.py``: Targets). Measured (bench-like relative RMS over the open
vertices that do not emit, the scene sees and are not buried under a block): the open box
under a uniform sky, estimated 0.33% against 0.48% measured (0.75% against 0.82% while its
vertices cast sky rays of their own beside a gather of half as many rays: the gather's rays
find the sky now, core/output/indirect.py); the one-sided Cornell box 1.3%
against 1.5% (it was 3.2% against 1.6% while the output elements straddled the blocks' outlines:
the coarser output read their buried corners); with its lamp lighting the ceiling from its
back, 1.2% against 2.1%. The detail term leaves out what lies in a coarse element whose
corners differ 2x or more: there it measures the coarse output's own interpolation error.
"""
from types import SimpleNamespace

import numpy as np
from tests.support import fronts
import pytest

from hemicube_radiosity.core import pipeline, builtin_scenes as scenes
from hemicube_radiosity.core.light.emitters import vertex_frames
from hemicube_radiosity.core.output.estimate import _lit_vertices, _vertex_owner, relative_rms
from hemicube_radiosity.core.output.interpolate import interpolate_at
from hemicube_radiosity.core.output.sides import open_elements, seen_vertices
from tests.support.markers import needs_embree


def _measured(meshes, settings, world=None):
    """(bake with the estimate, its error against the converged bake)."""
    r = pipeline.bake(meshes, pipeline.BakeSettings.from_mapping(dict(settings, estimate_error=True)), world=world)
    fine = pipeline.bake(meshes, pipeline.BakeSettings.from_mapping(dict(
        settings, patch_size=r.settings.patch_size, element_size=r.settings.element_size / 3, gather_rays=512)),
        world=world)
    xv, nv, _ = vertex_frames(r.elements)
    truth = interpolate_at(fine.elements, fine.vertex_radiosity, xv, _vertex_owner(r.elements), nv)
    opened = open_elements(SimpleNamespace(settings=r.settings, cache=None), r.elements)
    ctx = SimpleNamespace(settings=r.settings, cache=None)
    seen = seen_vertices(ctx, r.elements)      # a buried corner carries the open side's limit
    return r, relative_rms(r.vertex_radiosity, truth, _lit_vertices(r.elements, opened) & seen)


def _open_box():
    box = scenes.cornell_box()
    return [box[0], *box[6:]]          # the floor and the two blocks, under the sky


@pytest.mark.slow
@needs_embree
@pytest.mark.parametrize("case", ["cornell_one_sided", "open_box_sky"])
def test_estimated_error_is_within_a_factor_two_of_the_measured(case):
    if case == "cornell_one_sided":
        r, measured = _measured(scenes.cornell_box(), {"two_sided_emission": False})
    else:
        r, measured = _measured(_open_box(), {}, world=np.array([1.0, 1.0, 1.0]))
    e = r.error_estimate
    assert e.method == "detail" and e.noise > 0 and e.detail > 0
    assert e.error == pytest.approx(np.hypot(e.noise, e.detail))
    assert 0.003 < measured < 0.1                         # a real error to estimate
    assert 0.5 <= e.error / measured <= 2.0, (e.error, measured)
    assert e.describe().startswith("estimated error")        # said in the summary, not as a note
    assert not any(n.startswith("estimated error") for n in r.notes)
    assert r.timings["estimate"] > 0


@pytest.mark.slow
@needs_embree
def test_estimated_error_with_a_lamp_lighting_the_ceiling_from_its_back():
    """A two-sided lamp 2 mm under the ceiling: 1.2% estimated against 2.1% measured. At twice
    the detail size the elements across the lamp's edge smear its back-lit ceiling into the
    room, which the output at the detail size does not do (it reads such elements on a grid):
    coarse elements whose corners differ 2x or more are left out of the detail term (with them,
    the bench's Cornell box was estimated at 150% against 1.1% measured, its room 20% against 3%)."""
    r, measured = _measured(scenes.cornell_box(), {})
    assert 0.5 <= r.error_estimate.error / measured <= 2.0


@needs_embree
def test_faces_finer_than_the_detail_estimate_the_noise_only():
    """A box modelled finer than the detail size (triangles of 0.17 m sides, 0.24 m diagonals, in 0.25 m) is output on its own faces: no coarser output
    to compare, so the estimate is the gather's noise, measured by an independent half-ray
    gather, and the note says so. The noise shrinks as the rays grow (as 1/sqrt(n) for
    independent rays; the shared stratified pattern does better)."""
    m = scenes.tessellate(scenes.cornell_box(), 12)
    est = {}
    for rays in (32, 128):
        r = pipeline.bake(m, pipeline.BakeSettings(patch_size=0.5, element_size=0.25, gather_rays=rays,
                                                   estimate_error=True))
        assert fronts(r, r.elements.owner).sum() == 16 * 2 * 12 ** 2           # the user's faces
        e = r.error_estimate
        assert e.method == "rays" and e.detail == 0 and e.error == e.noise > 0
        assert "sampling noise only" in e.describe()
        est[rays] = e.noise
    assert est[128] < 0.6 * est[32]


def test_no_estimate_without_a_detail_size_says_why():
    r = pipeline.bake(scenes.cornell_box(), pipeline.BakeSettings(element_size=None, estimate_error=True))
    assert r.error_estimate is None
    assert any("no error estimate" in n for n in r.notes)


def test_no_estimate_unless_asked():
    r = pipeline.bake(scenes.cornell_box(), pipeline.BakeSettings(element_size=None))
    assert r.error_estimate is None and "estimate" in r.timings
