"""Hard cases and bad input: each is a correct bake, or one line naming the object (or
file) and the problem, with a non-zero exit from the CLI, the input file byte-identical and the
scene unchanged (``conftest.scene_hash``: every mesh's vertices, faces and attributes, every
object's visibility). Core-level where the core decides, through the operator and the CLI where
Blender is involved. The messages are listed with their causes in docs/troubleshooting.md."""
from __future__ import annotations

import errno
import io
import os

import numpy as np
import pytest

from tests.support.addon import MODAL_BAKE, modal_run, select, sub
from tests.support.scene import file_sha256, node_tree, scene_hash

from hemicube_radiosity.core.mesh.patches import MeshInput, PatchError
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.pipeline import BakeSettings as CoreSettings, bake as core_bake
from hemicube_radiosity.core.runtime.progress import Cancelled as CoreCancelled

pytestmark = pytest.mark.blender

BAKE = dict(patch_size=0.5, resolution=8, element_size=0.0)
CLI_BAKE = ["--patch-size", "0.5", "--resolution", "8", "--element-size", "0"]
QUAD = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]


def run_cli(addon, argv):
    out, err = io.StringIO(), io.StringIO()
    rc = sub(addon, "blender.cli.main").main(argv, in_blender=True, out=out, err=err)
    return rc, out.getvalue(), err.getvalue()


def one_error_line(err):
    """The CLI's single error line (its text after 'error: ')."""
    assert err.count("\n") == 1 and err.startswith("hemicube_radiosity: error: "), err
    return err.split("error: ", 1)[1].strip()


def mesh_object(bpy, name, verts, faces, edges=()):
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(map(float, v)) for v in verts], list(edges), [tuple(f) for f in faces])
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def emitter(bpy, z=1.0, size=1.0, strength=5.0):
    """A plane facing down at height z, glowing white."""
    bpy.ops.mesh.primitive_plane_add(size=size, location=(0.5, 0.5, z), rotation=(np.pi, 0, 0))
    lamp = bpy.context.active_object
    lamp.name = "Lamp"
    lamp.data.materials.append(principled(bpy, "Glow", base=(0, 0, 0), em=(1, 1, 1), strength=strength))
    return lamp


def principled(bpy, name, base=(0.5, 0.5, 0.5), em=(0, 0, 0), strength=0.0):
    m = bpy.data.materials.new(name)
    b = node_tree(m).nodes["Principled BSDF"]
    b.inputs["Base Color"].default_value = (*base, 1)
    b.inputs["Emission Color"].default_value = (*em, 1)
    b.inputs["Emission Strength"].default_value = strength
    return m


def refused(bpy, objs, match, **kw):
    """The operator refuses with one ERROR line matching ``match``; the scene is unchanged."""
    select(bpy, objs)
    before = scene_hash(bpy)
    with pytest.raises(RuntimeError, match=match) as ex:
        bpy.ops.object.radiosity_bake(**{**BAKE, **kw})
    text = str(ex.value).strip()
    assert text.startswith("Error: ") and "\n" not in text, text
    assert "Traceback" not in text
    assert scene_hash(bpy) == before
    return text


def baked(bpy, objs, **kw):
    select(bpy, objs)
    assert bpy.ops.object.radiosity_bake(**{**BAKE, **kw}) == {"FINISHED"}


def attribute_rgb(me, name="Radiosity"):
    a = me.color_attributes[name]
    col = np.empty(len(a.data) * 4, np.float32)
    a.data.foreach_get("color", col)
    return col.reshape(-1, 4)[:, :3]


def prepare(addon, bpy, objs, **kw):
    bake = sub(addon, "blender.bake")
    return bake.BakeJob.prepare(bpy.context, objs, bake.BakeSettings(**{**BAKE, **kw}))


# ============================================================================ core level
def test_core_mesh_without_faces_is_named():
    m = MeshInput(np.array(QUAD, float), np.array([0]), np.zeros(0, int), np.zeros((0, 3)),
                  np.zeros((0, 3)), "Bare")
    with pytest.raises(PatchError, match="'Bare': the mesh has no faces"):
        build_patches([m])


