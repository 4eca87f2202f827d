"""The whole core bake on closed-form and measured cases (furnace, Cornell box)."""
import re

import numpy as np
from tests.support import fronts
import pytest

from hemicube_radiosity.core.runtime.cache import FormFactorCache
from hemicube_radiosity.core.pipeline import BakeSettings, bake
from hemicube_radiosity.core.builtin_scenes import CORNELL_WHITE, box, closed_box, cornell_box
from hemicube_radiosity.core.mesh import subdivide
from tests.support.patching import everywhere

METHODS = ["hemicube", "embree"]


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("rho", [0.5, 0.9])
def test_furnace_every_patch_is_e_over_one_minus_rho(method, rho):
    """Closed room, E = 1 and the same rho everywhere: B = E / (1 - rho) exactly (paper-notes)."""
    r = bake(closed_box(size=(1.0, 1.3, 0.8), rho=(rho,) * 3, emission=(1.0,) * 3),
             BakeSettings(patch_size=0.2, resolution=128, method=method, tolerance=1e-7, max_iterations=2000))
    assert r.solution.converged
    np.testing.assert_allclose(r.solution.B, 1 / (1 - rho), rtol=5e-3)
    np.testing.assert_allclose(r.vertex_radiosity, 1 / (1 - rho), rtol=5e-3)
    assert r.solution.energy["imbalance"] < 5e-3


def _block_hit(origins, targets, block):
    """True where the segment origin->target passes through a (z-rotated) box block."""
    lo, hi, ang = block
    c = 0.5 * (np.asarray(lo) + np.asarray(hi))
    ca, sa = np.cos(-ang), np.sin(-ang)

    def local(p):
        q = p - c
        return np.stack([ca * q[..., 0] - sa * q[..., 1], sa * q[..., 0] + ca * q[..., 1], q[..., 2]], -1) + c

    o, t = local(origins), local(targets)
    d = t - o
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = (np.asarray(lo) - o) / d
        t1 = (np.asarray(hi) - o) / d
    tmin = np.nanmax(np.minimum(t0, t1), axis=-1)
    tmax = np.nanmin(np.maximum(t0, t1), axis=-1)
    return (tmax >= np.maximum(tmin, 1e-9)) & (tmin < 1 - 1e-9)


def light_visibility(points, s=2.0, light=0.5, n=16):
    """Fraction of the ceiling light visible from each point, by exact segment-box tests."""
    g = (np.arange(n) + 0.5) / n * light + (s - light) / 2
    lp = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    lp = np.concatenate([lp, np.full((len(lp), 1), s * (1 - 1e-3))], 1)
    blocks = [((0.27 * s, 0.17 * s, 0), (0.57 * s, 0.47 * s, 0.3 * s), np.radians(-17)),
              ((0.53 * s, 0.5 * s, 0), (0.83 * s, 0.8 * s, 0.6 * s), np.radians(17))]
    o = np.repeat(points[:, None, :], len(lp), 1)
    t = np.broadcast_to(lp[None], o.shape)
    blocked = np.zeros(o.shape[:2], bool)
    for b in blocks:
        blocked |= _block_hit(o, t, b)
    return 1 - blocked.mean(axis=1)


@pytest.fixture(scope="module")
def cornell():
    # refine_levels=0: the same floor grid with and without the blocks
    settings = BakeSettings(patch_size=0.125, resolution=64, method="hemicube", element_size=None,
                            refine_levels=0)
    cache = FormFactorCache()
    with_blocks = bake(cornell_box(), settings, cache=cache)
    no_blocks = bake(cornell_box()[:6], settings)
    white = [m for m in cornell_box()]
    white[3].face_rho[:] = CORNELL_WHITE  # the red wall painted white (same geometry: F reused)
    all_white = bake(white, settings, cache=cache)
    assert all_white.form_factor_source == "cached"
    return with_blocks, no_blocks, all_white


def floor(r):
    ps = r.patches
    sel = ps.owner == ps.object_names.index("Floor")
    return ps.centers[sel], r.solution.B[sel]


