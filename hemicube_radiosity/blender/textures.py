# SPDX-License-Identifier: GPL-3.0-or-later
"""Baked copies that keep their textures: each material's colour times the light arriving.

A baked copy shows the radiosity at every face corner: a texture is its colour at the corners, so
a floor of tiles modelled as one quad loses its pattern. Where an object's materials are textured
(what feeds the Base Color of the Principled BSDF, or the Color of the Diffuse BSDF, wired to the
output comes from nodes) and none of its faces emits, its copy (``settings.keep_textures``) gets:

* a second corner attribute, ``<attribute> Light``, made the active and render colour (glTF's
  COLOR_0): on the faces of a textured material the light arriving at each corner (radiance:
  irradiance / pi; ``BakeResult.corner_lighting``) times ``k``, Cycles' diffuse albedo of that
  material with a white Base Color (the specular layer's darkening: 0.963 for Blender's default
  Principled BSDF; asked of Cycles once for all the materials, :func:`albedo_scales`); on the
  other faces the radiosity (:func:`light_values`). The radiosity attribute is written as well
  (the untextured, game-ready output);
* per textured slot a material that shows ``colour x attribute``: a copy of the user's material
  (``Radiosity Bake (<attribute> Light x <material>)``) whose Base Color chain is multiplied (Mix,
  Multiply) by the attribute and wired into the output, an unlit material (glTF: baseColorTexture
  and COLOR_0 under KHR_materials_unlit); a plain slot shows the attribute as it is (the bake's
  own material);
* UVs: a copy of the user's topology keeps them; an element mesh (the bake cut the faces finer,
  or the object has a back) gets every UV map of the user's mesh at its corners
  (:func:`element_uvs`), barycentric in the triangle of Blender's triangulation of the source face
  that holds the corner, as Cycles interpolates them.

A slot whose material light passes through (:func:`see_through`: glass) keeps the user's own
material in any copy. Not done here (the radiosity attribute alone is shown): objects that emit,
other shaders than a Principled or Diffuse BSDF at the output, and in-place output (the user's
materials are never changed). The texture shows the colour Cycles renders only for a texture on
Base Color alone: a textured roughness or metallic changes ``k`` across the surface, and the copy
uses its value for their unlinked inputs.
"""
from __future__ import annotations

import bpy
import numpy as np

from .read import shading
from .read.materials import follow

__all__ = ["LIGHT_SUFFIX", "colour_input", "see_through", "textured_materials", "albedo_scales", "lit_materials",
           "light_values", "element_uvs"]

LIGHT_SUFFIX = " Light"
_COLOUR_INPUTS = {"BSDF_PRINCIPLED": "Base Color", "BSDF_DIFFUSE": "Color"}


def _surface_node(mat):
    """The node wired straight into ``mat``'s Surface (reroutes skipped), or None."""
    out = shading.output_node(mat) if mat is not None else None
    return None if out is None else follow(out.inputs["Surface"])[0]


def colour_input(mat):
    """The colour input socket of the BSDF wired straight into ``mat``'s Surface (Principled:
    Base Color, Diffuse: Color), or None."""
    node = _surface_node(mat)
    name = _COLOUR_INPUTS.get(getattr(node, "type", None))
    return None if name is None else node.inputs[name]


_SEE_THROUGH = {"BSDF_GLASS", "BSDF_REFRACTION", "BSDF_TRANSPARENT"}


def see_through(mat) -> bool:
    """True for a material that light passes through rather than reflects diffusely: a Glass,
    Refraction or Transparent BSDF, or a Principled BSDF of Transmission Weight 0.5 or more,
    wired straight into the Surface (its baked colour, near black, would make a window an
    opaque slab: a copy keeps the user's own material on such faces)."""
    node = _surface_node(mat)
    if node is None:
        return False
    if node.type in _SEE_THROUGH:
        return True
    sock = node.inputs.get("Transmission Weight") if node.type == "BSDF_PRINCIPLED" else None
    return sock is not None and not sock.is_linked and sock.default_value >= 0.5


def textured_materials(mats) -> list:
    """The materials of ``mats`` whose colour comes from nodes (a texture), once each."""
    out = []
    for m in mats:
        sock = colour_input(m)
        if sock is not None and follow(sock)[0] is not None and m not in out:
            out.append(m)
    return out


def albedo_scales(mats) -> dict:
    """{material name_full: k (3,)}: Cycles' diffuse albedo of each material of ``mats`` with its
    colour input unlinked and white, all in one Cycles bake; ones where Cycles cannot bake."""
    if not mats:
        return {}
    copies = []
    try:
        for m in mats:
            c = m.copy()
            sock = colour_input(c)
            for link in list(sock.links):
                c.node_tree.links.remove(link)
            sock.default_value = (1.0, 1.0, 1.0, 1.0)
            copies.append(c)
        try:
            _, consts, _, _ = shading.evaluate([], bpy.context.evaluated_depsgraph_get(), copies, emit=False)
        except (RuntimeError, AttributeError, TypeError):
            return {m.name_full: np.ones(3) for m in mats}
        return {m.name_full: np.clip(np.asarray(consts[c.name_full][0], float), 0.0, 1.0)
                for m, c in zip(mats, copies)}
    finally:
        for c in copies:
            bpy.data.materials.remove(c)


