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

    # the elements' own work apart (the lamp refines other patches than the sun: other shadow
    # edges and rays that hit; test_the_outputs_terms_follow_what_they_count)
    monkeypatch.setattr(forecast_module, "PER_EDGE", 0.0)
    monkeypatch.setattr(forecast_module, "PER_VERTEX_HIT", 0.0)
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


def test_the_outputs_terms_follow_what_they_count(monkeypatch):
    """Under lamps the output's forecast is a rate per casting vertex that grows with the share
    of its rays that meet a surface, plus a rate per element a shadow's edge crosses and per
    leaning corner: doubling each count adds exactly its term (on one worker), and the counts
    are those of the bake's own output mesh."""
    from types import SimpleNamespace
    from hemicube_radiosity.core.light.lamps import SunLight
    from hemicube_radiosity.core.runtime import forecast as forecast_module
    from hemicube_radiosity.core.runtime.forecast import (
        PER_EDGE, PER_LEANING, PER_VERTEX_HIT, PER_VERTEX_LAMPS, forecast)

    room = scenes.cornell_box(light_radiance=0.0)
    sun = [SunLight((0.0, 0.0, -1.0))]
    r = bake(room, BakeSettings(workers=1, **SMALL), lights=sun)
    f = r.forecast
    assert f.hit is not None and 0.5 < f.hit < 1.0          # inside a box open on one side
    assert f.leaning == 0                                   # flat faces: no corner normals
    ctx = SimpleNamespace(settings=r.settings, patches=r.patches, clusters=r.clusters,
                          unknowns=r.patches, lights=sun, meshes=None)
    counts = {}
    monkeypatch.setattr(forecast_module, "rays_ahead", lambda *a, **k: (counts["hit"], counts["edges"]))
    monkeypatch.setattr(forecast_module, "leaning_ahead", lambda *a, **k: counts["leaning"])

    def output(hit=0.25, edges=100.0, leaning=300.0):
        counts.update(hit=hit, edges=edges, leaning=leaning)
        return forecast(ctx, 10, 1000, mesh=r.patches).output
    base = output()
    rays = max(r.settings.gather_rays, 32) / 128                 # (at least 32: forecast())
    assert np.isclose(base, 1000 * (PER_VERTEX_LAMPS + 0.25 * PER_VERTEX_HIT) * rays + 100 * PER_EDGE + 300 * PER_LEANING)
    assert np.isclose(output(edges=200.0) - base, 100 * PER_EDGE)
    assert np.isclose(output(leaning=600.0) - base, 300 * PER_LEANING)
    assert np.isclose(output(hit=0.5) - base, 1000 * 0.25 * PER_VERTEX_HIT * rays)
    assert forecast(ctx, 10, 1000).output < base            # no mesh: nothing of it counted


def _plate(x0, x1, z, up=True):
    from hemicube_radiosity.core.mesh.patches import MeshInput
    v = [[x0, x0, z], [x1, x0, z], [x1, x1, z], [x0, x1, z]]
    return MeshInput.from_faces(v, [[0, 1, 2, 3] if up else [0, 3, 2, 1]])


def test_rays_ahead_count_the_sky_hidden_and_the_shadow_edges():
    """The share of rays that meet a surface, from the elements of two parallel 2 x 2 squares
    1 apart facing each other, is their view factor (closed form for parallel rectangles,
    0.4155); from one square alone, none. A square 3 across a unit above a floor of unit
    elements, its edges at their middles, shadows the sun straight down: its shadow's edge
    crosses the ring of 12 elements around it, two such squares 24."""
    from hemicube_radiosity.core.light.lamps import SunLight
    from hemicube_radiosity.core.mesh.subdivide import build_patches
    from hemicube_radiosity.core.runtime.forecast import rays_ahead
    X = 2.0
    q = np.sqrt(1 + X * X)
    view = 2 / (np.pi * X * X) * (np.log((1 + X * X) / np.sqrt(1 + 2 * X * X))
                                  + 2 * X * q * np.arctan(X / q) - 2 * X * np.arctan(X))
    plates = build_patches([_plate(0, 2, 0), _plate(0, 2, 1, up=False)], 0.125)
    hit, edges = rays_ahead(plates, plates, [])
    assert abs(hit - view) < 0.02 and edges == 0 and abs(view - 0.4155) < 1e-3
    alone = build_patches([_plate(0, 2, 0)], 0.125)
    assert rays_ahead(alone, alone, [])[0] == 0
    sun = [SunLight((0.0, 0.0, -1.0))]
    one = [_plate(0, 16, 0), _plate(2.5, 5.5, 1)]
    two = one + [_plate(9.5, 12.5, 1)]
    for meshes, ring in ((one, 12), (two, 24)):
        m = build_patches(meshes, 1.0)
        assert rays_ahead(m, m, sun, sky=False) == (None, ring)