def test_cornell_blocks_cast_shadows(cornell):
    """Floor patches the light cannot see (umbra, by exact segment tests) keep only indirect light."""
    wb, nb, _ = cornell
    c, B = floor(wb)
    c0, B0 = floor(nb)
    # the same 16 x 16 floor grid in both bakes, the blocks' outlines cutting it further
    # (core/mesh/contact.py): each piece against the blocks-free patch it lies in
    cell = (np.floor(c / 0.125).astype(int) @ [16, 1, 0])
    cell0 = (np.floor(c0 / 0.125).astype(int) @ [16, 1, 0])
    assert len(c0) == 256 and np.array_equal(np.sort(cell0), np.arange(256)) and len(c) > 256
    B0 = B0[np.argsort(cell0)][cell]
    vis = light_visibility(c + [0, 0, 1e-6])
    # patches under a block's footprint see nothing; exclude them (they are covered, not shadowed)
    umbra = (vis == 0) & (B.sum(1) > 0) & (B0.sum(1) > 0)
    lit = vis == 1
    assert umbra.sum() >= 8 and lit.sum() >= 50
    ratio = B.sum(1) / B0.sum(1)
    # in the umbra only indirect light remains: far below the unshadowed floor
    assert np.median(ratio[umbra]) < 0.35
    assert np.median(ratio[lit]) > 0.85
    # and shadowing grows monotonically with how much of the light is hidden (coarse bins)
    part = (vis > 0.3) & (vis < 0.7)
    assert np.median(ratio[umbra]) < np.median(ratio[part]) < np.median(ratio[lit])


def test_cornell_red_bleeds_onto_the_floor_near_the_red_wall(cornell):
    wb, _, aw = cornell
    c, B = floor(wb)
    c2, B2 = floor(aw)
    near_red = (c[:, 0] < 0.25) & (c[:, 1] > 0.5) & (c[:, 1] < 1.5)
    near_green = (c[:, 0] > 1.75) & (c[:, 1] > 0.5) & (c[:, 1] < 1.5)
    # red/green ratio per floor patch (patches buried under a block are black: left out)
    lit = (B[:, 1] > 0) & (B2[:, 1] > 0)
    near_red &= lit
    near_green &= lit
    rg = np.where(lit, B[:, 0], 0) / np.where(lit, B[:, 1], 1)
    rg_white = np.where(lit, B2[:, 0], 0) / np.where(lit, B2[:, 1], 1)
    # with a white wall the floor keeps the white paint's own tint (0.725/0.71) ...
    assert np.median(rg_white[near_red]) == pytest.approx(0.725 / 0.71, rel=0.03)
    # ... with the red wall the floor near it turns measurably red, near the green wall it does not
    assert np.median(rg[near_red]) > 1.15 * np.median(rg_white[near_red])
    assert np.median(rg[near_red]) > 1.3 * np.median(rg[near_green])


def test_relight_reuses_form_factors_and_equals_a_cold_bake():
    meshes = cornell_box()
    cache = FormFactorCache()
    s = BakeSettings(patch_size=0.25, resolution=32, method="hemicube", tolerance=1e-8)
    first = bake(meshes, s, cache=cache)
    assert first.form_factor_source == "computed"
    relit = cornell_box(light_radiance=20.0)
    relit[4].face_rho[:] = (0.2, 0.2, 0.8)  # green wall painted blue
    warm = bake(relit, s, cache=cache)
    assert warm.form_factor_source == "cached" and warm.form_factors is first.form_factors
    cold = bake(relit, s)
    assert cold.form_factor_source == "computed"
    np.testing.assert_allclose(warm.solution.B, cold.solution.B, rtol=1e-6, atol=1e-9)
    assert not np.allclose(warm.solution.B, first.solution.B, rtol=0.05)
    # geometry change -> recomputed
    moved = cornell_box(light_size=0.6)
    assert bake(moved, s, cache=cache).form_factor_source == "computed"


