# SPDX-License-Identifier: GPL-3.0-or-later
"""Core result -> Blender data: baked copies, or the attribute written in place.

Copy mode (default, non-destructive): one new object per baked object (same world matrix), a
FLOAT_COLOR corner attribute (set as active and render colour) with the output at every face
corner (``BakeResult.corner_values``: a textured face's corners each with their own colour), and a
material that shows that attribute (the colour wired straight into the output: Cycles/EEVEE render
it as emission, the glTF exporter writes KHR_materials_unlit). Its mesh is either

* the user's own mesh, as evaluated (modifiers applied, in the evaluated mesh's local space), when
  the bake did not cut the object's faces: every source face gave at most max(1, corners - 2)
  output elements (a quad may be split into two triangles) and every face corner is an element
  vertex. Topology, UV maps, custom normals, sharp edges and other attributes are kept (each
  material slot shows the bake material; the UVs stay for a texture multiplied at run time);
  ``obj["radiosity_mesh"] == "source"``;
* otherwise the element mesh (the object's output elements in its own local space, rebuilt from
  the bake's arrays: no UVs or attributes of the user's), ``obj["radiosity_mesh"] == "elements"``.

Copies live in the "Radiosity" collection; each remembers its source in
``obj["radiosity_source"]``. The originals are hidden (viewport and render), never deleted or
edited. Re-baking an object removes its previous copy first.

In-place mode (the attribute on the user's own meshes) is :mod:`.in_place`.

Values are radiance (an emission strength of 1 in white is 1.0) times ``2**exposure``; no
clamping or tone mapping.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import bpy
import numpy as np
from ..core.runtime.cache import PER_MESH, Memo, frozen, inverse
from ..core.runtime.errors import RadiosityError
from . import textures

__all__ = ["WriteError", "COLLECTION_NAME", "SOURCE_KEY", "write_copies",
           "baked_material", "remove_bakes", "copies_of", "copies_collection",
           "place_copy", "select_copies", "source_mesh_copy", "set_materials",
           "set_color_attribute", "corner_slots"]

COLLECTION_NAME = "Radiosity"
SOURCE_KEY = "radiosity_source"
MESH_KIND_KEY = "radiosity_mesh"     # on a copy: "source" (the user's topology) or "elements"
LAYOUT_KEY = "radiosity_layout"      # on an element mesh: what its geometry and UVs were made from
WRITTEN_KEY = "radiosity_written"    # ... and its attributes' names when written
MATERIAL_PREFIX = "Radiosity Bake"


class WriteError(RadiosityError, RuntimeError):
    pass


def baked_material(attribute_name: str, culled: bool = False):
    """A material that shows colour attribute ``attribute_name`` as emitted light (shared).
    ``culled``: for a copy that carries the backs of its open surfaces (core/mesh/backs.py), each
    side shows its own light: back faces are culled in the viewport and glTF's material is
    single-sided (Cycles sees the nearer face, which is the one facing it)."""
    name = f"{MATERIAL_PREFIX} ({attribute_name}{', two-sided' if culled else ''})"
    mat = bpy.data.materials.get(name)
    if mat is not None and mat.node_tree is not None and mat.get("radiosity_attribute") == attribute_name \
            and mat.use_backface_culling == culled:
        return mat
    mat = mat or bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0) or mat.node_tree is None:
        mat.use_nodes = True  # Blender < 5 only; 5.x materials always have nodes
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    out.location = (300, 0)
    col = nt.nodes.new("ShaderNodeVertexColor")
    col.layer_name = attribute_name
    col.location = (0, 0)
    nt.links.new(col.outputs["Color"], out.inputs["Surface"])
    mat.diffuse_color = (1.0, 1.0, 1.0, 1.0)
    mat.use_backface_culling = culled
    mat["radiosity_attribute"] = attribute_name
    return mat


def copies_collection(scene):
    """The 'Radiosity' collection of baked copies, made and linked to ``scene`` if need be."""
    coll = bpy.data.collections.get(COLLECTION_NAME)
    if coll is None:
        coll = bpy.data.collections.new(COLLECTION_NAME)
    if scene.collection.children.get(coll.name) is None and coll not in scene.collection.children_recursive:
        scene.collection.children.link(coll)
    return coll


def copies_of(names):
    """Baked copies whose source is one of ``names``."""
    names = set(names)
    return [o for o in bpy.data.objects if o.get(SOURCE_KEY) in names]


def remove_bakes(names, unhide=False, keep=()):
    """Delete the baked copies of objects ``names`` (and their meshes, but those named in
    ``keep``); optionally unhide sources."""
    obs = copies_of(names)
    meshes = {ob.data.name: ob.data for ob in obs if ob.data is not None and ob.data.name not in keep}
    # one batch: removing the copies one by one scans every object each time (the staircase's
    # 775 copies took 12-27 s of a relight's write)
    bpy.data.batch_remove(obs)
    bpy.data.batch_remove([me for me in meshes.values() if me.users == 0])
    if unhide:
        for n in names:
            src = bpy.data.objects.get(n)
            if src is not None:
                src.hide_render = False
                try:
                    src.hide_set(False)
                except RuntimeError:
                    pass


_BY_OWNER = Memo(4)      # an owner array -> (its rows sorted by owner, each owner's first)


def rows_of(patches, owner) -> np.ndarray:
    """``np.flatnonzero(np.isin(patches.owner, owner))``: the rows of the owners ``owner`` (an
    index, or several), in order, from the rows grouped by owner once per owner array (scanning
    every element for each of the staircase's 775 objects was a second of each write)."""
    def make():
        order = np.argsort(patches.owner, kind="stable")
        first = np.searchsorted(patches.owner[order], np.arange(int(patches.owner.max(initial=-1)) + 2))
        return order, first
    order, first = _BY_OWNER.of((patches.owner,), make)
    parts = [order[first[o]:first[o + 1]] for o in np.unique(np.atleast_1d(owner)) if 0 <= o < len(first) - 1]
    if not parts:
        return np.zeros(0, np.int64)
    return parts[0] if len(parts) == 1 else np.sort(np.concatenate(parts))


#: :func:`_element_layout` by the identity of the elements' geometry arrays (never changed in
#: place: a relight's elements are the cached ones), the owners, the matrix and the flip: a
#: relight writes the same layouts (26 ms of the bunny's relight). Read only.
_LAYOUTS = Memo(PER_MESH)


def _element_layout(patches, owner, matrix_world, flipped):
    """One owner's patches as a mesh: local-space verts (V', 3), loop vertex ids (L,), loop starts
    (F,), each loop's patch corner as an index into the (N * 4) flattened corners (L,), and the
    patches (F,) (``owner``: an index, or several: an object and its back); read only."""
    M = np.asarray(matrix_world, float)
    key = (np.asarray(owner, np.int64).tobytes(), M.shape, M.tobytes(), bool(flipped))

    def make():
        return frozen(*_layout(patches, owner, M, flipped))
    return _LAYOUTS.of((patches.verts, patches.polys, patches.owner), make, key=key)


def _layout(patches, owner, M, flipped):
    sel = rows_of(patches, owner)
    polys = patches.polys[sel]
    used = np.unique(polys[polys >= 0])
    remap = np.full(len(patches.verts), -1, np.int64)
    remap[used] = np.arange(used.size)
    Minv = inverse(M)
    local = patches.verts[used] @ Minv[:3, :3].T + Minv[:3, 3]
    nside = np.where(polys[:, 3] < 0, 3, 4)
    order = np.tile(np.arange(4), (len(polys), 1))
    if flipped:  # the reader reversed the rings to keep world-space fronts; undo for local space
        order[nside == 4] = [3, 2, 1, 0]
        order[nside == 3] = [2, 1, 0, 3]
        polys = np.take_along_axis(polys, order, axis=1)
    mask = np.arange(4)[None, :] < nside[:, None]
    loop_vert = remap[polys[mask]]                  # row-major: face by face
    starts = np.concatenate([[0], np.cumsum(nside)[:-1]])
    return local, loop_vert, starts, (sel[:, None] * 4 + order)[mask], sel


def set_color_attribute(me, name, rgb):
    old = me.color_attributes.get(name)
    if old is not None:
        me.color_attributes.remove(old)
    if name in me.attributes:
        raise WriteError(f"mesh '{me.name}' already has a non-colour attribute named '{name}'")
    attr = me.color_attributes.new(name, "FLOAT_COLOR", "CORNER")
    rgba = np.ones((len(rgb), 4), np.float32)
    rgba[:, :3] = rgb
    attr.data.foreach_set("color", rgba.ravel())
    me.color_attributes.active_color = attr
    idx = me.color_attributes.find(name)
    me.color_attributes.render_color_index = idx
    try:
        me.color_attributes.active_color_index = idx
    except AttributeError:
        pass
    return attr


def write_copies(context, scene_input, result, attribute_name="Radiosity", exposure=0.0, keep_textures=True):
    """Create the baked copies; returns them (one per baked object, in order). ``keep_textures``:
    a textured object's copy shows its texture times the light (:mod:`.textures`)."""
    scene = context.scene
    baked = [s for s in scene_input.objects if s.bake]
    kept = _element_meshes([s.name for s in baked])      # a relight may write into them again
    remove_bakes([s.name for s in baked], keep={me.name for me in kept.values()})
    coll = copies_collection(scene)
    scale = 2.0 ** float(exposure)
    depsgraph = context.evaluated_depsgraph_get()
    corners = result.corner_values()
    lighting = result.corner_lighting() if keep_textures else None
    textured = {} if lighting is None else _textured_objects(scene_input, result, depsgraph)
    scales = textures.albedo_scales(list({m.name_full: m for ms in textured.values() for m in ms}.values()))
    out = []
    for oi, src in enumerate(scene_input.objects):
        if not src.bake:
            continue
        owners = result.owners_of(oi)
        mat = baked_material(attribute_name, culled=owners.size > 1)
        with _UserMesh(src, depsgraph) as user:
            # an object with a back (core/mesh/backs.py) is written as its elements, both sides
            copy = _source_topology_copy(depsgraph, result, corners, oi, src, attribute_name, scale, mat) \
                if owners.size == 1 else None
            if copy is None:
                copy = _element_mesh(result, corners, owners, src, attribute_name, scale, mat, user,
                                     kept.pop(src.name, None))
            if oi in textured:
                _show_textures(copy, user, corners, lighting, attribute_name, scale, scales, owners.size > 1)
            _keep_see_through(copy, user)
            if copy.kind == "elements":
                copy.me[WRITTEN_KEY] = _attribute_names(copy.me)
        out.append(place_copy(coll, src, copy.me, copy.kind))
    for me in kept.values():                 # not written again: gone, as with every old copy
        if me.users == 0:
            bpy.data.meshes.remove(me)
    select_copies(context, out)
    return out


def _element_meshes(names) -> dict:
    """{source name: the element mesh of its baked copy} for the copies of ``names`` whose mesh
    only that copy uses: a relight keeps a mesh whose geometry and UVs are still those it would
    make (:func:`_element_mesh`) and writes only its colours."""
    out = {}
    for ob in copies_of(names):
        me = ob.data
        if me is not None and ob.get(MESH_KIND_KEY) == "elements" and me.users == 1 and LAYOUT_KEY in me:
            out[ob[SOURCE_KEY]] = me
    return out


def _attribute_names(me) -> str:
    return "\n".join(sorted(a.name for a in me.attributes))


def _layout_key(local, loop_vert, starts, loop_face, user_mesh) -> str:
    """What an element mesh's geometry and UV maps are made from: its vertices, loops and
    polygons, each loop's face of the user's mesh, and (``user_mesh``, or None: no UV maps)
    that mesh's vertices, loops, polygons and UV maps."""
    import hashlib

    h = hashlib.sha256()
    for a in (local.astype(np.float32), loop_vert.astype(np.int32), starts.astype(np.int32),
              loop_face.astype(np.int64)):
        h.update(str(a.shape).encode() + a.tobytes())
    if user_mesh is not None:
        me = user_mesh
        co = np.empty(len(me.vertices) * 3, np.float32)
        me.vertices.foreach_get("co", co)
        lv = np.empty(len(me.loops), np.int32)
        me.loops.foreach_get("vertex_index", lv)
        tot = np.empty(len(me.polygons), np.int32)
        me.polygons.foreach_get("loop_total", tot)
        for a in (co, lv, tot):
            h.update(str(a.shape).encode() + a.tobytes())
        for layer in me.uv_layers:
            uv = np.empty(len(me.loops) * 2, np.float32)
            layer.data.foreach_get("uv", uv)
            h.update(layer.name.encode() + b"\0" + uv.tobytes())
    return h.hexdigest()


def place_copy(coll, src, me, kind):
    """A new object of mesh ``me`` standing for ``src`` (same world matrix) in collection
    ``coll``, marked as its baked copy of mesh kind ``kind``; the original is hidden."""
    me[SOURCE_KEY] = src.name
    ob = bpy.data.objects.new(f"{src.name}.radiosity", me)
    ob.matrix_world = _matrix(src.matrix_world)
    ob[SOURCE_KEY] = src.name
    ob[MESH_KIND_KEY] = kind
    coll.objects.link(ob)
    orig = bpy.data.objects.get(src.name)
    if orig is not None:
        orig.hide_render = True
        try:
            orig.hide_set(True)
        except RuntimeError:  # not in the current view layer
            pass
    return ob


def select_copies(context, out):
    """The copies ``out`` take over the selection (and the active object, the copy of the active
    source), so a re-bake of the selection re-bakes their sources."""
    vl = context.view_layer
    for ob in out:
        if vl.objects.get(ob.name) is not None:
            ob.select_set(True)
    if out and vl.objects.get(out[0].name) is not None:
        active = vl.objects.active
        src_active = active.name if active is not None else None
        vl.objects.active = next((o for o in out if o[SOURCE_KEY] == src_active), out[0])


def _textured_objects(scene_input, result, depsgraph):
    """{object index: its textured materials} of the baked objects whose copy shows its texture
    times the light (:mod:`.textures`): textured and emitting nothing."""
    out = {}
    for oi, src in enumerate(scene_input.objects):
        if not src.bake or src.corner_rho is None or bpy.data.objects.get(src.name) is None:
            continue
        if np.any(src.mesh.face_emission > 0) or (src.corner_emission is not None and np.any(src.corner_emission > 0)):
            continue
        mats = textures.textured_materials(_UserMesh(src, depsgraph).mats)
        if mats:
            out[oi] = mats
    return out


def _original(mat):
    """The user's material behind a depsgraph's evaluated copy (None stays None)."""
    return getattr(mat, "original", mat)


class _UserMesh:
    """The user's evaluated object behind a copy: its materials (the originals), each polygon's
    slot and its mesh (read only), each read on first use and once; the mesh is freed on exit."""

    def __init__(self, src, depsgraph):
        obj = bpy.data.objects.get(src.name)
        self.ob_eval = None if obj is None else obj.evaluated_get(depsgraph)
        self._mesh = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self._mesh is not None:
            self.ob_eval.to_mesh_clear()
            self._mesh = None

    @property
    def mesh(self):
        if self._mesh is None:
            self._mesh = self.ob_eval.to_mesh()
        return self._mesh

    @functools.cached_property
    def mats(self) -> list:
        slots = [] if self.ob_eval is None else self.ob_eval.material_slots
        return [_original(s.material) for s in slots] or [None]

    @functools.cached_property
    def slot(self) -> np.ndarray:
        """(polygons,) int64 each polygon's material slot, clipped to the slots there are."""
        slot = np.zeros(len(self.mesh.polygons), np.int64)
        self.mesh.polygons.foreach_get("material_index", slot)
        return np.clip(slot, 0, len(self.mats) - 1)


@dataclass
class _Copy:
    """A baked copy's mesh ``me`` and how its loops map to the bake: ``kind`` 'source' (the
    user's topology) or 'elements'; ``loop_corner`` (loops,) each loop's element corner, an index
    into the (N * 4) flattened corners; ``loop_face`` (loops,) the user's face (evaluated polygon)
    it lies on or behind; ``poly_face`` (polygons,) the same per polygon of an element mesh (None:
    the polygons are the user's own)."""

    me: object
    kind: str
    loop_corner: np.ndarray
    loop_face: np.ndarray
    poly_face: np.ndarray | None = None

    def slots(self, user) -> np.ndarray | None:
        """(polygons,) each polygon's slot in the user's material slots (None: the mesh's own)."""
        return None if self.poly_face is None else user.slot[self.poly_face]


def _show_textures(copy, user, corners, lighting, attribute_name, scale, scales, culled):
    """Give ``copy`` the light attribute (active: glTF's COLOR_0) and per slot a material of its
    colour times that light (:mod:`.textures`); ``culled``: it carries backs (two-sided)."""
    light_name = attribute_name + textures.LIGHT_SUFFIX
    light, rad = (a.reshape(-1, 3)[copy.loop_corner] for a in (lighting, corners))
    values = textures.light_values(light, rad, copy.loop_face, user.slot, user.mats, scales)
    set_color_attribute(copy.me, light_name, values * scale)
    plain = baked_material(light_name, culled=culled)
    set_materials(copy.me, textures.lit_materials(user.mats, scales, light_name, plain, culled=culled),
                  copy.slots(user))


def _keep_see_through(copy, user):
    """On the slots whose user material light passes through (glass, :func:`.textures.see_through`)
    the copy keeps that material (shared, not changed): a window stays a window. An element
    mesh gets the user's slots for that (each element the slot of its face)."""
    mats = user.mats
    if not any(textures.see_through(m) for m in mats):
        return
    me = copy.me
    slot = None if len(me.materials) == len(mats) else copy.slots(user)
    shown = [me.materials[min(i, len(me.materials) - 1)] for i in range(len(mats))]
    set_materials(me, [own if textures.see_through(own) else m for m, own in zip(shown, mats)], slot)


def set_materials(me, mats, slot=None):
    """``mats`` as the material slots of mesh ``me``; ``slot`` (polygons,): each polygon's slot
    (set after the slots: clearing them resets the polygons' indices), None: kept."""
    had = "material_index" in me.attributes         # absent: every polygon on slot 0
    if slot is None:
        slot = np.zeros(len(me.polygons), np.int32)
        if had:
            me.polygons.foreach_get("material_index", slot)
    slot = np.asarray(slot, dtype=np.int32)
    me.materials.clear()
    for m in mats:
        me.materials.append(m)
    if had or slot.any():                           # (writing zeros would add the attribute)
        me.polygons.foreach_set("material_index", slot)


def _element_faces(result, sel):
    """(n,) the user's face (evaluated polygon) each of the elements ``sel`` lies on or behind."""
    E = result.elements
    faces = E.source_face[sel].astype(np.int64)
    own = E.owner[sel]
    for o in np.unique(own):
        at = own == o
        faces[at] = result.front_faces(int(o), faces[at])
    return faces


def _element_mesh(result, corners, owners, src, attribute_name, scale, mat, user, old=None) -> _Copy:
    """A new mesh of the output elements of ``owners`` (an object, and its back) in the object's
    local space, with the attribute, and the user's UV maps at its corners
    (:func:`.textures.element_uvs`; ``user``: the :class:`_UserMesh`). ``old``: the element
    mesh of the object's previous copy, or None; where it was made from the same geometry and
    UV maps (:func:`_layout_key`) and has the same attributes as written then, it is used
    again with its colours, materials and slots cleared (a relight writes only its colours)."""
    local, loop_vert, starts, take, sel = _element_layout(result.elements, owners, src.matrix_world, src.flipped)
    faces = _element_faces(result, sel)
    loop_face = np.repeat(faces, np.diff(np.append(starts, len(loop_vert))))
    uvs = user.ob_eval is not None and len(user.mesh.uv_layers) and len(user.mesh.polygons) == src.eval_counts[2]
    key = _layout_key(local, loop_vert, starts, loop_face, user.mesh if uvs else None)
    if old is not None and old.get(LAYOUT_KEY) == key and old.get(WRITTEN_KEY) == _attribute_names(old):
        me = old
        for name in [a.name for a in me.color_attributes]:     # by name: removing moves the others
            me.color_attributes.remove(me.color_attributes[name])
        if "material_index" in me.attributes:
            me.attributes.remove(me.attributes["material_index"])
        me.materials.clear()
        me.update_tag()                       # (its colours change: drawn again)
    else:
        me = bpy.data.meshes.new(f"{src.name}.radiosity")
        me.vertices.add(len(local))
        me.vertices.foreach_set("co", local.astype(np.float32).ravel())
        me.loops.add(len(loop_vert))
        me.loops.foreach_set("vertex_index", loop_vert.astype(np.int32))
        me.polygons.add(len(starts))
        me.polygons.foreach_set("loop_start", starts.astype(np.int32))
        me.update(calc_edges=True)
        me[LAYOUT_KEY] = key
    set_color_attribute(me, attribute_name, corners.reshape(-1, 3)[take] * scale)
    me.materials.append(mat)
    if uvs and me is not old:
        for name, uv in textures.element_uvs(user.mesh, local[loop_vert], loop_face).items():
            me.uv_layers.new(name=name).data.foreach_set("uv", uv.ravel())
    return _Copy(me, "elements", take, loop_face, faces)


def faces_uncut(P, oi, src):
    """True when the bake kept object ``oi``'s faces as its output: every source face gave at
    most max(1, corners - 2) elements (a quad split into two triangles is not cut)."""
    sizes = np.diff(src.mesh.face_offsets)
    per_face = np.bincount(P.source_face[rows_of(P, oi)].astype(np.int64), minlength=sizes.size)
    return per_face.size == sizes.size and bool(np.all(per_face <= np.maximum(1, sizes - 2)))


def _source_topology_copy(depsgraph, result, corners, oi, src, attribute_name, scale, mat):
    """A copy of the user's evaluated mesh carrying the attribute (a :class:`_Copy`), or None
    where the bake cut the object's faces finer (or the evaluated mesh is no longer the one that
    was read)."""
    P = result.elements
    if not faces_uncut(P, oi, src):
        return None
    slots = corner_slots(P, oi, src)
    if np.any(slots < 0):
        return None
    me = source_mesh_copy(depsgraph, src)
    if me is None:
        return None
    loop_corner = np.zeros(len(me.loops), np.int64)
    loop_corner[src.corner_loop] = slots
    try:
        set_color_attribute(me, attribute_name, corners.reshape(-1, 3)[loop_corner] * scale)
    except WriteError:                        # a non-colour attribute of that name: keep it
        bpy.data.meshes.remove(me)
        return None
    # every slot shows the bake (material indices, hence the user's slot layout, are kept)
    set_materials(me, [mat] * max(1, len(me.materials)))
    loop_face = np.zeros(len(me.loops), np.int64)
    loop_face[src.corner_loop] = np.repeat(np.arange(len(src.mesh.face_offsets) - 1),
                                           np.diff(src.mesh.face_offsets))
    return _Copy(me, "source", loop_corner, loop_face)


def source_mesh_copy(depsgraph, src):
    """A new mesh ``<name>.radiosity``: the user's evaluated mesh of ``src`` (modifiers applied,
    every data layer kept: UV maps, attributes, custom normals), or None where it is not a mesh or
    no longer the mesh that was read (the scene changed since)."""
    obj = bpy.data.objects.get(src.name)
    if obj is None or obj.type != "MESH":
        return None
    try:
        me = bpy.data.meshes.new_from_object(obj.evaluated_get(depsgraph),
                                             preserve_all_data_layers=True, depsgraph=depsgraph)
    except RuntimeError:
        return None
    if (len(me.vertices), len(me.loops), len(me.polygons)) != tuple(src.eval_counts) or \
            len(me.loops) != src.corner_loop.size:
        bpy.data.meshes.remove(me)            # the scene changed since it was read
        return None
    me.name = f"{src.name}.radiosity"
    return me


def _matrix(m):
    from mathutils import Matrix

    return Matrix([list(map(float, row)) for row in np.asarray(m)])


def corner_slots(P, oi, src):
    """Element corner at every source-face corner (order of src.mesh.face_indices), as an index
    into the (N * 4) flattened corners: a corner of one of that face's elements at exactly the
    corner's position; -1 where there is none."""
    sel = rows_of(P, oi)
    polys = P.polys[sel]
    faces = np.repeat(P.source_face[sel].astype(np.int64), 4)
    vids = polys.reshape(-1).astype(np.int64)
    slot = (sel[:, None] * 4 + np.arange(4)).reshape(-1)
    ok = vids >= 0
    faces, vids, slot = faces[ok], vids[ok], slot[ok]
    m = src.mesh
    sizes = np.diff(m.face_offsets)
    cf = np.repeat(np.arange(sizes.size), sizes)
    cpos = np.asarray(m.verts, float)[m.face_indices]
    keys = np.concatenate([_face_position_keys(faces, P.verts[vids]), _face_position_keys(cf, cpos)])
    _, label = np.unique(keys, return_inverse=True)
    label = label.reshape(-1)
    table = np.full(label.max() + 1 if label.size else 0, -1, np.int64)
    table[label[:vids.size]] = slot
    return table[label[vids.size:]]


def _face_position_keys(faces, pos):
    """One bytes key per (face, exact float64 position) row, for exact matching."""
    a = np.empty((len(faces), 4), np.float64)
    a[:, 0] = faces
    a[:, 1:] = pos
    return np.ascontiguousarray(a).view(np.dtype((np.void, 32))).reshape(-1)
