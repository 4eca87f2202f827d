"""Lightmaps at UV seams: every texel of a UV island and of its margin holds a finite value that
is not the image's default (0), in the .exr as written to disk and read back by Blender's image
loader; texels either side of a UV seam that show the same point of a surface hold the same
light; the user's meshes and UV maps are byte for byte as they were, and each baked copy has its
original's topology.

The scene: a cube (rotated, moved) whose only UV map is Blender's cube unwrap, so the lightmap UV
map is made on the copy by Lightmap Pack (six islands, one a face), and a UV sphere baked through
its own UV map (``lightmap_uv='UVMap'``: one island cut by a seam along a meridian, the poles'
fans); lit by a sun and a constant sky, so every surface point sees light.

The island texels are found here, independently of ``core/output/lightmap.py``: a texel whose
centre lies inside a UV triangle (barycentric coordinates >= 0); its margin the texels within 8
texels of one (Chebyshev distance: ``lightmap.MARGIN`` passes of the 8-neighbour dilation).

Measured (density 48): cube 236 x 236, 33,451 island and 5,528 margin texels, sphere 169 x 169,
26,181 and 2,380, all between 0.28 and 0.88; 204 texel pairs across the sphere's seams (within
half a texel on the surface, more than 3 texels apart in the image) differ by at most 0.33% of
the brightest texel. Shaded flat, the same sphere is 288 surfaces and the pairs differ by up to
5.6% (each face its own light, as Cycles shows it too): the check can fail.
"""
from __future__ import annotations

import hashlib
import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tools import cycles_reference as cr  # noqa: E402
from hemicube_radiosity.blender import bake, write  # noqa: E402
from tests.support.fingerprint import hash_user_mesh  # noqa: E402

pytestmark = [pytest.mark.blender]

MARGIN = 8            # texels of dilation the lightmap target promises around every island


def mesh_arrays(me):
    """(world-free) vertex positions (V, 3), per-loop vertex index (L,), loop triangles (T, 3) as
    loop indices, their material indices (T,)."""
    co = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", co)
    lv = np.empty(len(me.loops), np.int64)
    me.loops.foreach_get("vertex_index", lv)
    me.calc_loop_triangles()
    tl = np.empty(len(me.loop_triangles) * 3, np.int64)
    me.loop_triangles.foreach_get("loops", tl)
    return co.reshape(-1, 3), lv, tl.reshape(-1, 3)


def uv_array(me, name):
    uv = np.empty(len(me.loops) * 2)
    me.uv_layers[name].data.foreach_get("uv", uv)
    return uv.reshape(-1, 2)


def topology(me):
    """Bytes of everything that makes a mesh's topology and shape."""
    h = hashlib.sha256()
    for coll, prop, n, dt in ((me.vertices, "co", 3, np.float32), (me.edges, "vertices", 2, np.int32),
                              (me.loops, "vertex_index", 1, np.int32), (me.loops, "edge_index", 1, np.int32),
                              (me.polygons, "loop_start", 1, np.int32), (me.polygons, "loop_total", 1, np.int32)):
        a = np.empty(len(coll) * n, dt)
        coll.foreach_get(prop, a)
        h.update(prop.encode() + a.tobytes())
    return h.hexdigest()


def user_data():
    """Every user mesh (not a baked copy's): geometry, every UV map's values, attributes, active
    UV map, material slots; in bytes."""
    h = hashlib.sha256()
    for me in sorted(bpy.data.meshes, key=lambda m: m.name):
        if me.get(write.SOURCE_KEY):
            continue
        hash_user_mesh(h, me)
    return h.hexdigest()


