"""Automatic sizes follow what was modelled, not one huge plane's bounding box: a room on a
ground plane 100 times its size gets the room's patch size, and the plane one of its own."""
import numpy as np
import pytest

from hemicube_radiosity.core import builtin_scenes as scenes
from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.mesh.sizes import auto_sizes
from hemicube_radiosity.core.pipeline import BakeSettings, bake
from hemicube_radiosity.core.settings import AUTO_PATCHES_PER_DIAGONAL as K
from tests.support.shapes import uv_sphere


def ground(half=110.0):
    """A 220 m ground plane of two triangles, just under the Cornell box (2 m)."""
    v = [(-half, -half, -0.01), (half, -half, -0.01), (half, half, -0.01), (-half, half, -0.01)]
    return MeshInput.from_faces(v, [(0, 1, 2), (0, 2, 3)], rho=(0.3, 0.3, 0.3), name="Ground")


def test_a_huge_ground_plane_does_not_set_the_scene_s_patch_size():
    room = scenes.cornell_box()
    alone, _ = auto_sizes(room, K)
    size, scales = auto_sizes(room + [ground()], K)
    assert size == alone == pytest.approx(np.linalg.norm([2, 2, 2]) / K)
    # the plane: its own diagonal / 14, the others the scene's
    assert scales[-1] * size == pytest.approx(220 * np.sqrt(2) / K, rel=1e-3)
    assert np.all(scales[:-1] == 1.0)


def test_a_room_modelled_as_one_mesh_is_the_scene_not_a_huge_object():
    """The room holds most of the faces: it sets the size though it is far larger than the ball."""
    room = scenes.tessellate([scenes.box((0, 0, 0), (12.0, 10.0, 3.0), inward=True, name="Room")], 8)
    assert len(room[0].face_offsets) - 1 > 100          # 768 faces: not a low-poly plane
    ball = uv_sphere(8, 4)
    ball.verts = ball.verts + (6.0, 5.0, 1.0)
    size, scales = auto_sizes(room + [ball], K)
    assert size == pytest.approx(np.linalg.norm([12, 10, 3]) / K)
    assert np.all(scales == 1.0)


def test_a_room_on_a_huge_plane_bakes_at_the_room_s_cost():
    s = BakeSettings(refine_levels=0, resolution=32)
    alone = bake(scenes.cornell_box(), s)
    both = bake(scenes.cornell_box() + [ground()], s)
    assert alone.settings.patch_size == both.settings.patch_size
    # the fronts at the room's cost; the room's outer walls get backs (light through its open
    # front reaches the ground, which they face), the ground none (its underside faces nothing)
    fronts = lambda r: int(np.count_nonzero(np.asarray(r.back_of)[r.patches.owner if r.clusters is None else r.clusters.owner] < 0))
    assert fronts(both) <= fronts(alone) + 200
    assert "Ground (back)" not in both.patches.object_names
    patch, detail = both.object_sizes(both.patches.object_names.index("Ground"))
    assert patch == pytest.approx(220 * np.sqrt(2) / K, rel=1e-3) and detail == pytest.approx(patch / 3)
    assert both.object_sizes(0) == (alone.settings.patch_size, alone.settings.element_size)
    # the room's light is the room's: the plane, under its floor, is seen only through the open front
    room = both.elements.owner < len(scenes.cornell_box())
    assert len(both.elements.verts) < 2 * len(alone.elements.verts)
    assert np.all(np.isfinite(both.vertex_radiosity)) and room.any()


def test_the_auto_detail_size_fits_the_elements_limit():
    """Long thin faces cut at a third of the patch size would pass Max Details: the automatic
    detail size grows until the elements fit, so the default bakes; a detail size set by hand
    is refused instead, naming one that fits."""
    from hemicube_radiosity.core.mesh.patches import PatchError

    strips = [MeshInput.from_faces([(0, y, 0.5), (2.0, y, 0.5), (2.0, y + 0.004, 0.5)], [(0, 1, 2)],
                                   name=f"Strip{i}") for i, y in enumerate(np.linspace(0.1, 1.9, 50))]
    scene = scenes.cornell_box() + strips
    s = BakeSettings(refine_levels=0, resolution=16, max_elements=20000)
    r = bake(scene, s)
    auto = np.linalg.norm([2, 2, 2]) / K / 3
    assert auto < r.settings.element_size < r.settings.patch_size and len(r.elements) <= 20000
    with pytest.raises(PatchError, match="Max Details"):
        bake(scene, BakeSettings(refine_levels=0, resolution=16, max_elements=20000, element_size=auto))


def test_a_patch_size_set_by_hand_leaves_a_huge_plane_its_own_size():
    s = BakeSettings(patch_size=0.5, element_size=0.1, refine_levels=0, resolution=16)
    r = bake(scenes.cornell_box() + [ground()], s)
    plane = r.object_sizes(r.patches.object_names.index("Ground"))
    assert r.object_sizes(0) == (0.5, 0.1)
    assert plane[0] == pytest.approx(220 * np.sqrt(2) / K, rel=1e-3) and plane[1] == pytest.approx(plane[0] / 5)
