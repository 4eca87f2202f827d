"""Surfaces standing on others (core/mesh/contact.py): output elements cut along
the contact lines, vertices there apart on each side, buried corners given the open side's limit.

A house standing on one large ground face under a uniform sky: uncut, the output elements
straddle the house's walls, and their corners under the house see only its inside. Truth: the
same scene with the ground modelled cut along the footprint (four faces around it).
"""
from __future__ import annotations

import dataclasses

import numpy as np
from tests.support import fronts
import pytest

from hemicube_radiosity.core.mesh import elements
from hemicube_radiosity.core.output import stage as output
from hemicube_radiosity.core import builtin_scenes as scenes
from hemicube_radiosity.core.mesh.contact import cut_along_contacts, open_side
from hemicube_radiosity.core.output.interpolate import interpolate_at
from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.pipeline import BakeSettings, bake
from hemicube_radiosity.core.rays import embree_scene
from tests.support.markers import needs_embree

X0, X1, Y0, Y1 = 0.83, 1.61, 0.77, 1.49          # the house's footprint, off the element grid


def _ground(cut):
    if not cut:
        return scenes.quad([(0, 0, 0), (3, 0, 0), (3, 3, 0), (0, 3, 0)], (0.5,) * 3, name="ground")
    verts, faces = [], []
    for a0, a1, b0, b1 in ((0, X0, 0, 3), (X1, 3, 0, 3), (X0, X1, 0, Y0), (X0, X1, Y1, 3)):
        faces.append(list(range(len(verts), len(verts) + 4)))
        verts += [(a0, b0, 0), (a1, b0, 0), (a1, b1, 0), (a0, b1, 0)]
    return MeshInput.from_faces(verts, faces, (0.5,) * 3, name="ground")


def _house():
    return scenes.box((X0, Y0, 0), (X1, Y1, 1.0), (0.6,) * 3, bottom=False, name="house")


def _beside_the_walls():
    """Points on the open ground 1-20 cm from the footprint, along its four sides."""
    pts = []
    for t in np.linspace(0.1, 0.9, 9):
        for d in (0.01, 0.03, 0.06, 0.1, 0.15, 0.2):
            pts += [(X0 - d, Y0 + t * (Y1 - Y0), 0), (X1 + d, Y0 + t * (Y1 - Y0), 0),
                    (X0 + t * (X1 - X0), Y0 - d, 0), (X0 + t * (X1 - X0), Y1 + d, 0)]
    return np.array(pts, dtype=np.float64)


def _ground_beside(cut):
    r = bake([_ground(cut), _house()], BakeSettings(patch_size=0.3, element_size=0.15), world=np.ones(3))
    p = _beside_the_walls()
    return interpolate_at(r.elements, r.vertex_radiosity, p, np.zeros(len(p), np.int64),
                          np.tile([0.0, 0.0, 1.0], (len(p), 1)))[:, 0]


@needs_embree
def test_the_ground_beside_a_house_on_one_face_is_the_cut_grounds(monkeypatch):
    """Measured against the cut ground: 1.1% RMS (5.2% at worst, at the house's corners); with
    nothing cut along the walls' feet, buried corners taking the open side's limit alone: 3.6%
    RMS (17% at worst, 1 cm from a wall, where the light falls steeply inside one element); with neither,
    the buried corners' dark spreads over the open half: 10.4% RMS, 42% at worst, 4.3% dark."""
    truth = _ground_beside(True)

    def off(e):
        return e / truth - 1

    e = off(_ground_beside(False))
    assert np.sqrt(np.mean(e ** 2)) < 0.015 and np.abs(e).max() < 0.06 and abs(e.mean()) < 0.005
    monkeypatch.setattr(elements, "cut_along_contacts", lambda elements, faces, **k: elements)
    e = off(_ground_beside(False))
    assert 0.02 < np.sqrt(np.mean(e ** 2)) < 0.05 and np.abs(e).max() < 0.25 and abs(e.mean()) < 0.015
    monkeypatch.setattr(output, "buried_side", lambda *a, **k: None)
    e = off(_ground_beside(False))
    assert np.sqrt(np.mean(e ** 2)) > 0.08 and e.mean() < -0.03


