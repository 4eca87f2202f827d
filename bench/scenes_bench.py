"""Benchmark scenes: a coarse scene (what the user models) and a fixed fine evaluation mesh.

Each :class:`BenchScene` holds
* ``coarse``: the scene as modelled (few large faces, ``list[MeshInput]``); our candidates cut it
  into patches of a chosen size;
* ``fine``: the same surfaces pre-cut into about 4,000 faces, with hard edges (every original
  face is its own vertex island, so each vertex lies on one plane and has one normal). The
  reference (Cycles at high samples) and every candidate are compared at ``fine``'s vertices;
* ``world``: constant world radiance (3,) or None (black), ``lights``: core.light.lamps lamps (or ()).

Emitters are plain emissive faces: in Cycles (bench/speed_vs_error.build_blender_scene) a Diffuse
BSDF plus an Emission, which lights both faces, as an artist's file has them; our bakes use the
default two-sided emission. (Until issue 10 the Cycles emitters had a black back.)

Objects keep their order between ``coarse`` and ``fine`` so owner indices agree.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hemicube_radiosity.core import builtin_scenes as scenes
from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.mesh.subdivide import build_patches

__all__ = ["BenchScene", "cut_fine", "fine_points", "contact_vertices", "cornell", "furnished_room", "open_yard", "SCENES",
           "get_scene"]

WHITE = scenes.CORNELL_WHITE


@dataclass
class BenchScene:
    name: str
    title: str
    coarse: list
    fine: list
    fine_size: float            # patch size that cut ``coarse`` into ``fine``
    patch_sizes: tuple          # coarser candidate patch sizes for our bake (besides faces-as-patches)
    world: tuple | None = None
    lights: tuple = ()
    notes: list = field(default_factory=list)

    @property
    def n_fine_faces(self) -> int:
        return int(sum(len(m.face_offsets) - 1 for m in self.fine))


def cut_fine(coarse: list, size: float) -> list:
    """``coarse`` cut by :func:`build_patches` into patches of edge ``size``, returned as MeshInputs
    (one per object, same order and names) whose vertices are shared inside an original face only."""
    ps = build_patches(coarse, size)
    out = []
    for o, name in enumerate(ps.object_names):
        sel = np.flatnonzero(ps.owner == o)
        polys = ps.polys[sel]
        src = ps.source_face[sel]
        # vertex key = (source face, patch vertex): a vertex on an edge between two original
        # faces is duplicated (hard edge)
        valid = polys >= 0
        key = np.where(valid, src[:, None].astype(np.int64) * (len(ps.verts) + 1) + polys, -1)
        uniq, inv = np.unique(key[valid], return_inverse=True)
        new = np.full(polys.shape, -1, np.int64)
        new[valid] = inv
        vid = uniq % (len(ps.verts) + 1)
        verts = ps.verts[vid]
        offsets = np.zeros(len(polys) + 1, np.int64)
        offsets[1:] = np.cumsum(valid.sum(1))
        idx = new[valid]  # row-major: each row's valid corners in order
        out.append(MeshInput(verts, offsets, idx, ps.rho[sel].copy(), ps.emission[sel].copy(), name))
    return out


def fine_points(fine: list):
    """(points (P,3), owner (P,), normals (P,3), emitter (P,) bool) for every vertex of ``fine``."""
    pts, own, nrm, emit = [], [], [], []
    for o, m in enumerate(fine):
        V = len(m.verts)
        n = np.zeros((V, 3))
        e = np.zeros(V, bool)
        for f in range(len(m.face_offsets) - 1):
            ids = m.face_indices[m.face_offsets[f]:m.face_offsets[f + 1]]
            p = m.verts[ids]
            fn = np.cross(p[1] - p[0], p[2] - p[0])
            n[ids] += fn
            if m.face_rho[f].max() == 0 and m.face_emission[f].max() > 0:
                e[ids] = True
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
        pts.append(m.verts)
        own.append(np.full(V, o))
        nrm.append(n)
        emit.append(e)
    return np.concatenate(pts), np.concatenate(own), np.concatenate(nrm), np.concatenate(emit)


def contact_vertices(coarse: list, points, normals, tol=1e-6) -> np.ndarray:
    """(P,) bool: fine vertices on a contact line that crosses their own surface: the point lies
    inside one of its own object's ``coarse`` faces (away from that face's edges) and on another
    face that is not parallel to it (a wall standing on the ground, a block on a floor: the
    ground's vertex on the wall's foot). There the radiosity jumps from the open side's limit to
    the buried side's, so no value is right: Cycles' vertex bake gives about the mean of the two
    (0.18 at the yard house's foot, whose open side reads 0.37), ours the open side's limit.
    Corners where faces end (a wall meeting a wall, a block's bottom edge) are not contact lines:
    the light there is the limit along the face and stays compared. ``tol``: of the scene's
    size."""
    points = np.asarray(points, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    eps = tol * float(np.ptp(points, axis=0).max())
    own_interior = np.zeros(len(points), bool)
    on_other = np.zeros(len(points), bool)
    for m in coarse:
        for f in range(len(m.face_offsets) - 1):
            c = np.asarray(m.verts[m.face_indices[m.face_offsets[f]:m.face_offsets[f + 1]]], np.float64)
            n = np.cross(c[1] - c[0], c[2] - c[0])
            n /= np.linalg.norm(n)
            near = np.abs((points - c[0]) @ n) < eps
            if not near.any():
                continue
            # signed distance inside each edge (a convex face, either winding)
            e = np.roll(c, -1, axis=0) - c
            inward = np.cross(n, e)
            inward /= np.linalg.norm(inward, axis=1, keepdims=True)
            depth = \
                ((points[near][:, None, :] - c[None]) * inward[None]).sum(-1)
            inside = depth.min(axis=1)
            idx = np.flatnonzero(near)
            parallel = np.abs(normals[idx] @ n) > 0.999
            own = parallel & (inside > eps)
            own_interior[idx[own]] = True
            on_other[idx[~parallel & (inside > -eps)]] = True
    return own_interior & on_other


def _quad(corners, rho, emission=(0, 0, 0), name="quad"):
    return scenes.quad(corners, rho, emission, name)


def cornell() -> BenchScene:
    coarse = scenes.cornell_box()
    size = 0.08
    return BenchScene("cornell", "Cornell box (demo scene), 2 m, light 0.5 m square",
                      coarse, cut_fine(coarse, size), size, (0.16, 0.25, 0.4))


def furnished_room() -> BenchScene:
    """A closed 5 x 4 x 2.6 m room, furniture-like blocks, one small bright ceiling light
    (0.12 m square, radiance 600): the hard case for hemi-cubes (the light covers few pixels).
    The lamp hangs 0.3 m under the ceiling (a pendant) and lights it from its back (two-sided
    emitter). At 5 mm its back lit a 0.12 m spot on the ceiling about as bright as the lamp itself,
    which no path tracer samples well: even 4,096 spp of Cycles kept 16.6% RMS of fireflies, and
    no bake could be measured against that reference."""
    W, D, H = 5.0, 4.0, 2.6
    room = scenes.box((0, 0, 0), (W, D, H), WHITE, inward=True, name="Room",
                      per_face_rho={"x0": (0.6, 0.45, 0.3), "y1": (0.35, 0.45, 0.6)})
    table = scenes.box((1.6, 1.4, 0.7), (3.0, 2.3, 0.76), (0.55, 0.35, 0.2), bottom=True, name="TableTop")
    legs = [scenes.box((x, y, 0), (x + 0.06, y + 0.06, 0.7), (0.55, 0.35, 0.2), bottom=False, name=f"Leg{i}")
            for i, (x, y) in enumerate([(1.65, 1.45), (2.89, 1.45), (1.65, 2.19), (2.89, 2.19)])]
    cabinet = scenes.box((0.0 + 0.02, 3.4, 0), (1.2, 3.98, 1.9), (0.7, 0.7, 0.65), bottom=False, name="Cabinet")
    sofa = scenes.box((3.3, 0.1, 0), (4.9, 0.9, 0.45), (0.25, 0.3, 0.5), bottom=False, name="Sofa")
    sofa_back = scenes.box((3.3, 0.1, 0.45), (4.9, 0.3, 0.85), (0.25, 0.3, 0.5), bottom=True, name="SofaBack")
    shelf = scenes.box((4.6, 2.0, 1.2), (4.98, 3.2, 1.24), (0.7, 0.7, 0.7), bottom=True, name="Shelf",
                       rotate_z=0.0)
    h = 0.06
    cx, cy, z = 2.3, 1.85, H - 0.3
    light = _quad([(cx - h, cy - h, z), (cx - h, cy + h, z), (cx + h, cy + h, z), (cx + h, cy - h, z)],
                  (0, 0, 0), (600.0,) * 3, name="Lamp")
    coarse = [room, table, *legs, cabinet, sofa, sofa_back, shelf, light]
    size = 0.165
    return BenchScene("room", "Furnished room 5x4x2.6 m, small bright light (0.12 m, radiance 600)",
                      coarse, cut_fine(coarse, size), size, (0.25, 0.4, 0.6))


def open_yard() -> BenchScene:
    """A 10 x 10 m ground with a few buildings under a uniform sky (world radiance 1): light from
    the world only, ambient occlusion and inter-reflection between walls."""
    g = 5.0
    ground = _quad([(-g, -g, 0), (g, -g, 0), (g, g, 0), (-g, g, 0)], (0.5, 0.5, 0.5), name="Ground")
    house = scenes.box((-2.5, -1.0, 0), (0.0, 1.5, 2.5), (0.75, 0.6, 0.5), bottom=False, name="House")
    wall = scenes.box((0.8, -3.0, 0), (1.0, 2.5, 1.5), (0.7, 0.7, 0.7), bottom=False, name="Wall")
    tower = scenes.box((2.0, 0.5, 0), (3.0, 1.5, 3.5), (0.4, 0.55, 0.7), bottom=False, rotate_z=0.4,
                       name="Tower")
    block = scenes.box((-1.5, -3.5, 0), (0.0, -2.0, 0.8), (0.6, 0.3, 0.25), bottom=False, rotate_z=-0.3,
                       name="Block")
    coarse = [ground, house, wall, tower, block]
    size = 0.21
    return BenchScene("yard", "Open yard 10x10 m with four blocks, uniform sky (world radiance 1)",
                      coarse, cut_fine(coarse, size), size, (0.4, 0.6, 1.0), world=(1.0, 1.0, 1.0))


SCENES = {"cornell": cornell, "room": furnished_room, "yard": open_yard}


def get_scene(name: str) -> BenchScene:
    return SCENES[name]()


if __name__ == "__main__":
    for name, fn in SCENES.items():
        s = fn()
        nc = [len(build_patches(s.coarse, p)) for p in s.patch_sizes]
        print(f"{name}: {s.n_fine_faces} fine faces, {sum(len(m.verts) for m in s.fine)} vertices;"
              f" coarser patch counts {dict(zip(s.patch_sizes, nc))}")
