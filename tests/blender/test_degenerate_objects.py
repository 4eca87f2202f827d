# SPDX-License-Identifier: GPL-3.0-or-later
"""One object that cannot be baked (every face of zero area, no faces, positions that are not
finite) among good ones is left out with one note naming it and why, and the rest bakes: a real
scene of hundreds of objects (bitterli_wooden_staircase has 20 collapsed to lines) must not be
refused for one of them. Only a selection with nothing bakeable left is refused, with one line.
docs/troubleshooting.md lists the messages."""
from __future__ import annotations

import io
import json

import numpy as np
import pytest

from tests.support.addon import select, sub

pytestmark = pytest.mark.blender

BAKE = dict(patch_size=0.5, resolution=8, element_size=0.0)
CLI_BAKE = ["--patch-size", "0.5", "--resolution", "8", "--element-size", "0"]
QUAD = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]


def mesh_object(bpy, name, verts, faces, edges=(), location=(0, 0, 0)):
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(map(float, v)) for v in verts], list(edges), [tuple(f) for f in faces])
    ob = bpy.data.objects.new(name, me)
    ob.location = location
    bpy.context.scene.collection.objects.link(ob)
    return ob


def lit_floor(bpy):
    """A 1 m floor under a glowing panel (both baked)."""
    floor = mesh_object(bpy, "Floor", QUAD, [(0, 1, 2, 3)])
    lamp = mesh_object(bpy, "Lamp", [(0, 0, 1), (0, 1, 1), (1, 1, 1), (1, 0, 1)], [(0, 1, 2, 3)])
    m = bpy.data.materials.new("Glow")
    if m.node_tree is None:
        m.use_nodes = True                  # Blender < 5: a new material has no nodes yet
    m.node_tree.nodes["Principled BSDF"].inputs["Emission Color"].default_value = (1, 1, 1, 1)
    m.node_tree.nodes["Principled BSDF"].inputs["Emission Strength"].default_value = 5.0
    lamp.data.materials.append(m)
    return [floor, lamp]


def broken_objects(bpy):
    """A collapsed box (all corners on one line, like bitterli_wooden_staircase's 'Mesh432'),
    a wire, and a quad with a NaN corner."""
    line = [(0, 0, t) for t in (0, 0.1, 0.2, 0.3)]
    sliver = mesh_object(bpy, "Sliver", line, [(0, 1, 2), (1, 2, 3), (0, 1, 3, 2)], location=(3, 0, 0))
    wire = mesh_object(bpy, "Wire", QUAD, [], edges=[(0, 1), (1, 2)])
    v = [list(p) for p in QUAD]
    v[2][1] = float("nan")
    nan = mesh_object(bpy, "Broken", v, [(0, 1, 2, 3)])
    return [sliver, wire, nan]


WHY = {"Sliver": "'Sliver': every face has zero area; left out",
       "Wire": "'Wire' has no faces; left out",
       "Broken": "'Broken': 1 vertex position(s) are not finite (NaN or infinity), first vertex 2: "
                 "fix or delete them; left out"}


def test_broken_objects_are_left_out_with_one_note_each(addon, empty_scene):
    bpy = empty_scene
    good = lit_floor(bpy)
    bad = broken_objects(bpy)
    bake = sub(addon, "blender.bake")
    job = bake.BakeJob.prepare(bpy.context, good + bad, bake.BakeSettings(**BAKE))
    assert [o.name for o in job.scene_input.objects] == ["Floor", "Lamp"]
    for name, line in WHY.items():
        assert [n for n in job.notes if f"'{name}'" in n] == [line], job.notes
    job.run()
    r = job.result
    assert r.patches.object_names == ["Floor", "Lamp"]
    floor = r.patches.owner == 0
    # the floor sees the panel 1 m above (form factor of two facing unit squares: 0.1998)
    B = r.solution.B[floor]
    assert np.all(np.isfinite(B)) and B.min() > 0
    assert float(np.average(B[:, 0], weights=r.patches.areas[floor])) == pytest.approx(
        0.8 * 5.0 * 0.1998, rel=0.1)
    # and the operator bakes them, saying so
    select(bpy, good + bad)
    assert bpy.ops.object.radiosity_bake(**BAKE) == {"FINISHED"}
    assert len(sub(addon, "blender.write").copies_of(["Floor"])) == 1
    assert not sub(addon, "blender.write").copies_of(["Sliver"])


