# SPDX-License-Identifier: GPL-3.0-or-later
"""Instances take part in the bake as Cycles sees them (``blender/read/instances.py``).

A floor under a crate that exists only as an instance: of a collection by an Empty, of a Geometry
Nodes Mesh Cube through Instance on Points, of an object through Object Info (two instances, one
of them mirrored, under the floor), of a particle system's one particle (its emitter hidden in
renders). A sun at 30 degrees throws the crate's shadow on the floor, a
sunlit wall bounces light into it (as ``cycles_scenes.case_sun``). The floor's corners are baked
by Cycles (DIFFUSE: rho H / pi, the crate instance seen by Cycles) and by the add-on's
``BakeJob`` (one patch per face, the same corners); the shadowed and the lit floor must agree in
the mean, with the instancer selected and not. Without the instances the shadow came out 4x too
bright (0.47 against Cycles' 0.116). Also: the user's scene is unchanged by the read, one note
names the instancers, a selection of nothing but an instancer is refused with one line, an
emitting instance lights the floor as it does in Cycles, an instancer hidden in the viewport is
said, and a textured instance gets Cycles' colours at its corners like its object.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tools import cycles_reference as cr  # noqa: E402
from hemicube_radiosity.blender.bake import BakeJob  # noqa: E402
from hemicube_radiosity.core.pipeline import BakeSettings  # noqa: E402
from hemicube_radiosity.core.runtime.errors import RadiosityError  # noqa: E402
from tests.support.cycles_scenes import RHO, SETTINGS, SUN_ELEVATION, box_arrays, floor_object, shadowed  # noqa: E402
from tests.support.scene import corner_data, scene_hash  # noqa: E402

pytestmark = [pytest.mark.blender, pytest.mark.cycles]

LO, HI = np.array((-0.5, -1.5, 0.0)), np.array((0.5, -0.5, 1.0))     # the crate's box
CENTER = (LO + HI) / 2
ZEN = math.pi / 2 - SUN_ELEVATION
TO_SUN = np.array([0.0, -math.sin(ZEN), math.cos(ZEN)])
SAMPLES = 128
OPERATOR = dict(patch_size=0.25, resolution=32, element_size=0.0)    # the floor's faces are patches
NOTE = "part as occluders and reflectors; their colours are not written"


# ----------------------------------------------------------------------------- scenes
def _crate_object(name="Crate", z0=0.0):
    """A unit crate at the origin (base at z = 0) in a collection excluded from the view layer:
    only its instances are drawn."""
    sc = bpy.context.scene
    coll = bpy.data.collections.new(name + "Coll")
    sc.collection.children.link(coll)
    v, f = box_arrays((-0.5, -0.5, z0), (0.5, 0.5, z0 + 1.0), 4)
    ob = cr.mesh_object(v, f, cr.diffuse_material((RHO,) * 3, name="crate"), name)
    sc.collection.objects.unlink(ob)
    coll.objects.link(ob)
    bpy.context.view_layer.layer_collection.children[coll.name].exclude = True
    return ob, coll


def _gn_object(name, build):
    """A mesh object without faces of its own whose Geometry Nodes modifier makes the tree
    ``build(nodes, links)`` returns the output geometry of."""
    ob = bpy.data.objects.new(name, bpy.data.meshes.new(name))
    bpy.context.scene.collection.objects.link(ob)
    nt = bpy.data.node_groups.new(name, "GeometryNodeTree")
    nt.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    out = nt.nodes.new("NodeGroupOutput")
    nt.links.new(build(nt.nodes, nt.links), out.inputs[0])
    ob.modifiers.new("GN", "NODES").node_group = nt
    return ob


def _points(nodes, positions):
    """A Mesh Line of len(positions) points, at the first and stepping to the second."""
    line = nodes.new("GeometryNodeMeshLine")
    line.inputs["Count"].default_value = len(positions)
    line.inputs["Start Location"].default_value = positions[0]
    step = np.subtract(positions[1], positions[0]) if len(positions) > 1 else (0, 0, 0)
    line.inputs["Offset"].default_value = tuple(map(float, step))
    return line


def _on_points(nodes, links, points, instance, scale=(1.0, 1.0, 1.0)):
    iop = nodes.new("GeometryNodeInstanceOnPoints")
    links.new(points.outputs[0], iop.inputs["Points"])
    links.new(instance, iop.inputs["Instance"])
    iop.inputs["Scale"].default_value = scale
    return iop.outputs[0]


def make_instancer(kind):
    """The crate as instances of kind 'collection', 'cube', 'object' or 'particles'; returns the
    instancer."""
    if kind == "collection":
        _, coll = _crate_object()
        ob = bpy.data.objects.new("Inst", None)
        bpy.context.scene.collection.objects.link(ob)
        ob.instance_type, ob.instance_collection = "COLLECTION", coll
        ob.location = (CENTER[0], CENTER[1], 0.0)
        return ob
    if kind == "cube":
        mat = cr.diffuse_material((RHO,) * 3, name="crate")

        def build(nodes, links):
            cube = nodes.new("GeometryNodeMeshCube")
            for axis in "XYZ":
                cube.inputs[f"Vertices {axis}"].default_value = 5
            setm = nodes.new("GeometryNodeSetMaterial")
            setm.inputs["Material"].default_value = mat
            links.new(cube.outputs[0], setm.inputs[0])
            return _on_points(nodes, links, _points(nodes, [tuple(CENTER)]), setm.outputs[0])
        return _gn_object("Scatter", build)
    if kind == "particles":
        # one particle on a 2 mm emitter inside the crate (the emitter hidden in renders); a
        # particle turns its instance, so the crate is centred on its origin (a cube either way)
        crate, _ = _crate_object(z0=-0.5)
        v, f = cr.grid_arrays(1, 1, CENTER[0] - 1e-3, CENTER[0] + 1e-3, CENTER[1] - 1e-3, CENTER[1] + 1e-3,
                              CENTER[2])
        ob = cr.mesh_object(v, f, None, "Emitter")
        ob.modifiers.new("Particles", "PARTICLE_SYSTEM")
        ps = ob.particle_systems[0].settings
        ps.count, ps.frame_start, ps.frame_end, ps.physics_type = 1, 1, 1, "NO"
        ps.render_type, ps.instance_object, ps.particle_size, ps.size_random = "OBJECT", crate, 1.0, 0.0
        ob.show_instancer_for_render = False
        bpy.context.scene.frame_set(1)
        return ob
    crate, _ = _crate_object()

    def build(nodes, links):
        info = nodes.new("GeometryNodeObjectInfo")
        info.inputs["Object"].default_value = crate
        info.transform_space = "RELATIVE"
        # the second crate sits under the floor, which hides it from the sun and from the floor
        pts = _points(nodes, [(CENTER[0], CENTER[1], 0.0), (CENTER[0], CENTER[1], -3.0)])
        return _on_points(nodes, links, pts, info.outputs["Geometry"], scale=(-1.0, 1.0, 1.0))
    return _gn_object("Scatter", build)


def sun_scene(kind):
    """(floor, instancer): the floor, the wall, the sun and the crate as instances of ``kind``."""
    cr.new_empty_scene()
    floor = floor_object(16, 2.0)
    v, f = cr.grid_arrays(16, 8, -2.0, 2.0, 0.0, 2.0)
    v = np.stack([v[:, 0], np.full(len(v), 2.0), v[:, 1]], 1)       # plane y = 2, facing -y
    cr.mesh_object(v, f, cr.diffuse_material((RHO,) * 3), "wall")
    cr.add_light("SUN", (0, 0, 5), (ZEN, 0, 0), energy=3.0, angle=0.0)
    return floor, make_instancer(kind)


def floor_regions(pos, step=0.25):
    """(deep, lit): floor corners whose whole neighbourhood of +-``step`` is in the crate's shadow,
    or in the sun; the floor under and next to the crate's foot is in neither."""
    offs = np.array([(dx, dy, 0) for dx in (-step, 0, step) for dy in (-step, 0, step)])
    vis = np.stack([shadowed(pos + o, TO_SUN, LO, HI) for o in offs], 1)
    foot = np.all((pos[:, :2] > LO[:2] - step) & (pos[:, :2] < HI[:2] + step), axis=1)
    return vis.all(axis=1) & ~foot, ~vis.any(axis=1) & ~foot


