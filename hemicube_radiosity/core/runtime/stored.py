"""Cache items as the arrays of one ``.npz``: what :class:`.cache.FormFactorCache` keeps on disk.

An item is an array, a CSR, or a structure of them: tuples, lists and dicts (string keys) of
arrays, numbers, strings, None and instances of the dataclasses marked :func:`storable` (the
patches, their clusters, an open side: what the geometry-only steps make). :func:`pack` turns
one into ``{name: array}`` (the arrays as they are, their layout as a literal in ``"layout"``),
:func:`unpack` makes it again, equal value for value; anything else is kept in memory only
(:func:`pack` returns None). The layout is read with :func:`ast.literal_eval` and a class only
by its registered name: a cache file makes no object of any other kind.
"""
from __future__ import annotations

import ast
import dataclasses

import numpy as np

__all__ = ["LAYOUT", "pack", "storable", "unpack"]

#: Name of the layout's entry in a packed item.
LAYOUT = "layout"
_TYPES: dict = {}            # registered name -> class


def storable(cls):
    """Class decorator: instances of the dataclass ``cls`` may be packed (their fields)."""
    _TYPES[f"{cls.__module__}.{cls.__qualname__}"] = cls
    return cls


class _Unstorable(Exception):
    pass


def pack(item) -> dict | None:
    """``{name: array}`` holding ``item`` (``LAYOUT``: its structure), or None when some part of
    it cannot be stored (a function, an unregistered object, an object array)."""
    arrays: dict = {}
    try:
        layout = _encode(item, arrays)
    except _Unstorable:
        return None
    arrays[LAYOUT] = np.array(repr(layout))
    return arrays


def _encode(x, arrays):
    if isinstance(x, np.ndarray):
        if x.dtype.hasobject:
            raise _Unstorable
        name = f"a{len(arrays)}"
        arrays[name] = x
        return ("a", name)
    if isinstance(x, np.generic):
        return ("g", _encode(np.asarray(x), arrays))
    if x is None or isinstance(x, (bool, int, float, str)):
        if isinstance(x, float) and not np.isfinite(x):
            return ("g", _encode(np.float64(x), arrays))
        return ("v", x)
    if isinstance(x, (tuple, list)):
        return ("t" if isinstance(x, tuple) else "l", [_encode(v, arrays) for v in x])
    if isinstance(x, dict) and all(isinstance(k, str) for k in x):
        return ("d", [(k, _encode(v, arrays)) for k, v in x.items()])
    name = f"{type(x).__module__}.{type(x).__qualname__}"
    if _TYPES.get(name) is type(x) and dataclasses.is_dataclass(x):
        return ("o", name, [(f.name, _encode(getattr(x, f.name), arrays))
                            for f in dataclasses.fields(x) if f.init])
    raise _Unstorable


def unpack(z):
    """The item :func:`pack` stored in ``z`` (an open ``.npz`` or a dict of its arrays); None
    when it names a class not registered in this process."""
    try:
        return _decode(ast.literal_eval(str(z[LAYOUT])), z)
    except _Unstorable:
        return None


def _decode(e, z):
    tag = e[0]
    if tag == "a":
        return z[e[1]]
    if tag == "g":
        return _decode(e[1], z)[()]
    if tag == "v":
        return e[1]
    if tag in ("t", "l"):
        items = [_decode(v, z) for v in e[1]]
        return tuple(items) if tag == "t" else items
    if tag == "d":
        return {k: _decode(v, z) for k, v in e[1]}
    cls = _TYPES.get(e[1])
    if tag != "o" or cls is None:
        raise _Unstorable
    return cls(**{k: _decode(v, z) for k, v in e[2]})
