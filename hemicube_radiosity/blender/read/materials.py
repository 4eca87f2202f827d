# SPDX-License-Identifier: GPL-3.0-or-later
"""Materials -> reflectance and emission, (3,) float64 in scene-linear radiance units.

:func:`material_rho_emission` reads a material's plain colour values from its nodes (Principled
BSDF, Diffuse BSDF, Emission, Mix / Add of them). Where that is not what Cycles renders (colours
from textures, colour attributes or other nodes; a Principled BSDF, whose specular layer,
metallic and transmission take light from its diffuse lobe), :func:`.shading.shade` has Cycles
bake the diffuse albedo and emission instead; :func:`corner_materials` takes, material by
material, the node values or Cycles' and gives every face corner of an object its (rho,
emission), made what the solve needs: finite, emission >= 0, reflectance in [0, ``RHO_MAX``].

An emission colour at strength 0 and negative emission are no light, each with a note naming the
material. Strength 0 is no light in Cycles too; negative light is not modelled (the solve needs
emission >= 0): Cycles subtracts light for an Emission node's negative strength, and for a
Principled BSDF's before Blender 5.0 (5.0 clamps that one to no light, as here).

:func:`follow`, :func:`rgb` and :func:`image_pixels` are the node helpers the lamp and world reader
(:mod:`.lights`) shares.
"""
from __future__ import annotations

import numpy as np

from ...core.mesh.patches import RHO_MAX       # the core needs reflectivity < 1 in every band
from ...core.form_factors.glossy import GLOSSY_MIN    # glossy albedo a face mirrors from
from ...core.runtime.notes import Note, note

__all__ = ["RHO_MAX", "rgb", "follow", "image_pixels", "uses_nodes", "material_rho_emission", "corner_materials"]

# Cycles' diffuse plus glossy reflectance this far below a material's colour is worth a note (a
# layer other than diffuse and specular takes light the bake leaves out; glass has its own line);
# Blender's default Principled BSDF (specular IOR level 0.5, IOR 1.5) keeps its colour
UNBAKED_SHARE = 0.10
# a specular or metallic layer reflecting this much or more mirrors its light with its direction
# (core/form_factors/glossy.py: Embree's rays; without Embree the bake spreads it as diffuse light
# and says so): worth a note; the default material's 0.037 is spread, and says nothing
SPREAD_SHARE = GLOSSY_MIN
SPREAD_NOTE = ("its specular or metallic layer mirrors light onto other surfaces as a sharp "
               "mirror does (its roughness is not read; lamps' light off it is spread as diffuse "
               "light, light mirrored twice is not followed)")
DEFAULT_RHO = (0.8, 0.8, 0.8)


def default_surface_rho() -> float:
    """Cycles' diffuse reflectance of a face with no material: its default surface. Blender 5's
    is a Principled BSDF (base colour 0.8, specular IOR level 0.5: a diffuse albedo of 0.770092,
    as a Cycles diffuse-colour bake reads it, tests/blender/test_cycles_parity.py), earlier
    versions' a grey 0.8 Diffuse BSDF. Read as 0.8, a scanned bunny with no material baked
    3.7% brighter than Cycles."""
    return _this_blenders(DEFAULT_SURFACE_RHO)


def default_surface_glossy() -> float:
    """The glossy albedo of Cycles' default surface (a Cycles GLOSSY colour bake of a face with
    no material): Blender 5's Principled BSDF reflects 0.037385 off its specular layer, which the
    solve bounces as a material's (:mod:`..core.form_factors.glossy`); earlier versions' Diffuse
    BSDF none. Left out, a level with no material (godot_zdm2) lost it at every bounce and
    baked 4.1% darker than Cycles."""
    return _this_blenders(DEFAULT_SURFACE_GLOSSY)


def _this_blenders(table) -> float:
    """``table``'s value for the running Blender's (major, minor), or its ``None`` entry."""
    import bpy

    return table.get(bpy.app.version[:2], table[None])


#: Cycles' default surface's diffuse albedo by Blender version (major, minor); None: any other.
DEFAULT_SURFACE_RHO = {(5, 0): 0.770092, None: 0.8}
#: ... and its glossy albedo (:func:`default_surface_glossy`).
DEFAULT_SURFACE_GLOSSY = {(5, 0): 0.037385, None: 0.0}


