"""The add-on inside Blender (bpy module): installed as an extension, operator, reader, writer."""
from __future__ import annotations

import importlib
import os

import numpy as np
import pytest

from tests.support.addon import ADDON_MODULE, disable_addon, enable_addon, modal_run, select, sub
from tests.support.scene import corner_data

pytestmark = pytest.mark.blender

# coarse, and the patches are the baked mesh (no detail size): the module bakes in seconds and its
# measured expectations are those of the patch solution itself
BAKE = dict(patch_size=0.25, resolution=32, element_size=0.0)


def mesh_snapshot(me):
    """Every array that defines the mesh, via foreach_get, for bit-identical comparisons."""
    snap = {}
    for coll, prop, dt, k in ((me.vertices, "co", np.float32, 3), (me.loops, "vertex_index", np.int32, 1),
                              (me.edges, "vertices", np.int32, 2), (me.polygons, "loop_start", np.int32, 1),
                              (me.polygons, "material_index", np.int32, 1), (me.polygons, "use_smooth", bool, 1)):
        a = np.empty(len(coll) * k, dt)
        coll.foreach_get(prop, a)
        snap[f"{prop}"] = a
    snap["attributes"] = sorted(a.name for a in me.attributes)
    snap["materials"] = [m.name if m else None for m in me.materials]
    return snap


def region(data, x0, x1, y0, y1):
    pos, col = data
    m = (pos[:, 0] > x0) & (pos[:, 0] < x1) & (pos[:, 1] > y0) & (pos[:, 1] < y1)
    assert m.sum() >= 3, (x0, x1, y0, y1)
    return col[m].mean(axis=0)


