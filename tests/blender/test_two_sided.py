# SPDX-License-Identifier: GPL-3.0-or-later
"""Both sides of a single plane reflect, as in Cycles (core/mesh/backs.py), compared with Cycles'
bake at its own face corners (tests/support/cycles_scenes.py: one patch per face, Cycles
COMBINED = E + rho H / pi): a lamp panel under a ceiling whose back bounces light with it, a
single-plane wall lit from behind, a floor turned away from the room by a negative scale. Each
case also bakes the paper's one-sided surfaces, which Cycles' answer must tell apart.

Run ``python -m tests.blender.test_two_sided`` to print the errors."""
from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tools import cycles_reference as cr  # noqa: E402
from hemicube_radiosity.core.pipeline import BakeSettings, bake  # noqa: E402
from tests.support.cycles_scenes import RHO, SETTINGS, Comparison, floor_object  # noqa: E402

pytestmark = [pytest.mark.blender, pytest.mark.cycles]

TOL = 0.03


def _one_sided(c):
    """Our bake of the same scene with surfaces that reflect from their front only, as
    (ours at the compared corners, in ``c``'s order)."""
    r = bake(c.meshes, BakeSettings(**SETTINGS, two_sided_reflection=False), lights=c.lights, world=c.world)
    P = r.patches
    out = np.empty_like(c.ours)
    for k in np.unique(c.owner):
        mine = np.flatnonzero(P.owner == k)
        # the same faces in the same order as the comparison (one patch per face, fronts first)
        out[c.owner == k] = r.vertex_radiosity[P.polys[mine]].reshape(-1, 3)
    return out


def lamp_panel_case():
    """A 1 m lamp panel (emission 5, reflectance 0.8 on both faces) 5 mm under a 2 m ceiling,
    over a floor: the panel's back and the ceiling bounce light between them."""
    cr.new_empty_scene()
    fl = floor_object(12, 1.5)
    v, f = cr.grid_arrays(16, 16, -1.0, 1.0, -1.0, 1.0, 1.0)
    ceiling = cr.mesh_object(v, f[:, ::-1], cr.diffuse_material((RHO,) * 3), "ceiling")
    v, f = cr.grid_arrays(4, 4, -0.5, 0.5, -0.5, 0.5, 0.995)
    lamp = cr.mesh_object(v, f[:, ::-1], cr.diffuse_material((RHO,) * 3, emission=5.0), "lamp")
    return Comparison([fl, ceiling, lamp], samples=256)


def _outline(c, half=0.5):
    """Corners within 1 cm of the lamp's outline seen from above (a step in the light there)."""
    x, y = np.abs(c.pos[:, 0]), np.abs(c.pos[:, 1])
    return ((np.abs(x - half) < 0.01) & (y < half + 0.01)) | ((np.abs(y - half) < 0.01) & (x < half + 0.01))


def test_a_lamp_panel_under_a_ceiling_bounces_light_off_its_back():
    """Over the panel the ceiling is 11.1 (Cycles 11.2; one-sided 4.0: the back reflected
    nothing); off the panel's outline 4.3% mean error against one-sided's 18%. Right over the
    outline ours is 5.4 where Cycles has 3.8-3.9: in the 5 mm gap the light falls off within a
    centimetre of the edge, and the back's reflected light is one value per 0.25 m patch."""
    c = lamp_panel_case()
    on_ceiling = c.owner == 1
    above = on_ceiling & (np.abs(c.pos[:, 0]) < 0.45) & (np.abs(c.pos[:, 1]) < 0.45)
    assert above.sum() >= 25
    ours, theirs = c.ours[above].mean(), c.cycles[above].mean()
    assert theirs > 10.0 and ours == pytest.approx(theirs, rel=0.03)
    lit = on_ceiling & (c.cycles.mean(axis=1) > 0.05) & ~_outline(c)
    assert c.error(lit) < 0.06
    near = (c.owner == 0) & (np.linalg.norm(c.pos[:, :2], axis=1) < 1.2)
    assert c.error(near) < TOL
    # the paper's one-sided panel reflects nothing from its back: the ceiling over it is far darker
    one = _one_sided(c)
    assert one[above].mean() < 0.5 * theirs
    assert np.mean(np.abs(one[lit].mean(axis=1) - c.cycles[lit].mean(axis=1)) / c.cycles[lit].mean(axis=1)) > 0.1