def rgb(v):
    """(3,) float64 of a colour value (a socket's default, a light's colour) or of a float."""
    try:
        return np.array([float(v[0]), float(v[1]), float(v[2])])
    except TypeError:  # a float socket
        return np.array([float(v)] * 3)


def _input(node, *names):
    for n in names:
        s = node.inputs.get(n)
        if s is not None:
            return s
    return None


def _value(node, notes, *names, default=0.0, color=True):
    s = _input(node, *names)
    if s is None:
        return np.full(3, default) if color else default
    if s.is_linked:
        notes.append(f"{node.name} '{s.name}' is linked (texture/nodes); used its unlinked value")
    if color:
        return rgb(s.default_value)
    return float(s.default_value)


def image_pixels(img) -> np.ndarray:
    """(H, W, channels) float32 the pixels of Blender image ``img``, row 0 at the bottom
    (``Image.pixels`` order)."""
    w, h = img.size
    px = np.empty(w * h * img.channels, np.float32)
    img.pixels.foreach_get(px)
    return px.reshape(h, w, img.channels)


def follow(socket):
    """The node and output socket feeding ``socket``, skipping reroutes; (None, None) if unlinked
    (or the link or the node feeding it is muted)."""
    while socket is not None and socket.is_linked:
        link = socket.links[0]
        if not link.is_valid or link.is_muted:
            return None, None
        node = link.from_node
        if node.type == "REROUTE":
            socket = node.inputs[0]
            continue
        if node.mute:
            return None, None
        return node, link.from_socket
    return None, None


def _note_unlit(node, em, strength, color_name, strength_name, notes):
    """An emission colour with strength 0 is no light in Cycles; say so (Blender 4.2's OBJ
    importer turns an .mtl ``Ke`` into exactly that: the colour, strength 0)."""
    if strength == 0 and np.any(em > 0):
        s = node.inputs.get(strength_name)
        if s is not None and s.is_linked:
            return                       # already noted as linked
        notes.append(f"{node.name} has {color_name} ({em[0]:.3g}, {em[1]:.3g}, {em[2]:.3g}) but "
                     f"{strength_name} 0: no light (as in Cycles); raise the strength to make it glow")


def _principled_clamps_negative_emission():
    """Whether this Blender's Cycles renders a Principled BSDF's negative Emission Strength as no
    light (5.0) rather than as negative light (4.2, 4.5)."""
    import bpy

    return bpy.app.version >= (5, 0, 0)


def _principled(node, notes):
    """(rho, emission) of a Principled BSDF read from its values (the fast path; Cycles' own
    albedo replaces rho when :mod:`.shading` can bake it)."""
    rho = _value(node, notes, "Base Color")
    for name in ("Metallic", "Transmission Weight", "Transmission"):
        s = node.inputs.get(name)
        if s is not None and (s.is_linked or float(s.default_value) > 0):
            notes.append(f"{node.name} '{name}' ignored (diffuse only)")
            break
    em = _value(node, notes, "Emission Color", "Emission")
    strength = _value(node, notes, "Emission Strength", default=1.0, color=False)
    if strength < 0 and np.any(em > 0):
        if _principled_clamps_negative_emission():
            # Cycles 5.0 clamps a Principled BSDF's emission at 0 (measured: no light, bakes 0)
            notes.append(f"{node.name} Emission Strength {strength:g} is negative: no light "
                         "(as in Cycles)")
        else:
            # Cycles 4.x emits negative light there, as from an Emission node (measured on
            # 4.2.23 and 4.5.15: a strength -2 panel bakes -2 x its colour and takes from the
            # floor exactly what strength +2 adds); the solve needs emission >= 0
            notes.append(f"{node.name} Emission Strength {strength:g} is negative: Cycles "
                         "subtracts light there, this bake takes it as no light")
        return rho, np.zeros(3)
    if not np.all(em == 1.0):       # white at strength 0 is every new Principled BSDF: no intent
        _note_unlit(node, em, strength, "Emission Color", "Emission Strength", notes)
    return rho, em * strength


#: shaders with no diffuse part: Cycles' diffuse bake reads 0 from them
_NOT_DIFFUSE = {"BSDF_GLASS", "BSDF_REFRACTION", "BSDF_TRANSPARENT"}