def test_relight_with_lamps_reuses_form_factors_and_direct_transport(monkeypatch):
    """A new lamp colour, a new emission strength and a new wall colour: F and the emitters'
    direct-light transport come from the cache (no hemi-cube; no emitter ray is cast before the
    vertex stage, which casts only for the points where the changed light is now abrupt), and
    the result equals a cold bake of the changed scene."""
    from hemicube_radiosity.core.light import emitters as direct
    from hemicube_radiosity.core import pipeline
    from hemicube_radiosity.core.light.lamps import PointLight

    s = BakeSettings(patch_size=0.25, resolution=32, tolerance=1e-8)
    cache = FormFactorCache()
    lamp = PointLight(position=(1.0, 0.6, 1.5), color=(1.0, 1.0, 1.0), power_w=40.0, radius=0.0)
    first = bake(cornell_box(), s, cache=cache, lights=[lamp])
    changed = cornell_box(light_radiance=5.0)
    changed[2].face_rho[:] = (0.3, 0.6, 0.3)
    lamp2 = PointLight(position=(1.0, 0.6, 1.5), color=(1.0, 0.5, 0.2), power_w=40.0, radius=0.0)
    cold = bake(changed, s, lights=[lamp2])

    def no_hemicubes(*a, **k):
        raise AssertionError("form factors must come from the cache")

    running, cast = [], []                     # the stage running; the stage of every transport
    real = direct.emitter_transport

    def spy(*a, **k):
        cast.append(running[-1])
        return real(*a, **k)

    def named(name, stage):
        return lambda ctx: running.append(name) or stage(ctx)

    everywhere(monkeypatch, direct.emitter_transport, spy)
    everywhere(monkeypatch, pipeline.compute_form_factors, no_hemicubes)
    monkeypatch.setattr(pipeline, "STAGES", tuple((n, named(n, f)) for n, f in pipeline.STAGES))
    warm = bake(changed, s, cache=cache, lights=[lamp2])
    assert running[:3] == ["patches", "refine", "form_factors"] and set(cast) <= {"vertices"}, cast
    assert warm.form_factor_source == "cached"
    np.testing.assert_allclose(warm.solution.B, cold.solution.B, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(warm.vertex_radiosity, cold.vertex_radiosity, rtol=1e-6, atol=1e-9)
    # and the lamp's colour really changed the bake: the lamp dominates, blue drops most
    ratio = warm.solution.B.sum(0) / first.solution.B.sum(0)
    assert ratio[2] < ratio[1] < ratio[0]


@pytest.mark.parametrize("gather_rays", [0, 64])
def test_furnace_holds_on_finer_output_elements(gather_rays):
    """Coarse patches solve, a finer output mesh takes the detail (interpolated or gathered):
    in the furnace every element vertex is still exactly E / (1 - rho)."""
    r = bake(closed_box(size=(1.0, 1.3, 0.8), rho=(0.5,) * 3, emission=(1.0,) * 3),
             BakeSettings(patch_size=0.4, element_size=0.1, gather_rays=gather_rays, tolerance=1e-8))
    assert len(r.elements) > 4 * len(r.patches)
    np.testing.assert_allclose(r.vertex_radiosity, 2.0, rtol=1e-4)


def _plate_scene():
    """A 2 m floor, a 0.4 m emitter 1.5 m above it and a floating 0.4 m plate between them:
    a shadow with a sharp umbra and a penumbra, and no contact edges."""
    from hemicube_radiosity.core.builtin_scenes import quad

    floor = quad([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], (0.7, 0.7, 0.7), name="floor")
    light = quad([(-0.2, -0.2, 1.5), (-0.2, 0.2, 1.5), (0.2, 0.2, 1.5), (0.2, -0.2, 1.5)],
                 (0, 0, 0), (10.0, 10.0, 10.0), name="light")
    plate = box((0.0, -0.2, 0.7), (0.4, 0.2, 0.72), (0.5, 0.5, 0.5), name="plate")
    return [floor, light, plate]


def test_elements_keep_sharp_shadows_that_coarse_patches_lose():
    """With 0.5 m patches alone the floor's vertices cannot follow the plate's shadow; with
    0.1 m output elements (direct light exact at each vertex) they match a bake whose patches
    are all 0.1 m."""
    from hemicube_radiosity.core.output.interpolate import interpolate_at

    fine = bake(_plate_scene(), BakeSettings(patch_size=0.1, resolution=32, method="embree", element_size=None))
    elem = bake(_plate_scene(), BakeSettings(patch_size=0.5, resolution=32, element_size=0.1, gather_rays=0))
    coarse = bake(_plate_scene(), BakeSettings(patch_size=0.5, resolution=32, element_size=None))
    E = fine.elements
    assert np.allclose(elem.elements.verts, E.verts)
    floor = np.isin(np.arange(len(E.verts)), E.polys[E.owner == 0])
    lum = np.array([0.2126, 0.7152, 0.0722])
    ref = fine.vertex_radiosity[floor] @ lum
    got = elem.vertex_radiosity[floor] @ lum
    blurred = interpolate_at(coarse.elements, coarse.vertex_radiosity, E.verts[floor]) @ lum
    err_elem = np.sqrt(np.mean((got - ref) ** 2)) / ref.mean()
    err_coarse = np.sqrt(np.mean((blurred - ref) ** 2)) / ref.mean()
    assert err_coarse > 0.1          # the shadow is there, and coarse patches smear it
    assert err_elem < 0.2 * err_coarse
    assert err_elem < 0.04          # penumbra sampling and interpolated indirect light


def test_too_many_patches_stop_before_the_form_factors_with_a_clear_error():
    from hemicube_radiosity.core.mesh.patches import PatchError

    with pytest.raises(PatchError, match=r"makes [\d,]+ patches, more than the limit of 500") as refused:
        bake(cornell_box(), BakeSettings(patch_size=0.1, max_patches=500))
    # the size it names passes, and makes as many patches as it says (it was measured)
    size, n = re.search(r"a patch size of ([\d.]+) makes ([\d,]+)$", str(refused.value).split(";")[0]).groups()
    r = bake(cornell_box(), BakeSettings(patch_size=float(size), max_patches=500, refine_levels=0))
    assert r.unknowns == int(n.replace(",", "")) <= 500


def test_an_absurd_patch_size_is_refused_from_the_faces_before_anything_is_cut(monkeypatch):
    """Half a millimetre in a 2 m box would be 50 million patches: refused from the faces' edges
    and areas; nothing is cut at that size (cutting it took minutes and 18 GB in two processes).
    The size the refusal names was measured by cutting at it."""
    from hemicube_radiosity.core.mesh import subdivide as sub
    from hemicube_radiosity.core.mesh.patches import PatchError

    real = sub._subdivide

    def guarded(verts, polys, size):
        assert not size or size > 0.01, f"cut at {size}"
        return real(verts, polys, size)
    monkeypatch.setattr(sub, "_subdivide", guarded)
    with pytest.raises(PatchError, match=r"a patch size of 0.0005 makes about [\d,]+ patches, more than "
                       r"the limit of 20,000 \(Max Patches\): a patch size of ([\d.]+) makes ([\d,]+);") as refused:
        bake(cornell_box(), BakeSettings(patch_size=0.0005, element_size=0.0005 / 3))
    size = float(re.search(r": a patch size of ([\d.]+) makes", str(refused.value)).group(1))
    assert 0.03 < size < 0.1


def test_an_absurd_detail_size_is_refused_before_anything_is_cut(monkeypatch):
    from hemicube_radiosity.core.mesh import subdivide as sub
    from hemicube_radiosity.core.mesh.patches import PatchError

    monkeypatch.setattr(sub, "_subdivide", lambda v, p, size: pytest.fail(f"cut at {size}"))
    with pytest.raises(PatchError, match=r"a detail size of 0.0001 cuts the scene into at least [\d,]+ "
                       r"output elements, more than the limit of 400,000 \(Max Details\): use a detail size of"):
        bake(cornell_box(), BakeSettings(patch_size=0.5, element_size=0.0001))


def test_relight_with_elements_and_gather_casts_nothing_and_equals_a_cold_bake(monkeypatch):
    """With output elements and a final gather, a relight reuses F, the emitters' transport, the
    element mesh and the gather matrix: no hemi-cube, no ray, no cutting; same result as cold."""
    from hemicube_radiosity.core.light import emitters as direct
    from hemicube_radiosity.core.output import gather
    from hemicube_radiosity.core import pipeline

    s = BakeSettings(patch_size=0.5, element_size=0.125, gather_rays=64, resolution=32, tolerance=1e-8)
    cache = FormFactorCache()
    bake(cornell_box(), s, cache=cache)
    changed = cornell_box(light_radiance=7.0)
    changed[3].face_rho[:] = (0.2, 0.2, 0.7)
    cold = bake(changed, s)

    def forbidden(*a, **k):
        raise AssertionError("a relight must not recompute geometry-only work")

    for fn in (pipeline.compute_form_factors, direct.emitter_transport, gather.gather_matrix,
               subdivide.build_patches):
        everywhere(monkeypatch, fn, forbidden)
    warm = bake(changed, s, cache=cache)
    np.testing.assert_allclose(warm.vertex_radiosity, cold.vertex_radiosity, rtol=1e-6, atol=1e-9)
    # the cached element mesh took its materials from the changed meshes
    red = warm.elements.owner == warm.elements.object_names.index("RedWall")
    np.testing.assert_allclose(warm.elements.rho[red], [[0.2, 0.2, 0.7]] * int(red.sum()))


def test_automatic_sizes_follow_the_scene_scale():
    """'auto': patch size = diagonal / 14, detail = a third of it, so a scene scaled by 10
    is cut into the same patches and elements."""
    from hemicube_radiosity.core.mesh.subdivide import build_patches

    small = cornell_box()
    big = cornell_box(size=20.0, light_size=5.0)
    s = BakeSettings()
    assert s.patch_size == "auto" and s.element_size == "auto"
    rs, rb = s.resolved(small), s.resolved(big)
    diag = np.linalg.norm([2.0, 2.0, 2.0])
    assert rs.patch_size == pytest.approx(diag / 14) and rs.element_size == pytest.approx(diag / 42)
    assert rb.patch_size == pytest.approx(10 * rs.patch_size)
    assert len(build_patches(small, rs.patch_size)) == len(build_patches(big, rb.patch_size))
    r = bake(big, BakeSettings(resolution=16, gather_rays=0, refine_levels=0))
    assert r.settings.patch_size == pytest.approx(rb.patch_size) and len(r.elements) > 4 * len(r.patches)


@pytest.mark.parametrize("kw", [dict(patch_size=0.2, element_size=None), dict(patch_size=0.4, element_size=0.1),
                                dict(patch_size=0.4, element_size=0.1, gather_rays=0),
                                dict(patch_size=0.2, element_size=None, direct="hemicube")],
                         ids=["patches", "gathered", "interpolated", "paper"])
def test_lighting_pass_in_the_furnace_is_the_incoming_radiance(kw):
    """Closed room, E = 1, rho = 0.5: B = 2 everywhere, and the light arriving everywhere is the
    radiance of what is seen, 2 (emission and the surface's own colour left out)."""
    r = bake(closed_box(size=(1.0, 1.3, 0.8), rho=(0.5,) * 3, emission=(1.0,) * 3),
             BakeSettings(**kw, output_pass="lighting", tolerance=1e-8, max_iterations=2000))
    np.testing.assert_allclose(r.vertex_radiosity, 2.0, rtol=2e-3)


@pytest.mark.parametrize("gather_rays", [64, 0])
def test_corner_colours_reach_the_output_vertices(gather_rays):
    """A texture seen at the corners (MeshInput.corner_rho / corner_emission): a plane under a
    uniform white world sends back rho at each vertex (the sky is all it sees), and an emissive
    corner colour is the vertex's emission, while the solve uses the faces' means."""
    from hemicube_radiosity.core.mesh.patches import MeshInput
    from hemicube_radiosity.core.builtin_scenes import quad, tessellate

    plane = tessellate([quad([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)])], 12, triangles=False)[0]
    pos = plane.verts[plane.face_indices]
    checker = ((np.floor(pos[:, 0] * 4) + np.floor(pos[:, 1] * 4)) % 2)[:, None]
    corner_rho = 0.2 + 0.6 * checker * np.array([1.0, 0.5, 0.25])
    face = np.repeat(np.arange(len(plane.face_offsets) - 1), 4)
    rho = np.stack([np.bincount(face, weights=corner_rho[:, k]) / 4 for k in range(3)], 1)
    textured = MeshInput(plane.verts, plane.face_offsets, plane.face_indices, rho, plane.face_emission,
                         "plane", corner_rho, None)
    r = bake([textured], BakeSettings(patch_size=0.5, element_size=0.2, gather_rays=gather_rays),
             world=np.array([1.0, 1.0, 1.0]))
    assert r.elements is r.patches                 # the plane's own faces are the output
    want = np.zeros((len(r.elements.verts), 3))
    # each output vertex: the mean of its corners' reflectance (corners of one vertex agree here
    # unless the vertex lies on a checker edge)
    # the plane's front (its back, lit by the world from below, is the same texture: the
    # vertices of both sides but a hair apart)
    front = fronts(r, r.elements.owner)
    p, c = np.nonzero(r.elements.polys[front] >= 0)
    key = {tuple(x): v for x, v in zip(pos.round(9), corner_rho)}
    for v in np.unique(r.elements.polys[front][p, c]):
        want[v] = key[tuple(r.elements.verts[v].round(9))]
    inside = np.all((r.elements.verts[:, :2] * 4) % 1 > 1e-6, axis=1)   # off the checker's edges
    inside &= np.abs(r.elements.verts[:, 2]) < 1e-9
    assert inside.sum() > 50
    np.testing.assert_allclose(r.vertex_radiosity[inside], want[inside], rtol=1e-6 if gather_rays else 0.1)
    # every corner, on the checker's edges too: its own face's colour (what the writer writes)
    own = {(f, *x): v for f, x, v in zip(face, pos.round(9), corner_rho)}
    E = r.elements
    got, exp = [], []
    for n in np.flatnonzero(front):
        for k in range(4):
            got.append(r.corner_values()[n, k])
            exp.append(own[(E.source_face[n], *E.verts[E.polys[n, k]].round(9))])
    got, exp = np.array(got), np.array(exp)
    assert len(np.unique(exp.round(6), axis=0)) == 2                 # both colours at corners
    np.testing.assert_allclose(got, exp, rtol=1e-6 if gather_rays else 0.1)