@needs_embree
def test_an_edge_into_a_wall_meets_it_where_it_stands():
    """A 1 m floor face cut into 0.25 m elements, a wall across it at x = 0.6: the edges from
    x = 0.5 (open) to x = 0.75 (behind the wall, buried) meet the wall a thousandth of the edge
    short of x = 0.6 (the inner ones from both elements they border); a buried vertex takes the mean of
    what arrives at its edges' ends; edges of elements the scene does not see are left out."""
    floor = scenes.quad([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], (0.5,) * 3, name="floor")
    wall = scenes.quad([(0.6, 0, 0), (0.6, 1, 0), (0.6, 1, 1), (0.6, 0, 1)], (0.5,) * 3, name="wall")
    el = build_patches([floor, wall], 0.25)
    v = el.verts
    on_floor = np.abs(v[:, 2]) < 1e-12
    buried = on_floor & (v[:, 0] > 0.6) & (v[:, 0] < 0.8)          # the column at x = 0.75
    side = open_side(el, buried, embree_scene(el))
    inner = buried & (v[:, 1] > 0) & (v[:, 1] < 1)      # (a ray along the wall's own edge may miss it)
    assert inner.sum() == 3 and side.count[inner].min() >= 2 and side.count[~buried].max() == 0
    np.testing.assert_allclose(v[side.open_v, 0], 0.5)
    np.testing.assert_allclose(side.points[:, 0], 0.6 - 0.25e-3, atol=1e-9)
    np.testing.assert_allclose(side.points[:, 1], v[side.open_v, 1], atol=1e-12)
    assert np.all(side.normals[:, 2] == 1.0)
    at = np.arange(len(side), dtype=np.float64)[:, None]
    got = side.spread(np.full((len(v), 1), -1.0), at)
    for b in np.flatnonzero(side.count):
        assert got[b, 0] == pytest.approx(at[side.buried_v == b, 0].mean())
    assert np.all(got[side.count == 0] == -1.0)
    hidden = np.zeros(len(el))                                       # no element is seen
    assert len(open_side(el, buried, embree_scene(el), hidden)) == 0


