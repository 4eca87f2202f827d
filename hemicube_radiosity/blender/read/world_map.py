# SPDX-License-Identifier: GPL-3.0-or-later
"""A world whose light varies with direction, as Cycles evaluates it: rendered into an
equirectangular map (Blender glue only).

A Sky Texture, a gradient, a node set-up of any kind behind the world's Background: this bake
has no node interpreter, so Cycles renders the world alone through a panoramic equirectangular
camera (a temporary scene holding nothing but the camera; the user's scenes and data are not
touched, and everything made is removed), and the map lights the scene as an HDRI does
(:mod:`...core.light.environment`). The camera looks along +X with +Z up, so the map has the
Environment Texture's convention: +X at the centre column, +Z the top row, -Y to the right.

Rays from a camera are camera rays: a world that shows one thing to the camera and another to
diffuse rays (a Light Path node's "Is Camera Ray") is read as the camera sees it (noted).
"""
from __future__ import annotations

import math
import os
import shutil
import tempfile

import numpy as np

from .materials import image_pixels

__all__ = ["render_world_map", "MAP_WIDTH", "MAP_SAMPLES"]

MAP_WIDTH = 256          # 1.4 degrees a pixel: a sun disk of Nishita's sky spans a pixel or two
MAP_SAMPLES = 1024       # per pixel: the sun of a Sky Texture, a third of a pixel, to 1% (0.7 s)


def render_world_map(world, notes, width=MAP_WIDTH, samples=MAP_SAMPLES):
    """(H, W, 3) float radiance of ``world`` by direction, rows bottom-up (Blender's order), or
    None when Cycles cannot render it (said in ``notes``)."""
    import bpy

    world = getattr(world, "original", world)        # a depsgraph's copy cannot be rendered
    had_result = "Render Result" in bpy.data.images
    if any(n.type == "LIGHT_PATH" for n in world.node_tree.nodes):
        notes.append("world: a Light Path node in the world: its light is read as camera rays see it")
    made, folder = [], tempfile.mkdtemp(prefix="hr_world_")
    try:
        sc = bpy.data.scenes.new("_hr_world_map")
        made.append((bpy.data.scenes, sc))
        sc.world = world
        sc.render.engine = "CYCLES"
        sc.cycles.samples = int(samples)
        sc.cycles.device = "CPU"
        if hasattr(sc.cycles, "use_denoising"):
            sc.cycles.use_denoising = False
        # a pixel is the mean over its own directions (a box of one pixel), not a blend of its
        # neighbours', nor its centre alone (the sun of a Sky Texture is a third of a pixel)
        sc.cycles.pixel_filter_type, sc.cycles.filter_width = "BOX", 1.0
        h = max(1, width // 2)
        sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = width, h, 100
        cam_data = bpy.data.cameras.new("_hr_world_map")
        made.append((bpy.data.cameras, cam_data))
        cam_data.type = "PANO"
        cam_data.panorama_type = "EQUIRECTANGULAR"
        cam = bpy.data.objects.new("_hr_world_map", cam_data)
        made.insert(0, (bpy.data.objects, cam))
        sc.collection.objects.link(cam)
        cam.rotation_euler = (math.pi / 2, 0.0, -math.pi / 2)    # along +X, +Z up
        sc.camera = cam
        sc.view_settings.view_transform = "Standard"
        sc.view_settings.exposure, sc.view_settings.gamma = 0.0, 1.0
        sc.render.image_settings.file_format = "OPEN_EXR"
        sc.render.image_settings.color_depth = "32"
        path = os.path.join(folder, "world.exr")
        sc.render.filepath = path
        bpy.ops.render.render(write_still=True, scene=sc.name)
        img = bpy.data.images.load(path)
        made.append((bpy.data.images, img))
        return image_pixels(img)[..., :3].astype(np.float64)
    except (RuntimeError, AttributeError, TypeError) as ex:
        notes.append(f"world: Cycles could not render its light by direction ({ex}); used a constant sky")
        return None
    finally:
        if not had_result and "Render Result" in bpy.data.images:    # leave the file as it was
            made.append((bpy.data.images, bpy.data.images["Render Result"]))
        for coll, block in made:
            try:
                coll.remove(block)
            except (ReferenceError, RuntimeError):
                pass
        shutil.rmtree(folder, ignore_errors=True)
