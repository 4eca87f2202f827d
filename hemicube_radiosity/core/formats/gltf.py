# SPDX-License-Identifier: GPL-3.0-or-later
"""Baked glTF made valid: COLOR_0 tone-mapped into 0..1, the HDR values kept as ``_RADIANCE``.

glTF's COLOR_0 is *linear* and must lie in 0..1 (the Khronos validator reports every value
outside as ``ACCESSOR_NON_CLAMPED``); a viewer multiplies it into the material and applies the
display's sRGB encoding itself. The bake writes HDR radiance (x 2^exposure): a lamp of strength 12
is 12.0. :func:`tone_map_gltf` rewrites a file that Blender's exporter wrote:

* every primitive's float COLOR_0 keeps its values under the application-specific attribute
  ``_RADIANCE`` (float VEC3, allowed by the spec's rule for names starting with an underscore),
* and gets a new float VEC3 COLOR_0 = :func:`display_linear` of them, in 0..1.

:func:`display_linear` returns the *linear* value whose sRGB encoding (done by the viewer) is what
Blender shows on an sRGB display with that view transform:

``standard``
    Blender's "Standard" = clip(x) then the sRGB piecewise OETF (config.ocio: the sRGB display's
    ``ExponentWithLinearTransform {gamma: 2.4, offset: 0.055, direction: inverse}``). So the
    linear value is ``clip(x, 0, 1)`` and the viewer's sRGB output encoding does the rest: a
    glTF viewer and Blender's render give the same 8-bit pixels.
``khronos_neutral``
    The Khronos PBR Neutral tone mapper (the Khronos reference formula); Blender's "Khronos PBR
    Neutral" view is a 3D LUT of the same curve.
``agx``
    AgX-like: the analytic fit of AgX that Filament and three.js use (inset matrix, log2 from
    -12.47 to +4.03 stops, a polynomial sigmoid, outset matrix), decoded with a 2.4 power as
    Blender's AgX LUT output is (three.js uses 2.2, which is further from Blender). Blender's "AgX"
    view is a 3D LUT (``AgX_Base_sRGB.cube``) in E-Gamut: close, not identical (docs/gltf.md).

:func:`add_light_maps` adds a lightmap's lighting-only pass to the materials of lightmapped
copies: the PNG as one more image and texture of the file, named in the material's ``extras``
(glTF has no lightmap slot; see docs/gltf.md for how three.js wires it).

Pure Python + NumPy: reads and writes ``.glb`` and ``.gltf`` (external ``.bin`` or data URI).
"""
from __future__ import annotations

import base64
import json
import os
import shutil
import struct

import numpy as np

__all__ = ["VIEW_TRANSFORMS", "RADIANCE_ATTRIBUTE", "display_linear", "srgb_encode",
           "tone_map_gltf", "add_light_maps", "LIGHT_MAP_EXTRAS", "LIGHTING_NOTE", "read_gltf", "write_gltf"]

RADIANCE_ATTRIBUTE = "_RADIANCE"
VIEW_TRANSFORMS = ("standard", "khronos_neutral", "agx")

LIGHTING_NOTE = ("the light arriving (radiance: irradiance / pi) x the material's albedo scale x "
                 "2^exposure, clamped to 0..1 and sRGB-encoded: multiply the surface's base colour by it")
LIGHT_MAP_EXTRAS = "hemicube_radiosity"   # the key of a material's extras that names its light map
_FLOAT, _ARRAY_BUFFER = 5126, 34962
_GLB_MAGIC, _JSON, _BIN = b"glTF", 0x4E4F534A, 0x004E4942


