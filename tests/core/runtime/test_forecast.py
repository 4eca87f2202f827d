"""The time a bake expects, said before its form factors (core/runtime/forecast.py): counted from the
bake's own receivers, curved pieces and output vertices; none when the form factors are cached.
(How close it comes to the time taken is measured by bench/bench_dense.py, not here: timings in
unit tests are mostly the noise of whatever else the machine runs.)"""
import numpy as np

from hemicube_radiosity.core import builtin_scenes as scenes
from hemicube_radiosity.core.runtime.cache import FormFactorCache
from hemicube_radiosity.core.runtime.forecast import OTHER, curved_pieces
from hemicube_radiosity.core.form_factors.stage import receivers_needed
from hemicube_radiosity.core.mesh.stage import cut_patches as _cut
from hemicube_radiosity.core.pipeline import BakeSettings, bake

from tests.support.shapes import sphere

SMALL = dict(patch_size=0.5, element_size=0.25, resolution=16, gather_rays=16)


def test_forecast_is_said_before_the_form_factors_and_counts_the_bake():
    said = []
    cache = FormFactorCache()
    r = bake(scenes.cornell_box(), BakeSettings(workers=1, **SMALL), cache=cache,
             progress=lambda stage, fr, msg: said.append((stage, fr, msg)))
    f = r.forecast
    ff = [m for st, _, m in said if st == "form_factors" and m]
    said_at = ff.index(f.describe())
    assert f.describe().startswith("expected about")
    eta = [i for i, m in enumerate(ff) if "ETA" in m]
    assert eta and min(eta) > said_at                   # said before the hemi-cubes' progress
    u = r.patches if r.clusters is None else r.clusters
    assert f.receivers == len(receivers_needed(u)) and f.workers == 1
    # the output it counted is the output the bake made, less the vertices that the cut along
    # contacts adds (made meanwhile, on two workers) and those split at partitions: 606 of 676
    assert 0.85 * len(r.elements.verts) <= f.vertices <= len(r.elements.verts)
    assert f.seconds > 0 and np.isclose(f.seconds, (1 + OTHER) * (f.form_factors + f.output))
    # a relight reads F from the cache: nothing long to forecast
    again = bake(scenes.cornell_box(), BakeSettings(workers=1, **SMALL), cache=cache)
    assert again.form_factor_source == "cached" and again.forecast is None


def test_forecast_follows_the_output_and_the_workers():
    coarse = bake(scenes.cornell_box(), BakeSettings(workers=1, **SMALL)).forecast
    fine = bake(scenes.cornell_box(), BakeSettings(workers=1, **{**SMALL, "element_size": 0.125})).forecast
    assert fine.vertices > 2 * coarse.vertices and fine.output > 2 * coarse.output
    assert fine.form_factors == coarse.form_factors                  # the same patches
    two = bake(scenes.cornell_box(), BakeSettings(workers=2, **SMALL)).forecast
    assert two.workers == 2 and two.seconds < coarse.seconds