def opening_case():
    """A 1.04 m lamp panel (emission 30 from both faces, black) 13 mm under a 1 m opening in a
    2 m ceiling, over a floor, nothing above: the staircase hall of ../shared/scenes. The panel's
    back faces only the dark above, except the opening's rim, a centimetre over it."""
    cr.new_empty_scene()
    fl = floor_object(12, 1.5)
    v, f = cr.grid_arrays(16, 16, -1.0, 1.0, -1.0, 1.0, 1.0)
    c = v[f].mean(axis=1)
    f = f[(np.abs(c[:, 0]) > 0.5) | (np.abs(c[:, 1]) > 0.5)]             # the opening
    ceiling = cr.mesh_object(v, f[:, ::-1], cr.diffuse_material((RHO,) * 3), "ceiling")
    v, f = cr.grid_arrays(4, 4, -0.52, 0.52, -0.52, 0.52, 0.987)
    lamp = cr.mesh_object(v, f[:, ::-1], cr.diffuse_material((0.0,) * 3, emission=30.0), "lamp")
    return Comparison([fl, ceiling, lamp], samples=64)


def test_a_lamp_panels_back_lights_the_rim_of_an_opening_over_it():
    """The rim's corners see the panel's back a centimetre under them: Cycles 20.4-22.7 there
    (closed form of the direct part 20.6-22.1). The back's probe rays from its centre all left
    through the opening, so it was left out and some of the rim read 1.7 (40% mean error). Ours
    is 8% high: 1.9 of indirect light off the floor, which the panel's black back hides from
    92% of the rim's view."""
    c = opening_case()
    rim = (c.owner == 1) & (np.abs(np.abs(c.pos[:, 0]) - 0.5) < 1e-6) & (np.abs(c.pos[:, 1]) < 0.51) \
        | (c.owner == 1) & (np.abs(np.abs(c.pos[:, 1]) - 0.5) < 1e-6) & (np.abs(c.pos[:, 0]) < 0.51)
    assert rim.sum() >= 32
    theirs, ours = c.cycles[rim].mean(axis=1), c.ours[rim].mean(axis=1)
    assert theirs.min() > 3.0
    assert float(np.mean(np.abs(ours - theirs) / theirs)) < 0.12


def back_lit_wall_case():
    """A single-plane wall facing away from a point lamp 1.2 m behind it, on a floor: the floor
    on the lamp's side gets the light the wall's back reflects."""
    cr.new_empty_scene()
    fl = floor_object(16, 2.0)
    v, f = cr.grid_arrays(16, 8, -2.0, 2.0, 0.0, 2.0)
    v = np.stack([v[:, 0], np.zeros(len(v)), v[:, 1]], 1)                  # plane y = 0 ...
    wall = cr.mesh_object(v, f, cr.diffuse_material((RHO,) * 3), "wall")   # ... facing -y
    cr.add_light("POINT", (0.0, 1.2, 1.0), energy=300.0, shadow_soft_size=0.0)
    return Comparison([fl, wall], samples=512)


def test_a_single_plane_wall_lit_from_behind_reflects_from_its_back():
    c = back_lit_wall_case()
    assert np.all(c.normal[c.owner == 1] @ np.array([0.0, -1.0, 0.0]) > 0.99)     # faces away from the lamp
    lamp_side = (c.owner == 0) & (c.pos[:, 1] > 0.05)
    assert lamp_side.sum() > 100
    assert c.error(lamp_side) < TOL
    # the wall's share: one-sided, the lamp's side of the floor misses it
    one = _one_sided(c)
    near = lamp_side & (c.pos[:, 1] < 0.6)
    assert one[near].mean() < 0.9 * c.cycles[near].mean() and \
        c.ours[near].mean() == pytest.approx(c.cycles[near].mean(), rel=0.03)


