# SPDX-License-Identifier: GPL-3.0-or-later
"""What of a material light passes through, as Cycles' shadow rays pass it (Blender glue only).

Cycles lets shadow rays through a Transparent BSDF unbent, times its colour, and a Principled
BSDF's Alpha is a mix with one: a shadow ray through a leaf whose image alpha cuts its outline
reaches the sun through the holes (measured: a plane of Alpha 0.5 over a floor passes half the
sun, a Transparent BSDF all of it). Read from the nodes at the material output's Surface:

* Transparent BSDF: its Color's mean (unlinked);
* Principled BSDF: 1 - Alpha, Alpha a value or an Image Texture's Alpha output;
* Mix Shader: its two shaders' mixed by Fac, a value or an Image Texture's Alpha output; Add
  Shader: their sum; every other shader passes nothing.

An image is read as its alpha channel through the UV map its node reads (the render UV map, or
a UV Map node's), with the node's interpolation (Closest, else bilinear) and extension (Repeat,
else clamped). What else drives Alpha or Fac (math, other textures, a mapping) is not read: the
surface stays opaque there, and a warning says so.

Glass, Refraction and a Principled BSDF's Transmission pass no shadow ray in Cycles; light
reaches a diffuse surface through them only along refracted paths, which Cycles follows only
with refractive caustics on (Render > Light Paths > Caustics). Measured on a 3 x 3 m pane 1 m
over a floor under a uniform world: with them off, the floor under the pane has 0.238 (the sky
around the pane's edge; no pane: 0.800), as an opaque pane gives; with them on, 0.524 for one
plane of Glass (IOR 1.5), 0.541 for a 2 cm slab, 0.802 for a slab of IOR 1.0, and the light of a
sun or a lamp arrives only as noisy caustics. So glass stays opaque here, and a warning names it
when the scene's refractive caustics are on.
"""
from __future__ import annotations

import numpy as np

from ...core.light.transmit import AlphaImage, Transmit
from ...core.runtime.notes import note, warning
from .materials import RHO_MAX, follow, image_pixels
from .shading import output_node

__all__ = ["material_transmit", "mesh_transmit", "see_through_note", "solve_rho"]

_GLASS = {"BSDF_GLASS", "BSDF_REFRACTION"}


class _Unread(Exception):
    """A node setup drives transparency in a way this reader does not follow."""


def material_transmit(mats, me, caustics: bool):
    """Per material slot of evaluated mesh ``me``: (uniform transmittance, AlphaImage or None,
    (nloops, 2) UVs or None), and the notes (subject: the material). ``caustics``: the scene's
    refractive caustics are on (glass then passes light in Cycles, not here)."""
    out, notes = [], []
    for m in mats:
        label = f"material '{m.name}'" if m is not None else None
        out_node = output_node(m) if m is not None else None
        node, _ = follow(out_node.inputs["Surface"]) if out_node is not None else (None, None)
        glass = []
        try:
            t, img = _shader(node, glass, 0)
        except _Unread as ex:
            notes.append(warning("Alpha is not transparency here: the surface is opaque where "
                                 "Cycles lets light through", label, detail=str(ex), topic="materials"))
            t, img = 0.0, None
        if glass and caustics:
            notes.append(warning("glass passes no light here; Cycles passes some along refracted "
                                 "paths with refractive caustics on", label, detail=", ".join(glass),
                                 topic="materials"))
        uv = None
        if img is not None:
            uv = _uvs(me, img[1], label, notes)
            if uv is None:
                img = None
        out.append((float(np.clip(t, 0.0, 1.0)), None if img is None else img[0], uv))
    return out, notes


def mesh_transmit(per_slot, face_slot, corner_slot, corner_loop) -> Transmit | None:
    """The mesh's :class:`Transmit` from :func:`material_transmit`'s ``per_slot``, each face's
    slot ``face_slot`` (F,), each face corner's slot ``corner_slot`` (L,) and mesh loop
    ``corner_loop`` (L,), or None when light passes no face."""
    if not any(t > 0 or img is not None for t, img, _ in per_slot):
        return None
    images, image_of = [], []
    for _, img, _ in per_slot:
        image_of.append(len(images) if img is not None else -1)
        if img is not None:
            images.append(img)
    face_image = np.asarray(image_of, np.int64)[face_slot]
    uv = np.zeros((len(corner_loop), 2))
    for k, (_, img, loop_uv) in enumerate(per_slot):
        if img is not None:
            sel = corner_slot == k
            uv[sel] = loop_uv[corner_loop[sel]]
    t = np.array([s[0] for s in per_slot])[face_slot]
    return Transmit(np.where(face_image >= 0, 0.0, t), face_image, uv, images)