def test_core_only_zero_area_faces_is_named():
    m = MeshInput.from_faces([(0, 0, 0), (1, 0, 0), (2, 0, 0), (3, 0, 0)], [(0, 1, 2), (0, 1, 3, 2)],
                             name="Flat")
    with pytest.raises(PatchError, match="'Flat': every face has zero area"):
        build_patches([m])


def test_core_degenerate_faces_are_dropped_and_the_rest_bakes():
    """A collinear triangle, a quad with a repeated corner and a good quad, under an emitter:
    the degenerate faces make no patches, the good one bakes to a finite, lit result."""
    verts = QUAD + [(2, 0, 0), (3, 0, 0), (0.5, 0.5, 1), (1.5, 0.5, 1), (0.5, -0.5, 1)]
    floor = MeshInput.from_faces(verts, [(0, 1, 2, 3), (0, 1, 4), (1, 1, 2, 3)], rho=0.5, name="Floor")
    lamp = MeshInput.from_faces([(0, 0, 1), (0, 1, 1), (1, 1, 1), (1, 0, 1)], [(0, 1, 2, 3)], rho=0.0,
                                emission=1.0, name="Lamp")
    r = core_bake([floor, lamp], CoreSettings(patch_size=0.5, element_size=0.0, resolution=16))
    P = r.patches
    assert np.all(P.areas > 0)
    np.testing.assert_allclose(P.areas[P.owner == 0].sum(), 1.0 + 0.5, rtol=1e-9)  # quad + the 1-1-2-3 triangle
    assert np.all(np.isfinite(r.vertex_radiosity)) and r.vertex_radiosity.max() > 0


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_core_nonfinite_vertices_are_named(bad):
    v = np.array(QUAD, float)
    v[2, 1] = bad
    with pytest.raises(PatchError, match="'Bad': vertex positions are not finite"):
        build_patches([MeshInput.from_faces(v, [(0, 1, 2, 3)], name="Bad")])


def test_core_concave_ngon_is_cut_exactly():
    """An L-shaped hexagon (area 3): ear clipping keeps its area and its orientation."""
    L = [(0, 0, 0), (2, 0, 0), (2, 1, 0), (1, 1, 0), (1, 2, 0), (0, 2, 0)]
    P = build_patches([MeshInput.from_faces(L, [range(6)], name="L")], patch_size=0.25)
    np.testing.assert_allclose(P.areas.sum(), 3.0, rtol=1e-9)
    np.testing.assert_allclose(P.normals, np.tile([0, 0, 1.0], (len(P), 1)), atol=1e-9)
    # no patch outside the L (the notch 1 < x, 1 < y is empty)
    assert not np.any((P.centers[:, 0] > 1 + 1e-9) & (P.centers[:, 1] > 1 + 1e-9))


def test_core_nonplanar_ngon_bakes_finite():
    ring = [(0, 0, 0), (1, 0, 0), (1.5, 1, 0.7), (0.5, 1.5, 0), (-0.5, 1, 0.7)]
    m = MeshInput.from_faces(ring, [range(5)], rho=0.5, emission=0.1, name="Warped")
    r = core_bake([m], CoreSettings(patch_size=0.25, element_size=0.0, resolution=16))
    assert len(r.patches) > 5 and np.all(r.patches.areas > 0)
    assert np.all(np.isfinite(r.vertex_radiosity)) and np.all(r.vertex_radiosity >= 0.1 - 1e-9)


@pytest.mark.parametrize("rho, em, match", [
    (1.0, 0.0, r"'M': face 0 has reflectivity .* must be in \[0, 1\)"),
    (np.nan, 0.0, "'M': reflectivity or emission is not finite"),
    (0.5, -1.0, "'M': face 0 has negative emission"),
])
def test_core_material_values_out_of_range_are_named(rho, em, match):
    """The core refuses them (the Blender reader clips them first, with a note: tests below)."""
    with pytest.raises(PatchError, match=match):
        build_patches([MeshInput.from_faces(QUAD, [(0, 1, 2, 3)], rho=rho, emission=em, name="M")])


