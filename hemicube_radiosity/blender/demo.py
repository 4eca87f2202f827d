# SPDX-License-Identifier: GPL-3.0-or-later
"""The demo: the core's Cornell box (``core.builtin_scenes.cornell_box``) as Blender objects, and a preview
render of the baked colours with Cycles on the CPU.

The objects get ordinary Principled BSDF materials (Base Color = reflectivity, Emission Color x
Strength = emission), so the bake reads them back through the same material path as any scene.
"""
from __future__ import annotations

import math

import bpy
import numpy as np

from ..core.builtin_scenes import cornell_box

__all__ = ["object_from_mesh_input", "build_cornell_box", "add_preview_camera", "render_preview"]


def _material(rho, emission):
    rho = tuple(round(float(x), 4) for x in rho)
    em = tuple(round(float(x), 4) for x in emission)
    name = f"Radiosity Demo {rho} {em}"
    mat = bpy.data.materials.get(name)
    if mat is not None:
        return mat
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0) or mat.node_tree is None:
        mat.use_nodes = True  # Blender < 5
    bsdf = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (*rho, 1.0)
    strength = max(em)
    if strength > 0:
        bsdf.inputs["Emission Color"].default_value = (*(e / strength for e in em), 1.0)
        bsdf.inputs["Emission Strength"].default_value = strength
    mat.diffuse_color = (*rho, 1.0)
    return mat


def object_from_mesh_input(m, collection):
    """A mesh object whose faces, vertices and per-face materials are those of MeshInput ``m``."""
    me = bpy.data.meshes.new(m.name)
    verts = np.asarray(m.verts, np.float64)
    off = np.asarray(m.face_offsets)
    me.vertices.add(len(verts))
    me.vertices.foreach_set("co", verts.astype(np.float32).ravel())
    me.loops.add(int(off[-1]))
    me.loops.foreach_set("vertex_index", np.asarray(m.face_indices, np.int32))
    me.polygons.add(len(off) - 1)
    me.polygons.foreach_set("loop_start", off[:-1].astype(np.int32))
    me.update(calc_edges=True)
    keys = [tuple(np.round(np.concatenate([r, e]), 6)) for r, e in zip(m.face_rho, m.face_emission)]
    uniq = list(dict.fromkeys(keys))
    for k in uniq:
        me.materials.append(_material(k[:3], k[3:]))
    me.polygons.foreach_set("material_index", np.array([uniq.index(k) for k in keys], np.int32))
    me.validate()
    ob = bpy.data.objects.new(m.name, me)
    collection.objects.link(ob)
    return ob


def build_cornell_box(context, **kwargs):
    """Cornell box objects in the scene's main collection; returns them."""
    return [object_from_mesh_input(m, context.scene.collection) for m in cornell_box(**kwargs)]


def add_preview_camera(context, size=2.0):
    """A camera in front of the open side (y = 0) looking into the box."""
    cam = bpy.data.cameras.new("Preview")
    cam.lens_unit = "FOV"
    cam.angle = math.radians(31.0)   # the open front (2 m wide) just fills the frame
    ob = bpy.data.objects.new("Preview Camera", cam)
    ob.location = (0.5 * size, -1.95 * size, 0.5 * size)
    ob.rotation_euler = (math.pi / 2, 0.0, 0.0)
    context.scene.collection.objects.link(ob)
    context.scene.camera = ob
    return ob


def render_preview(context, filepath, resolution=400, samples=16, exposure=0.0):
    """Render the scene's camera with Cycles (CPU) to a PNG. The baked material is pure emission,
    so no bounces are traced: the picture shows exactly the baked colours."""
    scene = context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.use_denoising = False
    scene.cycles.max_bounces = 0
    scene.render.resolution_x = scene.render.resolution_y = resolution
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = filepath
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = exposure
    if scene.world is not None:
        scene.world.color = (0.0, 0.0, 0.0)
    bpy.ops.render.render(write_still=True)
    return filepath