# ----------------------------------------------------------------------------- colour
def srgb_encode(x):
    """The sRGB piecewise OETF (IEC 61966-2-1) of linear ``x`` in 0..1."""
    x = np.clip(np.asarray(x, np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def _cols(*columns):
    """A GLSL ``mat3(col0, col1, col2)`` as a NumPy matrix (M @ v)."""
    return np.array(columns, np.float64).T


_SRGB_TO_2020 = _cols((0.6274, 0.0691, 0.0164), (0.3293, 0.9195, 0.0880), (0.0433, 0.0113, 0.8956))
_2020_TO_SRGB = _cols((1.6605, -0.1246, -0.0182), (-0.5876, 1.1329, -0.1006), (-0.0728, -0.0083, 1.1187))
_AGX_INSET = _cols((0.856627153315983, 0.137318972929847, 0.11189821299995),
                   (0.0951212405381588, 0.761241990602591, 0.0767994186031903),
                   (0.0482516061458583, 0.101439036467562, 0.811302368396859))
_AGX_OUTSET = _cols((1.1271005818144368, -0.1413297634984383, -0.14132976349843826),
                    (-0.11060664309660323, 1.157823702216272, -0.11060664309660294),
                    (-0.016493938717834573, -0.016493938717834257, 1.2519364065950405))
_AGX_MIN_EV, _AGX_MAX_EV = -12.47393, 4.026069


def _agx(x):
    c = x @ (_AGX_INSET @ _SRGB_TO_2020).T
    c = np.clip((np.log2(np.maximum(c, 1e-10)) - _AGX_MIN_EV) / (_AGX_MAX_EV - _AGX_MIN_EV), 0.0, 1.0)
    c2 = c * c
    c4 = c2 * c2
    c = (15.5 * c4 * c2 - 40.14 * c4 * c + 31.96 * c4 - 6.868 * c2 * c + 0.4298 * c2
         + 0.1191 * c - 0.00232)
    c = np.power(np.maximum(c @ _AGX_OUTSET.T, 0.0), 2.4)
    return c @ _2020_TO_SRGB.T


def _khronos_neutral(x):
    start, desat = 0.8 - 0.04, 0.15
    low = x.min(axis=-1, keepdims=True)
    offset = np.where(low < 0.08, low - 6.25 * low * low, 0.04)
    c = x - offset
    peak = c.max(axis=-1, keepdims=True)
    d = 1.0 - start
    new_peak = 1.0 - d * d / (peak + d - start)
    comp = c * (new_peak / np.where(peak > 0, peak, 1.0))
    g = 1.0 - 1.0 / (desat * (peak - new_peak) + 1.0)
    comp = comp * (1 - g) + new_peak * g
    return np.where(peak < start, c, comp)


def display_linear(rgb, view_transform="standard"):
    """Linear RGB in 0..1 that a viewer shows (after its sRGB encoding) as Blender shows HDR
    linear Rec.709 ``rgb`` (N, 3) through ``view_transform`` on an sRGB display."""
    x = np.nan_to_num(np.asarray(rgb, np.float64), nan=0.0, posinf=1e30, neginf=0.0)
    if view_transform == "standard":
        out = x
    elif view_transform == "khronos_neutral":
        out = _khronos_neutral(x)
    elif view_transform == "agx":
        out = _agx(np.maximum(x, 0.0))
    else:
        raise ValueError(f"unknown view transform {view_transform!r}; choose one of "
                         + ", ".join(VIEW_TRANSFORMS))
    return np.clip(out, 0.0, 1.0)


# ----------------------------------------------------------------------------- file format
def read_gltf(path):
    """(json dict, [bytearray per buffer]) of a ``.glb`` or ``.gltf``."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:4] == _GLB_MAGIC:
        jlen, jtype = struct.unpack_from("<II", data, 12)
        if jtype != _JSON:
            raise ValueError(f"{path}: the first GLB chunk is not JSON")
        doc = json.loads(data[20:20 + jlen])
        buffers = []
        if 20 + jlen < len(data):
            blen, btype = struct.unpack_from("<II", data, 20 + jlen)
            if btype == _BIN:
                buffers.append(bytearray(data[28 + jlen:28 + jlen + blen]))
        return doc, buffers
    doc = json.loads(data)
    base = os.path.dirname(os.path.abspath(path))
    buffers = []
    for b in doc.get("buffers", []):
        uri = b.get("uri", "")
        if uri.startswith("data:"):
            buffers.append(bytearray(base64.b64decode(uri.split(",", 1)[1])))
        else:
            with open(os.path.join(base, uri), "rb") as f:
                buffers.append(bytearray(f.read()))
    return doc, buffers


def write_gltf(path, doc, buffers):
    """Write ``doc`` and ``buffers`` as :func:`read_gltf` read them (same container, same .bin)."""
    with open(path, "rb") as f:
        glb = f.read(4) == _GLB_MAGIC
    if glb:
        js = json.dumps(doc, separators=(",", ":")).encode()
        js += b" " * (-len(js) % 4)
        chunks = struct.pack("<II", len(js), _JSON) + js
        if buffers:
            b = bytes(buffers[0]) + b"\0" * (-len(buffers[0]) % 4)
            chunks += struct.pack("<II", len(b), _BIN) + b
        with open(path, "wb") as f:
            f.write(_GLB_MAGIC + struct.pack("<II", 2, 12 + len(chunks)) + chunks)
        return
    base = os.path.dirname(os.path.abspath(path))
    for b, data in zip(doc.get("buffers", []), buffers):
        uri = b.get("uri", "")
        if uri.startswith("data:"):
            b["uri"] = "data:application/octet-stream;base64," + base64.b64encode(bytes(data)).decode()
        else:
            with open(os.path.join(base, uri), "wb") as f:
                f.write(bytes(data))
    with open(path, "w", encoding="utf-8") as f:
        json.dump(doc, f, indent=2)


_NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}


def _read_float_accessor(doc, buffers, i):
    acc = doc["accessors"][i]
    bv = doc["bufferViews"][acc["bufferView"]]
    k = _NCOMP[acc["type"]]
    stride = bv.get("byteStride", 4 * k)
    off = bv.get("byteOffset", 0) + acc.get("byteOffset", 0)
    n = acc["count"]
    raw = np.frombuffer(bytes(buffers[bv["buffer"]]), np.uint8, count=stride * (n - 1) + 4 * k, offset=off)
    rows = np.lib.stride_tricks.as_strided(raw, (n, 4 * k), (stride, 1))
    return np.ascontiguousarray(rows).view("<f4").reshape(n, k)


def _append_vec3(doc, buffers, values):
    """A new float VEC3 accessor (own buffer view in buffer 0) holding ``values``; its index."""
    if not buffers:
        buffers.append(bytearray())
        doc.setdefault("buffers", []).append({"byteLength": 0})
    buf = buffers[0]
    buf.extend(b"\0" * (-len(buf) % 4))
    data = np.ascontiguousarray(values, "<f4").tobytes()
    doc.setdefault("bufferViews", []).append(
        {"buffer": 0, "byteOffset": len(buf), "byteLength": len(data), "target": _ARRAY_BUFFER})
    buf.extend(data)
    doc["buffers"][0]["byteLength"] = len(buf)
    doc["accessors"].append({"bufferView": len(doc["bufferViews"]) - 1, "componentType": _FLOAT,
                             "count": len(values), "type": "VEC3",
                             "min": values.min(axis=0).tolist() if len(values) else [0, 0, 0],
                             "max": values.max(axis=0).tolist() if len(values) else [0, 0, 0]})
    return len(doc["accessors"]) - 1


def tone_map_gltf(path, view_transform="standard"):
    """Rewrite ``path`` (.glb/.gltf): each float COLOR_0 becomes :func:`display_linear` of its
    values and those HDR values stay as ``_RADIANCE``. A file already done is left alone.
    Returns {'primitives': how many were changed, 'max_radiance': the largest HDR value}."""
    if view_transform not in VIEW_TRANSFORMS:
        raise ValueError(f"unknown view transform {view_transform!r}; choose one of "
                         + ", ".join(VIEW_TRANSFORMS))
    doc, buffers = read_gltf(path)
    done = {}          # COLOR_0 accessor -> (new COLOR_0, _RADIANCE)
    changed, peak = 0, 0.0
    for mesh in doc.get("meshes", []):
        for prim in mesh.get("primitives", []):
            attrs = prim.get("attributes", {})
            i = attrs.get("COLOR_0")
            if i is None or RADIANCE_ATTRIBUTE in attrs:
                continue
            acc = doc["accessors"][i]
            if acc["componentType"] != _FLOAT or "bufferView" not in acc or acc.get("sparse"):
                continue           # normalized integers are in 0..1 already
            if i not in done:
                hdr = _read_float_accessor(doc, buffers, i)[:, :3].astype(np.float64)
                peak = max(peak, float(hdr.max(initial=0.0)))
                rad = i if acc["type"] == "VEC3" else _append_vec3(doc, buffers, hdr)
                done[i] = (_append_vec3(doc, buffers, display_linear(hdr, view_transform)), rad)
            attrs["COLOR_0"], attrs[RADIANCE_ATTRIBUTE] = done[i]
            changed += 1
    if changed:
        extras = doc.setdefault("asset", {}).setdefault("extras", {})
        extras["hemicube_radiosity"] = {
            "COLOR_0": f"linear, 0..1: the baked radiance x 2^exposure through the "
                       f"'{view_transform}' view transform",
            RADIANCE_ATTRIBUTE: "linear HDR: the baked radiance x 2^exposure (Cycles units)",
            "view_transform": view_transform,
        }
        write_gltf(path, doc, buffers)
    return {"primitives": changed, "max_radiance": peak}


def _append_image(doc, buffers, path, png, glb):
    """A new image holding the PNG file ``png``: in buffer 0 (a .glb), else the file copied beside
    ``path`` (a .gltf) and named by its URI; its index."""
    if glb:
        if not buffers:
            buffers.append(bytearray())
            doc.setdefault("buffers", []).append({"byteLength": 0})
        buf = buffers[0]
        buf.extend(b"\0" * (-len(buf) % 4))
        with open(png, "rb") as f:
            data = f.read()
        doc.setdefault("bufferViews", []).append({"buffer": 0, "byteOffset": len(buf), "byteLength": len(data)})
        buf.extend(data)
        doc["buffers"][0]["byteLength"] = len(buf)
        image = {"bufferView": len(doc["bufferViews"]) - 1, "mimeType": "image/png"}
    else:
        name = os.path.basename(png)
        target = os.path.join(os.path.dirname(os.path.abspath(path)), name)
        if os.path.abspath(png) != target:
            shutil.copyfile(png, target)
        image = {"uri": name.replace(" ", "%20"), "mimeType": "image/png"}
    images = doc.setdefault("images", [])
    image["name"] = os.path.splitext(os.path.basename(png))[0]
    images.append(image)
    return len(images) - 1


def add_light_maps(path, maps):
    """Give each material of ``path`` (.glb/.gltf) named in ``maps`` {material name: (PNG file,
    note)} that PNG as a light map: one more image and texture (the sampler and texCoord of the
    material's baseColorTexture), and ``extras[LIGHT_MAP_EXTRAS]`` = {"lightMap": {"index":
    texture, "texCoord": n}, "lightMapPass": note, "baseColorPass": ...}. A material that already
    has one is left alone. Returns how many materials got one."""
    doc, buffers = read_gltf(path)
    with open(path, "rb") as f:
        glb = f.read(4) == _GLB_MAGIC
    count = 0
    for mat in doc.get("materials", []):
        if mat.get("name") not in maps or LIGHT_MAP_EXTRAS in mat.get("extras", {}):
            continue
        png, note = maps[mat["name"]]
        base = mat.get("pbrMetallicRoughness", {}).get("baseColorTexture", {})
        texture = {"source": _append_image(doc, buffers, path, png, glb)}
        if "index" in base and "sampler" in doc["textures"][base["index"]]:
            texture["sampler"] = doc["textures"][base["index"]]["sampler"]
        doc.setdefault("textures", []).append(texture)
        mat.setdefault("extras", {})[LIGHT_MAP_EXTRAS] = {
            "lightMap": {"index": len(doc["textures"]) - 1, "texCoord": int(base.get("texCoord", 0))},
            "lightMapPass": note,
            "baseColorPass": "the radiosity: what the surface shows (radiance x 2^exposure, Standard "
                             "view), unlit",
        }
        count += 1
    if count:
        write_gltf(path, doc, buffers)
    return count