def test_core_form_factor_memory_is_estimated_before_the_work():
    """A scene whose form factors would not fit: refused in the patches stage with the estimate
    and a setting that helps, before any form factor is computed (cancelled() stops the bake at
    the first check after patches if the refusal is missing)."""
    big = MeshInput.from_faces([(0, 0, 0), (400, 0, 0), (400, 400, 0), (0, 400, 0)], [(0, 1, 2, 3)],
                               rho=0.5, name="Huge")
    s = CoreSettings(patch_size=1.0, element_size=0.0, resolution=64, max_patches=10 ** 7)
    done = []

    def progress(stage, fraction, message=""):
        if stage == "patches" and fraction >= 1.0:
            done.append(message)

    with pytest.raises(PatchError, match=r"(?s)patches.*GB.*patch size"):
        core_bake([big], s, progress=progress, cancelled=lambda: bool(done))


# ============================================================================ selection and object types
def test_empty_selection_is_one_line(addon, empty_scene):
    bpy = empty_scene
    bpy.ops.mesh.primitive_plane_add()
    refused(bpy, [], "no mesh object selected")


def test_text_object_bakes_as_geometry(addon, empty_scene):
    """An artist selects a text object to bake it: it is read as the mesh Blender makes of it and
    gets a baked copy like a mesh (the text itself is hidden, not changed)."""
    bpy = empty_scene
    bpy.ops.object.text_add()
    text = bpy.context.active_object
    body = text.data.body
    emitter(bpy, z=2.0, size=4.0)
    baked(bpy, [text])
    copy = sub(addon, "blender.write").copies_of([text.name])[0]
    assert len(copy.data.polygons) > 10 and attribute_rgb(copy.data).max() > 0
    assert text.hide_render and text.data.body == body


def test_curve_with_bevel_bakes_and_guide_curve_is_named(addon, empty_scene):
    bpy = empty_scene
    bpy.ops.curve.primitive_bezier_curve_add()
    guide = bpy.context.active_object
    guide.name = "Guide"
    refused(bpy, [guide], r"'Guide' has no faces \(a curve without bevel")
    bpy.ops.curve.primitive_bezier_curve_add(location=(0, 2, 0))
    tube = bpy.context.active_object
    tube.name = "Tube"
    tube.data.bevel_depth = 0.1
    select(bpy, [guide, tube])
    bake = sub(addon, "blender.bake")
    job = bake.BakeJob.prepare(bpy.context, [guide, tube], bake.BakeSettings(**BAKE))
    assert [o.name for o in job.scene_input.objects if o.bake] == ["Tube"]
    assert any(n.startswith("'Guide' has no faces") and n.endswith("left out") for n in job.notes), job.notes


def test_metaball_family_bakes_once(addon, empty_scene):
    bpy = empty_scene
    bpy.ops.object.metaball_add()
    base = bpy.context.active_object
    bpy.ops.object.metaball_add(location=(0.6, 0, 0))
    other = bpy.context.active_object
    job = prepare(addon, bpy, [base, other])
    assert [o.name for o in job.scene_input.objects if o.bake] == [base.name]
    assert any(other.name in n and "family's base object" in n for n in job.notes), job.notes
    baked(bpy, [base, other])
    assert len(sub(addon, "blender.write").copies_of([base.name])) == 1


@pytest.mark.parametrize("kind", ["points", "edges"])
def test_mesh_without_faces_is_one_line(addon, empty_scene, kind):
    bpy = empty_scene
    ob = mesh_object(bpy, "Wire", QUAD, [], edges=[(0, 1), (1, 2)] if kind == "edges" else [])
    refused(bpy, [ob], "'Wire' has no faces")