def test_elements_are_cut_along_a_wall_standing_across_them():
    """A 1 m floor cut into 0.25 m elements with a wall standing on it along a slanted line: the
    elements the line crosses are cut in two (each piece on one side of it, within a thousandth
    of an element), the floor's area is kept, the vertices on the line are apart on each side
    and pieces of one side share them; the elements the line misses keep their vertices. A wall
    meeting the floor at its edge cuts nothing."""
    floor = scenes.quad([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], (0.5,) * 3, name="floor")
    a, b = np.array([0.1, 0.0, 0.0]), np.array([0.9, 1.0, 0.0])
    wall = scenes.quad([tuple(a), tuple(b), tuple(b + [0, 0, 1]), tuple(a + [0, 0, 1])], (0.5,) * 3, name="wall")
    edge = scenes.quad([(0, 0, 0), (0, 1, 0), (0, 1, 1), (0, 0, 1)], (0.5,) * 3, name="edge")
    meshes = [floor, wall, edge]
    el = build_patches(meshes, 0.25)
    cut = cut_along_contacts(el, build_patches(meshes, None))
    on_floor = cut.owner == 0
    assert cut.areas[on_floor].sum() == pytest.approx(1.0, abs=1e-12)
    assert (cut.owner == 0).sum() > (el.owner == 0).sum() + 6          # the line crosses 7 elements
    np.testing.assert_array_equal(cut.areas[~on_floor], el.areas[el.owner != 0])   # walls: uncut
    d = (b - a) / np.linalg.norm(b - a)
    m = np.cross([0.0, 0.0, 1.0], d)
    h = np.where(cut.polys[..., None] >= 0, cut.verts[np.maximum(cut.polys, 0)], np.nan)
    h = (h - a) @ m                                                    # (N, 4) across the line
    floor_h = h[on_floor]
    assert np.all((np.nanmin(floor_h, axis=1) > -2.5e-4) | (np.nanmax(floor_h, axis=1) < 2.5e-4))
    # the floor's vertices on the line: each used by pieces of one side only, two at each place
    fp = cut.polys[on_floor]
    v_on = np.unique(fp[(np.abs(floor_h) < 1e-9) & (fp >= 0)])
    t = (cut.verts[v_on] - a) @ d
    ends = v_on[(t < 1e-9) | (t > np.linalg.norm(b - a) - 1e-9)]
    assert ends.size == 2                                   # the wall stops there: one vertex each
    v_on = np.setdiff1d(v_on, ends)
    assert v_on.size == 2 * 5       # 3 + 3 grid lines crossed inside, one place, (0.5, 0.5), for two
    side = np.sign(np.nansum(np.where(np.abs(floor_h) < 1e-9, 0, floor_h), axis=1))
    for v in v_on:
        assert np.unique(side[(fp == v).any(axis=1)]).size == 1
    places = np.unique(np.round(cut.verts[v_on], 9), axis=0, return_counts=True)[1]
    assert np.all(places == 2)
    # away from the line nothing changed: the same corner positions as before
    far = np.nanmin(np.abs(floor_h), axis=1) > 0.3
    before = {tuple(np.round(p, 9)) for p in el.corners()[el.owner == 0].reshape(-1, 3)}
    assert far.sum() > 0 and all(tuple(np.round(p, 9)) in before
                                 for p in cut.corners()[np.flatnonzero(on_floor)[far]].reshape(-1, 3))
    # a wall along the floor's own edge only: nothing to cut
    el2 = build_patches([floor, edge], 0.25)
    assert cut_along_contacts(el2, build_patches([floor, edge], None)) is el2


@needs_embree
def test_a_partition_off_the_grids_leaks_no_light():
    """A zero-thickness wall at x = 1.03 closing off half of a 2 x 1 x 1 room lit on its left:
    neither the 0.2 m patches nor the 0.1 m elements have an edge there. Cut along its foot
    (and along its sides and top, where it meets the room's walls and ceiling), the dark half's
    floor gets nothing: 0 measured, against 0.5% of the lit floor on average (2.9% at worst)
    with the patches across it and 0.4-1.0% with only the elements cut."""
    room = scenes.box((0, 0, 0), (2, 1, 1), (0.7,) * 3, inward=True, name="room")
    wall = scenes.quad([(1.03, 0, 0), (1.03, 1, 0), (1.03, 1, 1), (1.03, 0, 1)], (0.7,) * 3, name="wall")
    lamp = scenes.quad([(0.4, 0.4, 0.99), (0.4, 0.6, 0.99), (0.6, 0.6, 0.99), (0.6, 0.4, 0.99)], (0, 0, 0),
                       (10.0,) * 3, name="lamp")
    r = bake([room, wall, lamp], BakeSettings(patch_size=0.2, element_size=0.1))
    el = r.elements
    floor = (el.owner == 0) & (el.centers[:, 2] < 1e-9)

    def verts(sel):
        v = np.unique(el.polys[sel])
        return v[v >= 0]
    lit = r.vertex_radiosity[verts(floor & (el.centers[:, 0] < 0.98))].mean()
    dark = r.vertex_radiosity[verts(floor & (el.centers[:, 0] > 1.03))]
    assert lit > 0.05 and len(dark) > 100
    assert np.abs(dark).max() < 1e-6 * lit
    p = r.patches
    dark_patches = (p.owner == 0) & (p.centers[:, 2] < 1e-9) & (p.centers[:, 0] > 1.03)
    assert np.abs(r.patch_radiosity[dark_patches]).max() < 1e-6 * lit


