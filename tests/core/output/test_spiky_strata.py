"""A concave contact in the shade beside a spiky cell (core/output/abrupt.py, :class:`AbruptGrid`).

A wall 0.3 m high stands on a floor, facing +x, the sun (50 deg) behind it: the wall's face is in
the shade, and so is the floor for the first 0.25 m in front of it; beyond, the floor is sunlit.
The floor's 1 m elements beside the wall are abrupt, and the first cell of their grid (0.5 m)
is half in the sun: spiky. The gather's rays from the wall's foot land on the floor within
millimetres of the wall, where it is dark; read as the cell's mean, they lent the foot the
sun's light (2 to 5.5 times the truth along the wall; godot_zdm2's wall feet in the shade were
10% too bright for this). Each ray now reads the point of the stratum it lands in.

Truth: the same section solved in 2-D (the wall and floor as long strips, an L that sees
itself unoccluded; view factors by Hottel's crossed strings on strips graded toward the
corner, the sun's shadow edge in closed form, a black world), read at the point where our
vertex is evaluated: at a concave corner in the dark the light falls toward the corner as a
power of the distance, so the point matters (1.5 mm up the wall: 0.0043; 3 mm: 0.0067).
What stays over it (1.6x) is the light the patch solution still carries after the passes.

The sun 9 deg off the wall's line instead casts a shadow 3.9 cm deep (the section is the same,
the wall being long): inside the first of four even strata of the floor's cells, 1 to 7.1 cm
out, whose point is sunlit in some cells; read there, feet along the wall were up to 14 times
the truth (0.276 vs 0.020). The strata of a cell at its element's edge are graded toward it
(:func:`~hemicube_radiosity.core.output.abrupt.stratum_edges`): the first is 1 to 2.5 cm out,
in the shade, and the feet read 0.58 to 1.21 times the truth.
"""
from __future__ import annotations

import numpy as np
import pytest

from hemicube_radiosity.core.light.emitters import vertex_frames
from hemicube_radiosity.core.light.lamps import SunLight
from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.pipeline import BakeSettings, bake
from tests.support.markers import needs_embree

RHO, SUN, HIGH, DEEP, LONG = 0.8, 3.0, 0.3, 4.0, 8
ELEVATION = np.radians(50.0)


def _grid(origin, u, v, nu, nv, name):
    """nu x nv quads from ``origin`` along ``u`` and ``v`` (facing u x v)."""
    verts = [tuple(np.asarray(origin) + i * np.asarray(u) + j * np.asarray(v)) for j in range(nv + 1)
             for i in range(nu + 1)]
    faces = [(j * (nu + 1) + i, j * (nu + 1) + i + 1, (j + 1) * (nu + 1) + i + 1, (j + 1) * (nu + 1) + i)
             for j in range(nv) for i in range(nu)]
    return MeshInput.from_faces(verts, faces, rho=(RHO,) * 3, name=name)


def _section(edge, strips=600):
    """The 2-D section's radiosity: a function of the height z of a point on the wall's face,
    the floor sunlit from ``edge`` out."""
    def graded(length):
        t = np.linspace(0.0, 1.0, strips + 1) ** 3 * length
        return t[:-1], t[1:]
    fa, fb = graded(DEEP)
    wa, wb = graded(HIGH)
    lit = np.clip((fb - np.maximum(fa, edge)) / (fb - fa), 0.0, 1.0)

    def length(a, b):
        return np.hypot(a, b)
    crossed = (length(fa[:, None], wb[None]) + length(fb[:, None], wa[None])
               - length(fa[:, None], wa[None]) - length(fb[:, None], wb[None]))
    f_fw, f_wf = crossed / (2 * (fb - fa))[:, None], crossed.T / (2 * (wb - wa))[:, None]
    n = 2 * strips
    A = np.eye(n)
    A[:strips, strips:] -= RHO * f_fw
    A[strips:, :strips] -= RHO * f_wf
    B = np.linalg.solve(A, np.concatenate([RHO * SUN * np.sin(ELEVATION) / np.pi * lit, np.zeros(strips)]))

    def on_wall(z):          # what the floor's strips send a point z up the wall's face
        return RHO * 0.5 * (z / np.hypot(fa, z) - z / np.hypot(fb, z)) @ B[:strips]
    return on_wall


def _to_sun(across):
    """The direction to the sun at ELEVATION, behind the wall, ``across`` (radians) off the
    wall's line (pi / 2: square to it), and how far out from the wall its shadow ends."""
    c = np.cos(ELEVATION)
    return np.array([-c * np.sin(across), c * np.cos(across), np.sin(ELEVATION)]), \
        HIGH / np.tan(ELEVATION) * np.sin(across)


def _wall_feet(to_sun):
    """(values, heights): the wall's corners at its foot (|y| <= 2: away from its ends), and the
    heights of the points their vertices are evaluated at."""
    floor = _grid((0.0, -LONG, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), int(DEEP), 2 * LONG, "floor")
    wall = _grid((0.0, -LONG, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, HIGH), 2 * LONG, 1, "wall")   # faces +x
    r = bake([floor, wall], BakeSettings(patch_size=2.0, element_size=1.0, two_sided_reflection=False,
                                         gather_rays=128), lights=[SunLight(tuple(-to_sun), strength=SUN)])
    el, cid, cv = r.elements, r.elements.corner_ids(), r.corner_values()
    rows = np.flatnonzero(el.owner == el.object_names.index("wall"))
    pos = el.verts[cid[rows]]
    foot = (np.abs(pos[..., 0]) < 1e-9) & (np.abs(pos[..., 2]) < 1e-9) & (np.abs(pos[..., 1]) <= 2.0)
    assert foot.sum() == 10                               # 5 vertices, 2 faces each
    xv = vertex_frames(el)[0]
    return cv[rows][foot][:, 0], xv[cid[rows]][foot][:, 2]


@needs_embree
@pytest.mark.parametrize("across", [90.0, 9.0])
def test_a_shaded_wall_foot_reads_the_dark_floor_beside_it_not_its_cell_mean(across):
    to_sun, edge = _to_sun(np.radians(across))
    values, heights = _wall_feet(to_sun)
    on_wall = _section(edge)
    truth = np.array([on_wall(z) for z in heights])
    assert np.all((heights > 1e-4) & (heights < 1e-2)), heights
    np.testing.assert_array_less(0.5 * truth, values)
    np.testing.assert_array_less(values, 2.0 * truth)