def test_loose_vertices_and_edges_are_ignored(addon, empty_scene):
    bpy = empty_scene
    ob = mesh_object(bpy, "Loose", QUAD + [(5, 5, 5), (6, 6, 6), (7, 7, 7)], [(0, 1, 2, 3)], edges=[(4, 5)])
    emitter(bpy)
    baked(bpy, [ob], output_mode="IN_PLACE")
    rgb = attribute_rgb(ob.data)
    assert rgb.shape == (4, 3) and np.all(np.isfinite(rgb)) and rgb.min() > 0


def test_only_zero_area_faces_is_one_line(addon, empty_scene):
    bpy = empty_scene
    ob = mesh_object(bpy, "Sliver", [(0, 0, 0), (1, 0, 0), (2, 0, 0)], [(0, 1, 2)])
    refused(bpy, [ob], "'Sliver': every face has zero area")


def test_degenerate_faces_beside_good_ones_bake(addon, empty_scene):
    bpy = empty_scene
    ob = mesh_object(bpy, "Mixed", QUAD + [(2, 0, 0), (3, 0, 0)], [(0, 1, 2, 3), (1, 4, 5), (0, 1, 2)])
    emitter(bpy)
    baked(bpy, [ob])
    rgb = attribute_rgb(sub(addon, "blender.write").copies_of(["Mixed"])[0].data)
    assert np.all(np.isfinite(rgb)) and rgb.max() > 0


@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_nonfinite_coordinates_are_named(addon, empty_scene, bad):
    bpy = empty_scene
    v = [list(p) for p in QUAD]
    v[2][1] = bad
    ob = mesh_object(bpy, "Broken", v, [(0, 1, 2, 3)])
    refused(bpy, [ob], r"'Broken': 1 vertex position\(s\) are not finite .*first vertex 2")


def test_nonfinite_loose_vertex_does_not_matter(addon, empty_scene):
    bpy = empty_scene
    ob = mesh_object(bpy, "Stray", QUAD + [(float("nan"), 0, 0)], [(0, 1, 2, 3)])
    emitter(bpy)
    baked(bpy, [ob])


@pytest.mark.parametrize("mode", ["COPY", "IN_PLACE"])
@pytest.mark.parametrize("scale", [(-1, 1, 1), (-1, -1, -1)])
def test_negative_scale_front_stays_lit(addon, empty_scene, mode, scale):
    """A mirrored plane under an emitter: lit on the side Blender shows as its front."""
    bpy = empty_scene
    ob = mesh_object(bpy, "Mirror", [(-0.5, -0.5, 0), (0.5, -0.5, 0), (0.5, 0.5, 0), (-0.5, 0.5, 0)],
                     [(0, 1, 2, 3) if scale[2] > 0 else (3, 2, 1, 0)])
    ob.location = (0.5, 0.5, 0)
    ob.scale = scale
    emitter(bpy)
    bpy.context.view_layer.update()
    baked(bpy, [ob], output_mode=mode)
    target = ob if mode == "IN_PLACE" else sub(addon, "blender.write").copies_of(["Mirror"])[0]
    assert attribute_rgb(target.data).min() > 0.05


def test_concave_and_nonplanar_ngons_bake_in_place(addon, empty_scene):
    bpy = empty_scene
    L = mesh_object(bpy, "L", [(0, 0, 0), (2, 0, 0), (2, 1, 0), (1, 1, 0), (1, 2, 0), (0, 2, 0)], [range(6)])
    W = mesh_object(bpy, "Warped", [(3, 0, 0), (4, 0, 0), (4.5, 1, 0.3), (3.5, 1.5, 0), (2.5, 1, 0.3)],
                    [range(5)])
    emitter(bpy, z=2.0, size=6.0)
    baked(bpy, [L, W], output_mode="IN_PLACE", patch_size=0.25)
    for ob in (L, W):
        rgb = attribute_rgb(ob.data)
        assert np.all(np.isfinite(rgb)) and rgb.min() > 0, ob.name