def test_only_what_touches_a_face_cuts_it():
    """The Cornell box's short block's top is cut by nothing: the tall block's sides cross its
    plane beside it, not on it (they were cut along that line). The floor is cut along both
    blocks' feet."""
    meshes = scenes.cornell_box()
    faces = build_patches(meshes, None)
    els = build_patches(meshes, 0.4)                              # the top: 4 patches (were cut into 6)
    out = cut_along_contacts(els, faces)
    names = [m.name for m in meshes]

    def count(ps, name, up):
        o = ps.owner == names.index(name)
        return int((o & (ps.normals[:, 2] > 0.99 if up else o)).sum())

    assert count(out, "ShortBlock", True) == count(els, "ShortBlock", True) == 4
    assert count(out, "Floor", False) > count(els, "Floor", False)


def test_a_warped_mesh_does_not_cut_itself():
    """A bumpy sheet of slightly warped quads (as a subdivision surface makes them): each quad's
    diagonal neighbours cross its plane at the corner they share; the mesh going on cuts
    nothing."""
    k = 24
    x, y = np.meshgrid(np.linspace(0, 1, k + 1), np.linspace(0, 1, k + 1))
    z = 0.05 * np.sin(7 * x) * np.cos(5 * y) + 0.003 * np.sin(40 * x + 30 * y)
    verts = np.stack([x, y, z], -1).reshape(-1, 3)
    quads = [[j * (k + 1) + i, j * (k + 1) + i + 1, (j + 1) * (k + 1) + i + 1, (j + 1) * (k + 1) + i]
             for j in range(k) for i in range(k)]
    m = MeshInput.from_faces(verts, quads, name="sheet")
    faces = build_patches([m], None)
    c = faces.corners()
    warp = np.abs(np.einsum("pkj,pj->pk", c - c[:, :1], faces.normals)).max(1)
    assert warp.max() > 1e-3 * np.sqrt(faces.areas).max()         # warped well past the touch tolerance
    assert len(cut_along_contacts(faces, faces)) == len(faces)


def test_a_blocks_foot_on_a_dense_floor_reads_the_open_floor():
    """The Cornell box modelled as 10,368 triangles and baked on its own vertices (no contact
    cut): the floor's triangles run on under the blocks, so a block's bottom vertices gather
    from floor triangles with corners under the block. Those corners are read as their open
    side, as the cut elements of the coarse box have it: the blocks' sides at the floor match
    the coarse bake (cut along the contacts) within 6% (1.5% and 1.1% here). Read as what they
    gathered (nothing: they are under the block), the short block's foot came out 14% dark."""
    s = BakeSettings(patch_size=0.5)
    dense = bake(scenes.tessellate(scenes.cornell_box(), 18), s)
    coarse = bake(scenes.cornell_box(), s)
    assert len(dense.elements) == len(dense.patches)
    assert fronts(dense, dense.elements.owner).sum() == 10368           # its own faces
    assert len(coarse.elements.verts) > len(coarse.patches.verts)      # cut elements
    el = dense.elements
    lum = np.array([0.2126, 0.7152, 0.0722])
    for name in ("ShortBlock", "TallBlock"):
        o = el.object_names.index(name)
        vs = np.unique(el.polys[el.owner == o])
        vs = vs[vs >= 0]
        foot = vs[np.abs(el.verts[vs, 2]) < 1e-9]
        foot = foot[(dense.vertex_radiosity[foot] @ lum) > 0]
        normals = np.zeros((len(foot), 3))
        for f in np.flatnonzero(el.owner == o):                       # a side's own normal
            if abs(el.normals[f, 2]) < 0.5:
                on = np.isin(foot, el.polys[f])
                normals[np.isin(foot, foot[on])] = el.normals[f]
        keep = np.abs(normals).sum(1) > 0
        pts = el.verts[foot[keep]] + 1e-4 * normals[keep]
        ours = dense.vertex_radiosity[foot[keep]] @ lum
        ref = interpolate_at(coarse.elements, coarse.vertex_radiosity, pts - 1e-4 * normals[keep],
                             owner=np.full(len(pts), coarse.elements.object_names.index(name)),
                             normals=normals[keep]) @ lum
        assert len(ours) >= 20
        assert abs(ours.mean() / ref.mean() - 1) < 0.06, name