def mirrored_floor_case():
    """A floor under a point lamp beside a wall, baked by Cycles as it is; then the same floor
    mirrored by a negative scale (its faces now point down, away from the room) baked by us.
    Cycles bakes a face's front, so its answer for the mirrored floor's up side is the
    unmirrored floor's: (comparison of the plain floor, our bake of the mirrored scene)."""
    cr.new_empty_scene()
    v, f = cr.grid_arrays(12, 12, -1.5, 1.5, -1.5, 1.5)
    fl = cr.mesh_object(v, f, cr.diffuse_material((RHO,) * 3), "floor")
    v, f = cr.grid_arrays(12, 8, -1.5, 1.5, 0.0, 2.0)
    v = np.stack([v[:, 0], np.full(len(v), 1.5), v[:, 1]], 1)               # plane y = 1.5, facing -y
    wall = cr.mesh_object(v, f, cr.diffuse_material((0.6, 0.3, 0.3)), "wall")
    cr.add_light("POINT", (0.0, 0.0, 1.5), energy=200.0, shadow_soft_size=0.0)
    c = Comparison([fl, wall], samples=512)
    fl.scale = (1.0, 1.0, -1.0)
    bpy.context.view_layer.update()
    dg = bpy.context.evaluated_depsgraph_get()
    from hemicube_radiosity.blender.read import scene as reader

    meshes = reader.read_scene(dg, [fl, wall]).meshes
    return c, meshes, bake(meshes, BakeSettings(**SETTINGS), lights=c.lights, world=c.world)


def _floor_up_side(c, meshes, r):
    """Our light on the up side of the mirrored floor at the plain floor's compared corners
    (matched by position), and whether the floor's front faces down."""
    P = r.elements
    back = r.owners_of(0)[1:]
    assert back.size == 1, "the mirrored floor's up side is its back"
    sel = np.isin(P.owner, back)
    v = np.unique(P.polys[sel][P.polys[sel] >= 0])
    key = {tuple(np.round(P.verts[i, :2], 6)): r.vertex_radiosity[i] for i in v}
    floor = c.owner == 0
    return np.array([key[tuple(np.round(p[:2], 6))] for p in c.pos[floor]]), floor


def test_a_floor_turned_away_by_a_negative_scale_is_lit_from_the_room():
    c, meshes, r = mirrored_floor_case()
    front = r.patches.normals[r.patches.owner == 0]
    assert np.all(front[:, 2] < -0.99)                       # the mirrored floor faces down
    up, floor = _floor_up_side(c, meshes, r)
    theirs = c.cycles[floor]
    assert theirs.mean() > 0.5
    assert float(np.mean(np.abs(up.mean(axis=1) - theirs.mean(axis=1)) / theirs.mean(axis=1))) < TOL
    # one-sided, the mirrored floor has no up side: its front, facing down, is black
    one = bake(meshes, BakeSettings(**SETTINGS, two_sided_reflection=False), lights=c.lights, world=c.world)
    down = np.unique(one.elements.polys[one.elements.owner == 0])
    assert one.vertex_radiosity[down[down >= 0]].max() < 1e-6


if __name__ == "__main__":
    c, meshes, r = mirrored_floor_case()
    up, floor = _floor_up_side(c, meshes, r)
    print(f" mirrored floor: Cycles {c.cycles[floor].mean():.4f}, ours (up side) {up.mean():.4f}")
    for name, case in (("panel", lamp_panel_case), ("back-lit", back_lit_wall_case)):
        c = case()
        one = _one_sided(c)
        for k in np.unique(c.owner):
            m = c.owner == k
            print(f"{name:>9} object {k}: Cycles {c.cycles[m].mean():.4f}, ours {c.ours[m].mean():.4f} "
                  f"(err {100 * c.error(m):.2f}%), one-sided {one[m].mean():.4f}; "
                  f"Cycles {c.cycles_seconds:.1f} s, ours {c.our_seconds:.1f} s")