# ============================================================================ linked library
@pytest.fixture
def linked_plane(addon, empty_scene, tmp_path):
    bpy = empty_scene
    bpy.ops.mesh.primitive_plane_add(size=1, location=(0.5, 0.5, 0))
    bpy.context.active_object.name = "LibPlane"
    lib = str(tmp_path / "library.blend")
    bpy.ops.wm.save_as_mainfile(filepath=lib)
    bpy.ops.wm.read_homefile(use_empty=True)
    digest = file_sha256(lib)
    with bpy.data.libraries.load(lib, link=True) as (_, dst):
        dst.objects = ["LibPlane"]
    ob = dst.objects[0]
    bpy.context.scene.collection.objects.link(ob)
    emitter(bpy)
    bpy.context.view_layer.update()
    assert ob.library is not None and ob.data.library is not None
    return bpy, ob, lib, digest


def test_linked_library_object_bakes_as_copy(addon, linked_plane):
    bpy, ob, lib, digest = linked_plane
    baked(bpy, [ob])
    copy = sub(addon, "blender.write").copies_of(["LibPlane"])[0]
    assert copy.library is None and attribute_rgb(copy.data).min() > 0
    assert "Radiosity" not in ob.data.attributes
    assert file_sha256(lib) == digest


def test_linked_library_object_in_place_is_refused(addon, linked_plane):
    bpy, ob, lib, digest = linked_plane
    refused(bpy, [ob], r"'LibPlane' is linked from library 'library.blend', read-only here: bake it as a copy",
            output_mode="IN_PLACE")
    assert file_sha256(lib) == digest


# ============================================================================ the output attribute
def test_existing_non_colour_attribute_in_place_is_refused(addon, empty_scene):
    bpy = empty_scene
    ob = mesh_object(bpy, "Tagged", QUAD, [(0, 1, 2, 3)])
    ob.data.attributes.new("Radiosity", "FLOAT", "POINT")
    other = mesh_object(bpy, "Other", [(x + 2, y, z) for x, y, z in QUAD], [(0, 1, 2, 3)])
    emitter(bpy)
    # both selected: refused before the first one is written
    refused(bpy, [other, ob], r"mesh 'Tagged' of 'Tagged' already has a non-colour attribute named "
                              r"'Radiosity' \(FLOAT on points\)", output_mode="IN_PLACE")
    baked(bpy, [ob])          # a copy is free to carry its own attribute; the original keeps its own
    assert ob.data.attributes["Radiosity"].data_type == "FLOAT"


@pytest.mark.parametrize("data_type, domain", [("BYTE_COLOR", "POINT"), ("FLOAT_COLOR", "POINT"),
                                               ("BYTE_COLOR", "CORNER")])
def test_existing_colour_attribute_of_another_kind_is_replaced_with_a_note(addon, empty_scene, data_type, domain):
    bpy = empty_scene
    ob = mesh_object(bpy, "Painted", QUAD, [(0, 1, 2, 3)])
    ob.data.color_attributes.new("Radiosity", data_type, domain)
    emitter(bpy)
    job = prepare(addon, bpy, [ob], output_mode="in_place")
    assert f"Painted: its colour attribute 'Radiosity' ({data_type} on {domain.lower()}s) is replaced" \
        in " ".join(job.notes), job.notes
    baked(bpy, [ob], output_mode="IN_PLACE")
    a = ob.data.color_attributes["Radiosity"]
    assert (a.data_type, a.domain) == ("FLOAT_COLOR", "CORNER") and attribute_rgb(ob.data).min() > 0


@pytest.mark.parametrize("name, match", [("position", "'position' is one Blender keeps for itself"),
                                         ("", "the attribute name is empty"),
                                         (".hidden", "'.hidden' is one Blender keeps for itself")])
@pytest.mark.parametrize("mode", ["COPY", "IN_PLACE"])
def test_reserved_or_empty_attribute_name_is_refused(addon, empty_scene, name, match, mode):
    bpy = empty_scene
    ob = mesh_object(bpy, "Plane", QUAD, [(0, 1, 2, 3)])
    refused(bpy, [ob], match, attribute_name=name, output_mode=mode)