def bake(selection, **settings):
    """(job, baked copy of the first selected object): the add-on's whole bake, as the operator."""
    job = BakeJob.prepare(bpy.context, selection, BakeSettings(**{**SETTINGS, **settings}))
    job.run()
    return job, job.write(bpy.context)


def cycles_floor(floor):
    """(positions, band means) of Cycles' DIFFUSE bake at every floor corner."""
    ref = cr.bake_vertex_radiance([floor], samples=SAMPLES, mode="DIFFUSE")
    me = floor.data
    co = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", co)
    lv = np.empty(len(me.loops), np.int64)
    me.loops.foreach_get("vertex_index", lv)
    return co.reshape(-1, 3)[lv], ref.corner[floor.name].mean(axis=1)


# ----------------------------------------------------------------------------- tests
@pytest.mark.parametrize("selected", [False, True], ids=["floor", "floor+instancer"])
@pytest.mark.parametrize("kind", ["collection", "cube", "object", "particles"])
def test_instanced_crate_shadows_the_floor_as_in_cycles(kind, selected):
    floor, instancer = sun_scene(kind)
    pos, cycles = cycles_floor(floor)
    deep, lit = floor_regions(pos)
    assert deep.sum() >= 30 and lit.sum() >= 600
    before = scene_hash(bpy)
    job = BakeJob.prepare(bpy.context, [floor, instancer] if selected else [floor],
                          BakeSettings(**SETTINGS))
    assert scene_hash(bpy) == before             # the read wrote nothing (its copies are gone)
    assert not [o for o in bpy.data.objects if o.name.startswith("_hr_")]
    job.run()
    copy = job.write(bpy.context)[0]        # (a selected particle emitter is baked as well)
    assert copy.name == "floor.radiosity"
    n = 2 if kind == "object" else 1
    inst = [o for o in job.scene_input.objects if not o.bake and o.name.startswith(instancer.name)]
    assert len(inst) == n
    assert sorted(o.name for o in job.scene_input.objects if not o.bake and o not in inst) == ["wall"]
    said = [m for m in job.messages().notes + job.messages().warnings if NOTE in m]
    word = "instances take" if n > 1 else "instance takes"
    assert said == [f"'{instancer.name}': {n} {word} part as occluders and reflectors; "
                    "their colours are not written"]
    assert not any(instancer.name in m and "faces" in m for m in job.notes)   # no "has no faces"
    rep = job.report()        # an instancer is one entry, however many instances it makes
    assert rep["instances"] == {instancer.name: n} and rep["occluders"] == ["wall"]
    assert not [k for k in rep["per_object"] if "[instance" in k]
    # every instance faces outward, the mirrored ones too (their rings were reversed)
    for o in inst:
        m = o.mesh
        v = m.verts[m.face_indices].reshape(-1, 4, 3)
        normal = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        assert np.all(np.einsum("ij,ij->i", normal, v.mean(axis=1) - m.verts.mean(axis=0)) > 0)
    ours_pos, ours = corner_data(copy)
    d = np.linalg.norm(pos[:, None, :] - ours_pos[None, :, :], axis=2)
    assert d.min(axis=1).max() < 1e-5             # the same corners
    ours = ours[d.argmin(axis=1)].mean(axis=1)
    # measured: deep shadow Cycles 0.1157 (128 samples), ours 0.1154; lit 0.4943 and 0.4937
    assert ours[deep].mean() == pytest.approx(cycles[deep].mean(), rel=0.05)
    assert ours[lit].mean() == pytest.approx(cycles[lit].mean(), rel=0.02)
    assert cycles[deep].mean() < 0.35 * cycles[lit].mean()          # a shadow Cycles sees


