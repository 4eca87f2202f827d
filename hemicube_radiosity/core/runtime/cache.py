"""Form-factor cache: form factors depend on geometry alone, so a relight reuses them.

Key = SHA-256 of the patch geometry (vertex positions and patch corners) and the settings that
shape F (method, resolution, rays, rotation seed). Materials, emission, lamps and the world are
not in the key: changing them re-solves only. Kept in memory (a few entries, most recent first)
and, when ``directory`` is set, as ``<key>.npz`` files there.
"""
from __future__ import annotations

import hashlib
import os
from collections import OrderedDict

import numpy as np

from ..util.sparse import CSR

__all__ = ["FormFactorCache", "array_key", "cache_key", "cached", "geometry_key", "kept"]


def cache_key(geometry_key: bytes, settings_key) -> str:
    h = hashlib.sha256(geometry_key)
    h.update(repr(settings_key).encode())
    return h.hexdigest()


def kept(store: dict, key, make, keep: int):
    """``store[key]``, made by ``make()`` when absent and kept with the ``keep`` most recently
    made (the oldest go first; with ``keep`` <= 0 nothing is kept): an in-process memo of what
    a bake asks for again (ray scenes by geometry, emitter outlines)."""
    if keep <= 0:
        return make()
    got = store.get(key)
    if got is None:
        got = make()
        while len(store) >= keep:
            store.pop(next(iter(store)))
        store[key] = got
    return got


_GEOMETRY: dict = {}     # id(polys) -> (verts, polys, key): the last few geometries hashed


def geometry_key(patches) -> bytes:
    """``patches.geometry_key()``, hashed once per pair of ``verts`` and ``polys`` arrays (the
    same objects: a relight's patches and elements share their cached geometry's arrays, and a
    bake keys a dozen products on them). Geometry arrays are never changed in place."""
    v, p = patches.verts, patches.polys
    hit = _GEOMETRY.get(id(p))
    if hit is not None and hit[0] is v and hit[1] is p:
        return hit[2]
    key = patches.geometry_key()
    while len(_GEOMETRY) >= 16:
        _GEOMETRY.pop(next(iter(_GEOMETRY)))
    _GEOMETRY[id(p)] = (v, p, key)
    return key


_ARRAYS: dict = {}       # id(array) -> (array, digest): the last few point sets hashed


def array_key(a) -> bytes:
    """SHA-256 digest of the array ``a``'s dtype, shape and values, hashed once per array object
    (kept, so its id is not reused while remembered): the point sets a bake keys its
    geometry-only products on (a relight's output vertices and patch grid points are the same,
    cached arrays; hashing their bytes again was a few ms of every relight). As for
    :func:`geometry_key`, arrays so keyed are never changed in place; anything else (a list, a
    new array each call) is hashed as given."""
    if not isinstance(a, np.ndarray):
        a = np.asarray(a)
    hit = _ARRAYS.get(id(a))
    if hit is not None and hit[0] is a:
        return hit[1]
    c = np.ascontiguousarray(a)
    h = hashlib.sha256(str(c.dtype).encode() + str(c.shape).encode())
    h.update(c.tobytes())
    key = h.digest()
    _ARRAYS.pop(id(a), None)
    # what is remembered stays alive: at most 32 arrays and ARRAY_MEMO_BYTES of them (a relight's
    # are cached anyway; a bake's one-off point sets go first)
    while _ARRAYS and (len(_ARRAYS) >= 32 or sum(x.nbytes for x, _ in _ARRAYS.values()) + a.nbytes > ARRAY_MEMO_BYTES):
        _ARRAYS.pop(next(iter(_ARRAYS)))
    _ARRAYS[id(a)] = (a, key)
    return key


#: Bytes of arrays :func:`array_key` keeps alive at most.
ARRAY_MEMO_BYTES = 64 << 20


def cached(cache, key, make, disk=True):
    """``cache``'s item under ``key``, made by ``make()`` and stored when absent (no cache: made).
    ``disk=False``: kept in memory only (what is quickly made again from another item, e.g. a
    transport transposed)."""
    item = cache.get(key) if cache is not None else None
    if item is None:
        item = make()
        if cache is not None:
            if disk:
                cache.put(key, item)
            else:
                cache.put(key, item, disk=False)
    return item


class FormFactorCache:
    def __init__(self, directory=None, max_items=256, max_bytes=2 << 30):
        """Keeps at most ``max_items`` items and ``max_bytes`` of arrays in memory (the least
        recently used go first; the newest always stays): a bake stores a dozen items (form
        factors, patches, direct-light transports, the gather's rays), a relight needs them all."""
        self.directory = os.fspath(directory) if directory else None
        self.max_items = max_items
        self.max_bytes = max_bytes
        self._mem: OrderedDict[str, CSR] = OrderedDict()
        self._bytes: dict[str, int] = {}
        if self.directory:
            os.makedirs(self.directory, exist_ok=True)

    def _path(self, key):
        return os.path.join(self.directory, key + ".npz")

    def get(self, key: str):
        """The CSR (or array) stored under ``key``, from memory or disk; None when absent."""
        if key in self._mem:
            self._mem.move_to_end(key)
            return self._mem[key]
        if self.directory and os.path.exists(self._path(key)):
            with np.load(self._path(key), allow_pickle=False) as z:
                item = z["array"] if "array" in z.files else None
            if item is None:
                item = CSR.load(self._path(key))
            self._remember(key, item)
            return item
        return None

    def put(self, key: str, item, disk=True) -> None:
        """Store a CSR (form factors) or an ndarray (e.g. direct-light transport) in memory and
        (unless ``disk`` is False) on disk; anything else (e.g. an output element mesh) in memory
        only."""
        self._remember(key, item)
        if disk and self.directory and isinstance(item, (CSR, np.ndarray)):
            tmp = self._path(key) + ".tmp.npz"
            if isinstance(item, CSR):
                item.save(tmp)
            else:
                np.savez_compressed(tmp, array=np.asarray(item))
            os.replace(tmp, self._path(key))

    def _remember(self, key, F):
        self._mem[key] = F
        self._mem.move_to_end(key)
        self._bytes[key] = _nbytes(F)
        while len(self._mem) > 1 and (len(self._mem) > self.max_items
                                      or sum(self._bytes.values()) > self.max_bytes):
            old, _ = self._mem.popitem(last=False)
            self._bytes.pop(old, None)

    def clear(self) -> None:
        self._mem.clear()
        self._bytes.clear()


def _nbytes(item, depth=0) -> int:
    """Bytes of the arrays in ``item``: an array, a CSR, or the arrays among the fields of a
    tuple or an object (one level down)."""
    if isinstance(item, np.ndarray):
        return int(item.nbytes)
    if isinstance(item, CSR):
        return item.nbytes + (0 if item.sky is None else int(np.asarray(item.sky).nbytes))
    if depth > 1:
        return 0
    parts = item if isinstance(item, (tuple, list)) else getattr(item, "__dict__", {}).values()
    return sum(_nbytes(x, depth + 1) for x in parts)