# ============================================================================ material values
def test_base_colour_above_one_is_clipped_with_a_note(addon, empty_scene):
    bpy = empty_scene
    ob = mesh_object(bpy, "Hot", QUAD, [(0, 1, 2, 3)])
    ob.data.materials.append(principled(bpy, "TooBright", base=(2.0, 0.5, 0.5)))
    job = prepare(addon, bpy, [ob])
    rho = job.scene_input.objects[0].mesh.face_rho
    assert np.all(rho < 1) and np.all(rho >= 0)
    assert any("'TooBright'" in n and "clipped to [0, 0.999]" in n for n in job.notes), job.notes


def test_nan_base_colour_is_zero_with_a_note(addon, empty_scene):
    """Cycles renders a NaN band of a base colour as 0: so does the bake, and says so."""
    bpy = empty_scene
    ob = mesh_object(bpy, "Odd", QUAD, [(0, 1, 2, 3)])
    ob.data.materials.append(principled(bpy, "NotANumber", base=(float("nan"), 0.5, 0.5)))
    emitter(bpy)
    job = prepare(addon, bpy, [ob])
    rho = job.scene_input.objects[0].mesh.face_rho
    assert np.all(np.isfinite(rho)) and rho[0, 0] == 0 and rho[0, 1] > 0.4
    assert any("'NotANumber'" in n and "not a number" in n for n in job.notes), job.notes
    baked(bpy, [ob])


