"""A relight keeps what only the geometry decides: the rays from a receiver to the parts of an
unevenly lit cluster it sees (``core/light/seen.py``), which source corner each output corner
takes its colour from (``core/output/corners.py``). The relight must equal a fresh bake of the
changed scene, bit for bit, after a light change (nothing cast again) and after a geometry edit
(cast again: a moved plate is never served the old rays), from memory and from a cache folder.

The scene is that of ``tests/blender/test_seen_direct.py``: a fan of 32 triangles (one unknown)
lit at its rim and dark under a plate 3 cm above it, under an emitting panel 1.4 m up; the fan
is textured (its corners' reflectivity varies)."""
from __future__ import annotations

import numpy as np
import pytest

from hemicube_radiosity.core.light import seen
from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.output import corners
from hemicube_radiosity.core.pipeline import BakeSettings, bake
from hemicube_radiosity.core.rays import embree_available
from hemicube_radiosity.core.runtime.cache import FormFactorCache

pytestmark = pytest.mark.skipif(not embree_available(), reason="the seen-direct rays need Embree")

SETTINGS = BakeSettings(patch_size=0.5, element_size=0, light_samples=16, light_seed=1)


def _fan(r, z, n=32, down=False, name="fan"):
    a = 2 * np.pi * np.arange(n) / n
    verts = np.concatenate([[[0.0, 0.0, z]], np.column_stack([r * np.cos(a), r * np.sin(a), np.full(n, z)])])
    faces = [(0, 1 + i, 1 + (i + 1) % n)[::-1 if down else 1] for i in range(n)]
    return MeshInput.from_faces(verts, faces, rho=(0.8,) * 3, name=name)


def _scene(plate_z=0.03, strength=20.0):
    disc = _fan(0.1, 0.0, name="disc")
    # a texture: each corner its own reflectivity about the face's
    L = disc.face_indices.size
    disc.corner_rho = 0.8 - 0.3 * np.abs(np.sin(np.arange(L)))[:, None] * np.array([1.0, 0.5, 0.2])
    disc.face_rho = np.add.reduceat(disc.corner_rho, disc.face_offsets[:-1], axis=0) / 3
    disc.face_material = np.zeros(len(disc.face_rho), np.int64)     # one material: grouped
    plate = _fan(0.075, plate_z, down=True, name="plate")
    lamp = MeshInput.from_faces(np.array([[-0.25, -0.25, 1.4], [0.25, -0.25, 1.4], [0.25, 0.25, 1.4],
                                          [-0.25, 0.25, 1.4]]), [(3, 2, 1, 0)], rho=(0.8,) * 3,
                                emission=(strength,) * 3, name="lamp")
    return [disc, plate, lamp]


def _counting(monkeypatch):
    calls = {"hits": 0, "slots": 0}
    hits, slots = seen._hits, corners._corner_slots.__globals__["unique_rows"]

    def counted_hits(*a, **k):
        calls["hits"] += 1
        return hits(*a, **k)

    def counted_rows(*a, **k):
        calls["slots"] += 1
        return slots(*a, **k)
    monkeypatch.setattr(seen, "_hits", counted_hits)
    monkeypatch.setattr(corners, "unique_rows", counted_rows)
    corners._SLOTS.clear()
    return calls


def _same(a, b):
    np.testing.assert_array_equal(a.corner_values(), b.corner_values())
    np.testing.assert_array_equal(a.solution.B, b.solution.B)


@pytest.mark.parametrize("folder", [False, True])
def test_relight_and_edit_equal_fresh_bakes(monkeypatch, tmp_path, folder):
    calls = _counting(monkeypatch)
    cache = FormFactorCache(tmp_path if folder else None)
    first = bake(_scene(), SETTINGS, cache=cache)
    assert calls == {"hits": 1, "slots": 1}, calls          # the scene has what is tested here
    assert seen.seen_direct is not None and first.corner_values() is not None
    if folder:                                              # a new process: only the folder
        cache = FormFactorCache(tmp_path)
        corners._SLOTS.clear()
    relit = bake(_scene(strength=30.0), SETTINGS, cache=cache)
    assert calls == {"hits": 1, "slots": 1}, calls          # light only: nothing cast again
    _same(relit, bake(_scene(strength=30.0), SETTINGS))
    assert np.abs(relit.corner_values() - 1.5 * first.corner_values()).max() \
        <= 1e-8 * np.abs(first.corner_values()).max()
    moved = bake(_scene(plate_z=0.035, strength=30.0), SETTINGS, cache=cache)
    assert calls["hits"] >= 2 and calls["slots"] >= 2, calls    # new geometry: cast again
    _same(moved, bake(_scene(plate_z=0.035, strength=30.0), SETTINGS))
    assert not np.allclose(moved.corner_values()[:len(relit.corner_values())], relit.corner_values())