def test_relight_of_a_lamp_under_a_ceiling_casts_no_ray_and_equals_a_cold_bake(monkeypatch):
    """The bench's case: a two-sided lamp 2 mm under the ceiling, so the gather reads exact light
    at its hits and the ceiling ring beside the lamp shines on the vertices by shadow rays. A
    relight (the lamp brighter, a wall's colour changed) reuses all of it: not one ray is cast
    (each class that casts rays is forbidden), and the result equals a cold bake."""
    from hemicube_radiosity.core import pipeline, rays

    s = BakeSettings(patch_size=0.5, element_size=0.125, gather_rays=64, resolution=32, tolerance=1e-8)
    assert s.two_sided_emission                # cornell_box's lamp hangs 2 mm under the ceiling
    cache = FormFactorCache()
    bake(cornell_box(light_radiance=5.0), s, cache=cache)
    changed = cornell_box(light_radiance=7.0)
    changed[3].face_rho[:] = (0.2, 0.2, 0.7)
    cold = bake(changed, s)

    def forbidden(*a, **k):
        raise AssertionError("a relight must not cast rays nor recompute geometry")

    for cls in (rays.EmbreeScene, rays.NumpyOccluder):
        for name in ("intersect", "occluded"):
            if hasattr(cls, name):
                monkeypatch.setattr(cls, name, forbidden)
    everywhere(monkeypatch, pipeline.compute_form_factors, forbidden)
    everywhere(monkeypatch, subdivide.build_patches, forbidden)
    warm = bake(changed, s, cache=cache)
    np.testing.assert_allclose(warm.vertex_radiosity, cold.vertex_radiosity, rtol=1e-6, atol=1e-9)