@pytest.mark.parametrize("node", ["principled", "emission"])
def test_negative_emission_strength_is_no_light_with_a_note(addon, empty_scene, node):
    bpy = empty_scene
    ob = mesh_object(bpy, "Dark", QUAD, [(0, 1, 2, 3)])
    if node == "principled":
        m = principled(bpy, "Negative", em=(1, 1, 1), strength=-3.0)
    else:
        m = bpy.data.materials.new("Negative")
        nt = node_tree(m)
        nt.nodes.clear()
        e = nt.nodes.new("ShaderNodeEmission")
        e.inputs["Strength"].default_value = -3.0
        nt.links.new(e.outputs[0], nt.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    ob.data.materials.append(m)
    job = prepare(addon, bpy, [ob])
    assert np.all(job.scene_input.objects[0].mesh.face_emission == 0)
    negative = [n for n in job.notes if "'Negative'" in n and "negative" in n]
    assert len(negative) == 1 and "no light" in negative[0], job.notes
    assert not any("raise the strength" in n for n in job.notes), job.notes   # not told twice


# ============================================================================ the CLI: damaged inputs
def _damaged(bpy, tmp_path, kind):
    """A damaged input file of ``kind``; returns its path."""
    p = tmp_path / kind.split(":")[0]
    if kind in ("truncated.blend", "truncated.glb"):
        bpy.ops.wm.read_homefile(use_empty=True)
        bpy.ops.mesh.primitive_plane_add()
        good = tmp_path / ("good" + os.path.splitext(kind)[1])
        if kind.endswith(".blend"):
            bpy.ops.wm.save_as_mainfile(filepath=str(good))
        else:
            bpy.ops.export_scene.gltf(filepath=str(good))
        data = good.read_bytes()
        p.write_bytes(data[:len(data) // 2])
    elif kind == "garbage.blend":
        p.write_bytes(b"BLENDER-v300" + bytes(range(256)) * 8)
    elif kind == "empty.blend":
        p.write_bytes(b"")
    elif kind == "garbage.glb":
        p.write_bytes(b"glTF\x02\x00\x00\x00" + b"\x00" * 64)
    elif kind == "broken.gltf":
        p.write_text("{not json")
    elif kind == "crash.gltf":   # valid JSON that Blender's importer trips over (a Python error)
        p.write_text('{"asset": {"version": "2.0"}, "meshes": [{"primitives": [{"attributes": '
                     '{"POSITION": 5}}]}], "nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}], "scene": 0}')
    elif kind == "garbage.obj":
        p.write_bytes(bytes(range(256)) * 8)
    return str(p)


@pytest.mark.parametrize("kind, reason", [
    ("garbage.blend", "Missing DNA block"),
    ("truncated.blend", "Missing DNA block"),
    ("empty.blend", "File format is not supported"),
    ("garbage.glb", "Bad GLB"),
    ("truncated.glb", "Bad GLB"),
    ("broken.gltf", "Bad glTF: json error"),
    ("crash.gltf", "Blender's importer stopped (TypeError: "),
    ("garbage.obj", "no mesh objects that a render shows in"),
])
def test_cli_damaged_input_is_one_line_naming_the_file(addon, empty_scene, tmp_path, kind, reason):
    src = _damaged(empty_scene, tmp_path, kind)
    digest = file_sha256(src)
    out = tmp_path / "out" / "baked.glb"
    rc, _, err = run_cli(addon, ["bake", src, "-o", str(out), *CLI_BAKE])
    line = one_error_line(err)
    assert rc == 1 and src in line and reason in line, line
    assert "Traceback" not in err and "Python:" not in line and not line.split(src, 1)[1].startswith(": Error")
    assert file_sha256(src) == digest and not out.exists()


def test_cli_bake_without_output_is_refused(addon, tmp_path):
    src = tmp_path / "x.obj"
    src.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    rc, _, err = run_cli(addon, ["bake", str(src), *CLI_BAKE])
    assert rc == 2 and one_error_line(err).startswith("nothing would be written: give -o OUTPUT")


def test_cli_output_onto_the_input_is_refused(addon, empty_scene, tmp_path):
    bpy = empty_scene
    bpy.ops.mesh.primitive_plane_add()
    src = str(tmp_path / "scene.blend")
    bpy.ops.wm.save_as_mainfile(filepath=src)
    digest = file_sha256(src)
    rc, _, err = run_cli(addon, ["bake", src, "-o", os.path.join(str(tmp_path), ".", "scene.blend"), *CLI_BAKE])
    assert rc == 2 and "would overwrite the input" in one_error_line(err)
    assert file_sha256(src) == digest


def test_cli_scene_problem_names_the_object_and_leaves_the_input(addon, empty_scene, tmp_path):
    bpy = empty_scene
    v = [list(p) for p in QUAD]
    v[1][2] = float("nan")
    mesh_object(bpy, "Spiky", v, [(0, 1, 2, 3)])
    src = str(tmp_path / "nan.blend")
    bpy.ops.wm.save_as_mainfile(filepath=src)
    digest = file_sha256(src)
    rc, _, err = run_cli(addon, ["bake", src, "-o", str(tmp_path / "b.glb"), *CLI_BAKE])
    assert rc == 1 and one_error_line(err).startswith("'Spiky': 1 vertex position(s) are not finite")
    assert file_sha256(src) == digest and not (tmp_path / "b.glb").exists()


# ============================================================================ the CLI: a full disk
@pytest.fixture
def plane_blend(addon, empty_scene, tmp_path):
    bpy = empty_scene
    bpy.ops.mesh.primitive_plane_add(size=2)
    src = str(tmp_path / "plane.blend")
    bpy.ops.wm.save_as_mainfile(filepath=src)
    return src


@pytest.mark.parametrize("ext", [".glb", ".gltf", ".blend", ".npz", ".json"])
def test_full_disk_leaves_no_half_written_output(addon, plane_blend, tmp_path, monkeypatch, ext):
    """The writer writes part of the file(s) and fails with ENOSPC: one line naming the output,
    exit 1, the previous output under the final name untouched, no partial file left."""
    export = sub(addon, "blender.export")
    writer, what, single = export.EXPORTERS[ext]

    def half_then_full(path, job, report):
        with open(path, "wb") as f:
            f.write(b"half")
        if ext == ".gltf":
            with open(os.path.splitext(path)[0] + ".bin", "wb") as f:
                f.write(b"half")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), path)

    monkeypatch.setitem(export.EXPORTERS, ext, (half_then_full, what, single))
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    target = out_dir / f"baked{ext}"
    target.write_bytes(b"previous bake")
    digest = file_sha256(plane_blend)
    argv = ["bake", plane_blend, *CLI_BAKE] + (["--report", str(target)] if ext == ".json" else ["-o", str(target)])
    rc, _, err = run_cli(addon, argv)
    assert rc == 1 and one_error_line(err) == f"could not write {target}: No space left on device"
    assert target.read_bytes() == b"previous bake"
    assert sorted(os.listdir(out_dir)) == [target.name]
    assert file_sha256(plane_blend) == digest


@pytest.fixture
def tiny_disk(tmp_path):
    """A 64 KiB tmpfs (root only; skipped elsewhere)."""
    import subprocess

    d = tmp_path / "tiny"
    d.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(d)],
                                           capture_output=True).returncode != 0:
        pytest.skip("cannot mount a small tmpfs here (needs root)")
    yield d
    if subprocess.run(["umount", str(d)], capture_output=True).returncode:   # busy: a failed test's file
        subprocess.run(["umount", "-l", str(d)], check=False)                # still open; detach it


