# SPDX-License-Identifier: GPL-3.0-or-later
"""The reader on the real third-party scenes of ../shared/scenes (its README credits them): every
file opens the way the CLI opens it and reads with default settings, what a render shows, without
an exception; the triangles read are the inspector's counts of the README (less the objects left
out, each with its note); reflectance and emission are what the solve needs. Skipped when the
folder is absent (a fresh clone). Reading is fast enough to run them all: the slowest,
bitterli_wooden_staircase (775 objects, 349 of them textured), took 368 s before the Cycles
material bakes were joined, about 7 s since."""
from __future__ import annotations

import os

import numpy as np
import pytest

from tests.support import ROOT
from tests.support.addon import sub

SCENES = os.path.join(os.path.dirname(ROOT), "shared", "scenes")

pytestmark = [pytest.mark.blender,
              pytest.mark.skipif(not os.path.isdir(SCENES), reason=f"no real scenes at {SCENES}")]

# file: (objects a render shows, objects read, triangles read)
EXPECTED = {
    "bitterli_wooden_staircase/wooden_staircase.blend": (775, 755, 262527),
    "bitterli_breakfast_room/breakfast_room.blend": (53, 53, 269538),
    "bitterli_grey_white_room/grey_white_room.blend": (65, 65, 143163),
    "godot_zdm2/zdm2.blend": (1, 1, 58737),
    "godot_zdm2/zdm2.glb": (1, 1, 58772),
    "godot_living_room/living_room.blend": (2, 2, 5088),
    "godot_living_room/living_room.glb": (2, 2, 5086),
    "godot_truck_town/model/town_model.gltf": (20, 20, 30477),
    "sauer_pandora/pandora.obj": (1, 1, 60690),
    "stanford_bunny/bun_zipper.ply": (1, 1, 69451),
}


def read(addon, rel):
    import bpy

    path = os.path.join(SCENES, rel)
    if not os.path.isfile(path):
        pytest.skip(f"{rel} is not in {SCENES}")
    try:
        sub(addon, "blender.cli.main").load_input(path)
    except sub(addon, "blender.cli.parser").CLIError as ex:
        # the Bitterli scenes were saved by Blender 5, whose file format 4.2 does not read
        if bpy.app.version < (5, 0, 0) and "not a blend file" in str(ex):
            pytest.skip(f"{rel}: Blender {bpy.app.version_string} cannot read it (saved by a newer Blender)")
        raise
    scene = sub(addon, "blender.read.scene")
    objs = sub(addon, "blender.read.visibility").render_visible_objects(bpy.context.view_layer,
                                                                       scene.GEOMETRY_TYPES)
    bake = sub(addon, "blender.bake")
    return len(objs), bake.BakeJob.prepare(bpy.context, objs, bake.BakeSettings())


@pytest.mark.parametrize("rel", list(EXPECTED))
def test_scene_reads(addon, rel):
    objs, job = read(addon, rel)
    shown, kept, tris = EXPECTED[rel]
    s = job.scene_input
    assert objs == shown and len(s.objects) == kept
    assert sum(int((np.diff(o.mesh.face_offsets) - 2).sum()) for o in s.objects) == tris
    assert len(s.skipped) == shown - kept and all(n.endswith("; left out") for n in s.skipped)
    for o in s.objects:
        m = o.mesh
        assert np.all(np.isfinite(m.verts))
        assert m.face_rho.min() >= 0 and m.face_rho.max() < 1 and m.face_emission.min() >= 0
        assert np.all(np.isfinite(o.corner_rho)) and np.all(np.isfinite(o.corner_emission))
    assert not any("Cycles could not evaluate" in n for n in job.notes)
    # what a person reads: a handful of lines, each a different kind, however many objects
    # (the staircase's 755 objects say 622 lines; grouped, 3)
    m = job.messages()
    assert len(m.warnings) + len(m.notes) <= 4, m
    assert len(m.warnings) == len(set(m.warnings)) and len(m.notes) == len(set(m.notes))
    check = CHECKS.get(rel)
    if check is not None:
        check(job)


def wooden_staircase(job):
    """20 objects are collapsed to lines (every face below 1e-17 m2): each is left out with one
    note, and the rest reads: the emitter at radiance 30, the textured floor and stairs varying
    over their corners as Cycles evaluates the images."""
    left = [n for n in job.notes if n.endswith("every face has zero area; left out")]
    assert len(left) == 20 and "'Mesh432': every face has zero area; left out" in left
    names = {o.name for o in job.scene_input.objects}
    assert "Mesh432" not in names and len(names) == 755
    em = np.concatenate([o.mesh.face_emission for o in job.scene_input.objects])
    np.testing.assert_allclose(em.max(axis=0), 30.0)
    textured = [o for o in job.scene_input.objects if o.mesh.corner_rho is not None]
    assert len(textured) > 300
    assert max(float(np.ptp(o.corner_rho[:, 0])) for o in textured) > 0.3


def pandora(job):
    """sauer_pandora's .mtl gives 206 materials 35 textures the scene does not include: their
    materials read as their own colour, not Cycles' magenta for a missing image; each image is
    said once, and all of them in one warning line."""
    rho = job.scene_input.objects[0].mesh.face_rho
    np.testing.assert_allclose(rho, 0.8, atol=1e-6)
    missing = [n for n in job.notes if "cannot be read" in n and "magenta" in n]
    assert len(missing) == len({n.subject for n in missing}) == 35
    warned = [w for w in job.messages().warnings if "cannot be read" in w]
    assert len(warned) == 1 and warned[0].startswith("images '") and "and 31 more" in warned[0]


CHECKS = {"bitterli_wooden_staircase/wooden_staircase.blend": wooden_staircase,
          "sauer_pandora/pandora.obj": pandora}
