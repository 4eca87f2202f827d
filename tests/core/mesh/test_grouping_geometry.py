"""Grouping sees geometry, not shading: a mesh whose vertices are split (flat shading, sharp
edges, UV seams: what Blender hands over for most real files) groups exactly as its welded twin,
and a textured material groups as a plain one, its patches solving with the area-mean
reflectance while the output keeps every corner's colour."""
import numpy as np
import pytest

from hemicube_radiosity.core import builtin_scenes as scenes
from hemicube_radiosity.core.mesh.clusters import group_pieces, piece_materials
from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.pipeline import BakeSettings, bake
from tests.support.shapes import uv_sphere


def split_every_face(m: MeshInput) -> MeshInput:
    """The same faces, each with its own copies of its corners: a flat-shaded mesh."""
    idx = np.asarray(m.face_indices)
    return MeshInput(np.asarray(m.verts)[idx], np.asarray(m.face_offsets), np.arange(idx.size),
                     m.face_rho, m.face_emission, m.name, m.corner_rho, m.corner_emission, m.face_material)


def split_along(m: MeshInput, seam) -> MeshInput:
    """The faces for which ``seam(face centre)`` is True get their own copies of their vertices
    (a UV seam: the mesh is cut along the border of that region)."""
    v, off, idx = np.asarray(m.verts), np.asarray(m.face_offsets), np.asarray(m.face_indices).copy()
    F = len(off) - 1
    for f in range(F):
        c = v[idx[off[f]:off[f + 1]]].mean(axis=0)
        if seam(c):
            idx[off[f]:off[f + 1]] += len(v)
    return MeshInput(np.vstack([v, v]), off, idx, m.face_rho, m.face_emission, m.name,
                     face_material=m.face_material)


def partition(meshes, size):
    """Cluster of each piece (None: nothing grouped), and the pieces."""
    p = build_patches(meshes, size)
    c = group_pieces(p, size, material=piece_materials(p, meshes))
    return (None if c is None else c.of), p


def same_partition(a, b):
    """Two labellings of the same items that group them alike (the labels may differ)."""
    pairs = np.unique(np.stack([a, b], 1), axis=0)
    return len(pairs) == len(np.unique(a)) == len(np.unique(b))


@pytest.mark.parametrize("split", [split_every_face, lambda m: split_along(m, lambda c: c[0] > 0.1)],
                         ids=["flat-shaded", "uv-seam"])
def test_split_vertices_group_as_the_welded_mesh(split):
    smooth = uv_sphere(96, 48)                          # 4,608 faces, every one smaller than a patch
    flat = split(smooth)
    assert len(flat.verts) > len(smooth.verts)
    a, _ = partition([smooth], 0.4)
    b, _ = partition([flat], 0.4)
    assert a is not None and len(np.unique(a)) < len(a) / 10
    assert same_partition(a, b)


def test_a_bake_of_a_flat_shaded_mesh_solves_as_few_patches_as_the_smooth_one():
    room = [scenes.box((0, 0, 0), (4.0, 4.0, 3.0), inward=True, name="room")]
    lamp = scenes.quad([(1.5, 1.5, 2.99), (2.5, 1.5, 2.99), (2.5, 2.5, 2.99), (1.5, 2.5, 2.99)],
                       emission=(5.0, 5.0, 5.0), name="lamp")
    lamp = MeshInput(lamp.verts, lamp.face_offsets, lamp.face_indices[::-1].copy(), lamp.face_rho,
                     lamp.face_emission, "lamp")
    ball = uv_sphere(64, 32)
    ball = MeshInput(ball.verts * 0.6 + (2.0, 2.0, 0.6), ball.face_offsets, ball.face_indices,
                     ball.face_rho, ball.face_emission, "ball")
    s = BakeSettings(patch_size=0.5, element_size=None, refine_levels=0)
    smooth = bake(room + [lamp, ball], s)
    flat = bake(room + [lamp, split_every_face(ball)], s)
    assert smooth.unknowns == flat.unknowns < len(smooth.patches) / 4
    # the same solve: the ball's patches carry the same radiosity
    np.testing.assert_allclose(flat.solution.B, smooth.solution.B, rtol=1e-6, atol=1e-9)