def test_instances_of_an_unselected_instancer_stay_out_without_other_meshes():
    floor, instancer = sun_scene("cube")
    job = BakeJob.prepare(bpy.context, [floor], BakeSettings(**SETTINGS, include_others=False))
    assert [o.name for o in job.scene_input.objects] == ["floor"]
    job = BakeJob.prepare(bpy.context, [floor, instancer], BakeSettings(**SETTINGS, include_others=False))
    assert [o.name for o in job.scene_input.objects] == ["floor", "Scatter [instance 1]"]


@pytest.mark.parametrize("kind", ["collection", "cube"])
def test_an_instancer_alone_is_refused_with_one_line(kind):
    _, instancer = sun_scene(kind)
    before = scene_hash(bpy)
    with pytest.raises(RadiosityError) as ex:
        BakeJob.prepare(bpy.context, [instancer], BakeSettings(**SETTINGS))
    msg = str(ex.value)
    assert "\n" not in msg and f"'{instancer.name}'" in msg
    assert scene_hash(bpy) == before


def test_emitting_instances_light_the_floor_as_in_cycles():
    """Two glowing panels made by Instance on Points light the floor (no lamp)."""
    cr.new_empty_scene()
    floor = floor_object(16, 2.0)
    glow = cr.diffuse_material((0.0,) * 3, emission=5.0, name="glow")

    def build(nodes, links):
        grid = nodes.new("GeometryNodeMeshGrid")          # 0.5 m panel, facing up: flip it down
        grid.inputs["Size X"].default_value = grid.inputs["Size Y"].default_value = 0.5
        flip = nodes.new("GeometryNodeFlipFaces")
        links.new(grid.outputs[0], flip.inputs[0])
        setm = nodes.new("GeometryNodeSetMaterial")
        setm.inputs["Material"].default_value = glow
        links.new(flip.outputs[0], setm.inputs[0])
        return _on_points(nodes, links, _points(nodes, [(-0.8, 0.0, 0.8), (0.8, 0.0, 0.8)]), setm.outputs[0])
    lamps = _gn_object("Lamps", build)
    pos, cycles = cycles_floor(floor)
    job, (copy,) = bake([floor])
    said = [m for m in job.notes if "part as occluders" in m]
    assert said == ["'Lamps': 2 instances take part as occluders, reflectors and emitters; their "
                    "colours are not written"]
    ours_pos, ours = corner_data(copy)
    ours = ours[np.linalg.norm(pos[:, None, :] - ours_pos[None, :, :], axis=2).argmin(axis=1)].mean(axis=1)
    assert lamps.name == "Lamps" and cycles.mean() > 0.1
    assert ours.mean() == pytest.approx(cycles.mean(), rel=0.03)
    under = np.linalg.norm(pos[:, :2] - (0.8, 0.0), axis=1) < 0.3
    assert ours[under].mean() == pytest.approx(cycles[under].mean(), rel=0.05)