@pytest.mark.parametrize("ext", [".glb", ".gltf"])
def test_real_full_disk_through_blenders_exporter(addon, plane_blend, tiny_disk, ext):
    """The real thing: Blender's glTF exporter fails inside with ENOSPC (a RuntimeError carrying
    a Python traceback): still one line, nothing left under the final names."""
    target = tiny_disk / f"baked{ext}"
    rc, _, err = run_cli(addon, ["bake", plane_blend, "-o", str(target), "--patch-size", "0.05",
                                 "--element-size", "0.02", "--resolution", "8"])
    assert rc == 1 and one_error_line(err) == f"could not write {target}: No space left on device"
    assert os.listdir(tiny_disk) == []
    # and the space is free again: no file left open there (the exporter's, in a dropped frame)
    held = [os.readlink(f"/proc/self/fd/{fd}") for fd in os.listdir("/proc/self/fd")
            if os.path.exists(f"/proc/self/fd/{fd}")]
    assert not [h for h in held if h.startswith(str(tiny_disk))], held


# ============================================================================ cancelling
def test_cancel_mid_bake_leaves_the_scene_unchanged(addon, empty_scene):
    bpy = empty_scene
    objs = sub(addon, "blender.demo").build_cornell_box(bpy.context)
    core_progress = sub(addon, "core.runtime.progress")
    sub(addon, "blender.bake").clear_session_cache()
    before = scene_hash(bpy)
    job = prepare(addon, bpy, objs)
    seen = []
    with pytest.raises(core_progress.Cancelled):
        job.run(progress=lambda st, fr, msg="": seen.append(st), cancelled=lambda: "form_factors" in seen)
    assert "form_factors" in seen and job.result is None
    assert scene_hash(bpy) == before


def test_modal_esc_and_modal_error_leave_the_scene_unchanged(addon, empty_scene):
    bpy = empty_scene
    objs = sub(addon, "blender.demo").build_cornell_box(bpy.context)
    before = scene_hash(bpy)
    ret, op, ui = modal_run(addon, bpy, objs, cancel_first=True)
    assert ret == {"CANCELLED"} and scene_hash(bpy) == before
    # an error in the worker (the core refuses the patches: more than Max Patches) is one ERROR
    # report, nothing written
    before = scene_hash(bpy)
    ret, op, ui = modal_run(addon, bpy, objs, cancel_first=False, settings=dict(MODAL_BAKE, max_patches=4))
    assert ret == {"CANCELLED"} and scene_hash(bpy) == before
    errors = [m for lvl, m in op.reports if lvl == {"ERROR"}]
    assert len(errors) == 1 and "limit of 4" in errors[0] and "\n" not in errors[0], errors