def island_texels(uv_tris, size):
    """Texels (size, size) bool whose centre lies inside a UV triangle of ``uv_tris`` (T, 3, 2),
    and per texel the triangle (-1 none) and barycentric coordinates (size, size, 3). Row 0 at
    v = 0, texel (r, c) centred at ((c + 0.5) / size, (r + 0.5) / size)."""
    c = (np.arange(size) + 0.5) / size
    P = np.stack(np.meshgrid(c, c), -1).reshape(-1, 2)            # (u, v) of texel (r, c) at r * size + c
    tri = np.full(len(P), -1)
    bary = np.zeros((len(P), 3))
    for t, (a, b, d) in enumerate(uv_tris):
        m = np.array([b - a, d - a]).T
        if abs(np.linalg.det(m)) < 1e-14:
            continue
        lo, hi = np.floor(np.min([a, b, d], 0) * size - 1).astype(int), np.ceil(np.max([a, b, d], 0) * size + 1).astype(int)
        rows, cols = np.arange(max(lo[1], 0), min(hi[1], size)), np.arange(max(lo[0], 0), min(hi[0], size))
        idx = (rows[:, None] * size + cols[None, :]).ravel()
        st = np.linalg.solve(m, (P[idx] - a).T).T
        w = np.c_[1 - st.sum(1), st]
        ok = np.all(w >= -1e-9, 1)
        tri[idx[ok]] = t
        bary[idx[ok]] = w[ok]
    return tri.reshape(size, size) >= 0, tri.reshape(size, size), bary.reshape(size, size, 3)


def grow(mask, texels):
    """``mask`` grown by ``texels`` in Chebyshev distance (the 8 neighbours, that many times)."""
    out = mask.copy()
    for _ in range(texels):
        p = np.pad(out, 1)
        out = np.logical_or.reduce([p[1 + dr:1 + dr + out.shape[0], 1 + dc:1 + dc + out.shape[1]]
                                    for dr in (-1, 0, 1) for dc in (-1, 0, 1)])
    return out


def read_exr(path):
    """(H, W, 3) float64 of the .exr at ``path`` through Blender's image loader."""
    im = bpy.data.images.load(path, check_existing=False)
    rgb = cr.image_rgb(im)
    bpy.data.images.remove(im)
    return rgb


def scene():
    """(cube, sphere): Blender's primitives with their own UV maps, a sun and a sky; the sphere
    smooth-shaded (one surface: its light is continuous across its edges, the UV seam's too)."""
    cr.new_empty_scene()
    cr.set_world((0.4, 0.5, 0.6), 1.0)
    cr.add_light("SUN", (0, 0, 5), (math.radians(35), math.radians(10), 0.3), energy=3.0)
    bpy.ops.mesh.primitive_cube_add(size=2.0, location=(-2.0, 0.5, 1.2), rotation=(0.3, 0.2, 0.9))
    cube = bpy.context.active_object
    bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12, radius=1.0, location=(1.5, 0.0, 1.0))
    sphere = bpy.context.active_object
    sphere.data.polygons.foreach_set("use_smooth", np.ones(len(sphere.data.polygons), bool))   # one surface
    for ob, rho in ((cube, (0.7, 0.6, 0.5)), (sphere, (0.5, 0.6, 0.7))):
        ob.data.materials.append(cr.diffuse_material(rho, name=ob.name))
    bpy.context.view_layer.update()
    return cube, sphere