def test_relight_that_moves_the_bright_areas_chooses_again_and_equals_a_cold_bake(monkeypatch):
    """What the gather reads exactly or shines (abrupt and hot elements, their grid's cells) is
    judged on the light arriving, and the hits' correction matrix is cached under that choice:
    a relight that only scales the light reuses it, while one that moves the light elsewhere (a
    second lamp low on the red wall turned from as bright as the ceiling lamp to dim) chooses
    again and builds a new one, never reads a stale one, and equals a cold bake."""
    from hemicube_radiosity.core.output import indirect as output
    from hemicube_radiosity.core.builtin_scenes import quad

    def scene(top, low, wall=None):
        meshes = cornell_box(light_radiance=top)
        z, y = 0.3, 1.0       # a small lamp 1 cm off the red wall (x = 0), facing +x
        meshes.append(quad([(0.01, y - 0.15, z - 0.15), (0.01, y - 0.15, z + 0.15), (0.01, y + 0.15, z + 0.15),
                            (0.01, y + 0.15, z - 0.15)], (0.0, 0.0, 0.0), (low,) * 3, name="LowLamp"))
        if wall is not None:
            meshes[4].face_rho[:] = wall
        return meshes

    built = []
    real = output.correction_matrix
    monkeypatch.setattr(output, "correction_matrix", lambda *a, **k: built.append(1) or real(*a, **k))
    s = BakeSettings(patch_size=0.5, element_size=0.125, gather_rays=64, resolution=32, tolerance=1e-8)
    cache = FormFactorCache()
    bake(scene(8.0, 8.0), s, cache=cache)
    assert built
    built.clear()
    warm = bake(scene(10.0, 10.0, (0.2, 0.2, 0.7)), s, cache=cache)      # the same light, scaled
    assert not built
    cold = bake(scene(10.0, 10.0, (0.2, 0.2, 0.7)), s)
    np.testing.assert_allclose(warm.vertex_radiosity, cold.vertex_radiosity, rtol=1e-6, atol=1e-9)
    built.clear()
    warm = bake(scene(8.0, 0.08), s, cache=cache)                          # the light moved
    assert built
    cold = bake(scene(8.0, 0.08), s)
    np.testing.assert_allclose(warm.vertex_radiosity, cold.vertex_radiosity, rtol=1e-6, atol=1e-9)