def textured_floor(n=30, seed=1, material=True):
    """A 3 x 3 m floor of n x n quads whose reflectance varies per face (a texture), in one material."""
    g = np.linspace(0.0, 3.0, n + 1)
    x, y = np.meshgrid(g, g, indexing="ij")
    verts = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a = (i * (n + 1) + j).ravel()
    faces = np.stack([a, a + n + 1, a + n + 2, a + 1], 1)
    rho = np.random.default_rng(seed).uniform(0.1, 0.8, (n * n, 1)) * (1.0, 0.9, 0.7)
    m = MeshInput.from_faces(verts, faces, rho=rho, name="floor")
    if material:
        m.face_material = np.zeros(n * n, np.int64)
    return m


def test_a_textured_floor_groups_as_a_plain_one_with_the_area_mean_reflectance():
    tex = textured_floor()
    plain = MeshInput.from_faces(tex.verts, tex.face_indices.reshape(-1, 4), rho=(0.5, 0.5, 0.5), name="floor")
    a, p = partition([tex], 0.5)
    b, _ = partition([plain], 0.5)
    assert a is not None and same_partition(a, b) and len(np.unique(a)) == 36
    c = group_pieces(p, 0.5, material=piece_materials(p, [tex]))
    want = np.stack([np.bincount(c.of, p.areas * p.rho[:, k]) / np.bincount(c.of, p.areas) for k in range(3)], 1)
    np.testing.assert_allclose(c.rho, want, rtol=1e-12)
    # without material ids, every face is its own material: nothing groups
    assert partition([textured_floor(material=False)], 0.5)[0] is None


def test_a_grouped_textured_floor_keeps_its_texture_in_the_output():
    """Grouping a textured floor costs no accuracy where the light is smooth: its corners'
    radiosity against the same bake with one patch per face, within a percent, and each output
    vertex still follows its own face's reflectance."""
    room = [scenes.box((0, 0, 0), (3.0, 3.0, 2.5), rho=(0.6, 0.6, 0.6), inward=True, bottom=False, name="room")]
    lamp = scenes.quad([(1.0, 1.0, 2.49), (2.0, 1.0, 2.49), (2.0, 2.0, 2.49), (1.0, 2.0, 2.49)],
                       emission=(4.0, 4.0, 4.0), name="lamp")
    lamp = MeshInput(lamp.verts, lamp.face_offsets, lamp.face_indices[::-1].copy(), lamp.face_rho,
                     lamp.face_emission, "lamp")
    floor = textured_floor()
    s = BakeSettings(patch_size=0.5, element_size=None, refine_levels=0)
    grouped = bake(room + [lamp, floor], s)
    single = bake(room + [lamp, floor], BakeSettings(patch_size=0.5, element_size=None, refine_levels=0,
                                                     group_faces=False))
    assert grouped.unknowns < single.unknowns - 800
    a, b = (floor_vertices(r, len(room) + 1) for r in (grouped, single))
    assert a.keys() == b.keys() and len(a) == 31 * 31
    a, b = (np.array([d[k] for k in sorted(a)]) for d in (a, b))
    assert np.sqrt(np.mean((a / b - 1) ** 2)) < 0.01
    # the texture is in the output: the floor's corners spread as widely as its reflectance
    assert a[:, 0].std() / a[:, 0].mean() > 0.2


def floor_vertices(result, owner):
    """{rounded position: radiosity (3,)} of the output vertices of object ``owner``."""
    e = result.elements
    ids = np.unique(e.polys[e.owner == owner].ravel())
    ids = ids[ids >= 0]
    return {tuple(np.round(e.verts[i], 6)): result.vertex_radiosity[i] for i in ids}


