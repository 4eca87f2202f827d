"""glTF files read back without the exporter: the JSON and the accessors of a .glb or .gltf (+ .bin),
with struct and json only, so a test checks what was written, not what Blender reads."""
import json
import os
import struct

import numpy as np


def read_gltf(path):
    """(json dict, accessor reader) of a .glb or .gltf (+ .bin) file, with struct + json only.

    ``accessor(i)`` returns accessor ``i`` as a float64/int64 array of shape (count, components).
    """
    with open(path, "rb") as f:
        data = f.read()
    if data[:4] == b"glTF":
        _, _, length = struct.unpack_from("<III", data, 0)
        jlen, jtype = struct.unpack_from("<II", data, 12)
        assert jtype == 0x4E4F534A  # JSON
        doc = json.loads(data[20:20 + jlen])
        blen, btype = struct.unpack_from("<II", data, 20 + jlen)
        assert btype == 0x004E4942  # BIN
        buffers = [data[28 + jlen:28 + jlen + blen]]
    else:
        doc = json.loads(data)
        base = os.path.dirname(path)
        buffers = []
        for b in doc["buffers"]:
            with open(os.path.join(base, b["uri"]), "rb") as f:
                buffers.append(f.read())
    ncomp = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}
    dtypes = {5126: np.float32, 5125: np.uint32, 5123: np.uint16, 5121: np.uint8}

    def accessor(i):
        acc = doc["accessors"][i]
        bv = doc["bufferViews"][acc["bufferView"]]
        k = ncomp[acc["type"]]
        dt = np.dtype(dtypes[acc["componentType"]])
        off = bv.get("byteOffset", 0) + acc.get("byteOffset", 0)
        stride = bv.get("byteStride", k * dt.itemsize)
        buf = buffers[bv["buffer"]]
        raw = np.frombuffer(buf, np.uint8, count=stride * (acc["count"] - 1) + k * dt.itemsize, offset=off)
        rows = np.lib.stride_tricks.as_strided(raw, (acc["count"], k * dt.itemsize), (stride, 1))
        out = np.ascontiguousarray(rows).view(dt).reshape(acc["count"], k)
        return out.astype(np.float64 if dt.kind == "f" else np.int64)

    return doc, accessor