def test_lamps_other_than_suns_count_what_shines(monkeypatch):
    """A point lamp's pools of light shine (core/output/shine.py), a sun's light does not: the
    lamp's forecast counts each output vertex a transport per group the budget allows, and
    each lamp past the first its shadow rays."""
    from hemicube_radiosity.core.light.lamps import PointLight, SunLight
    from hemicube_radiosity.core.output.shine import BUDGET
    from hemicube_radiosity.core.runtime import forecast as forecast_module
    from hemicube_radiosity.core.runtime.forecast import PER_EXTRA_LAMP, PER_VERTEX_SHINE

    # the elements' own work apart (the lamp refines other patches than the sun: another count
    # of elements cut; test_the_elements_cut_count_on_their_own)
    monkeypatch.setattr(forecast_module, "PER_ELEMENT_CUT", 0.0)
    # nor the vertices that share a place's gather rays (elements of refined patches meet
    # others' at their corners: another count for another refinement)
    monkeypatch.setattr(forecast_module, "PER_JOINED", 1.0)
    room = scenes.cornell_box(light_radiance=0.0)          # no emitting face
    sun = bake(room, BakeSettings(workers=1, **SMALL), lights=[SunLight((0.0, 0.0, -1.0))]).forecast
    lamp = bake(room, BakeSettings(workers=1, **SMALL), lights=[PointLight((1.0, 1.0, 1.0))]).forecast
    per_vertex = sun.output / sun.vertices                   # the gather and the direct light
    assert np.isclose(lamp.output, lamp.vertices * (per_vertex + BUDGET * PER_VERTEX_SHINE))
    two = bake(room, BakeSettings(workers=1, **SMALL), lights=[PointLight((1.0, 1.0, 1.0)),
                                                              PointLight((0.5, 1.5, 1.0))]).forecast
    assert np.isclose(two.output, two.vertices * (per_vertex + BUDGET * PER_VERTEX_SHINE + PER_EXTRA_LAMP))


def test_the_elements_cut_count_on_their_own(monkeypatch):
    """Under lamps, each output element the detail size makes beyond the pieces adds its own
    work to the output's forecast (what shines, abrupt grids, covered corners, the contact cut:
    indoor scenes of large walls spent 3-7 times a bunny's time per vertex); the pieces' own
    faces as the output add nothing."""
    from hemicube_radiosity.core.form_factors import stage
    from hemicube_radiosity.core.light.lamps import SunLight
    from hemicube_radiosity.core.runtime import forecast as forecast_module
    from hemicube_radiosity.core.runtime.forecast import PER_ELEMENT_CUT

    cut = []
    counted = stage.elements_cut_ahead
    monkeypatch.setattr(stage, "elements_cut_ahead", lambda ctx: cut.append(counted(ctx)) or cut[-1])
    room = scenes.cornell_box(light_radiance=0.0)
    sun = [SunLight((0.0, 0.0, -1.0))]
    with_cut = bake(room, BakeSettings(workers=1, **SMALL), lights=sun).forecast
    monkeypatch.setattr(forecast_module, "PER_ELEMENT_CUT", 0.0)
    without = bake(room, BakeSettings(workers=1, **SMALL), lights=sun).forecast
    assert cut[0] == cut[1] > 0
    assert np.isclose(with_cut.output - without.output, PER_ELEMENT_CUT * cut[0])
    whole = bake(room, BakeSettings(workers=1, **{**SMALL, "element_size": None}), lights=sun)
    assert cut[2] == 0 and whole.forecast.vertices == len(whole.patches.verts)


def test_curved_pieces_are_those_of_bent_clusters():
    """A flat cluster is drawn as its outline however it is cut; a curved one face by face."""
    flat = scenes.tessellate(scenes.cornell_box(), 4)
    pieces, clusters = _cut(flat, BakeSettings().resolved(flat))
    assert clusters is not None and curved_pieces(pieces, clusters) == 0
    ball = scenes.cornell_box() + [sphere(20)]
    pieces, clusters = _cut(ball, BakeSettings().resolved(ball))
    on_ball = np.array([pieces.object_names[o] == "Sphere" for o in pieces.owner])
    n = curved_pieces(pieces, clusters)
    assert 0.8 * on_ball.sum() <= n <= on_ball.sum()