# ----------------------------------------------------------------------------- the demo scene
@pytest.fixture(scope="module")
def cornell(addon, tmp_path_factory):
    import bpy

    write = sub(addon, "blender.write")
    bpy.ops.wm.read_homefile(use_empty=True)
    objs = sub(addon, "blender.demo").build_cornell_box(bpy.context)
    blend = str(tmp_path_factory.mktemp("cornell") / "cornell.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    names = [o.name for o in objs]
    before = {o.name: mesh_snapshot(o.data) for o in objs}
    select(bpy, objs)
    result = bpy.ops.object.radiosity_bake(**BAKE)
    coll = bpy.data.collections[write.COLLECTION_NAME]
    copies = {o[write.SOURCE_KEY]: o for o in coll.objects}
    out = dict(
        blend=blend, names=names, before=before, result=result,
        after={n: mesh_snapshot(bpy.data.objects[n].data) for n in names},
        hidden={n: (bpy.data.objects[n].hide_get(), bpy.data.objects[n].hide_render) for n in names},
        data={n: corner_data(copies[n]) for n in names},
        copy_names=sorted(o.name for o in coll.objects),
        counts=(len(bpy.data.objects), len(bpy.data.meshes), len(bpy.data.materials)),
    )
    # re-bake with the copies selected (what the user has after a bake): replaces, no pile-up
    select(bpy, list(coll.objects))
    out["result2"] = bpy.ops.object.radiosity_bake(**BAKE)
    out["counts2"] = (len(bpy.data.objects), len(bpy.data.meshes), len(bpy.data.materials))
    out["copy_names2"] = sorted(o.name for o in bpy.data.collections[write.COLLECTION_NAME].objects)
    return out


def test_bake_operator_runs_on_selection(cornell):
    assert cornell["result"] == {"FINISHED"}
    assert cornell["copy_names"] == sorted(f"{n}.radiosity" for n in cornell["names"])


def test_red_bleeds_onto_floor_near_red_wall(cornell):
    floor = cornell["data"]["Floor"]
    # strips along both walls at 0.5 < y < 1, clear of both blocks' shadows; red wall at x = 0
    # (measured at these settings: red 0.216 vs 0.115, chromaticity ratio 1.54)
    near_red = region(floor, 0.0, 0.3, 0.5, 1.0)
    near_green = region(floor, 1.7, 2.0, 0.5, 1.0)
    ratio_r = near_red[0] / near_green[0]
    # chromaticity: red over green, near each wall (independent of how much light arrives)
    chroma = (near_red[0] / near_red[1]) / (near_green[0] / near_green[1])
    assert ratio_r > 1.5, (near_red, near_green)
    assert chroma > 1.3, (near_red, near_green)
    # and green bleeds the other way
    assert near_green[1] / near_green[0] > near_red[1] / near_red[0]


def test_blocks_cast_shadows(cornell):
    floor = cornell["data"]["Floor"]
    lum = lambda c: float(c.sum())  # noqa: E731
    # behind the tall block, seen from the light at the centre of the ceiling
    behind_tall = lum(region(floor, 1.7, 2.0, 1.7, 2.0))
    # same distance from the wall, open floor at the front
    open_front = lum(region(floor, 1.7, 2.0, 0.0, 0.3))
    assert behind_tall < 0.5 * open_front, (behind_tall, open_front)   # measured 0.089 / 0.370
    # right next to the short block, on the side facing away from the light
    beside_short = lum(region(floor, 0.3, 0.55, 0.05, 0.3))
    open_left = lum(region(floor, 0.3, 0.55, 1.3, 1.7))
    assert beside_short < 0.3 * open_left, (beside_short, open_left)   # measured 0.056 / 0.595


def test_light_is_hdr_and_in_radiance_units(cornell):
    _, col = cornell["data"]["Light"]
    np.testing.assert_allclose(col, 12.0, rtol=1e-6)   # rho = 0: B = E, strength 12 in white


def test_original_meshes_bit_identical_and_hidden(cornell):
    for n in cornell["names"]:
        b, a = cornell["before"][n], cornell["after"][n]
        assert b.keys() == a.keys()
        for k in b:
            if isinstance(b[k], np.ndarray):
                assert b[k].tobytes() == a[k].tobytes(), (n, k)
            else:
                assert b[k] == a[k], (n, k)
        assert cornell["hidden"][n] == (True, True)


def test_rebake_replaces_previous_bake(cornell):
    assert cornell["result2"] == {"FINISHED"}
    assert cornell["counts2"] == cornell["counts"]
    assert cornell["copy_names2"] == cornell["copy_names"]


def test_reopen_restores_scene_and_operator_is_undoable(cornell, addon, bpy_module):
    bpy = bpy_module
    assert "UNDO" in sub(addon, "blender.ui.operators").OBJECT_OT_radiosity_bake.bl_options
    bpy.ops.wm.open_mainfile(filepath=cornell["blend"])
    assert bpy.data.collections.get("Radiosity") is None
    for n in cornell["names"]:
        ob = bpy.data.objects[n]
        assert not ob.hide_get() and not ob.hide_render
        snap = mesh_snapshot(ob.data)
        for k, v in cornell["before"][n].items():
            assert (v.tobytes() == snap[k].tobytes()) if isinstance(v, np.ndarray) else v == snap[k]


# ----------------------------------------------------------------------------- registration
def test_enable_disable_enable_leaves_nothing_behind(addon, empty_scene):
    bpy = empty_scene
    pkg = sub(addon, "blender")
    assert hasattr(bpy.types.Scene, "hemicube_radiosity")
    assert pkg._cli_handle is not None
    disable_addon()
    assert ADDON_MODULE not in bpy.context.preferences.addons
    assert not hasattr(bpy.types.Scene, "hemicube_radiosity")
    for cls in ("OBJECT_OT_radiosity_bake", "OBJECT_OT_radiosity_clear", "RENDER_PT_radiosity_bake",
                "VIEW3D_PT_radiosity_bake", "RadiositySettings"):
        assert not hasattr(bpy.types, cls), cls
    assert not [n for n in dir(bpy.types) if "_PT_radiosity_" in n]    # the sub-panels too
    assert pkg._cli_handle is None
    enable_addon()
    assert ADDON_MODULE in bpy.context.preferences.addons
    assert hasattr(bpy.types, "OBJECT_OT_radiosity_bake")
    assert sub(addon, "blender")._cli_handle is not None
    bpy.ops.mesh.primitive_plane_add()
    assert bpy.ops.object.radiosity_bake(patch_size=0, resolution=8) == {"FINISHED"}


def test_operator_takes_unset_values_from_panel_settings(addon, empty_scene):
    bpy = empty_scene
    bpy.ops.mesh.primitive_plane_add(size=2)
    plane = bpy.context.active_object
    s = bpy.context.scene.hemicube_radiosity
    assert s.auto_size                 # sizes follow the scene unless the artist sets them
    s.auto_size = False
    s.patch_size = 0.5
    s.element_size = 0.0               # the patches are the baked mesh
    s.attribute_name = "FromPanel"
    assert bpy.ops.object.radiosity_bake(resolution=8) == {"FINISHED"}
    copy = sub(addon, "blender.write").copies_of([plane.name])[0]
    assert len(copy.data.polygons) == 16            # 2 m / 0.5 m = 4 x 4 patches
    assert "FromPanel" in copy.data.color_attributes
    assert copy.data.color_attributes.active_color.name == "FromPanel"
    assert copy.data.color_attributes[copy.data.color_attributes.render_color_index].name == "FromPanel"
    # an explicit value wins over the panel
    select(bpy, [copy])
    assert bpy.ops.object.radiosity_bake(resolution=8, patch_size=1.0) == {"FINISHED"}
    assert len(sub(addon, "blender.write").copies_of([plane.name])[0].data.polygons) == 4


# ----------------------------------------------------------------------------- errors
def test_errors_are_reported_with_the_object_name(addon, empty_scene):
    bpy = empty_scene
    with pytest.raises(RuntimeError, match="no mesh object selected"):
        bpy.ops.object.radiosity_bake(**BAKE)
    me = bpy.data.meshes.new("Points")
    me.from_pydata([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [], [])
    ob = bpy.data.objects.new("JustPoints", me)
    bpy.context.scene.collection.objects.link(ob)
    select(bpy, [ob])
    with pytest.raises(RuntimeError, match="'JustPoints' has no faces"):
        bpy.ops.object.radiosity_bake(**BAKE)
    assert len(bpy.data.objects) == 1   # nothing written


# ----------------------------------------------------------------------------- reader
def _plane_grid(bpy, name, faces=2, smooth=False):
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=faces, y_subdivisions=faces, size=2)
    ob = bpy.context.active_object
    ob.name = name
    for p in ob.data.polygons:
        p.use_smooth = smooth
    return ob


def test_weld_rule(addon, empty_scene):
    bpy = empty_scene
    read = sub(addon, "blender.read.scene")
    dg = lambda: bpy.context.evaluated_depsgraph_get()  # noqa: E731
    # a flat-shaded wall cut into 2 x 2 faces stays one surface: 9 shared vertices
    wall = _plane_grid(bpy, "Wall", faces=2)
    assert len(read.read_object(wall, dg()).mesh.verts) == 9
    # flat cube: every face has its own 4 corners; smooth cube: 8 shared corners
    bpy.ops.mesh.primitive_cube_add()
    cube = bpy.context.active_object
    assert len(read.read_object(cube, dg()).mesh.verts) == 24
    for p in cube.data.polygons:
        p.use_smooth = True
    assert len(read.read_object(cube, dg()).mesh.verts) == 8
    # sharp edges all around one smooth face cut it loose (one sharp edge alone does not split
    # a vertex whose faces stay connected through the other edges, as in Blender's normals)
    top = max(cube.data.polygons, key=lambda p: p.center.z)
    for k in top.edge_keys:
        cube.data.edges[[e.key for e in cube.data.edges].index(k)].use_edge_sharp = True
    cube.data.update()
    assert len(read.read_object(cube, dg()).mesh.verts) == 12
    # a material border splits even between coplanar faces
    m1, m2 = bpy.data.materials.new("A"), bpy.data.materials.new("B")
    wall.data.materials.append(m1)
    wall.data.materials.append(m2)
    wall.data.polygons[0].material_index = 1   # one corner face of the 2x2 grid
    assert len(read.read_object(wall, dg()).mesh.verts) == 9 + 3


def test_world_space_modifiers_and_negative_scale(addon, empty_scene):
    bpy = empty_scene
    read = sub(addon, "blender.read.scene")
    bpy.ops.mesh.primitive_plane_add(size=1, location=(1, 2, 3))
    ob = bpy.context.active_object
    ob.scale = (2, 1, 1)
    mod = ob.modifiers.new("Array", "ARRAY")
    mod.count = 3
    src = read.read_object(ob, bpy.context.evaluated_depsgraph_get())
    assert len(src.mesh.face_offsets) - 1 == 3            # modifiers applied
    v = src.mesh.verts
    np.testing.assert_allclose([v[:, 0].min(), v[:, 0].max()], [1 - 1, 1 - 1 + 2 * 3], atol=1e-6)
    np.testing.assert_allclose(v[:, 2], 3.0, atol=1e-6)
    assert len(ob.data.polygons) == 1                       # the original is untouched
    # mirrored object: world-space front stays +z
    ob.modifiers.remove(mod)
    ob.scale = (-1, 1, 1)
    bpy.context.view_layer.update()
    src = read.read_object(ob, bpy.context.evaluated_depsgraph_get())
    assert src.flipped
    ring = src.mesh.verts[src.mesh.face_indices[:3]]
    n = np.cross(ring[1] - ring[0], ring[2] - ring[1])
    assert n[2] > 0, n
    # the baked copy keeps the original's local winding (Blender mirrors it back for display)
    assert bpy.ops.object.radiosity_bake(patch_size=0, resolution=8) == {"FINISHED"}
    copy = sub(addon, "blender.write").copies_of([ob.name])[0]
    np.testing.assert_allclose(np.array(copy.matrix_world), np.array(ob.matrix_world), atol=1e-6)
    np.testing.assert_allclose(copy.data.polygons[0].normal, ob.data.polygons[0].normal, atol=1e-6)


def test_material_reading(addon, empty_scene):
    bpy = empty_scene
    read = sub(addon, "blender.read.materials")

    def principled(name, base, em=(0, 0, 0), strength=0.0):
        m = bpy.data.materials.new(name)
        if m.node_tree is None:
            m.use_nodes = True
        b = m.node_tree.nodes["Principled BSDF"]
        b.inputs["Base Color"].default_value = (*base, 1)
        b.inputs["Emission Color"].default_value = (*em, 1)
        b.inputs["Emission Strength"].default_value = strength
        return m

    def shader(name, kind, **inputs):
        m = bpy.data.materials.new(name)
        if m.node_tree is None:
            m.use_nodes = True
        nt = m.node_tree
        nt.nodes.clear()
        out = nt.nodes.new("ShaderNodeOutputMaterial")
        node = nt.nodes.new(kind)
        for k, v in inputs.items():
            node.inputs[k].default_value = v
        nt.links.new(node.outputs[0], out.inputs["Surface"])
        return m, node

    rho, em, notes = read.material_rho_emission(principled("P", (0.2, 0.4, 0.6), (1, 0.5, 0), 3.0))
    np.testing.assert_allclose(rho, [0.2, 0.4, 0.6], atol=1e-6)
    np.testing.assert_allclose(em, [3.0, 1.5, 0.0], atol=1e-6)
    assert notes == []
    m, _ = shader("D", "ShaderNodeBsdfDiffuse", Color=(0.3, 0.2, 0.1, 1))
    rho, em, _ = read.material_rho_emission(m)
    np.testing.assert_allclose(rho, [0.3, 0.2, 0.1], atol=1e-6)
    np.testing.assert_allclose(em, 0, atol=0)
    m, _ = shader("E", "ShaderNodeEmission", Color=(1, 1, 0.5, 1), Strength=4.0)
    rho, em, _ = read.material_rho_emission(m)
    np.testing.assert_allclose(rho, 0, atol=0)
    np.testing.assert_allclose(em, [4, 4, 2], atol=1e-6)
    # unsupported shader: viewport colour, and said so
    m, _ = shader("G", "ShaderNodeBsdfGlossy")
    m.diffuse_color = (0.1, 0.5, 0.25, 1)
    rho, em, notes = read.material_rho_emission(m)
    np.testing.assert_allclose(rho, [0.1, 0.5, 0.25], atol=1e-6)
    assert any("viewport colour" in n for n in notes)
    # a textured base colour: unlinked value, said so
    m = principled("T", (0.5, 0.5, 0.5))
    tex = m.node_tree.nodes.new("ShaderNodeTexChecker")
    m.node_tree.links.new(tex.outputs["Color"], m.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    rho, _, notes = read.material_rho_emission(m)
    np.testing.assert_allclose(rho, 0.5, atol=1e-6)
    assert any("linked" in n for n in notes)
    # white is clipped below 1 (the solver needs rho < 1), a 0.1% change: not said; above white is
    rho, _, notes = read.material_rho_emission(principled("W", (1, 1, 1)))
    assert np.all(rho < 1) and not any("clipped" in n for n in notes)
    rho, _, notes = read.material_rho_emission(principled("W2", (1.5, 1, 1)))
    assert np.all(rho < 1) and any("'W2'" in n and "clipped" in n for n in notes)
    # no material at all: Cycles' default surface (test_cycles_parity.py bakes it), no note
    rho, em, notes = read.material_rho_emission(None)
    np.testing.assert_allclose(rho, read.default_surface_rho())
    assert not notes and not em.any()
    # the operator reports what it approximated
    bpy.ops.mesh.primitive_plane_add()
    bpy.context.active_object.data.materials.append(bpy.data.materials["G"])
    select(bpy, [bpy.context.active_object])
    sub(addon, "blender.ui.operators")  # registered
    from io import StringIO  # noqa: F401  (reports go to the operator; check the job directly)
    bake = sub(addon, "blender.bake")
    job = bake.BakeJob.prepare(bpy.context, [bpy.context.active_object], bake.BakeSettings())
    assert any("viewport colour" in n for n in job.notes)
    # a shader that is not modelled changes the result: a warning, naming the material
    assert any("viewport colour" in w and "material 'G'" in w for w in job.messages().warnings)
    # what the operator reports after the bake: the warnings first, each a WARNING of its own,
    # then the summary's numbers (the popup lists the same lines)
    job.run()
    lines = sub(addon, "blender.ui.operators").report_lines(job)
    kinds = [k for k, _ in lines]
    assert kinds[0] == {"WARNING"} and kinds.count({"INFO"}) >= 1
    assert kinds == sorted(kinds, key=lambda k: "INFO" in k)           # no warning after the summary
    assert any("material 'G'" in t and "viewport colour" in t for k, t in lines if "WARNING" in k)
    # then where to read what to change (the popup also has a button that opens it)
    helps = [t for k, t in lines if "what to change" in t]
    assert helps[0] == ("Radiosity: what to change: docs/troubleshooting.md, 'Materials (the bake goes on)' "
                        "(https://github.com/hemicube-radiosity/hemicube_radiosity/blob/main/docs/troubleshooting.md"
                        "#materials-the-bake-goes-on)")
    assert len(helps) == len(set(helps)) == len(job.messages().topics)   # once per topic
    assert [t for _, t in lines[len(job.messages().warnings):][:len(helps)]] == helps
    summary = next(t for k, t in lines if "INFO" in k and "what to change" not in t)
    assert summary == job.summary() and "patches solved from 1 face," in summary


def test_lamps_light_the_bake_in_cycles_units(addon, empty_scene):
    """A 1000 W point lamp 2 m above a small plane with no material (Cycles' default surface:
    0.770 in Blender 5, 0.8 before): B = rho I / (pi h^2), I = P / 4 pi."""
    bpy = empty_scene
    bpy.ops.mesh.primitive_plane_add(size=0.01)
    plane = bpy.context.active_object
    bpy.ops.object.light_add(type="POINT", location=(0, 0, 2))
    lamp = bpy.context.active_object
    lamp.data.energy = 1000.0
    lamp.data.shadow_soft_size = 0.0
    select(bpy, [plane])
    rho = sub(addon, "blender.read.materials").default_surface_rho()
    expected = rho * 1000.0 / (4 * np.pi) / 2.0 ** 2 / np.pi
    assert bpy.ops.object.radiosity_bake(patch_size=0, resolution=8) == {"FINISHED"}
    _, col = corner_data(sub(addon, "blender.write").copies_of([plane.name])[0])
    np.testing.assert_allclose(col, expected, rtol=1e-4)
    select(bpy, sub(addon, "blender.write").copies_of([plane.name]))
    assert bpy.ops.object.radiosity_bake(patch_size=0, resolution=8, use_lights=False) == {"FINISHED"}
    _, col = corner_data(sub(addon, "blender.write").copies_of([plane.name])[0])
    np.testing.assert_allclose(col, 0.0, atol=0)


# ----------------------------------------------------------------------------- output modes
def _lit_pair(bpy, linked=True):
    """Two planes facing an emitter; the second is a linked duplicate of the first (shared mesh)."""
    bpy.ops.mesh.primitive_plane_add(size=1, location=(0, 0, 0))
    a = bpy.context.active_object
    a.name = "A"
    b = bpy.data.objects.new("B", a.data if linked else a.data.copy())
    bpy.context.scene.collection.objects.link(b)
    b.location = (3, 0, 0)
    bpy.ops.mesh.primitive_plane_add(size=1, location=(0, 0, 1), rotation=(np.pi, 0, 0))
    lamp = bpy.context.active_object
    lamp.name = "Lamp"
    m = bpy.data.materials.new("Glow")
    if m.node_tree is None:
        m.use_nodes = True
    nt = m.node_tree
    nt.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0, 0, 0, 1)
    nt.nodes["Principled BSDF"].inputs["Emission Color"].default_value = (1, 1, 1, 1)
    nt.nodes["Principled BSDF"].inputs["Emission Strength"].default_value = 5.0
    lamp.data.materials.append(m)
    bpy.context.view_layer.update()
    return a, b, lamp


def test_linked_duplicates_get_their_own_results(addon, empty_scene):
    bpy = empty_scene
    a, b, lamp = _lit_pair(bpy)
    select(bpy, [a, b])
    assert bpy.ops.object.radiosity_bake(patch_size=0.25, resolution=16) == {"FINISHED"}
    write = sub(addon, "blender.write")
    ca, cb = write.copies_of(["A"])[0], write.copies_of(["B"])[0]
    assert ca.data != cb.data
    va, vb = corner_data(ca)[1], corner_data(cb)[1]
    assert va.max() > 10 * vb.max()        # A is under the lamp, B is 3 m to the side
    assert bpy.data.objects["A"].data == bpy.data.objects["B"].data   # still linked
    assert "Lamp.radiosity" not in bpy.data.objects   # the lamp only emits (not selected)


def test_in_place_mode_and_exposure(addon, empty_scene):
    bpy = empty_scene
    a, b, lamp = _lit_pair(bpy)
    shared = a.data
    select(bpy, [a, b])
    assert bpy.ops.object.radiosity_bake(patch_size=0, resolution=16, output_mode="IN_PLACE",
                                         attribute_name="GI") == {"FINISHED"}
    assert bpy.data.collections.get("Radiosity") is None
    assert a.data != b.data and shared in (a.data, b.data)   # linked duplicate was split
    ga, gb = corner_data(a, "GI")[1], corner_data(b, "GI")[1]
    assert ga.max() > 10 * gb.max()
    assert not a.hide_get()
    # against the copy mode at the same settings (faces are the patches, no finer detail): same values
    select(bpy, [a])
    assert bpy.ops.object.radiosity_bake(patch_size=0, resolution=16, attribute_name="GI",
                                         exposure=1.0, element_size=0.0) == {"FINISHED"}
    pos_c, col_c = corner_data(sub(addon, "blender.write").copies_of(["A"])[0], "GI")
    pos_a, col_a = corner_data(a, "GI")
    order_c = np.lexsort(pos_c.T)
    order_a = np.lexsort(pos_a.T)
    np.testing.assert_allclose(pos_c[order_c], pos_a[order_a], atol=1e-6)
    np.testing.assert_allclose(col_c[order_c], 2.0 * col_a[order_a], rtol=1e-5)   # exposure +1
    # back to in place: the copy goes away and the original is shown again
    select(bpy, sub(addon, "blender.write").copies_of(["A"]))
    assert bpy.ops.object.radiosity_bake(patch_size=0, resolution=16, attribute_name="GI",
                                         output_mode="IN_PLACE") == {"FINISHED"}
    assert sub(addon, "blender.write").copies_of(["A"]) == []
    assert not a.hide_get() and not a.hide_render


# ----------------------------------------------------------------------------- progress/cancel
def test_cancel_leaves_scene_unchanged_and_stages_are_printed(addon, empty_scene, capsys):
    bpy = empty_scene
    objs = sub(addon, "blender.demo").build_cornell_box(bpy.context)
    bake = sub(addon, "blender.bake")
    core_progress = importlib.import_module(ADDON_MODULE + ".hemicube_radiosity.core.runtime.progress")
    n_obj, n_mesh = len(bpy.data.objects), len(bpy.data.meshes)
    job = bake.BakeJob.prepare(bpy.context, objs, bake.BakeSettings(**BAKE))
    calls = []

    def cancelled():
        calls.append(1)
        return len(calls) > 2
    with pytest.raises(core_progress.Cancelled):
        job.run(cancelled=cancelled)
    assert job.result is None
    assert (len(bpy.data.objects), len(bpy.data.meshes)) == (n_obj, n_mesh)
    assert bpy.data.collections.get("Radiosity") is None
    # the script path prints one line per stage
    select(bpy, objs)
    capsys.readouterr()
    assert bpy.ops.object.radiosity_bake(**BAKE) == {"FINISHED"}
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("radiosity: ")]
    # and, before the form factors, the time it expects (a line of its own)
    expected = [ln for ln in lines if ln.startswith("radiosity: form factors: expected about ")]
    assert len(expected) == 1 and lines.index(expected[0]) < lines.index(
        next(ln for ln in lines if "nonzeros" in ln)), lines
    lines = [ln for ln in lines if ln not in expected]
    stages = [ln.split(":")[1].strip() for ln in lines]
    assert len(stages) == len(set(stages)), lines                  # one line per stage
    main = [st for st in stages if st in ("patches", "form factors", "solve", "write")]
    assert main == ["patches", "form factors", "solve", "write"], lines
    assert "residual" in lines[stages.index("solve")]
    assert "nonzeros" in lines[stages.index("form factors")]