def _lit_material(name, attribute, source, culled=False):
    """A copy of material ``source`` that shows its colour chain times colour attribute
    ``attribute`` as light (made anew each bake: the copy keeps the user's textures)."""
    old = bpy.data.materials.get(name)
    if old is not None and old.users == 0:
        bpy.data.materials.remove(old)
    mat = source.copy()
    mat.name = name
    nt = mat.node_tree
    chain = follow(colour_input(mat))[1]
    out = shading.output_node(mat)
    x, y = out.location
    attr = nt.nodes.new("ShaderNodeVertexColor")
    attr.layer_name, attr.location = attribute, (x - 400, y - 200)
    mix = nt.nodes.new("ShaderNodeMix")
    mix.data_type, mix.blend_type, mix.location = "RGBA", "MULTIPLY", (x - 200, y)
    mix.inputs["Factor"].default_value = 1.0
    a, b = [s for s in mix.inputs if s.type == "RGBA"][:2]
    nt.links.new(chain, a)
    nt.links.new(attr.outputs["Color"], b)
    for link in list(out.inputs["Surface"].links):
        nt.links.remove(link)
    nt.links.new(next(s for s in mix.outputs if s.type == "RGBA"), out.inputs["Surface"])
    for n in list(nt.nodes):                  # the one output Cycles, EEVEE and glTF read
        if n.type == "OUTPUT_MATERIAL" and n != out:
            nt.nodes.remove(n)
    out.target, out.is_active_output = "ALL", True
    mat.use_backface_culling = culled
    mat["radiosity_attribute"] = attribute
    return mat


def lit_materials(mats, scales, attribute, plain, culled=False):
    """One material per slot of ``mats`` for a textured copy: a textured slot (in ``scales``)
    its colour chain times colour attribute ``attribute``; a plain slot ``plain`` (the bake's
    material showing that attribute as it is). ``culled``: the copy carries the backs of open
    surfaces (as ``write.baked_material``'s two-sided material)."""
    two = ", two-sided" if culled else ""
    return [_lit_material(f"Radiosity Bake ({attribute} x {m.name}{two})", attribute, m, culled)
            if m is not None and m.name_full in scales else plain for m in mats]


def light_values(light, radiosity, face, slot, mats, scales):
    """(n, 3) what colour attribute ``<attribute> Light`` holds at n corners: on a face of a
    textured slot the light arriving (``light`` (n, 3)) times the slot's albedo scale ``k`` (the
    material multiplies its texture by it), elsewhere the radiosity (``radiosity`` (n, 3)); each
    corner on face ``face`` (n,), whose slot is ``slot`` (faces,)."""
    k = np.array([scales[m.name_full] if m is not None and m.name_full in scales else np.full(3, np.nan)
                  for m in mats], dtype=np.float64)[slot[face]]
    return np.where(np.isnan(k), radiosity, np.nan_to_num(k) * light)


def _barycentric(p, a, b, c):
    """(n, 3) barycentric coordinates of points ``p`` (n, 3) in triangles ``a``, ``b``, ``c`` (n, 3)
    each, of the point's projection onto the triangle's plane."""
    e1, e2, d = b - a, c - a, p - a
    d11, d12, d22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    d1, d2 = (d * e1).sum(1), (d * e2).sum(1)
    det = d11 * d22 - d12 * d12
    det = np.where(np.abs(det) > 1e-300, det, 1.0)
    v = (d22 * d1 - d12 * d2) / det
    w = (d11 * d2 - d12 * d1) / det
    return np.stack([1.0 - v - w, v, w], axis=1)


def element_uvs(me, points, polygon):
    """{UV map name: (n, 2) float32} every UV map of mesh ``me`` at ``points`` (n, 3), in its
    local space, each on polygon ``polygon`` (n,): barycentric in the triangle of Blender's
    triangulation of that polygon that holds the point (the one it is least outside of)."""
    me.calc_loop_triangles()
    T = len(me.loop_triangles)
    tl = np.empty(T * 3, np.int64)
    me.loop_triangles.foreach_get("loops", tl)
    tl = tl.reshape(T, 3)
    tp = np.empty(T, np.int64)
    me.loop_triangles.foreach_get("polygon_index", tp)
    order = np.argsort(tp, kind="stable")
    tl, tp = tl[order], tp[order]
    first = np.searchsorted(tp, np.arange(len(me.polygons)))
    count = np.bincount(tp, minlength=len(me.polygons))
    co = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", co)
    lv = np.empty(len(me.loops), np.int64)
    me.loops.foreach_get("vertex_index", lv)
    pos = co.reshape(-1, 3)[lv]                              # (loops, 3)
    n = len(points)
    best_tri = np.full(n, -1, np.int64)
    best_w = np.zeros((n, 3))
    best_score = np.full(n, -np.inf)
    for k in range(int(count[polygon].max()) if n else 0):
        has = count[polygon] > k
        idx = np.flatnonzero(has)
        tri = first[polygon[idx]] + k
        w = _barycentric(points[idx], *(pos[tl[tri, j]] for j in range(3)))
        score = w.min(axis=1)
        better = score > best_score[idx]
        best_score[idx[better]], best_tri[idx[better]], best_w[idx[better]] = score[better], tri[better], w[better]
    out = {}
    for layer in me.uv_layers:
        uv = np.empty(len(me.loops) * 2, np.float32)
        layer.data.foreach_get("uv", uv)
        uv = uv.reshape(-1, 2).astype(np.float64)
        out[layer.name] = np.einsum("nj,njk->nk", best_w, uv[tl[best_tri]]).astype(np.float32)
    return out
