# SPDX-License-Identifier: GPL-3.0-or-later
"""A long, thin, twisted quad (a bevel's strip: 4.5 m long, 5 cm wide, two corners lifted 1.2 cm)
is lit as the two triangles Cycles renders, not as the core's bilinear quad
(``core/mesh/ngons.py``: ``bent_faces`` judges a quad's warp against its width as well as its
size: 1.2 cm is 3e-3 of its 4.5 m but a quarter of its 5 cm).

Blender cuts the quad along its first diagonal (corners 0 and 2); with corners 1 and 3 lifted
the two triangles make a valley, each tilted about 13 degrees from the other. Under a constant
white world of strength 1, a point on one triangle sees all the sky but what the other triangle
hides, at most the part an infinite half-plane tilted by that angle hides: the light arriving
directly (radiance) lies between (1 + cos angle) / 2 and 1, and what the other triangle reflects
into it adds at most the share it hides, (1 - cos angle) / 2: the texel (albedo 0.8) lies between
0.8 (1 + cos angle) / 2 and 0.8 (1 + (1 - cos angle) / 2) (measured: 0.787 .. 0.821 of 0.756 .. 0.843). The bilinear quad lies above the
triangles (it passes half the lift above the diagonal's midpoint): shadow rays started 0.2 mm
off the triangles hit it (measured before the change: texels 0.0 .. 0.797).
"""
from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tools import cycles_reference as cr  # noqa: E402
from hemicube_radiosity.blender import bake  # noqa: E402
from hemicube_radiosity.core.mesh.ngons import WARPED, bent_faces  # noqa: E402

pytestmark = [pytest.mark.blender]

LENGTH, WIDTH, LIFT, RHO = 4.5, 0.05, 0.012, 0.8


def _strip():
    v = np.array([[0.0, 0.0, 0.0], [LENGTH, 0.0, LIFT], [LENGTH, WIDTH, 0.0], [0.0, WIDTH, LIFT]])
    return v, [[0, 1, 2, 3]]


def _lightmap(ob, density, folder):
    """(image (h, w, 3), the lightmap's record, the baked copy's mesh, (h, w) bool the texels whose
    centre lies inside a UV triangle) of a default lightmap bake of ``ob`` alone."""
    from hemicube_radiosity.blender import lightmap as blm
    from hemicube_radiosity.core.output import lightmap as core_lightmap
    settings = bake.BakeSettings(target="lightmap", lightmap_density=density, lightmap_dir=str(folder))
    job = bake.BakeJob.prepare(bpy.context, [ob], settings)
    job.run()
    job.write(bpy.context)
    rec, = job.lightmaps
    img = cr.image_rgb(bpy.data.images[f"{ob.name}.lightmap.exr"])
    w, h = rec["size"]
    copy = bpy.data.objects[f"{ob.name}.radiosity"].data
    _, _, inside = core_lightmap.rasterize(blm._triangle_uvs(copy, rec["uv_map"]), w, h)
    return img, rec, copy, inside


def test_a_twisted_strip_is_lit_as_blenders_two_triangles(tmp_path):
    v, f = _strip()
    # warped against its width, not against its size
    off, size = LIFT / 2, np.linalg.norm(v.max(0) - v.min(0))
    assert off < WARPED * size and bent_faces(v, [0, 4], [0, 1, 2, 3])[0]
    cr.new_empty_scene()
    cr.set_world((1.0, 1.0, 1.0), 1.0)
    ob = cr.mesh_object(v, f, cr.diffuse_material((RHO,) * 3, name="Strip"), "Strip")
    me = ob.data
    me.calc_loop_triangles()
    tris = [tuple(t.vertices) for t in me.loop_triangles]
    assert sorted(map(sorted, tris)) == [[0, 1, 2], [0, 2, 3]], tris       # the valley's diagonal
    n = [np.cross(v[b] - v[a], v[c] - v[a]) for a, b, c in tris]
    cos = float(np.dot(n[0], n[1]) / np.linalg.norm(n[0]) / np.linalg.norm(n[1]))
    assert np.dot(n[0], [0, 0, 1]) > 0 and cos < np.cos(np.radians(10))   # facing up, a real fold
    img, rec, copy, inside = _lightmap(ob, 64.0, tmp_path)
    y = img[inside].mean(-1)
    assert y.size > 100
    low, high = RHO * (1 + cos) / 2, RHO * (1 + (1 - cos) / 2)
    print(f"\n{y.size} texels: {y.min():.4f} .. {y.max():.4f}, bounds {low:.4f} .. {high:.4f}")
    assert y.min() >= low - 2e-3 and y.max() <= high + 2e-3, (y.min(), y.max(), low, high)


