# SPDX-License-Identifier: GPL-3.0-or-later
"""The scenes the Cycles comparisons build and the harness that compares them: each case makes a
small scene in bpy, bakes it with Cycles (``tools/cycles_reference.py``: COMBINED = E + rho H / pi
at every face corner) and with our pipeline (meshes through the add-on's reader, lamps and world
through ``blender.read.lights.read_lights``, one patch per face), and ``Comparison`` holds the two
at the same face corners. Used by ``tests/blender/test_lighting_cycles.py`` and the other Cycles
tests, and by ``tools/lighting_pictures.py`` (the same scenes rendered). Needs bpy."""
from __future__ import annotations

import math
import time

import bpy
import numpy as np

from hemicube_radiosity.blender.read import scene as reader
from hemicube_radiosity.blender.read.lights import read_lights
from hemicube_radiosity.core.pipeline import BakeSettings, bake
from tools import cycles_reference as cr

RHO = 0.8
SETTINGS = dict(patch_size=None, resolution=64, method="hemicube", element_size=None,  # faces = patches = output
                light_samples=64, light_seed=1)


# ----------------------------------------------------------------------------- a textured floor
FLOOR_SUN, FLOOR_SKY = 2.0, (0.3, 0.35, 0.4)


def _pattern():
    """An 8-bit sRGB image, as a texture file is (Cycles reads it as linear colour, the glTF
    exporter writes its bytes): red along u, green in stripes along v, blue a bump (a shifted UV
    shows; the stripes are detail between the floor's corners)."""
    n = 64
    img = bpy.data.images.new("pattern", n, n)
    y, x = (np.mgrid[0:n, 0:n] + 0.5) / n
    px = np.stack([0.1 + 0.8 * x, 0.1 + 0.8 * np.sin(3 * np.pi * y) ** 2,
                   0.2 + 0.6 * np.exp(-8 * ((x - 0.4) ** 2 + (y - 0.6) ** 2)), np.ones_like(x)], -1)
    img.pixels.foreach_set(px.astype(np.float32).ravel())
    img.pack()
    return img


def textured_floor(cuts=1):
    """A 2 x 2 m floor (``cuts`` x ``cuts`` quads, UVs over [0, 1]^2) whose default Principled
    BSDF takes its Base Color from an image through its UVs, under a sun of angle 0 (2 W/m^2) and
    a uniform world: deterministic light (``tests/blender/test_textured_copies.py``,
    ``test_viewer.py``)."""
    cr.new_empty_scene()
    m = bpy.data.materials.new("Floor")
    nt, out = cr.bare_node_tree(m)
    p = nt.nodes.new("ShaderNodeBsdfPrincipled")
    nt.links.new(p.outputs[0], out.inputs["Surface"])
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image, tex.extension = _pattern(), "EXTEND"
    nt.links.new(tex.outputs["Color"], p.inputs["Base Color"])
    v, f = cr.grid_arrays(cuts, cuts, -1.0, 1.0, -1.0, 1.0)
    ob = cr.mesh_object(v, f, m, "floor")
    me = ob.data
    lv = np.empty(len(me.loops), np.int64)
    me.loops.foreach_get("vertex_index", lv)
    uv = me.uv_layers.get("UVMap") or me.uv_layers.new(name="UVMap")
    uv.data.foreach_set("uv", ((v[lv, :2] + 1.0) / 2.0).astype(np.float32).ravel())
    cr.add_light("SUN", (0, 0, 3), (0.4, 0.2, 0.0), energy=FLOOR_SUN, angle=0.0)
    cr.set_world(FLOOR_SKY, 1.0)
    return ob



