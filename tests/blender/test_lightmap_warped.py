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
                                           (0.0, (1.0, 0.0, 0.2), True)])
def test_the_texels_shading_normal_and_face_as_cycles_takes_them(tmp_path, lean, to_sun, lit):
    """Custom normals leaning off their face (a game asset's weighted normals; at a contact they
    may turn away from it altogether): Cycles shades a diffuse surface with the interpolated
    normal n, and where n turns away from the face it bakes the point as seen from behind (n and
    the face's normal turned around). Measured on a lone quad facing +z, n leaning 0 / 60 / 85
    / 95 / 120 degrees toward +x, a sun from l = (1, 0, 0.2): rho x 3 x (n . l) / pi up to 85
    degrees, 0 at 95 and 120. Here a lone quad, every corner normal n leaning ``lean`` degrees,
    that sun at 3 W/m^2: every texel is rho x 3 x (n . l) / pi, or 0 where n turns away; and
    Cycles' own bake says so. The texels used to take the face's normal where n turns away:
    rho x 3 x (z . l) / pi, 0.15 here at 120 degrees.

    Not matched (not tested): a sun behind the face where n leans 60 degrees toward it lights
    Cycles' lone quad (its shadow ray leaves its own triangle out), not ours (its ray, started
    off the surface along n, crosses the quad)."""
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