def solve_rho(rho, corner_rho, tr, offsets):
    """(F, 3) the faces' reflectance for the solve where an image's alpha cuts them: Cycles'
    albedo carries the alpha at each corner (colour x alpha), so a leaf card whose corners fall
    in holes reads as black and one whose corners fall on the leaf as solid. Each such face
    takes its colour from its opaque corners (alpha over 0.5: the corners' albedo over their
    alpha) times its opacity over the face (:meth:`Transmit.opacity`); a face with no opaque
    corner keeps its corners' mean."""
    if tr is None or tr.face_image is None or not np.any(tr.face_image >= 0):
        return rho
    counts = np.diff(offsets)
    corner_face = np.repeat(np.arange(len(counts)), counts)
    img = tr.face_image[corner_face]
    op = np.zeros(len(corner_face))
    for k in np.unique(img[img >= 0]):
        op[img == k] = 1.0 - tr.images[k].at(tr.corner_uv[img == k])
    w = (op > 0.5).astype(float)
    den = np.bincount(corner_face, weights=w * op, minlength=len(counts))
    num = np.stack([np.bincount(corner_face, weights=w * corner_rho[:, c], minlength=len(counts))
                    for c in range(3)], 1)
    cut = (tr.face_image >= 0) & (den > 0)
    out = np.array(rho, float)
    out[cut] = num[cut] / den[cut, None] * tr.opacity(offsets)[cut, None]
    return np.clip(out, 0.0, RHO_MAX)


def _shader(node, glass, depth):
    """(transmittance, (AlphaImage, UV map name or None) or None) of the shader ``node``."""
    if node is None or depth > 16:
        return 0.0, None
    t = node.type
    if t == "BSDF_TRANSPARENT":
        s = node.inputs["Color"]
        if s.is_linked:
            raise _Unread(f"{node.name} 'Color' is linked")
        return float(np.mean(s.default_value[:3])), None
    if t == "BSDF_PRINCIPLED":
        _transmission(node, glass)
        return _alpha(node, node.inputs["Alpha"], lambda a: 1.0 - a)
    if t in _GLASS:
        glass.append(node.name)
        return 0.0, None
    if t in ("MIX_SHADER", "ADD_SHADER"):
        shaders = [s for s in node.inputs if s.type == "SHADER"][:2]
        parts = [_shader(follow(s)[0], glass, depth + 1) for s in shaders]
        while len(parts) < 2:
            parts.append((0.0, None))
        if any(img is not None for _, img in parts):
            raise _Unread(f"{node.name} mixes an image's alpha")
        (ta, _), (tb, _) = parts
        if t == "ADD_SHADER":
            return min(ta + tb, 1.0), None
        fac = node.inputs[0]
        return _alpha(node, fac, lambda a: ta + a * (tb - ta))
    return 0.0, None


def _transmission(node, glass):
    for name in ("Transmission Weight", "Transmission"):
        s = node.inputs.get(name)
        if s is not None and (s.is_linked or float(s.default_value) > 0):
            glass.append(f"{node.name} '{name}'")
            return


def _alpha(node, socket, to_t):
    """(transmittance ``to_t(value)``, None) of an unlinked ``socket``; (0, (AlphaImage of
    ``to_t(alpha)``, its UV map name or None)) of one an Image Texture's Alpha output feeds;
    raises :class:`_Unread` for anything else."""
    if not socket.is_linked:
        return float(to_t(float(socket.default_value))), None
    src, out = follow(socket)
    if src is None:
        return float(to_t(float(socket.default_value))), None
    if src.type != "TEX_IMAGE" or out.name != "Alpha" or src.image is None:
        raise _Unread(f"{node.name} '{socket.name}' from {src.bl_label} ({out.name})")
    uv_map = None
    vec, _ = follow(src.inputs["Vector"])
    if vec is not None:
        if vec.type != "UVMAP":
            raise _Unread(f"image '{src.image.name}' read through {vec.bl_label}")
        uv_map = vec.uv_map or None
    img = src.image
    W, H = img.size
    if W == 0 or H == 0 or img.channels < 4:
        return float(to_t(1.0)), None                # no alpha channel: alpha 1 everywhere
    alpha = image_pixels(img)[..., 3]
    pixels = np.clip(to_t(alpha.astype(np.float64)), 0.0, 1.0).astype(np.float32)
    return 0.0, (AlphaImage(pixels, closest=src.interpolation == "Closest",
                            repeat=src.extension in ("REPEAT", "MIRROR")), uv_map)


def _uvs(me, name, label, notes):
    """(nloops, 2) the UVs of layer ``name`` (None: the render UV map) of mesh ``me``, or None
    with a warning when it has none."""
    layers = me.uv_layers
    layer = layers.get(name) if name else next((l for l in layers if l.active_render), None)
    if layer is None:
        notes.append(warning("Alpha is not transparency here: the surface is opaque where "
                             "Cycles lets light through", label, detail=f"no UV map '{name or ''}'",
                             topic="materials"))
        return None
    uv = np.empty(len(me.loops) * 2, np.float32)
    layer.data.foreach_get("uv", uv)
    return uv.reshape(-1, 2).astype(np.float64)


def see_through_note(name):
    """The approximation a see-through object brings, said once for all of them."""
    return note(name, "light passes its transparent parts on direct and sky rays; the light "
                      "reflected by what lies behind them is not passed on")