def _shader(node, out_socket, mat, notes, depth=0):
    """(rho, emission) of the shader that ``node`` outputs."""
    zero = np.zeros(3)
    if depth > 16:
        notes.append("shader tree too deep; treated as black")
        return zero, zero
    t = node.type
    if t == "BSDF_PRINCIPLED":
        return _principled(node, notes)
    if t == "BSDF_DIFFUSE":
        return _value(node, notes, "Color"), zero
    if t == "EMISSION":
        em = _value(node, notes, "Color")
        strength = _value(node, notes, "Strength", default=1.0, color=False)
        if strength < 0 and np.any(em > 0):
            # Cycles really emits negative light from an Emission node (it darkens what it sees);
            # the solve needs emission >= 0
            notes.append(f"{node.name} Strength {strength:g} is negative: Cycles subtracts light there, "
                         "this bake takes it as no light")
            return zero, zero
        _note_unlit(node, em, strength, "Color", "Strength", notes)
        return zero, em * strength
    if t in ("MIX_SHADER", "ADD_SHADER"):
        shaders = [s for s in node.inputs if s.type == "SHADER"]
        parts = []
        for s in shaders[:2]:
            n2, o2 = follow(s)
            parts.append(_shader(n2, o2, mat, notes, depth + 1) if n2 is not None else (zero, zero))
        while len(parts) < 2:
            parts.append((zero, zero))
        if t == "ADD_SHADER":
            return parts[0][0] + parts[1][0], parts[0][1] + parts[1][1]
        fac = float(np.clip(_value(node, notes, "Fac", "Factor", color=False), 0.0, 1.0))
        return ((1 - fac) * parts[0][0] + fac * parts[1][0], (1 - fac) * parts[0][1] + fac * parts[1][1])
    if t in _NOT_DIFFUSE:
        # light these pass or refract, none they scatter diffusely (Cycles' diffuse albedo: 0);
        # what they let through is :mod:`.transparency`'s
        return zero, zero
    if out_socket is not None and out_socket.type in ("RGBA", "VECTOR", "VALUE") and t in ("RGB", "VALUE"):
        # A colour wired straight into the output renders as emission of that colour.
        v = out_socket.default_value
        c = np.array([float(v[0]), float(v[1]), float(v[2])]) if out_socket.type != "VALUE" else np.full(3, float(v))
        return zero, c
    notes.append(f"shader '{node.name}' ({node.bl_idname}) approximated by the viewport colour")
    return np.array(mat.diffuse_color[:3], float), zero


def uses_nodes(mat):
    """Blender 5 materials always use their node tree (``use_nodes`` is deprecated there)."""
    import bpy

    if bpy.app.version >= (5, 0, 0):
        return mat.node_tree is not None
    return bool(mat.use_nodes) and mat.node_tree is not None