def test_polygons_seen_are_those_in_front_and_facing():
    """Inside a room every receiver on the floor sees the four walls and the ceiling whole
    (their pieces in front of it and facing it), none of the floor; outside a sphere a point
    on it sees none of the sphere's other faces (but for a neighbour in its plane, to
    round-off). A flat cluster counts as its outline (2)."""
    from hemicube_radiosity.core.mesh.clusters import make_clusters
    from hemicube_radiosity.core.runtime.forecast import polygons_seen
    from hemicube_radiosity.core.mesh.subdivide import build_patches
    room = build_patches([scenes.box((0, 0, 0), (2, 2, 2), inward=True)], 0.25)
    floor = np.flatnonzero(room.normals[:, 2] > 0.5)
    assert len(floor) == 64 and len(room) == 6 * 64
    seen = polygons_seen(room, None, room.centers[floor], room.normals[floor])
    assert seen == 5 * 64
    # each face one flat cluster: drawn as its outline, 2 polygons a face seen
    axis = np.argmax(np.abs(room.normals), axis=1)
    face = 2 * axis + (room.normals[np.arange(len(room)), axis] > 0)
    clusters = make_clusters(room, np.unique(face, return_inverse=True)[1])
    assert len(clusters) == 6
    assert np.isclose(polygons_seen(room, clusters, room.centers[floor], room.normals[floor]), 5 * 2)
    ball = build_patches([sphere(16)], None)
    assert len(ball) == 512 and polygons_seen(ball, None, ball.centers, ball.normals) < 1   # (round-off at the poles)


def test_the_form_factors_forecast_is_the_time_of_a_sample_where_one_is_drawn(monkeypatch):
    """Where the hemi-cube draws a sample first (here with fewer receivers than a real scene
    needs), the form factors' forecast is its time per receiver times the receivers, over the
    workers' speed-up; said once, before the progress, and saying so."""
    from hemicube_radiosity.core.form_factors import hemicube
    from hemicube_radiosity.core.runtime.forecast import PER_EXTRA_WORKER
    monkeypatch.setattr(hemicube, "PROBE_MIN_BATCHES", 1)
    said = []
    r = bake(scenes.cornell_box(), BakeSettings(workers=2, method="hemicube", **SMALL),
             progress=lambda stage, fr, msg: said.append((stage, msg)))
    f = r.forecast
    assert f.per_receiver is not None and 0 < f.per_receiver < 1
    assert np.isclose(f.form_factors, f.receivers * f.per_receiver / (1 + PER_EXTRA_WORKER))
    ff = [m for st, m in said if st == "form_factors" and m]
    assert sum(m.startswith("expected about") for m in ff) == 1 and "timed on a sample" in ff[0]


def test_vertices_that_share_a_places_gather_rays_count_their_share():
    """A flat-shaded mesh's corners at one place cast one set of gather rays
    (core/output/shared.py): the forecast counts each corner past the first at PER_JOINED of a
    vertex, and a smooth mesh (no two vertices at one place) as before."""
    from hemicube_radiosity.core.mesh.patches import MeshInput
    from hemicube_radiosity.core.output.shared import joined_ahead
    from hemicube_radiosity.core.mesh.subdivide import build_patches
    from hemicube_radiosity.core.runtime.forecast import PER_JOINED, forecast

    a = np.arange(6) * np.pi / 3
    ring = np.c_[np.cos(a), np.sin(a), np.zeros(6)]
    smooth = MeshInput.from_faces(np.vstack([[0, 0, 0.3], ring]), [[0, 1 + i, 1 + (i + 1) % 6] for i in range(6)])
    flat = MeshInput.from_faces(np.array([v for i in range(6) for v in ([0, 0, 0.3], ring[i], ring[(i + 1) % 6])]),
                                [[3 * i, 3 * i + 1, 3 * i + 2] for i in range(6)])
    assert joined_ahead(build_patches(smooth, None)) == 0
    # the apex's 6 corners share (faces 38 degrees apart), each ring place's 2 (faces 19 apart)
    assert joined_ahead(build_patches(flat, None)) == 5 + 6
    r = bake(scenes.cornell_box(), BakeSettings(workers=1, **SMALL))
    from types import SimpleNamespace
    ctx = SimpleNamespace(settings=r.settings, patches=r.patches, clusters=r.clusters, unknowns=r.patches)
    one = forecast(ctx, 10, 1000)
    shared = forecast(ctx, 10, 1000, joined=600)
    assert np.isclose(shared.output, one.output * (400 + 600 * PER_JOINED) / 1000)
    assert shared.form_factors == one.form_factors
