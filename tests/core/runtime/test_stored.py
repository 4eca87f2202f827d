"""Cache items on disk (:mod:`.runtime.stored`): a relight in a new process finds the geometry."""
import sys

import numpy as np
import pytest

from hemicube_radiosity.core.builtin_scenes import quad
from hemicube_radiosity.core.light.lamps import SunLight
from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.pipeline import BakeSettings, bake
from hemicube_radiosity.core.rays import embree_available
from hemicube_radiosity.core.runtime.cache import FormFactorCache, Memo
from hemicube_radiosity.core.runtime.stored import pack, unpack
from hemicube_radiosity.core.util.sparse import CSR
from tests.support.patching import everywhere


def test_a_structure_of_patches_and_matrices_comes_back_equal_and_anything_else_stays_in_memory(tmp_path):
    P = build_patches([quad([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], name="floor")], 0.25)
    F = CSR.from_dense(np.arange(12.0).reshape(3, 4) % 5, meta={"method": "hemicube", "res": 32})
    F.sky = np.array([0.5, 0.25, 1.0])
    item = (P, [F, None, 3, 2.5, "x"], {"n": np.int64(7), "nan": float("nan")})
    cache = FormFactorCache(tmp_path)
    cache.put("k", item)
    got = FormFactorCache(tmp_path).get("k")             # a new process: from the file
    P2, (F2, none, three, half, x), d = got
    for f in ("verts", "polys", "centers", "normals", "areas", "rho", "emission", "owner", "source_face"):
        a, b = getattr(P, f), getattr(P2, f)
        assert a.dtype == b.dtype
        np.testing.assert_array_equal(a, b)
    assert P2.object_names == P.object_names == ["floor"] and P2.see_through is None
    np.testing.assert_array_equal(F2.to_dense(), F.to_dense())
    np.testing.assert_array_equal(F2.sky, F.sky)
    assert F2.meta == F.meta and F2.shape == F.shape
    assert (none, three, half, x) == (None, 3, 2.5, "x")
    assert d["n"] == 7 and isinstance(d["n"], np.integer) and np.isnan(d["nan"])
    # a function, or an object of a class not marked storable, is not written
    assert pack((P, lambda: 0)) is None and pack(object()) is None
    cache.put("f", (1, print))
    assert FormFactorCache(tmp_path).get("f") is None
    # a file naming a class this process does not know is a miss, not an error
    packed = pack((P,))
    packed["layout"] = np.array(str(packed["layout"]).replace("PatchSet", "Nothing"))
    assert unpack(packed) is None


def _forget_memos():
    """Clear every in-process memo (what a new process starts without)."""
    for name, module in list(sys.modules.items()):
        if module is not None and name.startswith("hemicube_radiosity"):
            for value in list(vars(module).values()):
                if isinstance(value, Memo):
                    value.clear()


def _scene(scale):
    """A smooth-shaded step (corner normals: crease corners) on a floor, a sun and the world."""
    profile = ((-1.0, 0.6), (-0.5, 0.6), (0.0, 0.6), (0.15, 0.3), (0.3, 0.0))
    xs = np.linspace(-1.0, 1.0, 4)
    verts = np.array([(x, y, z) for y, z in profile for x in xs])
    faces = [(k * 4 + i, k * 4 + i + 1, (k + 1) * 4 + i + 1, (k + 1) * 4 + i) for k in range(4) for i in range(3)]
    step = MeshInput.from_faces(verts, faces, name="step")
    seg = [np.array([0.0, z0 - z1, y1 - y0]) / np.hypot(z0 - z1, y1 - y0)
           for (y0, z0), (y1, z1) in zip(profile[:-1], profile[1:])]
    vn = [seg[0]] + [seg[i - 1] + seg[i] for i in range(1, 4)] + [seg[-1]]
    step.corner_normal = np.repeat([v / np.linalg.norm(v) for v in vn], 4, axis=0)[step.face_indices]
    floor = quad([(-1.5, -1.5, 0), (1.5, -1.5, 0), (1.5, 1.5, 0), (-1.5, 1.5, 0)], name="floor")
    sun = SunLight(direction=(0.3, -0.5, -0.8), strength=3.0 * scale)
    return [step, floor], [sun], np.array([0.35, 0.45, 0.6]) * scale


@pytest.mark.skipif(not embree_available(), reason="the gather and the corners need Embree")
def test_a_relight_in_a_new_process_makes_no_geometry_again_and_scales_exactly(tmp_path, monkeypatch):
    """A bake with a cache folder, then (every in-process memo and the cache's memory gone, as
    in a new process) the sun and the world x1.5 with the same folder: the element cut, the
    patches, the located points and the crease corners come from the folder (each made in the
    first bake, forbidden in the second), and the result is 1.5 x the first."""
    from hemicube_radiosity.core.output import crease, indirect, interpolate
    from hemicube_radiosity.core.mesh import contact

    s = BakeSettings(patch_size=0.5, element_size=0.125, gather_rays=64, resolution=32, tolerance=1e-10)
    made = []
    real = {f.__name__: f for f in (build_patches, interpolate.locate, crease.crease_corners,
                                    contact.cut_along_contacts)}

    def spy(name):
        return lambda *a, **k: made.append(name) or real[name](*a, **k)
    for name, f in real.items():
        everywhere(monkeypatch, f, spy(name))
    meshes, lights, world = _scene(1.0)
    first = bake(meshes, s, lights=lights, world=world, cache=FormFactorCache(tmp_path))
    assert set(made) == set(real), made       # the first bake made each of them
    assert first.corner_radiosity is not None  # and lit corners on their own

    def forbidden(*a, **k):
        raise AssertionError("a relight through the cache folder must not make geometry again")
    monkeypatch.undo()
    for f in real.values():
        everywhere(monkeypatch, f, forbidden)
    _forget_memos()
    meshes, lights, world = _scene(1.5)
    warm = bake(meshes, s, lights=lights, world=world, cache=FormFactorCache(tmp_path))
    assert warm.form_factor_source == "cached"
    np.testing.assert_allclose(warm.corner_values(), 1.5 * first.corner_values(), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(warm.vertex_radiosity, 1.5 * first.vertex_radiosity, rtol=1e-9, atol=1e-12)