def test_every_island_and_margin_texel_is_set_and_seams_agree(tmp_path):
    cube, sphere = scene()
    assert [len(o.data.uv_layers) for o in (cube, sphere)] == [1, 1]
    before = user_data()
    topo = {o.name: topology(o.data) for o in (cube, sphere)}
    users_uv = {o.name: uv_array(o.data, "UVMap").copy() for o in (cube, sphere)}
    common = dict(target="lightmap", lightmap_density=48.0, resolution=32, gather_rays=64,
                  lightmap_dir=str(tmp_path))
    # the sphere through its own UV map (one bake each: lightmap_uv names the map for every object)
    records, copies = {}, {}
    for ob, uv in ((cube, ""), (sphere, "UVMap")):
        job = bake.BakeJob.prepare(bpy.context, [ob], bake.BakeSettings(**common, lightmap_uv=uv))
        job.run()
        copy, = job.write(bpy.context)
        rec, = job.lightmaps
        records[ob.name], copies[ob.name] = rec, copy
    assert user_data() == before
    assert records["Cube"]["made_uvs"] and records["Cube"]["uv_map"] == "Lightmap"
    assert not records["Sphere"]["made_uvs"] and records["Sphere"]["uv_map"] == "UVMap"

    for ob in (cube, sphere):
        rec, copy = records[ob.name], copies[ob.name]
        assert copy["radiosity_source"] == ob.name and copy["radiosity_mesh"] == "source"
        assert topology(copy.data) == topo[ob.name], ob.name
        assert np.array_equal(uv_array(copy.data, "UVMap"), users_uv[ob.name])
        co, lv, tl = mesh_arrays(copy.data)
        uv = uv_array(copy.data, rec["uv_map"])
        size = rec["size"][0]
        assert rec["size"] == [size, size] and size >= 64
        inside, tri, bary = island_texels(uv[tl], size)
        img = read_exr(rec["exr"])
        assert img.shape == (size, size, 3)
        islands = grow(inside, 0)
        margin = grow(inside, MARGIN) & ~islands
        Y = img.mean(-1)
        finite = np.all(np.isfinite(img), -1)
        print(f"\n{ob.name}: {size}x{size}, {islands.sum()} island texels, {margin.sum()} margin texels,"
              f" island min {Y[islands].min():.4f} max {Y[islands].max():.4f}")
        assert islands.sum() > 0.3 * size * size and margin.sum() > 0
        assert finite[islands].all() and finite[margin].all(), ob.name
        # sun and sky reach every point: nothing is left at the image's default 0
        assert (Y[islands] > 0.02).all(), (ob.name, Y[islands].min())
        assert (Y[margin] > 0.02).all(), (ob.name, Y[margin].min())
        assert not np.any(img[~grow(inside, MARGIN + 2)]), ob.name   # beyond the margin (and reach): untouched

        # seams: texels that show (nearly) the same surface point from two places of the UV map
        M = np.array(ob.matrix_world)
        world = (co @ M[:3, :3].T + M[:3, 3])[lv[tl]]                 # (T, 3, 3)
        r, c = np.nonzero(inside)
        pts = np.einsum("nk,nkj->nj", bary[r, c], world[tri[r, c]])
        nrm = np.cross(world[:, 1] - world[:, 0], world[:, 2] - world[:, 0])[tri[r, c]]
        nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
        spacing = math.sqrt(sum(p.area for p in ob.data.polygons) * abs(np.linalg.det(M[:3, :3])) ** (2 / 3)
                            / islands.sum())                          # world size of a texel
        pairs = seam_pairs(pts, nrm, r, c, 0.5 * spacing)
        if ob is sphere:       # the meridian seam (u = 0 against u = 1) and the poles' fans
            meridian = np.abs(c[pairs[:, 0]] - c[pairs[:, 1]]) > size // 2
            assert meridian.sum() > 20 and (~meridian).sum() > 20, (meridian.sum(), (~meridian).sum())
        if len(pairs):
            a, b = pairs.T
            d = np.abs(Y[r[a], c[a]] - Y[r[b], c[b]])
            print(f"{ob.name}: {len(pairs)} texel pairs across seams, largest difference "
                  f"{d.max() / Y[islands].max():.2%} of the brightest texel")
            # measured: 0.33% (at a pole); the sphere shaded flat, its faces' own light: 5.6%
            assert d.max() <= 0.015 * Y[islands].max(), d.max()


def seam_pairs(pts, nrm, r, c, radius):
    """(n, 2) index pairs of island texels whose surface points lie within ``radius`` of each
    other, on the same side (normals within 25 degrees), more than 3 texels apart in the image."""
    from mathutils import kdtree

    tree = kdtree.KDTree(len(pts))
    for i, p in enumerate(pts):
        tree.insert(p, i)
    tree.balance()
    out = []
    for i, p in enumerate(pts):
        for _, j, _ in tree.find_range(p, radius):
            if j > i and max(abs(r[i] - r[j]), abs(c[i] - c[j])) > 3 and np.dot(nrm[i], nrm[j]) > 0.9:
                out.append((i, j))
    return np.array(out, np.int64).reshape(-1, 2)