def test_only_broken_objects_is_one_line(addon, empty_scene):
    bpy = empty_scene
    bad = broken_objects(bpy)
    select(bpy, bad)
    with pytest.raises(RuntimeError) as ex:
        bpy.ops.object.radiosity_bake(**BAKE)
    text = str(ex.value).strip()
    assert text == ("Error: none of the 3 selected objects can be baked: 'Sliver': every face has zero "
                    "area; 'Wire' has no faces; 'Broken': 1 vertex position(s) are not finite (NaN or "
                    "infinity), first vertex 2: fix or delete them"), text
    # one object alone: its own line, as before
    select(bpy, bad[:1])
    with pytest.raises(RuntimeError, match=r"^Error: 'Sliver': every face has zero area\n?$"):
        bpy.ops.object.radiosity_bake(**BAKE)


def test_zero_area_is_relative_to_the_object_far_from_the_origin(addon, empty_scene):
    """A 1 cm tile 10 km away is fine, a collapsed one there is not: areas are taken relative
    to each face's corner (no cancellation against the 1e4 m coordinates) and compared with the
    object's own size."""
    bpy = empty_scene
    far = (1e4, -1e4, 5e3)
    tile = mesh_object(bpy, "Tile", [(0.01 * x, 0.01 * y, z) for x, y, z in QUAD], [(0, 1, 2, 3)], location=far)
    flat = mesh_object(bpy, "Flat", [(0, 0, 0), (0.01, 0, 0), (0.02, 0, 0), (0.03, 1e-15, 0)],
                       [(0, 1, 2, 3)], location=far)
    reader = sub(addon, "blender.read.scene")
    dg = bpy.context.evaluated_depsgraph_get()
    src = reader.read_object(tile, dg)
    assert src.mesh.face_offsets.tolist() == [0, 4]
    with pytest.raises(reader.ReadError, match="'Flat': every face has zero area"):
        reader.read_object(flat, dg)


def test_broken_occluder_does_not_stop_the_bake(addon, empty_scene):
    """Not selected, a broken object is an occluder that does not occlude (no note)."""
    bpy = empty_scene
    good = lit_floor(bpy)
    broken_objects(bpy)
    bake = sub(addon, "blender.bake")
    job = bake.BakeJob.prepare(bpy.context, good[:1], bake.BakeSettings(**BAKE))
    assert [(o.name, o.bake) for o in job.scene_input.objects] == [("Floor", True), ("Lamp", False)]
    job.run()
    assert np.all(np.isfinite(job.result.solution.B))


def test_cli_bakes_the_rest_and_prints_one_warning_per_object(addon, empty_scene, tmp_path):
    bpy = empty_scene
    lit_floor(bpy)
    broken_objects(bpy)
    src = str(tmp_path / "scene.blend")
    bpy.ops.wm.save_as_mainfile(filepath=src)
    out, err = io.StringIO(), io.StringIO()
    rc = sub(addon, "blender.cli.main").main(["bake", src, "-o", str(tmp_path / "b.json"), *CLI_BAKE],
                                             in_blender=True, out=out, err=err)
    assert rc == 0, err.getvalue()
    said = [ln for ln in out.getvalue().splitlines() if "left out" in ln and ": read: " not in ln]
    # an object left out changes the result: a warning each, before any note
    assert sorted(said) == sorted(f"radiosity: warning: {w}" for w in WHY.values()), out.getvalue()
    lines = out.getvalue().splitlines()
    notes = [i for i, ln in enumerate(lines) if ": note: " in ln]
    assert not notes or max(lines.index(s) for s in said) < min(notes)
    # the read's own line, before the stages
    assert "radiosity: read: 2 object(s) to bake (3 left out), 0 other(s), 2 faces (" in out.getvalue()
    rep = json.loads((tmp_path / "b.json").read_text())
    # the floor has no material: Cycles' default surface, Blender's own default, says nothing
    assert len(rep["warnings"]) == 3 and rep["per_object"]["Floor"]["note"] is None
    assert rep["per_object"]["Floor"]["vertices"] > 0
