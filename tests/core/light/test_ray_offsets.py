"""Rays start off their surface by their own object's size, not the scene's (:func:`.rays.ray_offsets`).

A 0.5 m plate lies 5 mm under a roof, both facing up, a sun and a white world above: the roof
hides both from the plate, whose direct light, sky and gathered sky are then exactly 0, while
the roof's open top takes the sun's ``strength * cos`` and the whole sky. A roof 2 km across
must give the same answers as one 2 m across: with rays started 1e-5 of the scene's diagonal
off their surface (2.8 cm), the plate's rays started above the big roof and read the full sun.
"""
import numpy as np
import pytest

from hemicube_radiosity.core.builtin_scenes import quad
from hemicube_radiosity.core.light.lamps import SunLight, direct_irradiance
from hemicube_radiosity.core.light.direct import DirectLight
from hemicube_radiosity.core.mesh.backs import offset
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.output.gather import gather_matrix
from hemicube_radiosity.core.rays import embree_available, embree_scene, mesh_offsets, ray_offsets

pytestmark = pytest.mark.skipif(not embree_available(), reason="needs embreex")

SUN = SunLight((0.3, 0.1, -1.0), strength=3.0)
COS = 1.0 / np.linalg.norm([0.3, 0.1, -1.0])         # the sun's incidence on both planes


def _scene(half):
    """Patches of the roof (owner 0: a square ``2 * half`` across at z = 0) and the plate
    (owner 1: 0.5 m square, 5 mm under it), both facing +Z; the plate's and the roof's test
    points (one each) with their normals."""
    roof = quad([(-half, -half, 0), (half, -half, 0), (half, half, 0), (-half, half, 0)], name="roof")
    z = -0.005
    plate = quad([(-0.25, -0.25, z), (0.25, -0.25, z), (0.25, 0.25, z), (-0.25, 0.25, z)], name="plate")
    ps = build_patches([roof, plate], None)
    pts = np.array([[0.1, 0.05, z], [0.5 * half, 0.3 * half, 0.0]])
    return ps, pts, np.tile([0.0, 0.0, 1.0], (2, 1))


@pytest.mark.parametrize("half", [1000.0, 1.0])
def test_plate_under_a_roof_is_dark_whatever_the_roofs_size(half):
    ps, pts, up = _scene(half)
    plate, roof = ps.owner == 1, ps.owner == 0
    # at the patch centres (their objects known)
    H = direct_irradiance(ps, [SUN])[:, 0]
    np.testing.assert_allclose(H[plate], 0.0, atol=0)
    np.testing.assert_allclose(H[roof], 3.0 * COS, rtol=1e-12)
    # at points (their objects found by a probe ray): sun and world, as the output vertices read them
    light = DirectLight(ps, [SUN], np.zeros(0, np.int64), 1, world=np.ones(3))
    D = light.at(pts, up, "test")[:, 0]
    np.testing.assert_allclose(D, [0.0, 3.0 * COS / np.pi + 1.0], rtol=1e-12, atol=0)
    # the final gather's rays: the plate sees only the roof's underside (nothing), the roof all sky
    _, sky = gather_matrix(ps, pts, up, embree_scene(ps), rays=64)
    np.testing.assert_allclose(sky, [0.0, 1.0], atol=0)


def test_offsets_are_four_backs_of_each_object():
    """Each object's start offset is 4 times its back offset (1e-5 of its own diagonal here), and a
    point takes its own object's, found by the probe even under the big roof's far larger one."""
    ps, pts, up = _scene(1000.0)
    roof = quad([(-1000, -1000, 0), (1000, -1000, 0), (1000, 1000, 0), (-1000, 1000, 0)]).verts
    plate = np.array([(-0.25, -0.25, -0.005), (0.25, 0.25, -0.005)])
    np.testing.assert_allclose(mesh_offsets(ps), [4 * offset(roof), 4 * offset(plate)], rtol=1e-12)
    np.testing.assert_allclose(mesh_offsets(ps), [1e-5 * np.sqrt(8e6), 1e-5 * np.sqrt(0.5)], rtol=1e-12)
    np.testing.assert_allclose(ray_offsets(ps, pts, up), mesh_offsets(ps)[[1, 0]], rtol=0)