@pytest.mark.parametrize("seed", range(6))
def test_overlapping_boxes_are_every_overlapping_pair(seed):
    """contact._overlapping against every pair compared, with many small boxes against a few
    large ones (a dense floor's elements against a block's sides: every large box covers more
    than 64 grid cells, so no box of that set goes through the grid). Before, an empty set of
    small boxes broke the grid's expansion (``np.repeat`` of (1,) by (0,)): a 100 x 100 textured
    floor with a block standing on it crashed in the elements' cut."""
    from hemicube_radiosity.core.mesh.contact import _overlapping

    rng = np.random.default_rng(seed)
    lo_a = rng.uniform(0, 4, (300, 3)) * [1, 1, 0]
    hi_a = lo_a + rng.uniform(0.01, 0.04, (300, 3))
    big = seed % 2 == 0                        # the other set: all large, or some of each
    lo_b = rng.uniform(0, 3, (5, 3))
    hi_b = lo_b + rng.uniform(0.5, 1.5, (5, 3)) * ([1, 1, 1] if big else rng.uniform(0.01, 1, (5, 1)))
    for a, b, swap in (((lo_a, hi_a), (lo_b, hi_b), False), ((lo_b, hi_b), (lo_a, hi_a), True)):
        i, j = _overlapping(a[0], a[1], b[0], b[1])
        want = np.all((a[0][:, None] <= b[1][None]) & (a[1][:, None] >= b[0][None]), axis=2)
        got = np.zeros_like(want)
        got[i, j] = True
        assert np.array_equal(got, want) and len(i) == want.sum(), swap


@pytest.mark.parametrize("seed", range(4))
def test_overlapping_boxes_of_every_size_are_every_overlapping_pair(seed):
    """contact._overlapping with boxes whose sizes span five orders of magnitude on both sides
    (a game level's slabs, walls and trim: each box on the grid of its own level, the pairs
    looked for on the coarser box's grid) finds exactly the pairs a comparison of every pair
    finds, each once, sorted by a's index then b's."""
    from hemicube_radiosity.core.mesh.contact import _overlapping

    rng = np.random.default_rng(100 + seed)

    def boxes(n):
        lo = rng.uniform(-50, 50, (n, 3))
        return lo, lo + 10.0 ** rng.uniform(-3, 2, (n, 1)) * rng.uniform(0, 1, (n, 3))
    (alo, ahi), (blo, bhi) = boxes(700), boxes(900)
    alo[:50] = blo[:50] - rng.uniform(0, 1, (50, 3))   # boxes that touch b's exactly, at a face
    ahi[:50] = bhi[:50]
    ahi[:50, 0] = blo[:50, 0]
    i, j = _overlapping(alo, ahi, blo, bhi)
    want = np.all((alo[:, None] <= bhi[None]) & (ahi[:, None] >= blo[None]), axis=2)
    wi, wj = np.nonzero(want)
    assert np.array_equal(i, wi) and np.array_equal(j, wj)
    assert len(np.unique(i * len(blo) + j)) == len(i) > 50


