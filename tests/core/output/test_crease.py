"""Direct light per corner where a corner's shading normal and its triangle disagree
(core/output/crease.py), against closed forms of Cycles' rule: a triangle whose smoothed normal
faces away from it is turned around (N and Ng both negated) and takes no light from below its
plane, with the cosine to the shading normal.

A single square faces down (Ng = -z); its corner normals lean 120 degrees off it, 60 degrees off
+z toward +x. Cycles shades it with N' = -N (30 degrees below the horizon, toward -x) and
Ng' = +z: light arrives only from the lune above the horizon on N''s side."""
import numpy as np
import pytest

from hemicube_radiosity.core.light.lamps import SunLight
from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.pipeline import BakeSettings, bake
from hemicube_radiosity.core.rays import embree_available

pytestmark = pytest.mark.skipif(not embree_available(), reason="the corners' rays need Embree")

RHO = 0.5
LEAN = np.radians(120.0)                       # shading normal off the face's own normal (-z)
N_SHADE = np.array([np.sin(LEAN), 0.0, -np.cos(LEAN)])    # (0.87, 0, 0.5): up and toward +x


def _overhang():
    """A 1 m square at z = 1 facing down, its corner normals all ``N_SHADE``."""
    m = MeshInput.from_faces([(0, 0, 1), (0, 1, 1), (1, 1, 1), (1, 0, 1)], [(0, 1, 2, 3)],
                             rho=(RHO, RHO, RHO), name="overhang")
    m.corner_normal = np.tile(N_SHADE, (4, 1))
    return m


def _corners(result):
    """(n, 3) the written values at the front object's element corners."""
    own = result.elements.owner == 0
    return result.corner_values()[own].reshape(-1, 3)


def _settings():
    return BakeSettings(patch_size=0.5, element_size=0.25, two_sided_reflection=False)


def test_a_sun_in_the_lune_lights_a_turned_around_corner_by_its_shading_cosine():
    # a sun 10 degrees above the horizon, from -x: 40 degrees off N' = -N_SHADE, 80 off Ng' = +z
    el = np.radians(10.0)
    to_sun = np.array([-np.cos(el), 0.0, np.sin(el)])
    r = bake([_overhang()], _settings(), lights=[SunLight(-to_sun, strength=3.0)])
    want = RHO * 3.0 * float(-N_SHADE @ to_sun) / np.pi      # cos 40 degrees
    got = _corners(r)
    np.testing.assert_allclose(got, want, rtol=1e-9)


def test_a_sun_above_the_shading_normal_does_not_light_a_turned_around_corner():
    # straight above: 30 degrees off the shading normal, but Cycles turns the face around (its
    # N' points down): 0, not the cos 30 of the shading normal as it is
    r = bake([_overhang()], _settings(), lights=[SunLight((0.0, 0.0, -1.0), strength=3.0)])
    np.testing.assert_array_equal(_corners(r), 0.0)


def test_the_world_lights_a_turned_around_corner_through_the_lune_only():
    # the cosine-weighted share of N''s hemisphere above the plane of Ng': (1 + N' . Ng') / 2
    # (the sky view factor of a plane tilted by their angle), 1/4 here
    s = _settings()
    s.sky_rays = 1024                         # the lattice's estimate of a lune: ~1% at 1024 rays
    r = bake([_overhang()], s, world=np.array([1.0, 1.0, 1.0]))
    want = RHO * (1.0 + float(-N_SHADE @ np.array([0.0, 0.0, 1.0]))) / 2
    got = _corners(r)
    assert want == pytest.approx(0.125)
    np.testing.assert_allclose(got, want, rtol=0.015)


def _step(profile, nx=3):
    """A step extruded along x over [-1, 1] from ``profile`` (y, z) points, quads facing up and
    +y, its corner normals Blender's smooth ones (the mean of the faces' at each vertex: all
    the faces' corners there are right angles)."""
    xs = np.linspace(-1.0, 1.0, nx + 1)
    verts = np.array([(x, y, z) for y, z in profile for x in xs])
    row = nx + 1
    faces = [(k * row + i, k * row + i + 1, (k + 1) * row + i + 1, (k + 1) * row + i)
             for k in range(len(profile) - 1) for i in range(nx)]
    m = MeshInput.from_faces(verts, faces, name="step")
    seg = [np.array([0.0, z0 - z1, y1 - y0]) / np.hypot(z0 - z1, y1 - y0)
           for (y0, z0), (y1, z1) in zip(profile[:-1], profile[1:])]
    k = np.arange(len(profile))
    vn = [seg[0] if i == 0 else seg[-1] if i == len(profile) - 1 else seg[i - 1] + seg[i] for i in k]
    vn = np.repeat([v / np.linalg.norm(v) for v in vn], row, axis=0)
    m.corner_normal = vn[m.face_indices]
    return m, faces