# ----------------------------------------------------------------------------- harness
class Comparison:
    """Cycles and our radiance at every face corner of the baked objects."""

    def __init__(self, objects, samples, bounces=32, mode="COMBINED", glossy=0, settings=None,
                 filter_glossy=None):
        self.objects = objects
        ref = cr.bake_vertex_radiance(objects, samples=samples, bounces=bounces, mode=mode, glossy=glossy,
                                      filter_glossy=filter_glossy)
        self.cycles_seconds = ref.seconds
        dg = bpy.context.evaluated_depsgraph_get()
        scene_input = reader.read_scene(dg, objects)
        lights, world, notes = read_lights(dg)
        self.lights, self.world, self.notes = lights, world, notes
        self.meshes = scene_input.meshes
        t = time.perf_counter()
        output = {"COMBINED": "radiosity", "LIGHTING": "lighting"}[mode]
        res = bake(scene_input.meshes, BakeSettings(**{**SETTINGS, **(settings or {})}, output_pass=output),
                   lights=lights, world=world)
        self.our_seconds = time.perf_counter() - t
        self.result = res
        P = res.patches
        E = res.elements          # the patches, or the same faces with each side its own vertices
        assert len(E) == len(P) and np.array_equal(E.source_face, P.source_face) and \
            np.array_equal(E.owner, P.owner), "cases bake one patch per face, output at its corners"
        ours, theirs, pos, nrm, owner, loop_ids = [], [], [], [], [], []
        for k, ob in enumerate(objects):
            me = ob.data
            M = np.array(ob.matrix_world)
            co = np.empty(len(me.vertices) * 3)
            me.vertices.foreach_get("co", co)
            co = co.reshape(-1, 3) @ M[:3, :3].T + M[:3, 3]
            lv = np.empty(len(me.loops), np.int64)
            me.loops.foreach_get("vertex_index", lv)
            ls = np.empty(len(me.polygons), np.int64)
            me.polygons.foreach_get("loop_start", ls)
            lt = np.empty(len(me.polygons), np.int64)
            me.polygons.foreach_get("loop_total", lt)
            assert np.all(lt == 4), "cases use quads only (one patch per face)"
            mine = np.flatnonzero(P.owner == k)
            assert mine.size == len(me.polygons)
            face_loops = ls[P.source_face[mine]][:, None] + np.arange(4)[None, :]   # (F, 4)
            loop_pos = co[lv[face_loops]]                                          # (F, 4, 3)
            patch_pos = P.verts[P.polys[mine]]                                     # (F, 4, 3)
            # which loop of the source face sits at each patch corner
            d = np.linalg.norm(patch_pos[:, :, None, :] - loop_pos[:, None, :, :], axis=-1)
            j = d.argmin(axis=2)
            assert np.all(d.min(axis=2) < 1e-5), "patch corners are the mesh corners"
            loops = np.take_along_axis(face_loops, j, axis=1)
            ours.append(res.corner_values()[mine].reshape(-1, 3))   # what the writer writes there
            theirs.append(ref.corner[ob.name][loops.reshape(-1)])
            pos.append(patch_pos.reshape(-1, 3))
            nrm.append(np.repeat(P.normals[mine], 4, axis=0))
            owner.append(np.full(mine.size * 4, k))
            loop_ids.append(loops.reshape(-1))
        self.ours = np.concatenate(ours)
        self.cycles = np.concatenate(theirs)
        self.pos = np.concatenate(pos)
        self.normal = np.concatenate(nrm)
        self.owner = np.concatenate(owner)
        self.loop = np.concatenate(loop_ids)      # mesh loop (corner) of each compared corner

    def error(self, mask=None):
        """Mean relative error (luminance-like mean of the bands) over ``mask``."""
        m = np.ones(len(self.pos), bool) if mask is None else mask
        a, b = self.ours[m].mean(axis=1), self.cycles[m].mean(axis=1)
        return float(np.mean(np.abs(a - b) / b))

    def at(self, p, owner=0):
        """(ours, cycles) band means at the corner nearest to ``p`` on object ``owner``."""
        idx = np.flatnonzero(self.owner == owner)
        i = idx[np.argmin(np.linalg.norm(self.pos[idx] - np.asarray(p), axis=1))]
        return self.ours[i].mean(), self.cycles[i].mean()


def lamps_at_corners(c):
    """rho H / pi of the lamps read by read_lights, evaluated by core.light.lamps at every compared
    corner itself (no patches, no shadows): the unit mapping alone, free of discretisation."""
    from hemicube_radiosity.core.light.lamps import direct_irradiance
    from hemicube_radiosity.core.mesh.patches import PatchSet

    n = len(c.pos)
    pts = PatchSet(c.pos, np.tile([0, 1, 2, -1], (n, 1)), c.pos, c.normal, np.ones(n),
                   np.full((n, 3), RHO), np.zeros((n, 3)), np.zeros(n, np.int32), np.zeros(n, np.int32))
    return RHO * direct_irradiance(pts, c.lights, shadows="none", samples=256) / math.pi