@pytest.mark.parametrize("ground", ["warped quad", "octagon"])
def test_a_house_on_any_piece_of_a_split_face_cuts_it(ground):
    """A face the reader splits into pieces (a warped quad into two triangles, an n-gon into a
    fan) is one source face; a house sunk into it parts every piece its walls cross, not only
    the first: no ground element reaches from the open ground under the house. (Clipped to the
    first piece only, the walls crossing a generated terrain's second triangles cut nothing, and
    the corners under the houses took the open side's light: 45% of its squared error against
    Cycles.)"""
    if ground == "warped quad":
        g = MeshInput.from_faces([(0, 0, 0), (3, 0, 0), (3, 3, 0.6), (0, 3, 0)], [[0, 1, 2, 3]], name="ground")
        g = dataclasses.replace(g, face_triangles=np.array([[0, 0, 1, 2], [0, 0, 2, 3]]))   # as Blender's reader
    else:
        a = np.radians(22.5 + 45 * np.arange(8))
        g = MeshInput.from_faces(np.c_[1.5 + 2 * np.cos(a), 1.5 + 2 * np.sin(a), np.zeros(8)], [list(range(8))],
                                 name="ground")
    house = scenes.box((X0, Y0, -0.5), (X1, Y1, 1.0), (0.6,) * 3, name="house")
    faces = build_patches([g, house], None)
    assert (faces.owner == 0).sum() > 1 and len(np.unique(faces.normals[faces.owner == 0].round(6), axis=0)) \
        == (2 if ground == "warped quad" else 1)
    for size in (None, 0.4):
        el = build_patches([g, house], size)
        cut = cut_along_contacts(el, faces)
        c = cut.corners()[cut.owner == 0]                                        # (n, 4, 3)
        real = np.r_[[True] * 3, [False]][None] | (cut.polys[cut.owner == 0, 3] >= 0)[:, None]
        inside = (c[..., 0] > X0 + 1e-6) & (c[..., 0] < X1 - 1e-6) & (c[..., 1] > Y0 + 1e-6) & (c[..., 1] < Y1 - 1e-6)
        outside = (c[..., 0] < X0 - 1e-6) | (c[..., 0] > X1 + 1e-6) | (c[..., 1] < Y0 - 1e-6) | (c[..., 1] > Y1 + 1e-6)
        straddle = (inside & real).any(axis=1) & (outside & real).any(axis=1)
        assert not straddle.any(), (ground, size, c[straddle][:3])
        assert cut.areas[cut.owner == 0].sum() == pytest.approx(el.areas[el.owner == 0].sum(), rel=1e-9)


def test_corners_met_counts_what_comparing_every_pair_of_corners_counts():
    """contact._corners_met against the (P, 4, 4, 3) comparison it replaced: corners within eps
    of any source corner, a triangle's repeated 4th left out; shared corners, near misses by
    a hair either side of eps, and none."""
    from hemicube_radiosity.core.mesh.contact import _corners_met
    rng = np.random.default_rng(7)
    P, eps = 4000, 1e-6
    src = rng.uniform(-1, 1, (P, 4, 3))
    cut = rng.uniform(-1, 1, (P, 4, 3))
    pick = rng.integers(0, 4, (P, 4))
    on = rng.uniform(size=(P, 4)) < 0.5
    jitter = rng.choice([0.0, 0.5 * eps, 0.99 * eps, 1.01 * eps, 3 * eps], size=(P, 4, 3))
    cut[on] = src[np.arange(P)[:, None].repeat(4, 1)[on], pick[on]] + jitter[on] * rng.choice([-1, 1], (on.sum(), 3))
    tri = rng.uniform(size=P) < 0.3
    cut[tri, 3] = cut[tri, 2]
    same = np.abs(src[:, :, None, :] - cut[:, None, :, :]).max(axis=-1) <= eps
    want = same.any(axis=1)[:, :3].sum(axis=1) + (same.any(axis=1)[:, 3] & ~tri)
    assert np.array_equal(_corners_met(src, cut, eps, ~tri), want) and want.max() == 4 and want.min() == 0