def test_relight_reads_materials_as_the_patches_and_clusters_do():
    """What a relight re-reads onto the cached patches and clusters (PatchSet.with_mesh_materials
    by its kept index, Clusters.with_materials) equals, bit for bit, each patch's face read mesh
    by mesh and the clusters' area-weighted mean; and a point set's cache digest
    (cache.array_key) is kept per array object and follows its values."""
    from hemicube_radiosity.core.runtime.cache import array_key
    from hemicube_radiosity.core.builtin_scenes import tessellate
    from hemicube_radiosity.core.mesh.backs import with_backs

    meshes = tessellate(cornell_box(), 3)
    r = bake(meshes, BakeSettings(patch_size=0.3, gather_rays=0, resolution=16))
    assert r.clusters is not None
    relit = tessellate(cornell_box(light_radiance=9.0), 3)
    rng = np.random.default_rng(2)
    for m in relit:
        m.face_rho[:] = rng.uniform(0.05, 0.9, np.shape(m.face_rho))
    relit = with_backs(relit)                            # as bake() reads them: the light's back too
    assert len(relit) == len(r.patches.object_names)
    want_rho, want_em = np.empty((len(r.patches), 3)), np.empty((len(r.patches), 3))
    for oi, m in enumerate(relit):
        sel = r.patches.owner == oi
        want_rho[sel] = np.asarray(m.face_rho, float)[r.patches.source_face[sel]]
        want_em[sel] = np.asarray(m.face_emission, float)[r.patches.source_face[sel]]
    for _ in range(2):                                   # the index made, then kept
        got = r.patches.with_mesh_materials(relit)
        assert np.array_equal(got.rho, want_rho) and np.array_equal(got.emission, want_em)
        assert got.verts is r.patches.verts and got.polys is r.patches.polys
    c = r.clusters.with_materials(got)
    assert np.array_equal(c.rho[c.sizes > 1], r.clusters.mean(got.rho, got.areas)[c.sizes > 1])
    assert np.array_equal(c.emission[c.sizes > 1], r.clusters.mean(got.emission, got.areas)[c.sizes > 1])
    x = rng.random((50, 3))
    assert array_key(x) == array_key(x) == array_key(x.copy())
    assert array_key(x) != array_key(x[::-1].copy()) and array_key(x) != array_key(x.astype(np.float32))