@pytest.mark.parametrize("lean, to_sun, lit", [(120.0, (1.0, 0.0, 0.2), False), (60.0, (1.0, 0.0, 0.2), True),
                                           (0.0, (1.0, 0.0, 0.2), True), (60.0, (1.0, 0.0, -0.2), True)])
def test_the_texels_shading_normal_and_face_as_cycles_takes_them(tmp_path, lean, to_sun, lit):
    """Custom normals leaning off their face (a game asset's weighted normals; at a contact they
    may turn away from it altogether): Cycles shades a diffuse surface with the interpolated
    normal n, and where n turns away from the face it bakes the point as seen from behind (n and
    the face's normal turned around). Measured on a lone quad facing +z, n leaning 0 / 60 / 85
    / 95 / 120 degrees toward +x, a sun from l = (1, 0, 0.2): rho x 3 x (n . l) / pi up to 85
    degrees, 0 at 95 and 120. Here a lone quad, every corner normal n leaning ``lean`` degrees,
    that sun at 3 W/m^2: every texel is rho x 3 x (n . l) / pi, or 0 where n turns away; and
    Cycles' own bake says so. The texels used to take the face's normal where n turns away:
    rho x 3 x (z . l) / pi, 0.15 here at 120 degrees. A sun 11 degrees behind the face where n
    leans 60 degrees toward it lights the quad too (Cycles' shadow ray toward it starts on the
    quad, lifted by nothing: every corner normal is the same; ours from there, not off the
    surface along n, where it crossed the quad: 0.0 before, 0.574 now)."""
    cr.new_empty_scene()
    cr.set_world((0.0, 0.0, 0.0), 0.0)
    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    ob = cr.mesh_object(v, [[0, 1, 2, 3]], cr.diffuse_material((RHO,) * 3, name="Turned"), "Turned")
    n = np.array([np.sin(np.radians(lean)), 0.0, np.cos(np.radians(lean))])
    ob.data.normals_split_custom_set([tuple(n)] * 4)
    corner = np.empty(12)
    ob.data.corner_normals.foreach_get("vector", corner)
    np.testing.assert_allclose(corner.reshape(4, 3), np.tile(n, (4, 1)), atol=1e-4)
    to_sun = np.asarray(to_sun) / np.linalg.norm(to_sun)
    sun = cr.add_light("SUN", (0.0, 0.0, 3.0), energy=3.0, angle=0.0)
    from mathutils import Vector
    sun.rotation_euler = Vector(tuple(to_sun)).to_track_quat("Z", "Y").to_euler()   # shines along its -z
    ours, rec, copy, inside = _lightmap(ob, 16.0, tmp_path)
    from hemicube_radiosity.blender import write
    w, _ = rec["size"]
    uv = np.empty(len(copy.loops) * 2, np.float32)
    copy.uv_layers[rec["uv_map"]].data.foreach_get("uv", uv)
    want = RHO * 3.0 * float(np.dot(n, to_sun)) / np.pi if lit else 0.0
    y = ours[inside].mean(-1)
    write.remove_bakes(["Turned"], unhide=True)
    ob.data.uv_layers.new(name="Bench").data.foreach_set("uv", uv)    # the copy's loops are the user's
    ref, _ = cr.bake_image(ob, w, samples=16, uv_layer="Bench")
    ry = ref[inside].mean(-1)
    print(f"\n{y.size} texels: ours {y.min():.4f} .. {y.max():.4f}, Cycles {ry.min():.4f} .. {ry.max():.4f}, "
          f"closed form {want:.4f}")
    assert y.size > 100
    np.testing.assert_allclose(ry, want, rtol=0.02, atol=1e-4)           # Cycles lights it so
    np.testing.assert_allclose(y, want, rtol=0.02, atol=1e-4)


