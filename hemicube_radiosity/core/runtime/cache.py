"""Form-factor cache: form factors depend on geometry alone, so a relight reuses them.

Key = SHA-256 of the patch geometry (vertex positions and patch corners) and the settings that
shape F (method, resolution, rays, rotation seed). Materials, emission, lamps and the world are
not in the key: changing them re-solves only. Kept in memory (a few entries, most recent first)
and, when ``directory`` is set, as ``<key>.npz`` files there.

Beside it, :class:`Memo`: the small in-process memos of what a bake or a relight asks for again
(ray scenes, hashes of cached arrays, topology, point grids), keyed by a value or by the
identity of the arrays they were made from.
"""
from __future__ import annotations

import hashlib
import os
from collections import OrderedDict

import numpy as np

from ..util.sparse import CSR
from .stored import LAYOUT, pack, unpack

__all__ = ["FormFactorCache", "Memo", "array_key", "cache_key", "cached", "frozen", "geometry_key",
           "PER_MESH", "inverse"]

#: Entries of the memos kept per mesh of a scene (its welded arrays, face spans, n-gon splits):
#: a scene of hundreds of objects (the staircase hall's 775) must find every one of them again on
#: a relight, or each is made anew and every product keyed on its arrays' identity is too.
PER_MESH = 4096


#: In every key: a cache folder written by a version that computed some entry differently (how
#: vertices are told apart per side, where contacts cut) is not read as this version's. Changed
#: with any change to what a cached entry holds for the same inputs.
COMPUTED = b"2026-12-06c: a flat-shaded mesh's corners at one place share their gather rays"


def cache_key(geometry_key: bytes, settings_key) -> str:
    h = hashlib.sha256(COMPUTED)
    h.update(geometry_key)
    h.update(repr(settings_key).encode())
    return h.hexdigest()


class Memo:
    """The values a bake asks for again, kept in this process: at most ``keep`` (with
    ``max_bytes``: at most that many bytes of the arrays held as keys, too), the oldest made
    (with ``refresh``: the least recently used) dropped first; with ``keep`` <= 0 nothing is
    kept. Two kinds of key:

    * :meth:`get` by a value (a digest of the geometry: ray scenes, emitter outlines);
    * :meth:`of` by the identity of some objects (the arrays of a relight's cached patches,
      which are the same objects every time), plus an optional value ``key`` (sizes, a
      selection's bytes). The objects are held while their value is kept, so their ids cannot
      be reused meanwhile, and a hit is checked with ``is``. Arrays so keyed must never be
      changed in place."""

    def __init__(self, keep: int, *, max_bytes=None, refresh=False):
        self.keep = keep
        self.max_bytes = max_bytes
        self.refresh = refresh
        self._store: dict = {}
        self._held = 0                       # bytes of the objects held (:func:`_nbytes_of`)

    def get(self, key, make):
        """The value under ``key``, made by ``make()`` when absent."""
        hit = self._hit(key)
        if hit is not None:
            return hit[1]
        value = make()
        self._put(key, (), value)
        return value

    def of(self, objs: tuple, make, key=()):
        """The value for the objects ``objs`` (by identity) and ``key``, made by ``make()``
        when absent."""
        ids = (tuple(map(id, objs)), key)
        hit = self._hit(ids)
        if hit is not None and all(a is b for a, b in zip(hit[0], objs)):
            return hit[1]
        value = make()
        self._put(ids, tuple(objs), value)
        return value

    def _hit(self, key):
        """The entry (objects held, value) under ``key``, or None (always, with ``keep`` <= 0)."""
        hit = self._store.get(key) if self.keep > 0 else None
        if hit is not None and self.refresh:                # the most recently used last
            if self._store.pop(key, None) is None:          # (another thread dropped it)
                self._held += _nbytes_of(hit[0])
            self._store[key] = hit
        return hit

    def _put(self, key, objs: tuple, value) -> None:
        """Keep (objs, value) under ``key`` as the newest entry, dropping the oldest beyond
        ``keep`` entries or ``max_bytes`` of objects held."""
        if self.keep <= 0:
            return
        store = self._store
        self._drop(key)
        size = _nbytes_of(objs)
        # the bytes held counted as entries come and go (summed over every entry on each put,
        # a relight of 775 objects spent a second in it)
        while store and (len(store) >= self.keep or self.max_bytes is not None and
                         self._held + size > self.max_bytes):
            self._drop(next(iter(store)))
        store[key] = (objs, value)
        self._held += size

    def _drop(self, key) -> None:
        hit = self._store.pop(key, None)
        if hit is not None:
            self._held -= _nbytes_of(hit[0])

    def clear(self) -> None:
        """Forget every value kept (and let go of the objects held)."""
        self._store.clear()
        self._held = 0

    def __len__(self) -> int:
        return len(self._store)