@pytest.mark.parametrize("hide", ["H", "monitor", "render"])
def test_an_instancer_hidden_in_the_viewport_is_said(hide):
    """Renders show the instances of an Empty hidden in the viewport, the viewport's depsgraph does
    not make them: a warning names it (not a silent shadow missing). Hidden in renders, its
    instances take no part, as in Cycles, and nothing is said."""
    floor, instancer = sun_scene("collection")
    if hide == "H":
        instancer.hide_set(True)
    elif hide == "monitor":
        instancer.hide_viewport = True
    else:
        instancer.hide_render = True
    job = BakeJob.prepare(bpy.context, [floor], BakeSettings(**SETTINGS))
    assert not [o for o in job.scene_input.objects if not o.bake and o.name.startswith("Inst")]
    if hide == "render":
        assert not [m for m in job.notes if "Inst" in m]
        return
    assert list(job.messages().warnings) == [
        "'Inst' is hidden in the viewport, so its instances of collection 'CrateColl' are not read "
        "(renders show them): show it for an exact bake"]
    assert not [m for m in job.notes if NOTE in m]


def test_in_place_with_the_instancer_selected_writes_the_floor_only():
    floor, instancer = sun_scene("cube")
    pos, cycles = cycles_floor(floor)
    deep, _ = floor_regions(pos)
    attrs = sorted(instancer.data.attributes.keys())
    job, written = bake([floor, instancer], output_mode="in_place")
    assert [o.name for o in written] == ["floor"]
    assert sorted(instancer.data.attributes.keys()) == attrs and not instancer.hide_get()
    ours_pos, ours = corner_data(floor)
    assert np.abs(ours_pos - pos).max() < 1e-6
    assert ours.mean(axis=1)[deep].mean() == pytest.approx(cycles[deep].mean(), rel=0.05)