def test_invoke_without_window_runs_synchronously_and_clear_restores(addon, empty_scene):
    bpy = empty_scene
    bpy.ops.mesh.primitive_plane_add()
    plane = bpy.context.active_object
    assert bpy.ops.object.radiosity_bake("INVOKE_DEFAULT", patch_size=0.5, resolution=8) == {"FINISHED"}
    write = sub(addon, "blender.write")
    assert len(write.copies_of([plane.name])) == 1 and plane.hide_get()
    assert bpy.ops.object.radiosity_clear(all=True) == {"FINISHED"}
    assert write.copies_of([plane.name]) == [] and not plane.hide_get() and not plane.hide_render
    assert len(bpy.data.meshes) == 1


def test_modal_loop_progress_finish_and_esc_cancel(addon, empty_scene):
    bpy = empty_scene
    objs = sub(addon, "blender.demo").build_cornell_box(bpy.context)
    write = sub(addon, "blender.write")
    n_obj = len(bpy.data.objects)
    # Esc: the worker stops, nothing is written, the UI is cleaned up
    ret, op, ui = modal_run(addon, bpy, objs, cancel_first=True)
    assert ret == {"CANCELLED"}
    assert len(bpy.data.objects) == n_obj and write.copies_of([o.name for o in objs]) == []
    assert ui.timers_removed == 1 and ui.ended and ui.status[-1] is None
    assert any("cancelled" in m for _, m in op.reports)
    # to the end: progress rises to the write stage, the result is written on the main thread
    ret, op, ui = modal_run(addon, bpy, objs, cancel_first=False)
    assert ret == {"FINISHED"}
    assert len(write.copies_of([o.name for o in objs])) == 8
    assert ui.progress == sorted(ui.progress) and ui.progress[-1] >= 850
    assert any(s and s.startswith("Radiosity: form factors") for s in ui.status)
    assert ui.timers_removed == 1 and ui.ended and ui.status[-1] is None
    assert any("patches" in m for lvl, m in op.reports if lvl == {"INFO"})