@pytest.mark.parametrize("profile, zenith, blocked", [
    (((-1.0, 1.0), (-0.5, 1.0), (0.0, 1.0), (0.15, 0.5), (0.3, 0.0)), 30.0, 0.0),
    (((-1.0, 1.0), (-0.5, 1.0), (0.0, 1.0), (0.1, 0.0)), 40.0, 1.0)])
def test_a_lip_s_slope_corner_is_blocked_where_cycles_lifted_ray_meets_the_slope(profile, zenith, blocked):
    """The sun below the slope's plane, above the smoothed normal's at the lip: Cycles' shadow
    ray, lifted off the slope's corner, passes over the lip's edge on the 73-degree slope and
    meets the slope on the 84-degree one (Cycles itself: tests/blender/test_shading_normals.py)."""
    from hemicube_radiosity.core.mesh.subdivide import build_patches
    from hemicube_radiosity.core.output.lift import face_corners, lifted_starts
    from hemicube_radiosity.core.rays import occluder

    m, faces = _step(profile)
    patches = build_patches([m], 10.0)
    assert np.array_equal(patches.source_face, np.arange(len(faces)))       # one patch a face
    occ = occluder(patches, "auto")
    zen = np.radians(zenith)
    to_sun = np.array([0.0, -np.sin(zen), np.cos(zen)])
    face = np.array([6, 7, 8] * 2)                              # the slope's first row
    top = np.array([np.asarray(m.verts)[faces[f][j]] for j in (0, 1) for f in (6, 7, 8)])
    corner = face_corners(m, face, top, 1e-9)
    assert np.array_equal(corner, [0, 0, 0, 1, 1, 1])
    start = lifted_starts(patches, [m], face, corner)
    assert np.all(np.isfinite(start))
    got = occ.occluded(start, np.broadcast_to(to_sun, start.shape), None)
    np.testing.assert_array_equal(got, bool(blocked))


def test_a_corner_lit_as_its_vertex_takes_the_vertexs_light_and_casts_no_ray(monkeypatch):
    """A smooth step on a floor under a sun and the world: the lip's and the slope's corners
    lean more than 15 degrees off their faces, but their shading normal is the vertex's and
    their rays start where the vertex's do, so they take the vertex's light (no ray of their
    own; here 72 of the 108 corners lit on their own, all inside the step's faces: a corner of
    a face, where Cycles bakes, starts its rays below the plane at Cycles' lifted start).
    Lighting every one of them again instead gives the same corners, to rounding."""
    from hemicube_radiosity.core.builtin_scenes import quad
    from hemicube_radiosity.core.light.direct import DirectLight
    from hemicube_radiosity.core.output import crease

    m, _ = _step(((-1.0, 0.6), (-0.5, 0.6), (0.0, 0.6), (0.15, 0.3), (0.3, 0.0)))
    floor = quad([(-1.5, -1.5, 0), (1.5, -1.5, 0), (1.5, 1.5, 0), (-1.5, 1.5, 0)], name="floor")
    sun = SunLight(direction=(0.3, -0.5, -0.8), strength=3.0)
    world = np.array([0.35, 0.45, 0.6])
    real, seen, lit = crease._make_corner_rays, [], []

    def spy(*a, force=False):
        out = real(*a)
        seen.append(out)
        return out[:6] + (np.zeros_like(out[6]),) + out[7:] if force else out
    real_at = DirectLight.at

    def at(self, points, *a, **k):
        if a and a[1] == "corners" or k.get("where") == "corners":
            lit.append(len(points))
        return real_at(self, points, *a, **k)
    monkeypatch.setattr(DirectLight, "at", at)
    monkeypatch.setattr(crease, "_make_corner_rays", spy)
    s = _settings()
    shared = bake([m, floor], s, lights=[sun], world=world)
    same, low = seen[-1][6], seen[-1][7]
    assert same.sum() >= len(same) // 2 and sum(lit) == (~same).sum()
    assert not (same & np.isfinite(low).all(axis=1)).any()
    monkeypatch.setattr(crease, "_make_corner_rays", lambda *a: spy(*a, force=True))
    lit.clear()
    own = bake([m, floor], s, lights=[sun], world=world)
    assert sum(lit) == len(same)
    np.testing.assert_allclose(shared.corner_values(), own.corner_values(), rtol=1e-9, atol=1e-12)