def test_a_smooth_bevels_texels_see_a_sun_below_its_plane_past_its_edge(tmp_path):
    """A smooth-shaded bevel (a 5 cm strip at 45 degrees between a box's top and side, its corner
    normals averaged with theirs: 22.5 degrees off its own toward each) under a sun 10 degrees
    below the strip's plane, on the side's side: where the interpolated normal n faces the sun,
    Cycles' shadow ray starts lifted off the strip toward the smooth surface (the
    shadow-terminator offset, ``core/output/lift.py``) and passes over the strip's edge, so the
    texels there are lit by rho x 3 x (n . l) / pi; ours did the same only at vertices
    (``core/output/crease.py``): a texel's ray, started off the strip along n, crossed the strip
    itself and read the sun blocked (ours 0.0 where Cycles lights 28% of the strip, 0.086 on average).
    No other light: a black world, and the convex box sees none of itself."""
    cr.new_empty_scene()
    cr.set_world((0.0, 0.0, 0.0), 0.0)
    w, d = 0.05, 0.5
    v = np.array([[0, -d, 0], [1, -d, 0], [0, 0, 0], [1, 0, 0], [0, w, -w], [1, w, -w],
                  [0, w, -w - d], [1, w, -w - d]], float)
    faces = [[0, 1, 3, 2], [2, 3, 5, 4], [4, 5, 7, 6]]          # top (+z), strip, side (+y)
    ob = cr.mesh_object(v, faces, cr.diffuse_material((RHO,) * 3, name="Bevel"), "Bevel")
    for p in ob.data.polygons:
        p.use_smooth = True
    strip_n = np.array([0.0, 1.0, 1.0]) / np.sqrt(2.0)
    down_strip = np.array([0.0, 1.0, -1.0]) / np.sqrt(2.0)
    to_sun = np.cos(np.radians(10)) * down_strip - np.sin(np.radians(10)) * strip_n
    sun = cr.add_light("SUN", (0.0, 0.0, 3.0), energy=3.0, angle=0.0)
    from mathutils import Vector
    sun.rotation_euler = Vector(tuple(to_sun)).to_track_quat("Z", "Y").to_euler()   # shines along its -z
    ours, rec, copy, inside = _lightmap(ob, 400.0, tmp_path)
    from hemicube_radiosity.blender import write
    from hemicube_radiosity.blender import lightmap as blm
    from hemicube_radiosity.core.output import lightmap as core_lightmap
    size, _ = rec["size"]
    tri, _, _ = core_lightmap.rasterize(blm._triangle_uvs(copy, rec["uv_map"]), size, size)
    face = np.empty(len(copy.loop_triangles), np.int64)
    copy.loop_triangles.foreach_get("polygon_index", face)
    strip = inside & (tri >= 0) & (face[np.maximum(tri, 0)] == 1)
    uv = np.empty(len(copy.loops) * 2, np.float32)
    copy.uv_layers[rec["uv_map"]].data.foreach_get("uv", uv)
    write.remove_bakes(["Bevel"], unhide=True)
    ob.data.uv_layers.new(name="Bench").data.foreach_set("uv", uv)    # the copy's loops are the user's
    ref, _ = cr.bake_image(ob, size, samples=4, uv_layer="Bench")
    y, ry = ours[strip].mean(-1), ref[strip].mean(-1)
    lit = ry > 1e-3
    print(f"\n{strip.sum()} strip texels, {lit.sum()} lit in Cycles: ours mean {y.mean():.4f}, Cycles {ry.mean():.4f}; "
          f"where Cycles is lit: ours {y[lit].mean():.4f}, Cycles {ry[lit].mean():.4f}")
    assert strip.sum() > 100 and 0.2 < lit.mean() < 0.9           # a lit band and a dark one
    assert y.mean() == pytest.approx(ry.mean(), rel=0.05)
    # texel by texel (the band's edge falls between texels differently: its width in texels)
    assert np.mean(np.abs(y - ry) <= 0.1 * ry.max()) >= 0.9
    side = inside & (tri >= 0) & (face[np.maximum(tri, 0)] == 2)            # the side, lit in front
    assert ours[side].mean(-1).mean() == pytest.approx(ref[side].mean(-1).mean(), rel=0.02)