def material_rho_emission(mat):
    """(rho (3,), emission (3,), notes) of a material, in scene-linear radiance units.

    Principled BSDF: Base Color; Emission Color x Emission Strength. Diffuse BSDF: Color.
    Emission: Color x Strength. Mix/Add shader: mixed/added. Unlinked inputs only (a linked
    input contributes its unlinked value, noted). No material: Cycles' default surface
    (:func:`default_surface_rho`). Material without a node
    tree: its viewport colour. Reflectivity is clipped to [0, 0.999] (noted).
    """
    notes = []
    zero = np.zeros(3)
    if mat is None:                       # Cycles' default surface: Blender's own, no note
        rho, em = np.full(3, default_surface_rho()), zero
    else:
        nt = mat.node_tree if uses_nodes(mat) else None
        if nt is None:
            notes.append(f"material '{mat.name}' has no nodes; used its viewport colour")
            rho, em = np.array(mat.diffuse_color[:3], float), zero
        else:
            outs = [n for n in nt.nodes if n.type == "OUTPUT_MATERIAL" and n.target in ("ALL", "CYCLES")]
            out = next((n for n in outs if n.is_active_output), outs[0] if outs else None)
            if out is None:
                notes.append(f"material '{mat.name}' has no output node; used its viewport colour")
                rho, em = np.array(mat.diffuse_color[:3], float), zero
            else:
                node, sock = follow(out.inputs["Surface"])
                if node is None:
                    notes.append(f"material '{mat.name}' has nothing connected to Surface; black")
                    rho, em = zero, zero
                else:
                    sub = []
                    rho, em = _shader(node, sock, mat, sub)
                    notes += [note(f"material '{mat.name}'", s, warning="viewport colour" in s, topic="materials")
                              for s in sub]
    rho = np.asarray(rho, float)
    em = np.asarray(em, float)
    where = f" in '{mat.name}'" if mat is not None else ""
    for what, v in (("reflectivity", rho), ("emission", em)):
        if not np.all(np.isfinite(v)):
            notes.append(f"{what} {_fmt(v)} is not a number{where}: taken as 0 there, as Cycles "
                         "does; fix the value")
    rho = np.where(np.isfinite(rho), rho, 0.0)
    em = np.where(np.isfinite(em), em, 0.0)
    if np.any(em < 0):
        notes.append(f"negative emission {tuple(np.round(em, 3))} taken as no light"
                     + (f" in '{mat.name}'" if mat is not None else ""))
        em = np.maximum(em, 0.0)
    if np.any(rho > 1.0 + 1e-6) or np.any(rho < 0):
        notes.append(_clipped(f"material '{mat.name}'" if mat is not None else None, rho))
    rho = np.clip(rho, 0.0, RHO_MAX)
    return rho, em, notes


# notes of material_rho_emission that a Cycles evaluation makes moot (it reads what they name)
_FIXED_BY_CYCLES = ("is linked (texture/nodes)", "by the viewport colour", "ignored (diffuse only)",
                    "has no nodes; used its viewport colour")


def corner_materials(name, mats, corner_mat, corner_loop, shaded, used):
    """(corner_rho (L,3), corner_emission (L,3), corner_glossy (L,3), notes) in the order of
    ``corner_loop``.

    Plain materials give their :func:`material_rho_emission` value at every corner (and no
    glossy layer); a material that :func:`.shading.classify` sends to Cycles gives Cycles' value:
    one per material ('constant'), or the object's baked corners ('corners'). ``corner_glossy``
    is the albedo of the specular and metallic layers, clipped to [0, ``RHO_MAX``]."""
    L = corner_loop.size
    corner_rho, corner_em, corner_glossy = np.empty((L, 3)), np.empty((L, 3)), np.zeros((L, 3))
    baked = shaded.corners.get(name)
    notes = []
    if baked is not None and baked[0].shape[0] != L:
        notes.append("Cycles' corner colours did not match the mesh read; used per-material values")
        baked = None
    for k, m in enumerate(mats):
        sel = corner_mat == k
        rho, em, n = material_rho_emission(m)
        kind, why = shaded.kinds.get(m.original.name_full if m is not None else None, ("plain", []))
        label = f"material '{m.name}'" if m is not None else ""
        if kind != "plain" and shaded.failed:
            n.append(f"{label}: {shaded.failed}; its unlinked values used")
        elif kind == "constant" and m.original.name_full in shaded.materials:
            n = [s for s in n if not any(f in s for f in _FIXED_BY_CYCLES)]
            c_rho, c_em, c_glossy = shaded.materials[m.original.name_full]
            n += [_of(label, w) for w in why]
            if np.any(rho - c_rho - c_glossy > UNBAKED_SHARE * np.maximum(rho, 1e-3)) and not _passes_light(m):
                n.append(note(label, "a layer other than diffuse and specular (sheen, subsurface, "
                              "...) takes light this bake leaves out (10% of the colour or more; "
                              "Cycles' diffuse and glossy reflectance are baked)"))
            if np.any(c_glossy >= SPREAD_SHARE):
                n.append(note(label, SPREAD_NOTE))
            rho, em = _clean(c_rho, c_em, label, n)
            corner_glossy[sel] = _glossy(c_glossy)
        elif kind == "corners" and baked is not None:
            n = [s for s in n if not any(f in s for f in _FIXED_BY_CYCLES)]
            n += _textured_notes(label, why)
            r, e = _clean(baked[0][corner_loop[sel]], baked[1][corner_loop[sel]], label, n)
            corner_rho[sel], corner_em[sel] = r, e
            corner_glossy[sel] = _glossy(baked[2][corner_loop[sel]])
            if np.any(corner_glossy[sel] >= SPREAD_SHARE):
                n.append(note(label, SPREAD_NOTE))
            if k in used:
                notes += [s for s in n if s not in notes]
            continue
        elif kind == "corners":
            n.append(f"{label}: not evaluated by Cycles; its unlinked values used")
        elif m is None:                       # Cycles' default surface: its specular layer too
            corner_glossy[sel] = default_surface_glossy()
        corner_rho[sel], corner_em[sel] = rho, em
        if k in used:
            notes += [s for s in n if s not in notes]
    return corner_rho, corner_em, corner_glossy, notes


