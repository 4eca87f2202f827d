# SPDX-License-Identifier: GPL-3.0-or-later
"""Core result -> the colour attribute on the user's own meshes (the 'in place' output).

One value per face corner: the output at that corner (where patches are finer than faces, the
detail inside a face is lost; a bake report line says so). Needs modifiers that keep the
topology. A mesh shared by several baked objects (linked duplicates) is made single-user first so
each object keeps its own result. An earlier baked copy of these objects (:mod:`.write`) is
removed. Values are radiance times ``2**exposure``, as in the copies.
"""
from __future__ import annotations

import bpy
import numpy as np
from .write import WriteError, corner_slots, remove_bakes, set_color_attribute

__all__ = ["write_in_place"]


def write_in_place(context, scene_input, result, attribute_name="Radiosity", exposure=0.0):
    """Write the attribute on the original meshes; returns (objects, notes)."""
    scale = 2.0 ** float(exposure)
    notes = []
    written = []
    P = result.elements
    corners = result.corner_values()
    # an earlier baked copy of these objects is replaced by the in-place result
    remove_bakes([s.name for s in scene_input.objects if s.bake], unhide=True)
    for oi, src in enumerate(scene_input.objects):
        if not src.bake:
            continue
        ob = bpy.data.objects[src.name]
        me = ob.data
        if (len(me.vertices), len(me.loops), len(me.polygons)) != src.eval_counts or \
                len(me.loops) != src.corner_loop.size:
            raise WriteError(f"'{src.name}': its modifiers change the topology, so the result "
                             "cannot be written in place; use the baked-copy output")
        values = _corner_values(P, oi, src, corners)
        if me.users > 1:
            ob.data = me.copy()
            notes.append(f"{src.name}: mesh '{me.name}' was shared; gave it its own copy "
                         f"'{ob.data.name}'")
            me = ob.data
        loop_rgb = np.zeros((len(me.loops), 3))
        loop_rgb[src.corner_loop] = values
        set_color_attribute(me, attribute_name, loop_rgb * scale)
        n_src = len(src.mesh.face_offsets) - 1
        if np.count_nonzero(P.owner == oi) > n_src:
            notes.append(f"{src.name}: in place keeps one value per face corner; "
                         "the finer patch detail inside faces is averaged away")
        if result.owners_of(oi).size > 1:
            notes.append(f"{src.name}: in place keeps the light on the front of its faces; "
                         "the light on the back of its open surfaces is in baked copies only")
        written.append(ob)
    return written, notes


def _corner_values(P, oi, src, corner_values):
    """The output at every source-face corner (order of src.mesh.face_indices), from the
    elements' (N, 4, 3) ``corner_values``; 0 where no element corner is at the corner."""
    slots = corner_slots(P, oi, src)
    out = np.zeros((slots.size, 3))
    found = slots >= 0
    out[found] = np.asarray(corner_values).reshape(-1, 3)[slots[found]]
    return out
