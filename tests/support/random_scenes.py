"""Seeded random scenes for whole bakes (tests/core/test_random_scenes.py): a room or an open
ground and props on and in it, built the ways Blender's reader hands meshes over.

Every mesh is a :class:`MeshInput` in world space. A grid face may be welded (smooth shading: one
vertex a place), split per face (flat shading: each face its own corners), or split along a
seam (a UV seam: the vertices of one row doubled); quads or triangles; plain or textured (a
reflectance per corner, ``corner_rho``, as the reader gives where a texture varies). Props: blocks
standing on the floor (their bottom left open) or sunk into it, closed boxes floating or resting
on it, boards a few millimetres thick, rugs coplanar with the floor and overlapping each other,
tiny and huge faces, convex and concave n-gons, sheets, spheres, small emissive quads; lamps
and a world. ``scene(seed)`` is the same scene for the same seed on every machine.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hemicube_radiosity.core.light.lamps import PointLight, SpotLight, SunLight
from hemicube_radiosity.core.mesh.patches import MeshInput

LAYOUTS = ("welded", "split", "seam")


@dataclass
class Scene:
    """``meshes`` and the ``lights`` and ``world`` to bake them with; ``parts`` names what was put
    in (for a failure's message). ``furnace``: (E, rho) when every surface emits E and reflects
    rho inside a closed room (every vertex is then E / (1 - rho)); ``bound``: the highest
    radiance any vertex may have when only emitting faces and the world light the scene
    (E_max / (1 - rho_max): B = E + rho F B with rows of F summing to at most 1), else None."""

    meshes: list
    lights: list = field(default_factory=list)
    world: np.ndarray | None = None
    parts: list = field(default_factory=list)
    furnace: tuple | None = None

    @property
    def bound(self):
        if self.lights:
            return None
        e = max(float(np.max(m.face_emission)) for m in self.meshes)
        if self.world is not None:
            e = max(e, float(np.max(self.world)))
        rho = max(float(np.max(m.face_rho if m.corner_rho is None else m.corner_rho)) for m in self.meshes)
        return e / (1 - rho)

    def __str__(self):
        faces = sum(len(m.face_offsets) - 1 for m in self.meshes)
        return f"{faces} faces: " + ", ".join(self.parts)


# ------------------------------------------------------------------------------------------
# meshes


def grid(origin, u, v, nu, nv, *, layout="welded", triangles=False, rho=(0.5,) * 3, emission=(0,) * 3,
         texture=None, rng=None, name="grid") -> MeshInput:
    """A parallelogram ``origin + s u + t v`` (s, t in [0, 1]) cut into nu x nv quads (each two
    triangles with ``triangles``), facing ``u x v``. ``layout``: 'welded', 'split' (every face its
    own corners) or 'seam' (welded, the vertices of one inner column doubled: the faces left of
    it use their own). ``texture``: None, 'checker' or 'noise' (a reflectance per corner: a
    checker of the position, or each corner its own), face_rho the mean of its corners."""
    o, u, v = (np.asarray(x, float) for x in (origin, u, v))
    s, t = np.meshgrid(np.linspace(0, 1, nu + 1), np.linspace(0, 1, nv + 1), indexing="ij")
    verts = o + s.reshape(-1, 1) * u + t.reshape(-1, 1) * v
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a = (i * (nv + 1) + j).ravel()
    quads = np.stack([a, a + nv + 1, a + nv + 2, a + 1], 1)          # counter-clockwise about u x v
    if layout == "seam" and nu >= 2:
        col = int(rng.integers(1, nu)) if rng is not None else nu // 2
        doubled = np.arange(col * (nv + 1), (col + 1) * (nv + 1))
        copy = np.full(len(verts), -1)
        copy[doubled] = len(verts) + np.arange(len(doubled))
        verts = np.concatenate([verts, verts[doubled]])
        left = i.ravel() < col
        q = quads[left]
        quads[left] = np.where(copy[q] >= 0, copy[q], q)
    faces = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]) if triangles else quads
    k = faces.shape[1]
    mesh = MeshInput.from_faces(verts, faces, rho, emission, name)
    if layout == "split":
        mesh = split_per_face(mesh)
    if texture is not None:
        mesh = textured(mesh, texture, rng)
    assert len(mesh.face_indices) == k * len(faces)
    return mesh


def textured(mesh: MeshInput, kind, rng) -> MeshInput:
    """``mesh`` with a reflectance per corner: 'checker' of the position (four squares across
    the mesh), or 'noise' (each corner its own); each face's rho the mean of its corners'."""
    pos = mesh.verts[mesh.face_indices]
    base = mesh.face_rho[np.repeat(np.arange(len(mesh.face_offsets) - 1), np.diff(mesh.face_offsets))]
    if kind == "checker":
        lo, span = pos.min(axis=0), np.maximum(np.ptp(pos, axis=0), 1e-300)
        cell = np.floor((pos - lo) / span * 4 - 1e-9).astype(int).sum(axis=1) % 2
        scale = np.where(cell[:, None] == 1, 1.0, 0.3) * np.array([1.0, 0.8, 0.6])
    else:
        scale = rng.uniform(0.0, 1.0, (len(pos), 3))
    corner = np.clip(base * scale / max(float(base.max()), 1e-9) * 0.9, 0, 0.95)
    face = np.repeat(np.arange(len(mesh.face_offsets) - 1), np.diff(mesh.face_offsets))
    n = np.bincount(face)[:, None]
    rho = np.stack([np.bincount(face, weights=corner[:, b]) for b in range(3)], 1) / n
    return MeshInput(mesh.verts, mesh.face_offsets, mesh.face_indices, rho, mesh.face_emission, mesh.name,
                     corner, mesh.corner_emission)


def split_per_face(mesh: MeshInput) -> MeshInput:
    """Every face its own corners (flat shading as Blender's reader gives it): the same faces,
    corner colours and materials."""
    verts = np.asarray(mesh.verts, float)[mesh.face_indices]
    return MeshInput(verts, mesh.face_offsets.copy(), np.arange(len(mesh.face_indices)), mesh.face_rho.copy(),
                     mesh.face_emission.copy(), mesh.name, mesh.corner_rho, mesh.corner_emission)


def merge(meshes, name) -> MeshInput:
    """One object of several meshes' faces (their vertices kept apart: hard edges)."""
    verts, offsets, idx, base, start = [], [np.zeros(1, np.int64)], [], 0, 0
    for m in meshes:
        verts.append(m.verts)
        idx.append(m.face_indices + base)
        offsets.append(m.face_offsets[1:] + start)
        base += len(m.verts)
        start += len(m.face_indices)
    corner = None
    if any(m.corner_rho is not None for m in meshes):
        corner = np.concatenate([m.corner_rho if m.corner_rho is not None else
                                 np.repeat(m.face_rho, np.diff(m.face_offsets), axis=0) for m in meshes])
    return MeshInput(np.concatenate(verts), np.concatenate(offsets), np.concatenate(idx),
                     np.concatenate([m.face_rho for m in meshes]), np.concatenate([m.face_emission for m in meshes]),
                     name, corner)


def box_sides(lo, hi, *, bottom=True, inward=False, rotate=0.0, n=1, layout="welded", triangles=False,
              rho=(0.5,) * 3, emission=(0,) * 3, texture=None, rng=None, name="box") -> MeshInput:
    """An axis-aligned box (turned ``rotate`` radians about its vertical axis) of six grids of n x n
    (five without the bottom), facing out (in with ``inward``): one object, its sides apart."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    d = hi - lo
    X, Y, Z = np.diag(d)
    sides = [(lo, Y, X), (lo + [0, 0, d[2]], X, Y), (lo, X, Z), (lo + [0, d[1], 0], Z, X),
             (lo, Z, Y), (lo + [d[0], 0, 0], Y, Z)]
    if not bottom:
        sides = sides[1:]
    parts = []
    for o, u, v in sides:
        if inward:
            u, v = v, u
        parts.append(grid(o, u, v, n, n, layout=layout, triangles=triangles, rho=rho, emission=emission,
                          texture=texture, rng=rng))
    m = merge(parts, name)
    if rotate:
        c = 0.5 * (lo + hi)
        ca, sa = np.cos(rotate), np.sin(rotate)
        r = m.verts - c
        m.verts = c + np.stack([ca * r[:, 0] - sa * r[:, 1], sa * r[:, 0] + ca * r[:, 1], r[:, 2]], 1)
    return m


def ngon(centre, radius, k, normal_up=True, concave=False, rho=(0.5,) * 3, name="ngon") -> MeshInput:
    """One horizontal face of k corners (a star of 2k corners when ``concave``), facing up or down."""
    centre = np.asarray(centre, float)
    if concave:
        a = np.linspace(0, 2 * np.pi, 2 * k, endpoint=False)
        r = np.where(np.arange(2 * k) % 2 == 0, radius, 0.45 * radius)
    else:
        a = np.linspace(0, 2 * np.pi, k, endpoint=False)
        r = np.full(k, radius)
    verts = centre + np.stack([r * np.cos(a), r * np.sin(a), np.zeros_like(a)], 1)
    face = list(range(len(verts)))
    return MeshInput.from_faces(verts, [face if normal_up else face[::-1]], rho, name=name)


def sphere(centre, radius, n, rho=(0.5,) * 3, name="sphere") -> MeshInput:
    """A welded UV sphere, n segments around, n // 2 rings (fans at the poles), facing out."""
    nv = max(n // 2, 3)
    th = np.linspace(0, np.pi, nv + 1)[1:-1]
    ph = np.linspace(0, 2 * np.pi, n, endpoint=False)
    t, f = np.meshgrid(th, ph, indexing="ij")
    v = np.stack([np.sin(t) * np.cos(f), np.sin(t) * np.sin(f), np.cos(t)], -1).reshape(-1, 3)
    v = np.vstack([v, [(0, 0, 1), (0, 0, -1)]]) * radius + np.asarray(centre, float)
    top, bot = len(v) - 2, len(v) - 1
    idx = lambda i, j: i * n + j % n
    faces = [[idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)] for i in range(nv - 2) for j in range(n)]
    faces += [[top, idx(0, j), idx(0, j + 1)] for j in range(n)]
    faces += [[bot, idx(nv - 2, j + 1), idx(nv - 2, j)] for j in range(n)]
    return MeshInput.from_faces(v, faces, rho, name=name)


# ------------------------------------------------------------------------------------------
# scenes


def _density(rng, most=12):
    """Faces per side, 1..120: mostly a few, now and then a dense grid."""
    return int(rng.integers(1, most + 1)) if rng.random() < 0.8 else int(rng.integers(most, 121))


def _look(rng):
    """Layout, triangles, texture: a random way the reader may hand a surface over."""
    return dict(layout=str(rng.choice(LAYOUTS)), triangles=bool(rng.random() < 0.3),
                texture=None if rng.random() < 0.6 else str(rng.choice(["checker", "noise"])))


def _rho(rng):
    return tuple(rng.uniform(0.05, 0.9, 3))


def _named(m, name, parts, what):
    m.name = name
    parts.append(what)
    return m


def scene(seed, budget=6000) -> Scene:
    """The random scene of ``seed``: a closed room (walls of random grids, a lamp panel or
    emitters) or an open ground under the world or lamps, and 0..6 props. About ``budget`` faces
    at most (dense grids are capped so a sweep stays quick)."""
    rng = np.random.default_rng(seed)
    s = float(np.exp(rng.uniform(np.log(0.05), np.log(20.0))))       # the scene's size, metres
    meshes, parts, lights, world = [], [], [], None
    faces = [0]

    def add(m, what):
        faces[0] += len(m.face_offsets) - 1
        meshes.append(_named(m, f"{what}{len(meshes)}", parts, what))

    def n_for(sides=1, most=12):
        n = _density(rng, most)
        left = max(budget - faces[0], 0) // max(sides, 1)
        return int(max(1, min(n, int(np.sqrt(max(left, 1)) / 1.5))))

    W, D, H = s * rng.uniform(0.6, 1.6, 3)
    room = rng.random() < 0.5
    if room:
        look = _look(rng)
        n = n_for(6)
        if rng.random() < 0.5:     # one object of six grids
            add(box_sides((0, 0, 0), (W, D, H), inward=True, n=n, rho=_rho(rng), rng=rng, **look),
                f"room {n}x{n} {look['layout']}{' tri' if look['triangles'] else ''}"
                f"{' ' + look['texture'] if look['texture'] else ''}")
        else:                       # the floor its own grid, the rest plain walls
            add(grid((0, 0, 0), (W, 0, 0), (0, D, 0), n, n, rho=_rho(rng), rng=rng, **look),
                f"floor {n}x{n} {look['layout']}{' tri' if look['triangles'] else ''}"
                f"{' ' + look['texture'] if look['texture'] else ''}")
            walls = box_sides((0, 0, 0), (W, D, H), inward=True, bottom=False, rho=_rho(rng), rng=rng)
            add(walls, "walls")
    else:
        big = float(rng.choice([1.0, 1.0, 10.0, 300.0]))            # now and then a huge ground
        look = _look(rng)
        n = n_for(1, most=30)
        x0, y0 = -big * W, -big * D
        add(grid((x0, y0, 0), (W * (1 + 2 * big), 0, 0), (0, D * (1 + 2 * big), 0), n, n, rho=_rho(rng),
                 rng=rng, **look),
            f"ground x{big:g} {n}x{n} {look['layout']}{' tri' if look['triangles'] else ''}"
            f"{' ' + look['texture'] if look['texture'] else ''}")
    for _ in range(int(rng.integers(0, 7))):
        _prop(rng, s, W, D, H, add, n_for)
    # light: emitting quads, lamps, the world (at least one of them)
    if rng.random() < 0.6 or room and not any(p.startswith("emitter") for p in parts):
        for _ in range(int(rng.integers(1, 3))):
            e = rng.uniform(0.05, 0.2) * s
            c = (rng.uniform(e, W - e), rng.uniform(e, D - e), H * rng.uniform(0.7, 0.995))
            q = grid(np.add(c, (-e / 2, -e / 2, 0)), (0, e, 0), (e, 0, 0), 1, 1, rho=(0,) * 3,
                     emission=(rng.uniform(1, 20),) * 3)
            add(q, "emitter")
    if rng.random() < 0.35:
        kind = rng.integers(3)
        p = (rng.uniform(0, W), rng.uniform(0, D), H * rng.uniform(0.3, 0.95))
        if kind == 0:
            lights.append(PointLight(p, power_w=float(rng.uniform(10, 500)) * s * s,
                                     radius=float(rng.choice([0.0, 0.05 * s]))))
        elif kind == 1:
            lights.append(SpotLight(p, (rng.normal(), rng.normal(), -2.0), power_w=float(rng.uniform(10, 500)) * s * s,
                                    spot_size=float(rng.uniform(0.3, 2.5)), spot_blend=float(rng.uniform(0, 1))))
        else:
            lights.append(SunLight((rng.normal(), rng.normal(), -1.5), strength=float(rng.uniform(0.5, 5)),
                                   angle=float(rng.choice([0.0, 0.05]))))
        parts.append(type(lights[-1]).__name__)
    if not room and (rng.random() < 0.5 or not lights and not any(p == "emitter" for p in parts)):
        world = np.array(rng.uniform(0.2, 1.5, 3))
        parts.append("world")
    return Scene(meshes, lights, world, parts)


PROPS = ("block", "sunk", "closed", "resting", "thin", "rug", "tiny", "ngon", "sheet", "sphere")


def _prop(rng, s, W, D, H, add, n_for):
    kind = str(rng.choice(PROPS))
    look = _look(rng)
    x0, y0 = rng.uniform(0, W * 0.7), rng.uniform(0, D * 0.7)
    w, d, h = s * rng.uniform(0.1, 0.4, 3)
    rot = float(rng.choice([0.0, rng.uniform(0, np.pi)]))
    tag = f"{look['layout']}{' tri' if look['triangles'] else ''}{' ' + look['texture'] if look['texture'] else ''}"
    if kind in ("block", "sunk", "closed", "resting", "thin"):
        n = n_for(6)
        z0 = {"block": 0.0, "sunk": -0.3 * h, "closed": rng.uniform(0.1, 0.5) * H, "resting": 0.0,
              "thin": float(rng.choice([0.0, 0.4 * H]))}[kind]
        if kind == "thin":
            h = float(rng.uniform(0.002, 0.005))                      # a board a few millimetres thick
        add(box_sides((x0, y0, z0), (x0 + w, y0 + d, z0 + h), bottom=kind not in ("block", "sunk"), rotate=rot,
                      n=n, rho=_rho(rng), rng=rng, **look), f"{kind} {n}x{n} {tag}")
    elif kind == "rug":                                               # coplanar with the floor
        n = n_for(1)
        add(grid((x0, y0, 0), (w * 2, 0, 0), (0, d * 2, 0), n, n, rho=_rho(rng), rng=rng, **look),
            f"rug {n}x{n} {tag}")
    elif kind == "tiny":
        e = s * float(rng.choice([1e-4, 1e-3, 1e-2]))
        add(grid((x0, y0, rng.uniform(0, H)), (e, 0, 0), (0, e, float(rng.choice([0, e]))), 1, 1, rho=_rho(rng),
                 **{**look, "layout": "welded"}, rng=rng), f"tiny {e:.1e}")
    elif kind == "ngon":
        k = int(rng.integers(5, 13))
        concave = bool(rng.random() < 0.4)
        add(ngon((x0 + w, y0 + d, rng.uniform(0.05, 0.9) * H), min(w, d), k, normal_up=bool(rng.random() < 0.5),
                 concave=concave, rho=_rho(rng)), f"{'concave ' if concave else ''}{k}-gon")
    elif kind == "sheet":                                             # open, one-sided, at an angle
        n = n_for(1)
        z = rng.uniform(0.1, 0.8) * H
        add(grid((x0, y0, z), (w, 0, rng.uniform(-0.5, 0.5) * h), (0, d, rng.uniform(-0.5, 0.5) * h), n, n,
                 rho=_rho(rng), rng=rng, **look), f"sheet {n}x{n} {tag}")
    else:
        n = max(n_for(1, most=24), 6)
        r = 0.5 * min(w, d, h)
        add(sphere((x0 + r, y0 + r, rng.uniform(r, H - r) if H > 2 * r else r), r, n, rho=_rho(rng)),
            f"sphere {n}")


def furnace_scene(seed, budget=300) -> Scene:
    """A closed room and closed boxes floating in it, every surface emitting E and reflecting
    rho (grids of random density, welded, split or seamed, textured with that same rho at every
    corner or not): every vertex is E / (1 - rho)."""
    rng = np.random.default_rng(seed)
    s = float(np.exp(rng.uniform(np.log(0.1), np.log(10.0))))
    rho, E = float(rng.uniform(0.2, 0.8)), float(rng.uniform(0.5, 2.0))
    W, D, H = s * rng.uniform(0.7, 1.5, 3)
    parts, meshes = [], []

    def look():
        lk = _look(rng)
        if lk["texture"]:
            lk["texture"] = "uniform"
        return lk

    def add(m, what, lk):
        if lk["texture"]:
            m.corner_rho = np.full((len(m.face_indices), 3), rho)
        meshes.append(_named(m, f"{what}{len(meshes)}", parts,
                             f"{what} {lk['layout']}{' tri' if lk['triangles'] else ''}{' tex' if lk['texture'] else ''}"))

    lk = look()
    n = min(_density(rng), int(np.sqrt(budget / 6)))
    add(box_sides((0, 0, 0), (W, D, H), inward=True, n=n, rho=(rho,) * 3, emission=(E,) * 3,
                  **{**lk, "texture": None}, rng=rng), f"room {n}x{n}", lk)
    taken = []
    for _ in range(int(rng.integers(0, 3))):
        lk = look()
        w, d, h = s * rng.uniform(0.1, 0.3, 3)
        if rng.random() < 0.3:
            h = 0.004                                                 # thin
        r = 0.5 * np.hypot(w, d) + 0.01 * s                           # inside the room however turned
        cx, cy = rng.uniform(r, W - r), rng.uniform(r, D - r)
        x, y, z = cx - w / 2, cy - d / 2, rng.uniform(0.02, 0.95) * (H - h)
        here = np.array([cx - r, cy - r, z - 0.01 * s, cx + r, cy + r, z + h + 0.01 * s])
        if any(np.all(here[:3] < o[3:]) and np.all(o[:3] < here[3:]) for o in taken):
            continue                          # not through another box: its inside sees no room
        taken.append(here)
        n = min(_density(rng, 6), int(np.sqrt(budget / 24)))
        add(box_sides((x, y, z), (x + w, y + d, z + h), n=n, rho=(rho,) * 3, emission=(E,) * 3,
                      rotate=float(rng.uniform(0, 1)), **{**lk, "texture": None}, rng=rng), f"box {n}x{n}", lk)
    return Scene(meshes, parts=parts, furnace=(E, rho))


def random_settings(seed, meshes):
    """Random bake settings for ``seed``: sizes against the scene's diagonal ('auto', one patch per
    face, or a fraction), grouping on or off, the hemi-cube at a few resolutions, either direct
    path, every solver, fewer or more rays; the bench's speed is no concern here."""
    from hemicube_radiosity.core.pipeline import BakeSettings

    rng = np.random.default_rng([seed, 7])
    lo = np.min([m.verts.min(axis=0) for m in meshes], axis=0)
    hi = np.max([m.verts.max(axis=0) for m in meshes], axis=0)
    diag = float(np.linalg.norm(hi - lo))
    patch = rng.choice(["auto", "face", "size"], p=[0.3, 0.1, 0.6])
    patch = "auto" if patch == "auto" else 0.0 if patch == "face" else diag / float(rng.uniform(3, 16))
    element = rng.choice(["auto", "none", "size"])
    element = "auto" if element == "auto" else None if element == "none" else diag / float(rng.uniform(8, 50))
    pick = lambda *xs: xs[int(rng.integers(len(xs)))]
    direct = pick("exact", "exact", "hemicube")
    if direct == "hemicube":
        element = None                     # (finer output elements need the exact direct light)
    return BakeSettings(
        patch_size=patch, element_size=element, group_faces=bool(rng.random() < 0.7),
        group_angle=float(rng.uniform(1, 90)), refine_levels=int(rng.integers(0, 4)), method="hemicube",
        resolution=pick(8, 16, 32, 48), direct=direct,
        two_sided_emission=bool(rng.random() < 0.7), patch_light_points=int(rng.integers(1, 4)),
        direct_samples=pick(4, 16), light_samples=pick(1, 16), sky_rays=pick(16, 256),
        gather_rays=pick(0, 32, 128), solver=pick("gauss_seidel", "jacobi", "progressive"),
        output_pass=pick("radiosity", "radiosity", "lighting"), output_mode=pick("copy", "copy", "in_place"),
        estimate_error=bool(rng.random() < 0.1), workers=pick(0, 1, 2), max_iterations=1000)