def _nbytes_of(objs) -> int:
    return sum(int(getattr(o, "nbytes", 0)) for o in objs)


def frozen(*arrays):
    """``arrays`` made read-only (``flags.writeable = False`` on every ndarray among them; None
    and anything else passed through as is) and returned: the one array when given one, else
    the tuple. What a memo keeps is frozen so: :meth:`Memo.of` keys on arrays that are never
    changed in place, and a product made from them is shared by every caller."""
    for a in arrays:
        if isinstance(a, np.ndarray):
            a.flags.writeable = False
    return arrays[0] if len(arrays) == 1 else arrays


_INVERSES = Memo(PER_MESH)


def inverse(M) -> np.ndarray:
    """``np.linalg.inv(M)`` (read only), once per matrix value: the reader and the writer invert
    every object's matrix on every bake, and on a busy machine one LAPACK call on a 3 x 3 took
    a millisecond or more (OpenBLAS's threads; 4 s of the staircase's relight)."""
    M = np.asarray(M, dtype=np.float64)

    return _INVERSES.get((M.shape, M.tobytes()), lambda: frozen(np.linalg.inv(M)))


_GEOMETRY = Memo(16)     # (verts, polys) -> key: the last few geometries hashed


def geometry_key(patches) -> bytes:
    """``patches.geometry_key()``, hashed once per pair of ``verts`` and ``polys`` arrays (the
    same objects: a relight's patches and elements share their cached geometry's arrays, and a
    bake keys a dozen products on them). Geometry arrays are never changed in place."""
    return _GEOMETRY.of((patches.verts, patches.polys), patches.geometry_key)


#: Bytes of arrays :func:`array_key` keeps alive at most.
ARRAY_MEMO_BYTES = 64 << 20
# what is remembered stays alive: at most 32 arrays and ARRAY_MEMO_BYTES of them (a relight's
# are cached anyway; a bake's one-off point sets go first)
_ARRAYS = Memo(32, max_bytes=ARRAY_MEMO_BYTES)     # array -> digest: the last few point sets hashed


def array_key(a) -> bytes:
    """SHA-256 digest of the array ``a``'s dtype, shape and values, hashed once per array object
    (kept, so its id is not reused while remembered): the point sets a bake keys its
    geometry-only products on (a relight's output vertices and patch grid points are the same,
    cached arrays; hashing their bytes again was a few ms of every relight). As for
    :func:`geometry_key`, arrays so keyed are never changed in place; anything else (a list, a
    new array each call) is hashed as given."""
    if not isinstance(a, np.ndarray):
        a = np.asarray(a)

    def digest():
        c = np.ascontiguousarray(a)
        h = hashlib.sha256(str(c.dtype).encode() + str(c.shape).encode())
        h.update(c.tobytes())
        return h.digest()
    return _ARRAYS.of((a,), digest)


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

    def get(self, key: str, remember=True):
        """The CSR (or array) stored under ``key``, from memory or disk; None when absent.
        ``remember`` False: an item read from disk is not kept in memory (many small items,
        the materials' evaluations, must not push the form factors out)."""
        if key in self._mem:
            self._mem.move_to_end(key)
            return self._mem[key]
        if self.directory and os.path.exists(self._path(key)):
            with np.load(self._path(key), allow_pickle=False) as z:
                packed = LAYOUT in z.files
                item = z["array"] if "array" in z.files else unpack(z) if packed else None
            if packed and item is None:
                return None                     # a class this process does not know
            if item is None:
                item = CSR.load(self._path(key))
            if remember:
                self._remember(key, item)
            return item
        return None

    def has(self, key: str) -> bool:
        """Whether an item is stored under ``key`` (in memory or on disk), without reading it."""
        return key in self._mem or bool(self.directory and os.path.exists(self._path(key)))

    def put(self, key: str, item, disk=True, remember=True) -> None:
        """Store a CSR (form factors) or an ndarray (e.g. direct-light transport) in memory and
        (unless ``disk`` is False) on disk, and so any structure of them :func:`.stored.pack`
        can hold (an output element mesh, a point set's located patches: what a relight in a
        new process would otherwise make again); anything else in memory only. ``remember``
        False: on disk only (see :meth:`get`)."""
        if remember or not (disk and self.directory):
            self._remember(key, item)
        if not (disk and self.directory):
            return
        packed = None if isinstance(item, (CSR, np.ndarray)) else pack(item)
        if packed is None and not isinstance(item, (CSR, np.ndarray)):
            return
        tmp = self._path(key) + ".tmp.npz"
        if isinstance(item, CSR):
            item.save(tmp)
        elif packed is not None:
            np.savez(tmp, **packed)             # geometry: read back fast, not compressed
        else:                                   # nor a transport (inflating was most of reading it)
            np.savez(tmp, array=np.asarray(item))
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