def test_a_bake_runs_on_small_pages_and_puts_numpys_setting_back(monkeypatch):
    """NumPy's huge-page advice is off while the stages run (a bake's many large temporaries
    ran slower on huge pages) and as it was afterwards, also when a stage fails."""
    from hemicube_radiosity.core import pipeline
    from hemicube_radiosity.core.builtin_scenes import cornell_box

    switch = pipeline._madvise_switch()
    if switch is None:
        pytest.fail("this NumPy has no huge-page switch: small_pages() would do nothing")
    seen = []

    def spy(ctx):
        now = switch(False)
        switch(now)
        seen.append(now)
    before = switch(True)
    try:
        monkeypatch.setattr(pipeline, "STAGES", pipeline.STAGES[:1] + (("spy", spy),))
        pipeline.bake(cornell_box(), pipeline.BakeSettings())
        assert seen == [False] and switch(True) is True

        def fails(ctx):
            raise RuntimeError("a stage failed")
        monkeypatch.setattr(pipeline, "STAGES", (("fails", fails),))
        with pytest.raises(RuntimeError):
            pipeline.bake(cornell_box(), pipeline.BakeSettings())
        assert switch(True) is True
    finally:
        switch(before)


@pytest.mark.parametrize("workers", [1, 2])
def test_a_mesh_finer_than_the_sizes_builds_its_faces_once_and_forks_nothing_for_them(monkeypatch, workers):
    """A mesh whose faces are smaller than the patch and detail sizes is its own patches and
    output elements (:func:`.subdivide.keeps_faces_whole`): the bake builds its faces once, not
    once for the patches, once for the elements and again inside a process forked only to
    find the two equal; the bake is the same as one that builds them every time."""
    from hemicube_radiosity.core.runtime import background, forked
    from hemicube_radiosity.core.builtin_scenes import tessellate
    meshes = tessellate(cornell_box(), 12)                 # 1/6 m cells
    s = BakeSettings(workers=workers, patch_size=0.5, element_size=0.25, resolution=16, gather_rays=16)
    built, started = [], []
    real = subdivide.build_patches
    everywhere(monkeypatch, real, lambda m, size=None, **k: built.append(size) or real(m, size, **k))
    start = background.Ahead.start
    monkeypatch.setattr(background.Ahead, "start", classmethod(lambda cls, fn: started.append(1) or start(fn)))
    r = bake(meshes, s)
    assert built == [None] and started == []
    assert len(r.elements) == len(r.patches)
    assert fronts(r, r.patches.owner).sum() == sum(len(m.face_offsets) - 1 for m in meshes)
    # the same bake with the faces measured as too large to keep (build_patches every time)
    everywhere(monkeypatch, subdivide.keeps_faces_whole, lambda *a: False)
    built.clear()
    again = bake(meshes, s)
    assert built == [0.5, 0.25] and started == ([1] if workers > 1 and forked.processes_available() else [])
    for a in ("verts", "polys"):
        assert np.array_equal(getattr(r.elements, a), getattr(again.elements, a))
    assert np.array_equal(r.vertex_radiosity, again.vertex_radiosity)


def test_a_scene_that_nothing_lights_says_so_and_bakes_black():
    """No emitting face, no lamp, no world: the bake is black, and says why (a real file with no
    light, or Lamps and World turned off, baked to black without a word)."""
    dark = cornell_box(light_radiance=0.0)
    r = bake(dark, BakeSettings(patch_size=0.7, refine_levels=0, resolution=12))
    assert np.all(r.vertex_radiosity == 0)
    assert any(n.startswith("nothing lights the scene") for n in r.notes)
    lit = bake(cornell_box(), BakeSettings(patch_size=0.7, refine_levels=0, resolution=12))
    assert not any(n.startswith("nothing lights the scene") for n in lit.notes)
    assert lit.vertex_radiosity.max() > 0
