"""What several tests share: builders, closed forms and the add-on's installation. Nothing here is
a test; test modules import from here and never from one another.

``ROOT`` is the repository root (the extension's source folder)."""
import os

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def fronts(result, owner):
    """(n,) bool: which of ``owner`` (a result's ``patches.owner``, ``elements.owner`` or
    ``clusters.owner``) are the objects' own faces, not the backs the bake gave their open
    surfaces (core/mesh/backs.py)."""
    import numpy as np

    back_of = np.asarray(result.back_of if result.back_of else [-1] * (int(np.max(owner, initial=0)) + 1))
    return back_of[np.asarray(owner, dtype=np.int64)] < 0