def _passes_light(mat) -> bool:
    """Whether material ``mat`` has glass in it (a Glass or Refraction BSDF, a Principled BSDF's
    Transmission): what it takes from the diffuse colour is light it passes, which
    :mod:`.transparency` speaks of (glass passes no light in Cycles' shadow rays either)."""
    nt = mat.node_tree if mat is not None and uses_nodes(mat) else None
    for node in (nt.nodes if nt is not None else ()):
        if node.type in ("BSDF_GLASS", "BSDF_REFRACTION"):
            return True
        if node.type == "BSDF_PRINCIPLED":
            s = node.inputs.get("Transmission Weight") or node.inputs.get("Transmission")
            if s is not None and (s.is_linked or float(s.default_value) > 0):
                return True
    return False


def _glossy(g):
    """Cycles' glossy albedo made what the solve needs: finite, in [0, ``RHO_MAX``]."""
    g = np.asarray(g, float)
    return np.clip(np.where(np.isfinite(g), g, 0.0), 0.0, RHO_MAX)


def _of(label, line):
    """``line`` said of the material ``label``, unless it has its own subject (an image)."""
    return line if isinstance(line, Note) and line.subject is not None else note(label, line)


def _textured_notes(label, why):
    """What a material that Cycles evaluates at the corners says: one note of one kind for its
    textures (so materials group into one line) and its other lines as they are. A wired Alpha
    is said by :mod:`.transparency`, which reads it."""
    out, textured = [], []
    for w in why:
        if "'Alpha' from" in w:
            continue
        elif " from " in w and not w.startswith("'") and not isinstance(w, Note):
            textured.append(w)
        else:
            out.append(_of(label, w))
    if textured:
        out.insert(0, note(label, "colour evaluated by Cycles at each output corner; texture "
                                  "detail finer than the corners is averaged",
                           detail="; ".join(textured)))
    return out


def _fmt(c):
    return "(" + ", ".join(f"{x:.3g}" for x in c) + ")"


def _clean(rho, em, label, notes):
    """Cycles' values made what the solve needs: finite, emission >= 0, reflectance in [0, RHO_MAX]."""
    if not (np.all(np.isfinite(rho)) and np.all(np.isfinite(em))):
        notes.append(f"{label}: Cycles evaluates it to a value that is not a number at some corners; "
                     "taken as 0 there")
        rho = np.where(np.isfinite(rho), rho, 0.0)
        em = np.where(np.isfinite(em), em, 0.0)
    if np.any(em < 0):
        # the node reader has already named the negative strength (an Emission node's, or a
        # Principled BSDF's before 5.0, whose negative light Cycles bakes too): one note, not two
        if not any(s.startswith(f"{label}: ") and "is negative" in s for s in notes):
            notes.append(f"{label}: negative emission (an Emission node of negative strength): Cycles "
                         "subtracts light there, this bake takes it as no light")
        em = np.maximum(em, 0.0)
    if np.any(rho > 1.0 + 1e-6) or np.any(rho < 0):
        notes[:] = [s for s in notes if not (getattr(s, "kind", None) == _CLIPPED)]
        notes.append(_clipped(label, rho))
    return np.clip(rho, 0.0, RHO_MAX), em


# white (1.0) is clipped to RHO_MAX too, a 0.1% change not worth saying; more than white is
_CLIPPED = f"reflectivity above 1 or below 0 (more light out than in) clipped to [0, {RHO_MAX}]"


def _clipped(label, rho):
    return note(label, _CLIPPED, detail=f"{float(np.min(rho)):.3g} to {float(np.max(rho)):.3g}")
