"""The light a covered corner's near faces hand on (core/output/near.py), against the closed form of
an infinite wedge: a floor and a wall rising from it at 45 deg over it, both lit by a sun shining
into the wedge, nothing else (a black world). Every point of an infinite wedge's wall sees the
other wall with the same view factor F = (1 + cos a) / 2 (a = 45 deg: 0.854), so each wall's
radiosity is uniform: B_f = rho E_f / pi + rho F B_w, B_w = rho E_w / pi + rho F B_f. Its partial
sums bound a corner at the apex from below: with one bounce off the other wall,
rho E_f / pi + rho F rho E_w / pi; and the full series from above. At the apex our vertex's rays
start over the wall's back (the floor's corner) or past the floor's plane: both corners are
covered (core/output/covered.py), and without near.py they kept only the share of their vertex's
light that the open scene sends, below even the one bounce (floor 0.216, one bounce 0.249,
closed form 0.305; Cycles' rays from the apex read the lit walls)."""
import numpy as np
import pytest

from hemicube_radiosity.core.light.lamps import SunLight
from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.pipeline import BakeSettings, bake
from hemicube_radiosity.core.rays import embree_available

pytestmark = pytest.mark.skipif(not embree_available(), reason="the corners' rays need Embree")

RHO, SUN, SIZE = 0.5, 3.0, 8
WEDGE, ELEVATION = np.radians(45.0), np.radians(20.0)


def _grid(origin, u, v, name):
    """A SIZE x SIZE grid of 1 m quads from ``origin`` along unit ``u`` and ``v`` (facing u x v)."""
    n = SIZE + 1
    verts = [tuple(np.asarray(origin) + i * np.asarray(u) + j * np.asarray(v)) for j in range(n) for i in range(n)]
    faces = [(j * n + i, j * n + i + 1, (j + 1) * n + i + 1, (j + 1) * n + i) for j in range(SIZE) for i in range(SIZE)]
    return MeshInput.from_faces(verts, faces, rho=(RHO,) * 3, name=name)


def _wedge_apex():
    """(floor's, wall's) values at their corners on the apex line (x = -1, 0, 1: away from the
    wedge's ends), and the closed forms (one bounce, the full series) for each."""
    floor = _grid((-SIZE / 2, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), "floor")
    rise = (0.0, np.cos(WEDGE), np.sin(WEDGE))
    wall = _grid((-SIZE / 2, 0.0, 0.0), rise, (1.0, 0.0, 0.0), "wall")        # its front faces the floor
    to_sun = np.array([0.0, np.cos(ELEVATION), np.sin(ELEVATION)])
    r = bake([floor, wall], BakeSettings(patch_size=1.0, element_size=1.0, two_sided_reflection=False,
                                         gather_rays=64), lights=[SunLight(tuple(-to_sun), strength=SUN)])
    E, cid, cv = r.elements, r.elements.corner_ids(), r.corner_values()
    wall_normal = np.cross(rise, (1.0, 0.0, 0.0))
    np.testing.assert_allclose(E.normals[E.owner == 1], np.broadcast_to(wall_normal, (SIZE * SIZE, 3)), atol=1e-9)
    Df, Dw = SUN * to_sun[2] / np.pi, SUN * (wall_normal @ to_sun) / np.pi
    F = (1.0 + np.cos(WEDGE)) / 2.0
    Bf, Bw = np.linalg.solve([[1.0, -RHO * F], [-RHO * F, 1.0]], [RHO * Df, RHO * Dw])
    out = []
    for owner, mine, other, full in ((0, Df, Dw, Bf), (1, Dw, Df, Bw)):
        rows = np.flatnonzero(E.owner == owner)
        pos = E.verts[cid[rows]]
        on_apex = (np.linalg.norm(pos[..., 1:], axis=-1) < 1e-9) & (np.abs(pos[..., 0]) < 1.5)
        assert on_apex.sum() == 6                    # 3 vertices, 2 faces each
        out.append((cv[rows][on_apex][:, 0], RHO * mine + RHO * F * RHO * other, full))
    return out


def test_a_sunlit_wedge_s_apex_corners_read_the_lit_wall_beside_them():
    for values, one_bounce, full in _wedge_apex():
        assert one_bounce < full
        assert values.min() >= 0.98 * one_bounce, (values, one_bounce, full)
        assert values.max() <= 1.02 * full, (values, one_bounce, full)
