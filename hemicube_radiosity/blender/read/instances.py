# SPDX-License-Identifier: GPL-3.0-or-later
"""Instances as Cycles sees them: collection instances, Geometry Nodes instances, particles.

An instancer (an Empty instancing a collection, a Geometry Nodes object with Instance on Points,
a particle system) makes objects that are in no collection: a render draws them, so they occlude,
reflect and emit like any surface, but :func:`.visibility.render_visible_objects` does not list
them. They are read from ``depsgraph.object_instances`` (only there, while the iterator is on one
of them, is ``inst.object`` the instanced geometry and ``inst.matrix_world`` its placement).

Instances of one mesh are read once: :func:`gather` groups them by their evaluated mesh and the
object they are of (whose slots give their materials) and copies each distinct mesh once, in one
pass over the depsgraph, into a TEMPORARY mesh and object, not
linked to any scene (a Geometry Nodes instance's geometry exists only in the depsgraph, so
``new_from_object`` cannot give it: the evaluated mesh is copied instead), with the original
materials of its slots. :mod:`.scene` reads each such prototype like an object at the identity
and places it by every matrix of its group; :func:`remove` deletes the prototypes again. The
user's objects, meshes and materials are never written.

Instances are occluders, reflectors and emitters only (``ObjectSource.bake`` False): the writer
has no object of theirs to write to, which :func:`note` says once, naming the instancers. Only
the instances the viewport's depsgraph makes can be read: an Empty hidden in the viewport makes
none there, while renders show them (:func:`unread` says so). A prototype's material is evaluated
by Cycles on the mesh at the origin, so a texture in object or generated coordinates is that of
the instanced object where it stands, not where each instance is.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .visibility import is_render_visible, render_visible_objects

__all__ = ["Prototype", "gather", "remove", "note", "unread"]

PROTOTYPE = "_hr_instance"
_GEOMETRY = frozenset({"MESH", "FONT", "CURVE", "SURFACE", "META"})
_RAYS = ("visible_diffuse", "visible_shadow")


@dataclass
class Prototype:
    """One distinct instanced mesh: a temporary object at the identity, and where it is placed."""

    ob: object                                      # temporary object (unlinked), its mesh a copy
    source: str                                     # the instanced object's name (for messages)
    matrices: list = field(default_factory=list)    # (4, 4) world matrix of every instance
    instancers: list = field(default_factory=list)  # the instancer's name for every instance


def _instancer(inst):
    """The original object that made the instance ``inst`` (its top-level instancer)."""
    parent = inst.parent
    return parent.original if parent is not None else None


def _materials(ob):
    """The original materials an evaluated instance object renders with: its mesh's, where a slot
    links the object's own material that one (Geometry Nodes sets materials on the mesh; the
    temporary object of its instances has slots of the instancer's)."""
    data = list(ob.data.materials) if ob.type == "MESH" else []
    slots = list(ob.material_slots)
    n = max(len(data), len(slots))
    mats = []
    for k in range(n):
        s = slots[k] if k < len(slots) else None
        m = data[k] if k < len(data) else None
        if s is not None and (s.link == "OBJECT" or m is None):
            m = s.material if s.material is not None else m
        mats.append(m)
    return [m.original if m is not None else None for m in mats]


def _copy_mesh(ob, depsgraph):
    """A temporary mesh with the evaluated geometry of the instance object ``ob`` (all its
    attributes), or None when it has none."""
    import bpy

    if ob.type == "MESH":
        return ob.data.copy()
    try:
        return bpy.data.meshes.new_from_object(ob, preserve_all_data_layers=True, depsgraph=depsgraph)
    except RuntimeError:
        return None


def gather(depsgraph, instancers=None):
    """(prototypes, made): [:class:`Prototype`] of the instances a render draws in ``depsgraph``
    and {instancer name: instance count} of every instancer a render shows. ``instancers``: the
    names of the instancers whose instances take part (None: all; empty: none, only ``made`` is
    counted). The caller must :func:`remove` the prototypes (also when reading them fails)."""
    import bpy

    vl = depsgraph.view_layer
    groups, out, made, shown = {}, [], {}, {}
    try:
        for inst in depsgraph.object_instances:
            if not inst.is_instance:
                continue
            ob = inst.object
            par = _instancer(inst)
            if ob.type not in _GEOMETRY or par is None or ob.hide_render:
                continue              # (an instanced collection's object hidden in renders)
            name = par.name
            if name not in shown:
                shown[name] = is_render_visible(par, vl)
            if not shown[name]:
                continue
            made[name] = made.get(name, 0) + 1
            if instancers is not None and name not in instancers:
                continue
            # one mesh and one set of slots (the instanced object's) make one prototype
            key = (ob.data.as_pointer() if ob.data is not None else 0, ob.original.as_pointer(), ob.type)
            proto = groups.get(key)
            if proto is None:
                proto = groups[key] = _prototype(ob, depsgraph) or False
                if proto:
                    out.append(proto)
            if proto:
                proto.matrices.append(np.array(inst.matrix_world, dtype=np.float64))
                proto.instancers.append(name)
    except BaseException:
        remove(out)
        raise
    return out, made


def _prototype(ob, depsgraph):
    """A :class:`Prototype` of the evaluated instance object ``ob``: a temporary object (in no
    scene) with a copy of its mesh wearing the original materials, or None without geometry."""
    import bpy

    mats = _materials(ob)
    me = _copy_mesh(ob, depsgraph)
    if me is None:
        return None
    for k, m in enumerate(mats):     # (clear() would reset the material indices)
        if k < len(me.materials):
            me.materials[k] = m
        else:
            me.materials.append(m)
    proto = bpy.data.objects.new(PROTOTYPE, me)
    for k in _RAYS:                  # what Cycles' rays see of it, for the reader's notes
        setattr(proto, k, getattr(ob, k))
    return Prototype(proto, ob.original.name)


def remove(protos):
    """Delete the temporary objects and meshes of ``protos``."""
    import bpy

    for p in protos:
        me = p.ob.data
        try:
            bpy.data.objects.remove(p.ob)
        except ReferenceError:
            pass
        if me is not None:
            try:
                bpy.data.meshes.remove(me)
            except ReferenceError:
                pass


def unread(depsgraph, made, instancers=None):
    """Notes for the Empties instancing a collection that a render shows but whose instances the
    viewport's depsgraph does not make (the Empty hidden in the viewport): ``made`` the names
    :func:`gather` found, ``instancers`` as for :func:`gather`."""
    out = []
    for ob in render_visible_objects(depsgraph.view_layer, {"EMPTY"}):
        if ob.instance_type != "COLLECTION" or ob.instance_collection is None or ob.name in made:
            continue
        if instancers is not None and ob.name not in instancers:
            continue
        if any(o.type in _GEOMETRY for o in ob.instance_collection.all_objects):
            out.append(f"'{ob.name}' is hidden in the viewport, so its instances of collection "
                       f"'{ob.instance_collection.name}' are not read (renders show them): show it "
                       "for an exact bake")
    return out


def note(counts, emits=False, shown=3):
    """The one note for the instances that took part: ``counts`` {instancer name: instances}."""
    if not counts:
        return None
    what = "occluders, reflectors and emitters" if emits else "occluders and reflectors"
    items = [f"'{k}': {n} instance{'s' if n != 1 else ''}" for k, n in counts.items()]
    more = len(items) - shown
    head = ", ".join(items[:shown]) + (f" and {more} more instancers" if more > 0 else "")
    verb = "takes" if len(items) == 1 and next(iter(counts.values())) == 1 else "take"
    return f"{head} {verb} part as {what}; their colours are not written"
