# SPDX-License-Identifier: GPL-3.0-or-later
"""What a render sees, and where it places it: render visibility and world matrices.

``render_visible_objects(view_layer)`` lists the objects a render shows (not ``hide_render``, in
a collection neither excluded nor disabled in renders), whatever the viewport shows. An object
disabled in viewports is not evaluated by the viewport depsgraph, so it is read without
modifiers and placed by :func:`world_matrix` (noted). Viewport and render modifier settings that
differ are noted (:func:`render_notes`). Shared by the mesh reader (:mod:`.scene`), the lamp
reader (:mod:`.lights`), Cycles' material bakes (:mod:`.shading`) and the CLI.
"""
from __future__ import annotations

import numpy as np

__all__ = ["render_visible_objects", "is_render_visible", "world_matrix", "unevaluated_note",
           "render_notes"]


def _render_collections(view_layer):
    """Collections whose objects the render sees in ``view_layer``: the layer-collection tree
    without excluded layer collections and collections disabled in renders (and everything under
    them). The viewport's switches (eye, monitor) do not matter to a render."""
    out, stack = [], [view_layer.layer_collection]
    while stack:
        lc = stack.pop()
        if lc.exclude or lc.collection.hide_render:
            continue
        out.append(lc.collection)
        stack.extend(lc.children)
    return out


def render_visible_objects(view_layer, types=None):
    """Original objects that a render of ``view_layer`` shows, in view-layer order: in a
    collection the render sees (not excluded, not disabled in renders up the tree) and not
    ``hide_render`` themselves, whatever their viewport visibility (hidden with H, disabled in
    viewports). ``types``: e.g. {'MESH'} or {'LIGHT'} (default: all). Instances made by
    instancers are not listed (the depsgraph has them)."""
    names = set()
    for coll in _render_collections(view_layer):
        names.update(o.name for o in coll.objects)
    return [o for o in view_layer.objects
            if o.name in names and not o.hide_render and (types is None or o.type in types)]


def is_render_visible(ob, view_layer):
    """True when a render of ``view_layer`` shows the original object ``ob``."""
    ob = ob.original
    if ob.hide_render or view_layer.objects.get(ob.name) is None:
        return False
    return any(c.objects.get(ob.name) is not None for c in _render_collections(view_layer))


def world_matrix(obj, depsgraph):
    """(4, 4) world matrix of ``obj`` as the render places it. Objects disabled in viewports are
    not evaluated by the viewport depsgraph and their stored ``matrix_world`` may be stale (never
    computed for an object made by a script), so theirs is rebuilt from location/rotation/scale
    and the parent chain (constraints and parent bones/vertices are not applied)."""
    ob_eval = obj.evaluated_get(depsgraph)
    if ob_eval.is_evaluated:
        return np.array(ob_eval.matrix_world, dtype=np.float64)
    obj = obj.original
    M = np.array(obj.matrix_basis, dtype=np.float64)
    if obj.parent is not None:
        P = world_matrix(obj.parent, depsgraph)
        M = P @ np.array(obj.matrix_parent_inverse, dtype=np.float64) @ M
    return M


def unevaluated_note(obj):
    """Why the matrix of an object the viewport does not evaluate may differ from the render's."""
    what = [w for w, on in (("constraints", len(obj.constraints) > 0),
                            ("animation", obj.animation_data is not None),
                            ("parent " + obj.parent_type.lower(),
                             obj.parent is not None and obj.parent_type != "OBJECT")) if on]
    if what:
        return (f"disabled in viewports, so not evaluated; placed by its location/rotation/scale "
                f"and parent only ({', '.join(what)} not applied)")
    return None


def render_notes(obj, ob_eval):
    """What the render sees differently from the viewport-evaluated mesh we read."""
    notes = []
    mods = [m for m in obj.modifiers]
    if not ob_eval.is_evaluated:
        n = unevaluated_note(obj)
        if n:
            notes.append(n)
        if any(m.show_render for m in mods):
            notes.append("disabled in viewports (not evaluated there): read without its modifiers; "
                         "enable it in viewports for an exact bake")
            return notes
    for m in mods:
        if m.show_render != m.show_viewport:
            notes.append(f"modifier '{m.name}' is {'on' if m.show_render else 'off'} in renders but "
                         f"{'on' if m.show_viewport else 'off'} in the viewport; the viewport's mesh was used")
        elif m.show_render and m.type in ("SUBSURF", "MULTIRES") and m.levels != m.render_levels:
            notes.append(f"modifier '{m.name}': viewport level {m.levels} used (renders use {m.render_levels})")
    off = [k for k in ("diffuse", "shadow") if not getattr(obj, f"visible_{k}")]
    if off:
        notes.append(f"not visible to {' and '.join(off)} rays in Cycles; here it still reflects and "
                     "casts shadows like any surface")
    return notes