def floor_object(n, half, rho=RHO, name="floor", z=0.0):
    v, f = cr.grid_arrays(n, n, -half, half, -half, half, z)
    return cr.mesh_object(v, f, cr.diffuse_material((rho,) * 3), name)


def box_arrays(lo, hi, n, inward=False, top=True, bottom=False):
    """Quads of an axis-aligned box, each side an n x n grid (vertices shared within a side)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    verts, faces = [], []
    u = np.linspace(0, 1, n + 1)
    U, V = np.meshgrid(u, u, indexing="xy")
    sides = []
    for axis in range(3):
        for side in (0, 1):
            if axis == 2 and side == 1 and not top:
                continue
            if axis == 2 and side == 0 and not bottom:
                continue
            sides.append((axis, side))
    for axis, side in sides:
        a1, a2 = (axis + 1) % 3, (axis + 2) % 3
        p = np.zeros((U.size, 3))
        p[:, axis] = hi[axis] if side else lo[axis]
        p[:, a1] = lo[a1] + U.ravel() * (hi[a1] - lo[a1])
        p[:, a2] = lo[a2] + V.ravel() * (hi[a2] - lo[a2])
        idx = len(verts and np.concatenate(verts)) + np.arange(U.size).reshape(n + 1, n + 1)
        q = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], -1).reshape(-1, 4)
        # (a1, a2, axis) is right-handed: this winding faces +axis; flip for the low side
        outward_low = side == 0
        if outward_low != inward:
            q = q[:, ::-1]
        verts.append(p)
        faces.append(q)
    return np.concatenate(verts), np.concatenate(faces)


def report(name, c, mask):
    print(f"{name:>10}: mean rel err {100 * c.error(mask):5.2f}% over {int(mask.sum())}/{mask.size} "
          f"corners (all: {100 * c.error():5.2f}%); Cycles {c.cycles_seconds:.2f} s, "
          f"ours {c.our_seconds:.2f} s")


# ----------------------------------------------------------------------------- cases
def case_point():
    cr.new_empty_scene()
    fl = floor_object(16, 2.0)
    cr.add_light("POINT", (0.0, 0.0, 1.0), energy=100.0, shadow_soft_size=0.0)
    c = Comparison([fl], samples=16)
    mask = np.ones(len(c.pos), bool)
    return c, mask


SPOT_H, SPOT_SIZE, SPOT_BLEND, SPOT_P = 1.5, math.radians(70), 0.3, 200.0


def case_spot():
    cr.new_empty_scene()
    fl = floor_object(20, 2.0)
    cr.add_light("SPOT", (0.0, 0.0, SPOT_H), energy=SPOT_P, shadow_soft_size=0.0, spot_size=SPOT_SIZE,
                 spot_blend=SPOT_BLEND)
    c = Comparison([fl], samples=16)
    r = np.linalg.norm(c.pos[:, :2], axis=1)
    ch = math.cos(SPOT_SIZE / 2)
    inner = math.acos(ch + (1 - ch) * SPOT_BLEND)    # the blend ramps from here to size / 2
    r_in, r_out = SPOT_H * math.tan(inner), SPOT_H * math.tan(SPOT_SIZE / 2)
    patch = 0.2                                       # floor face size
    ramp = (r > r_in - patch) & (r < r_out + patch)   # the cone's soft edge, one face either side
    return c, r, ramp, (r_in, r_out)


BOX_LO, BOX_HI = (-0.5, -1.5, 0.0), (0.5, -0.5, 1.0)
SUN_ELEVATION = math.radians(30)


def case_sun():
    cr.new_empty_scene()
    fl = floor_object(16, 2.0)
    v, f = box_arrays(BOX_LO, BOX_HI, 4)     # walls on floor grid lines: no floor patch under them
    bx = cr.mesh_object(v, f, cr.diffuse_material((RHO,) * 3), "box")
    # a sunlit wall at the far edge bounces light into the shadow (else the shadow is ~black
    # and only Cycles' noise would be compared there)
    v, f = cr.grid_arrays(16, 8, -2.0, 2.0, 0.0, 2.0)
    v = np.stack([v[:, 0], np.full(len(v), 2.0), v[:, 1]], 1)       # plane y = 2, facing -y
    wall = cr.mesh_object(v, f, cr.diffuse_material((RHO,) * 3), "wall")
    zen = math.pi / 2 - SUN_ELEVATION
    # the sun shines along the object's -Z: tilted about X by the zenith angle it comes from -y
    # and throws the box's shadow 1 / tan(30 deg) = 1.73 box heights toward +y
    cr.add_light("SUN", (0, 0, 5), (zen, 0, 0), energy=3.0, angle=0.0)
    c = Comparison([fl, bx, wall], samples=1024)
    to_sun = np.array([0.0, -math.sin(zen), math.cos(zen)])
    return c, to_sun


def shadowed(points, to_sun, lo, hi):
    """Ray from each point toward the sun hits the box [lo, hi] (slab test)."""
    d = np.where(np.abs(to_sun) < 1e-12, 1e-12, to_sun)
    t0 = (np.asarray(lo) - points) / d
    t1 = (np.asarray(hi) - points) / d
    tmin = np.minimum(t0, t1).max(axis=1)
    tmax = np.maximum(t0, t1).min(axis=1)
    return (tmax > np.maximum(tmin, 1e-9))


def case_area():
    cr.new_empty_scene()
    fl = floor_object(16, 2.0)
    cr.add_light("AREA", (0.25, 0.0, 1.2), energy=150.0, size=1.0, size_y=0.5, shape="RECTANGLE")
    c = Comparison([fl], samples=64)
    return c, np.ones(len(c.pos), bool)


def case_world():
    cr.new_empty_scene()
    v, f = box_arrays((-1, -1, 0), (1, 1, 1), 8, inward=True, top=False, bottom=True)
    bx = cr.mesh_object(v, f, cr.diffuse_material((RHO,) * 3), "openbox")
    cr.set_world((0.6, 0.7, 1.0), 1.5)
    c = Comparison([bx], samples=1024)
    return c


def case_emitter():
    cr.new_empty_scene()
    fl = floor_object(16, 2.0)
    v, f = cr.grid_arrays(2, 2, -0.5, 0.5, -0.5, 0.5, 1.0)
    lamp = cr.mesh_object(v, f[:, ::-1], cr.diffuse_material((0.0,) * 3, emission=5.0), "lamp")
    c = Comparison([fl, lamp], samples=64)
    return c


def face_corner_values(result, k, me):
    """(L, 3) ``result``'s value at every face corner of mesh ``me`` (object ``k`` of the bake),
    in its loop order (Cycles'), where the output is the faces themselves: a corner takes its
    face's element's value at the element vertex nearest it."""
    E = result.elements
    cv = result.corner_values()
    co = np.array([v.co[:] for v in me.vertices])
    mine = np.flatnonzero(E.owner == k)
    by_face = dict(zip(E.source_face[mine], mine))
    out = []
    for p in me.polygons:
        e = by_face[p.index]
        ids = E.polys[e][E.polys[e] >= 0]
        for vi in p.vertices:
            out.append(cv[e, int(np.argmin(np.linalg.norm(E.verts[ids] - co[vi], axis=1)))])
    return np.array(out)


def environment_world(pixels, name):
    """A world whose Background's colour is an Environment Texture of ``pixels`` (H, W, 3)
    float32 (a new float image), made the scene's. Returns (world, its node tree, the texture
    node)."""
    H, W = pixels.shape[:2]
    img = bpy.data.images.new(name + ".hdr", W, H, float_buffer=True)
    img.pixels.foreach_set(np.concatenate([pixels, np.ones((H, W, 1), np.float32)], axis=2).ravel())
    w = bpy.data.worlds.new(name)
    nt = cr.node_tree(w)
    bg = next(n for n in nt.nodes if n.type == "BACKGROUND")
    tex = nt.nodes.new("ShaderNodeTexEnvironment")
    tex.image = img
    nt.links.new(tex.outputs["Color"], bg.inputs["Color"])
    bpy.context.scene.world = w
    return w, nt, tex
