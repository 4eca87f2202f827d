"""Replace a function wherever the package looks it up.

``from .gather import gather_matrix`` binds the name in the importing module too, so patching
the defining module alone leaves every caller on the original: a test that forbids the call
("a relight casts no ray") would then check nothing. :func:`everywhere` patches every loaded
module of the package that holds the same object, and returns how many it patched.
:func:`counted_points` counts the points a function is called with; :class:`CountingScene` the
rays cast through a scene.
"""
from __future__ import annotations

import sys


def everywhere(monkeypatch, original, replacement, package="hemicube_radiosity") -> int:
    """Set every module-level name of ``package``'s loaded modules that is ``original`` to
    ``replacement`` (undone by ``monkeypatch`` after the test); at least one must be found."""
    count = 0
    for name, module in list(sys.modules.items()):
        if module is None or not (name == package or name.startswith(package + ".")):
            continue
        for attr, value in list(vars(module).items()):
            if value is original:
                monkeypatch.setattr(module, attr, replacement)
                count += 1
    assert count, f"{original!r} is bound in no module of {package}"
    return count


def counted_points(monkeypatch, module, name) -> list:
    """Wrap ``module.name``, a function whose second argument is an array of points, so that
    each call appends how many points it got to the returned list (undone by ``monkeypatch``)."""
    calls = []
    real = getattr(module, name)

    def counting(head, points, /, *args, **kwargs):
        calls.append(len(points))
        return real(head, points, *args, **kwargs)
    monkeypatch.setattr(module, name, counting)
    return calls


class CountingScene:
    """A ray scene (anything with ``occluded``) that counts the rays cast through it: ``rays``."""

    def __init__(self, scene):
        self.scene, self.rays = scene, 0

    def occluded(self, o, d, *a):
        self.rays += len(o)
        return self.scene.occluded(o, d, *a)
