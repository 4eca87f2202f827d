"""Scenes as plain arrays: the demo Cornell box and the closed-form test cases.

Each returns ``list[MeshInput]`` (one per object, world space, metres). The Blender demo builds
its objects from these same arrays, so the core tests and the add-on bake the same scene.
"""
from __future__ import annotations

import numpy as np

from .mesh.patches import MeshInput

__all__ = ["quad", "box", "closed_box", "cornell_box", "parallel_squares", "perpendicular_squares", "tessellate",
           "CORNELL_RED", "CORNELL_GREEN", "CORNELL_WHITE"]

# Reflectances of the Cornell box (Goral et al. 1984 measured spectra folded to RGB, commonly used)
CORNELL_WHITE = (0.725, 0.71, 0.68)
CORNELL_RED = (0.63, 0.065, 0.05)
CORNELL_GREEN = (0.14, 0.45, 0.091)


def quad(corners, rho=(0.5, 0.5, 0.5), emission=(0, 0, 0), name="quad") -> MeshInput:
    """One quad; corners counter-clockwise seen from the side the normal points to."""
    return MeshInput.from_faces(np.asarray(corners, float), [[0, 1, 2, 3]], rho, emission, name)


def box(lo, hi, rho=(0.5, 0.5, 0.5), emission=(0, 0, 0), inward=False, bottom=True, name="box",
        rotate_z=0.0, per_face_rho=None) -> MeshInput:
    """Axis-aligned box (optionally rotated about its vertical axis through its centre).

    Faces do not share vertices (hard edges). ``inward`` flips the normals into the box (a room).
    ``bottom=False`` leaves the floor face out (a block standing on a floor).
    ``per_face_rho``: dict face-name -> rho for 'x0','x1','y0','y1','z0','z1'.
    """
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    # outward CCW faces
    faces = {
        "z0": [(x0, y0, z0), (x0, y1, z0), (x1, y1, z0), (x1, y0, z0)],
        "z1": [(x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)],
        "y0": [(x0, y0, z0), (x1, y0, z0), (x1, y0, z1), (x0, y0, z1)],
        "y1": [(x0, y1, z0), (x0, y1, z1), (x1, y1, z1), (x1, y1, z0)],
        "x0": [(x0, y0, z0), (x0, y0, z1), (x0, y1, z1), (x0, y1, z0)],
        "x1": [(x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (x1, y0, z1)],
    }
    if not bottom:
        del faces["z0"]
    names = list(faces)
    verts = np.array([p for k in names for p in faces[k]], float)
    if rotate_z:
        c = 0.5 * (lo + hi)
        ca, sa = np.cos(rotate_z), np.sin(rotate_z)
        rel = verts - c
        verts = c + np.stack([ca * rel[:, 0] - sa * rel[:, 1], sa * rel[:, 0] + ca * rel[:, 1], rel[:, 2]], 1)
    polys = [[4 * i, 4 * i + 1, 4 * i + 2, 4 * i + 3] for i in range(len(names))]
    if inward:
        polys = [p[::-1] for p in polys]
    rhos = np.array([(per_face_rho or {}).get(k, rho) for k in names], float)
    return MeshInput.from_faces(verts, polys, rhos, emission, name)


def closed_box(size=(1.0, 1.0, 1.0), rho=(0.5, 0.5, 0.5), emission=(1.0, 1.0, 1.0), name="room") -> list:
    """A closed room (inward normals) with the same emission and reflectivity everywhere.

    Closed-form answer (the "furnace"): B = E / (1 - rho) on every patch, whatever the shape.
    """
    return [box((0, 0, 0), size, rho, emission, inward=True, name=name)]


def parallel_squares(d=1.0, side=1.0) -> list:
    """Two directly opposed parallel squares ``d`` apart: 'bottom' faces up, 'top' faces down."""
    s = side
    bottom = quad([(0, 0, 0), (s, 0, 0), (s, s, 0), (0, s, 0)], name="bottom")
    top = quad([(0, 0, d), (0, s, d), (s, s, d), (s, 0, d)], name="top")
    return [bottom, top]


def perpendicular_squares(side=1.0) -> list:
    """Two unit squares sharing the edge along x at y=z=0: 'floor' faces +z, 'wall' faces +y."""
    s = side
    floor = quad([(0, 0, 0), (s, 0, 0), (s, s, 0), (0, s, 0)], name="floor")
    wall = quad([(0, 0, 0), (0, 0, s), (s, 0, s), (s, 0, 0)], name="wall")
    return [floor, wall]


def cornell_box(size=2.0, light_size=0.5, light_radiance=12.0) -> list:
    """The demo scene: a Cornell-like box, open at the front (y = 0), red left wall (x = 0),
    green right wall (x = size), white floor/ceiling/back, an emissive square just below the
    ceiling's centre facing down, a short and a tall white block on the floor.
    """
    s = float(size)
    w, r, g = CORNELL_WHITE, CORNELL_RED, CORNELL_GREEN
    floor = quad([(0, 0, 0), (s, 0, 0), (s, s, 0), (0, s, 0)], w, name="Floor")
    ceiling = quad([(0, 0, s), (0, s, s), (s, s, s), (s, 0, s)], w, name="Ceiling")
    back = quad([(0, s, 0), (s, s, 0), (s, s, s), (0, s, s)], w, name="BackWall")
    left = quad([(0, 0, 0), (0, s, 0), (0, s, s), (0, 0, s)], r, name="RedWall")
    right = quad([(s, 0, 0), (s, 0, s), (s, s, s), (s, s, 0)], g, name="GreenWall")
    h = 0.5 * light_size
    c = 0.5 * s
    zl = s - 1e-3 * s
    light = quad([(c - h, c - h, zl), (c - h, c + h, zl), (c + h, c + h, zl), (c + h, c - h, zl)],
                 (0.0, 0.0, 0.0), (light_radiance,) * 3, name="Light")
    short = box((0.27 * s, 0.17 * s, 0), (0.57 * s, 0.47 * s, 0.3 * s), w, bottom=False,
                rotate_z=np.radians(-17), name="ShortBlock")
    tall = box((0.53 * s, 0.5 * s, 0), (0.83 * s, 0.8 * s, 0.6 * s), w, bottom=False,
               rotate_z=np.radians(17), name="TallBlock")
    return [floor, ceiling, back, left, right, light, short, tall]


def tessellate(meshes, n, triangles=True) -> list:
    """The same scene modelled densely: every quad face cut into ``n`` x ``n`` quads (each split
    into two triangles with ``triangles``), sharing vertices inside a face as a modeller's mesh
    does; other faces are kept. Materials per face are carried over."""
    out = []
    for m in meshes:
        verts, faces, rho, em = [], [], [], []
        base = 0
        for f in range(len(m.face_offsets) - 1):
            idx = m.face_indices[m.face_offsets[f]:m.face_offsets[f + 1]]
            c = np.asarray(m.verts, float)[idx]
            if len(idx) != 4:
                verts.append(c)
                faces.append(list(range(base, base + len(idx))))
                rho.append(m.face_rho[f]), em.append(m.face_emission[f])
                base += len(idx)
                continue
            t = np.linspace(0.0, 1.0, n + 1)
            u, v = np.meshgrid(t, t, indexing="ij")
            u, v = u.ravel()[:, None], v.ravel()[:, None]
            verts.append((1 - u) * (1 - v) * c[0] + u * (1 - v) * c[1] + u * v * c[2] + (1 - u) * v * c[3])
            i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
            a = base + (i * (n + 1) + j).ravel()
            b, d = a + (n + 1), a + 1
            e = b + 1
            quads = np.stack([a, b, e, d], 1)
            if triangles:
                new = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]).tolist()
            else:
                new = quads.tolist()
            faces += new
            rho += [m.face_rho[f]] * len(new)
            em += [m.face_emission[f]] * len(new)
            base += (n + 1) ** 2
        out.append(MeshInput.from_faces(np.concatenate(verts), faces, np.array(rho), np.array(em), m.name))
    return out