def test_a_corner_normal_a_hair_behind_its_face_is_turned_as_at_cycles_bake_point(monkeypatch):
    """A 1 m square facing up whose corner normals along x = 0 lie along the face, a millionth
    behind it ((-1, 0, -1e-6): a wall's foot shaded with the floor's normal, Cycles' per-vertex
    normals, core/mesh/cycles_normals.py), the other two +z. Cycles turns a triangle around by
    its normal at the bake point, 1e-4 in toward the triangle's centre, where the +z corners
    already tip it in front: those corners are not turned, and a sun from -x lights them by
    rho E (N . L) / pi, their rays starting off the face along the two normals' bisector. Turned
    by their own normal's sign, or with their rays started along that normal (a hair behind the
    face, they meet it), as before, they read 0."""
    n = np.array([-1.0, 0.0, -1e-6]) / np.linalg.norm([-1.0, 0.0, -1e-6])
    m = MeshInput.from_faces([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1, 2, 3)],
                             rho=(RHO, RHO, RHO), name="floor")
    m.corner_normal = np.array([n, (0, 0, 1), (0, 0, 1), n], dtype=np.float64)
    el = np.radians(30.0)
    to_sun = np.array([-np.cos(el), 0.0, np.sin(el)])
    r = bake([m], _settings(), lights=[SunLight(-to_sun, strength=3.0)])
    E = r.elements
    at_edge = E.verts[E.polys][..., 0] == 0.0               # (N, 4) element corners on x = 0
    got = r.corner_values()[at_edge & (E.polys >= 0)]
    assert len(got) == 8                                     # 4 elements along the edge, 2 corners each
    np.testing.assert_allclose(got, RHO * 3.0 * float(n @ to_sun) / np.pi, rtol=1e-6)
    import hemicube_radiosity.core.output.crease as crease
    monkeypatch.setattr(crease, "NEAR_PERPENDICULAR", 0.0)
    before = bake([m], _settings(), lights=[SunLight(-to_sun, strength=3.0)])
    np.testing.assert_array_equal(before.corner_values()[at_edge & (E.polys >= 0)], 0.0)


@pytest.mark.parametrize("scene", ["step", "board"])
def test_a_lightmap_reads_the_corners_reflected_light_and_finds_no_corner_s_own_direct(monkeypatch, scene):
    """The lightmap target lights its texels again (:mod:`..output.texels`) and reads only the
    corners' emission, reflectivity and light reflected more than once
    (``BakeResult.corner_parts``): no corner is lit on its own for it (no ray toward the lamps
    or the world from a creased or covered corner), and what it reads is the vertex-colour
    target's, bit for bit (the emission to rounding: it is what is left of each corner's value)."""
    from hemicube_radiosity.core.builtin_scenes import quad
    from hemicube_radiosity.core.light.direct import DirectLight
    from tests.core.output.test_covered import _board, _floor

    if scene == "step":
        m, _ = _step(((-1.0, 0.6), (-0.5, 0.6), (0.0, 0.6), (0.15, 0.3), (0.3, 0.0)))
        meshes = [m, quad([(-1.5, -1.5, 0), (1.5, -1.5, 0), (1.5, 1.5, 0), (-1.5, 1.5, 0)], name="floor")]
        s, sun = _settings(), SunLight(direction=(0.3, -0.5, -0.8), strength=3.0)
    else:
        meshes = [_floor(), _board(1e-5)]
        s = BakeSettings(patch_size=1.0, element_size=1.0, two_sided_reflection=False, gather_rays=64)
        sun = SunLight((0.0, 0.0, -1.0), strength=3.0)
    world = np.array([0.35, 0.45, 0.6])
    lit = []
    real_at = DirectLight.at

    def at(self, points, normals, where, *a, **k):
        lit.append(where)
        return real_at(self, points, normals, where, *a, **k)
    monkeypatch.setattr(DirectLight, "at", at)
    vc = bake(meshes, s, lights=[sun], world=world)
    own = {"step": "corners", "board": "covered"}[scene]
    assert own in lit and vc.corner_direct is not None
    lit.clear()
    from dataclasses import replace
    lm = bake(meshes, replace(s, target="lightmap", output_mode="copy"), lights=[sun], world=world)
    assert not {"corners", "corners-below", "covered", "covered-below"} & set(lit), set(lit)
    (E1, rho1, D1, I1), (E2, rho2, D2, I2) = vc.corner_parts(), lm.corner_parts()
    np.testing.assert_array_equal(rho1, rho2)
    np.testing.assert_array_equal(I1, I2)
    np.testing.assert_allclose(E1, E2, atol=1e-12)
    # the corners lit on their own for the vertex colours take their vertex's light here
    cv = lm.elements.corner_ids()
    np.testing.assert_array_equal(D2, lm.vertex_direct[cv])
    assert not np.array_equal(D1, D2)
