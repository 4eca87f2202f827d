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

from .sparse import CSR

__all__ = ["FormFactorCache", "cache_key"]


def cache_key(geometry_key: bytes, settings_key) -> str:
    h = hashlib.sha256(geometry_key)
    h.update(repr(settings_key).encode())
    return h.hexdigest()


class FormFactorCache:
    def __init__(self, directory=None, max_items=4):
        self.directory = os.fspath(directory) if directory else None
        self.max_items = max_items
        self._mem: OrderedDict[str, CSR] = OrderedDict()
        if self.directory:
            os.makedirs(self.directory, exist_ok=True)

    def _path(self, key):
        return os.path.join(self.directory, key + ".npz")

    def get(self, key: str) -> CSR | None:
        if key in self._mem:
            self._mem.move_to_end(key)
            return self._mem[key]
        if self.directory and os.path.exists(self._path(key)):
            F = CSR.load(self._path(key))
            self._remember(key, F)
            return F
        return None

    def put(self, key: str, F: CSR) -> None:
        self._remember(key, F)
        if self.directory:
            tmp = self._path(key) + ".tmp.npz"
            F.save(tmp)
            os.replace(tmp, self._path(key))

    def _remember(self, key, F):
        self._mem[key] = F
        self._mem.move_to_end(key)
        while len(self._mem) > self.max_items:
            self._mem.popitem(last=False)

    def clear(self) -> None:
        self._mem.clear()