def test_a_textured_instance_is_evaluated_by_cycles_like_its_object():
    """A crate whose Principled Base Color is a UV checker: its instance's reflectance at every
    corner is Cycles' evaluation, the same as the crate's own when it is read as an object."""
    from hemicube_radiosity.blender.read.scene import read_object

    cr.new_empty_scene()
    floor = floor_object(4, 2.0)
    crate, coll = _crate_object()
    m = bpy.data.materials.new("checker")
    if m.node_tree is None:
        m.use_nodes = True                  # Blender < 5: a new material has no nodes yet
    chk = m.node_tree.nodes.new("ShaderNodeTexChecker")
    chk.inputs["Scale"].default_value = 2.0
    m.node_tree.links.new(chk.outputs[0], m.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    crate.data.materials[0] = m
    uv = crate.data.uv_layers.new(name="UVMap")
    co = np.array([crate.data.vertices[l.vertex_index].co for l in crate.data.loops])
    uv.data.foreach_set("uv", (co[:, :2] + co[:, 1:] + 0.5).ravel())
    ob = bpy.data.objects.new("Inst", None)
    bpy.context.scene.collection.objects.link(ob)
    ob.instance_type, ob.instance_collection = "COLLECTION", coll
    job = BakeJob.prepare(bpy.context, [floor], BakeSettings(**SETTINGS))
    (inst,) = [o for o in job.scene_input.objects if not o.bake]
    assert not [n for n in job.notes if "not evaluated" in n or "could not" in n]
    bpy.context.view_layer.layer_collection.children[coll.name].exclude = False
    own = read_object(crate, bpy.context.evaluated_depsgraph_get(), False)
    lo, hi = own.corner_rho.min(), own.corner_rho.max()
    assert lo < 0.3 and hi > 0.7                                  # the checker's two colours
    np.testing.assert_allclose(inst.corner_rho, own.corner_rho, atol=1e-6)
    np.testing.assert_allclose(inst.mesh.verts, own.mesh.verts, atol=1e-6)


@pytest.mark.parametrize("kind", ["collection", "cube"])
def test_the_operator_bakes_with_the_instancer_selected_and_active(addon, kind):
    from tests.support.addon import select, sub

    floor, instancer = sun_scene(kind)
    select(bpy, [instancer, floor])
    assert bpy.ops.object.radiosity_bake(**OPERATOR) == {"FINISHED"}
    (copy,) = sub(addon, "blender.write").copies_of(["floor"])
    assert not sub(addon, "blender.write").copies_of([instancer.name])
    pos, ours = corner_data(copy)
    deep, lit = floor_regions(pos)
    assert ours[deep].mean() < 0.35 * ours[lit].mean()       # the instance's shadow
    select(bpy, [instancer])
    with pytest.raises(RuntimeError, match=rf"^Error: '{instancer.name}' only makes instances, which take "
                       r"part as occluders and reflectors but are not baked: select the meshes to bake "
                       r"as well\n?$"):
        bpy.ops.object.radiosity_bake(**OPERATOR)


def test_an_instanced_object_hidden_in_renders_takes_no_part():
    """Cycles draws no instance of a collection's object hidden in renders (measured: the floor
    in its place lit, 0.468 against 0.116 shadowed): nor does the bake."""
    floor, instancer = sun_scene("collection")
    bpy.data.objects["Crate"].hide_render = True
    job = BakeJob.prepare(bpy.context, [floor], BakeSettings(**SETTINGS))
    assert sorted(o.name for o in job.scene_input.objects) == ["floor", "wall"]
    assert not [m for m in job.notes if NOTE in m]


def test_an_instance_invisible_to_shadow_rays_is_said():
    floor, instancer = sun_scene("collection")
    bpy.data.objects["Crate"].visible_shadow = False
    job = BakeJob.prepare(bpy.context, [floor], BakeSettings(**SETTINGS))
    assert [m for m in job.notes if "shadow rays" in m] == [
        "instances of 'Crate': not visible to shadow rays in Cycles; here it still reflects and casts "
        "shadows like any surface"]


def test_cli_objects_may_name_a_collection_instancer(tmp_path):
    """``--objects floor <Empty instancing a collection>``: the Empty is not refused as 'not a
    mesh object'; its instance takes part (one entry in the report) and the floor is baked."""
    import io
    import json

    from hemicube_radiosity.blender.cli import main as cli

    floor, instancer = (o.name for o in sun_scene("collection"))   # the CLI loads the file anew
    src = str(tmp_path / "scene.blend")
    bpy.ops.wm.save_as_mainfile(filepath=src)
    out, err = io.StringIO(), io.StringIO()
    rc = cli.main(["bake", src, "--objects", floor, instancer, "-o", str(tmp_path / "r.json"),
                   "--patch-size", "0.25", "--element-size", "0", "--resolution", "16"],
                  in_blender=True, out=out, err=err)
    assert rc == 0, err.getvalue()
    rep = json.loads((tmp_path / "r.json").read_text())
    assert rep["instances"] == {instancer: 1} and rep["objects"] == [floor], rep["objects"]