def test_leaning_corners_are_counted_on_a_sample():
    """Corners whose shading normal leans past the crease angle off their face's: a 16 x 16 grid
    of quads whose corner normals all point up but for k faces', tilted 30 degrees: 4 k
    corners lean (counted on every corner, and on a sample of them about as many); tilted 10
    degrees, none."""
    from hemicube_radiosity.core.mesh.patches import MeshInput
    from hemicube_radiosity.core.mesh.subdivide import build_patches
    from hemicube_radiosity.core.runtime.forecast import leaning_ahead
    n = 16
    g = np.arange(n + 1.0)
    verts = np.array([[x, y, 0.0] for y in g for x in g])
    faces = [[j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i]
             for j in range(n) for i in range(n)]

    def grid(k, degrees=30.0):
        m = MeshInput.from_faces(verts, faces)
        cn = np.tile([0.0, 0.0, 1.0], (len(m.face_indices), 1))
        t = np.radians(degrees)
        cn[: 4 * k] = [np.sin(t), 0.0, np.cos(t)]
        m.corner_normal = cn
        return m
    for k in (10, 20, 40):
        m = grid(k)
        mesh = build_patches([m], None)
        assert leaning_ahead(mesh, [m]) == 4 * k
        assert abs(leaning_ahead(mesh, [m], sample=256) - 4 * k) <= 0.1 * 4 * k + 4
    m = grid(40, 10.0)
    assert leaning_ahead(build_patches([m], None), [m]) == 0
    assert leaning_ahead(build_patches([m], None), None) == 0


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


def test_an_environment_map_counts_its_rays_at_the_output():
    """An environment map's light is shadow rays toward its directions from every point the
    output lights (core/light/environment.py): the forecast counts ENV_POINTS points a vertex,
    each casting toward the half of its directions above its horizon. Counted, not timed: the
    rays the bake casts toward the map, by its kernel, within 2x of the count the forecast said."""
    from hemicube_radiosity.core.light import environment, lamps
    from hemicube_radiosity.core.light.environment import RAYS_PER_SKY_RAY
    from hemicube_radiosity.core.runtime.forecast import ENV_POINTS, PER_ENV_RAY, forecast
    from types import SimpleNamespace
    from tests.core.light.test_lamp_cache import _court, _sky

    env = environment.EnvironmentLight(_sky(), rays=64)
    cast = []
    kernel = lamps.KERNELS[environment.EnvironmentLight]

    def counted(light, x, n, *a, **k):
        d, _ = light.directions(light.rays, seed=0)
        cast.append(int(((np.asarray(n) @ d.T) > 0).sum()))
        return kernel(light, x, n, *a, **k)
    lamps.KERNELS[environment.EnvironmentLight] = counted
    try:
        r = bake(_court(), BakeSettings(workers=1, **SMALL), lights=[env], world=env.base())
    finally:
        lamps.KERNELS[environment.EnvironmentLight] = kernel
    f = r.forecast
    rays = RAYS_PER_SKY_RAY * r.settings.sky_rays                      # the map's directions a point
    said = f.vertices * ENV_POINTS * 0.5 * rays
    assert sum(cast) > f.vertices * rays / 4                          # the map lit the output
    assert 0.5 < said / sum(cast) < 2.0, (said, sum(cast), f.vertices)
    ctx = SimpleNamespace(settings=r.settings, patches=r.patches, clusters=r.clusters, unknowns=r.patches,
                          lights=[env], meshes=None)
    without = forecast(SimpleNamespace(**{**vars(ctx), "lights": []}), 10, 1000).output
    assert np.isclose(forecast(ctx, 10, 1000).output - without,
                      1000 * ENV_POINTS * 0.5 * rays * PER_ENV_RAY + 1000 * _shine_per_vertex())


def _shine_per_vertex():
    """Per vertex, what shines where a light other than a sun lights the scene (as for lamps)."""
    from hemicube_radiosity.core.output.shine import BUDGET
    from hemicube_radiosity.core.runtime.forecast import PER_VERTEX_SHINE
    return BUDGET * PER_VERTEX_SHINE


def test_a_dense_scene_s_faces_count_nothing_that_shines():
    """Where a dense scene's faces gather (``indirect.gathers_faces``) nothing shines (its
    corrections run with a budget of 0 groups): a point lamp adds the budget's shine to each
    output vertex's forecast elsewhere, nothing there."""
    from types import SimpleNamespace
    from hemicube_radiosity.core.light.lamps import PointLight
    from hemicube_radiosity.core.output.indirect import gathers_faces
    from hemicube_radiosity.core.rays import embree_available
    from hemicube_radiosity.core.runtime.forecast import forecast

    assert embree_available()                       # the faces' gather needs Embree
    lamp = PointLight((1.0, 1.0, 1.0))
    room = scenes.tessellate(scenes.cornell_box(light_radiance=0.0), 8)      # faces grouped
    r = bake(room, BakeSettings(workers=1, **SMALL), lights=[lamp])
    assert r.clusters is not None
    added = {}
    for dense in (False, True):
        ctx = SimpleNamespace(settings=r.settings, patches=r.patches, clusters=r.clusters, unknowns=r.clusters,
                              meshes=None, dense=dense, lights=[lamp])
        assert gathers_faces(ctx) == dense
        none = SimpleNamespace(**{**vars(ctx), "lights": []})
        added[dense] = forecast(ctx, 10, 1000).output - forecast(none, 10, 1000).output
    assert np.isclose(added[False], 1000 * _shine_per_vertex()) and added[True] == 0.0