def pebbles(n, seed=3, side=0.01, area=(2.0, 2.0)):
    """``n`` separate 1 cm boxes scattered on a floor (clutter), one object each."""
    rng = np.random.default_rng(seed)
    out = []
    for i, (x, y) in enumerate(rng.uniform((0.1, 0.1), (area[0] - 0.1, area[1] - 0.1), (n, 2))):
        out.append(scenes.box((x, y, 0.0), (x + side, y + side, side), rho=(0.6, 0.5, 0.4), bottom=False,
                              name=f"Pebble{i}"))
    return out


def test_1500_pebbles_are_grouped_across_objects_as_a_few_patches():
    """Each pebble is a separate object smaller than a patch: grouped as a volume (by material,
    normal and cell, not by object), they cost a few patches per cell and normal, not five per
    pebble (7,500, refused at the limit before)."""
    from hemicube_radiosity.core.mesh.stage import cut_patches

    room = [scenes.box((0, 0, 0), (2.0, 2.0, 2.0), inward=True, name="room")]
    s = BakeSettings().resolved(room)
    pieces, clusters = cut_patches(room + pebbles(1500), s)
    assert len(pieces) >= 7500
    per_cell = 5 * int(np.ceil(2.0 / s.patch_size)) ** 2        # five normals over the floor's cells
    pebble = clusters.owner >= 1
    assert pebble.sum() <= per_cell
    # every cluster of pebbles keeps one normal and one material: their tops face up together
    top = pieces.normals[:, 2] > 0.99
    assert np.all(np.bincount(clusters.of[top], minlength=len(clusters))[clusters.of[~top & (pieces.owner >= 1)]] == 0)


def test_grouped_clutter_is_lit_as_the_ungrouped_pebbles():
    """300 pebbles under a lamp: grouped across objects, the light on their corners and on the
    floor's as bright as in the bake with one patch per face. (Corner by corner they scatter
    by 9-11% RMS: the ungrouped bake's 1 cm faces each see the room from one hemi-cube, and a few
    of its corners inside overlapping pebbles are black.)"""
    room = [scenes.box((0, 0, 0), (2.0, 2.0, 2.0), inward=True, name="room")]
    lamp = scenes.quad([(0.7, 0.7, 1.99), (1.3, 0.7, 1.99), (1.3, 1.3, 1.99), (0.7, 1.3, 1.99)],
                       emission=(6.0, 6.0, 6.0), name="lamp")
    lamp = MeshInput(lamp.verts, lamp.face_offsets, lamp.face_indices[::-1].copy(), lamp.face_rho,
                     lamp.face_emission, "lamp")
    scene = room + [lamp] + pebbles(300)
    # one-sided: where pebbles overlap, the pockets inside both get backs (core/mesh/backs.py)
    # whose corners, never seen, the grouped and single bakes light differently (up to 85% at a
    # few dozen corners: 1.4% of the mean)
    s = dict(patch_size=0.25, element_size=None, refine_levels=0, resolution=64, two_sided_reflection=False)
    grouped = bake(scene, BakeSettings(**s))
    single = bake(scene, BakeSettings(group_faces=False, **s))
    assert grouped.unknowns < single.unknowns - 1000
    a, b = ({}, {})
    for r, d in ((grouped, a), (single, b)):
        for o in range(2, len(scene)):
            d.update(floor_vertices(r, o))
    common = sorted(a.keys() & b.keys())
    assert len(common) > 0.9 * len(a)
    a, b = (np.array([d[k] for k in common]) for d in (a, b))
    np.testing.assert_allclose(a.mean(axis=0), b.mean(axis=0), rtol=0.02)      # measured 0.5-1.2%
    fa, fb = (floor_vertices(r, 0) for r in (grouped, single))
    common = sorted(fa.keys() & fb.keys())                   # the room's own corners
    fa, fb = (np.array([d[k] for k in common]) for d in (fa, fb))
    assert np.sqrt(np.mean((fa - fb) ** 2)) / fb.mean() < 0.02
