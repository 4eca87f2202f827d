"""Headless: ``python -m hemicube_radiosity bake ...`` and the registered Blender CLI command."""
from __future__ import annotations

import importlib
import io
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from tests.support import ROOT
from tests.support.addon import sub
from tests.support.gltf import read_gltf
from tests.support.scene import corner_data, node_tree

pytestmark = pytest.mark.blender

BAKE_ARGS = ["--patch-size", "0.25", "--resolution", "32", "--element-size", "0"]


def run(addon, argv):
    """The registered command's handler (what ``blender -c hemicube_radiosity`` calls)."""
    out, err = io.StringIO(), io.StringIO()
    rc = sub(addon, "blender.cli.main").main(argv, in_blender=True, out=out, err=err)
    return rc, out.getvalue(), err.getvalue()


def baked_attributes(bpy):
    """{source name: (corner world positions, corner colours)} of every baked copy in the file."""
    out = {}
    for ob in bpy.data.objects:
        src = ob.get("radiosity_source")
        if src is None:
            continue
        out[src] = corner_data(ob)
    return out


@pytest.fixture(scope="module")
def cornell_blend(addon, tmp_path_factory):
    import bpy

    bpy.ops.wm.read_homefile(use_empty=True)
    sub(addon, "blender.demo").build_cornell_box(bpy.context)
    path = str(tmp_path_factory.mktemp("cli") / "cornell.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    return path


@pytest.fixture(scope="module")
def cli_bake(addon, cornell_blend, tmp_path_factory):
    d = tmp_path_factory.mktemp("cli_out")
    files = {k: str(d / n) for k, n in (("blend", "baked.blend"), ("report", "report.json"),
                                        ("patches", "patches.npz"))}
    rc, out, err = run(addon, ["bake", cornell_blend, "-o", files["blend"], "--report", files["report"],
                               "--patches", files["patches"], *BAKE_ARGS])
    return dict(rc=rc, out=out, err=err, **files)


def test_cli_bake_exit_code_and_stage_lines(cli_bake):
    assert cli_bake["rc"] == 0, cli_bake["err"]
    assert cli_bake["err"] == ""
    lines = [ln for ln in cli_bake["out"].splitlines() if ln.startswith("radiosity: ")]
    expected = [i for i, ln in enumerate(lines) if ln.startswith("radiosity: form factors: expected about ")]
    stages = [ln.split(":")[1].strip() for i, ln in enumerate(lines) if i not in expected]
    for st in ("patches", "form factors", "solve", "write"):
        assert stages.count(st) == 1, cli_bake["out"]
    # the time the bake expects, printed before the form factors' work (their line when done)
    done = [i for i, ln in enumerate(lines) if ln.startswith("radiosity: form factors: ") and i not in expected]
    assert len(expected) == 1 and expected[0] < done[0], cli_bake["out"]


def test_cli_report(cli_bake):
    rep = json.load(open(cli_bake["report"]))
    for k in ("patches", "form_factors", "solve", "write", "total"):
        assert rep["timings"][k] >= 0
    assert rep["timings"]["total"] >= rep["timings"]["form_factors"] + rep["timings"]["solve"]
    assert rep["forecast"]["seconds"] > 0 and rep["forecast"]["receivers"] > 0
    z = np.load(cli_bake["patches"])
    assert rep["patches"] == len(z["areas"]) > 100
    assert rep["nonzeros"] > rep["patches"]
    assert rep["iterations"] >= 1 and rep["residual"] < rep["settings"]["tolerance"]
    assert rep["error_estimate"] is None                     # only with --estimate-error
    e = rep["energy"]
    # open box: emitted = absorbed + escaped (through the open front)
    assert min(e["emitted"]) > 0 and e["imbalance"] < 0.02
    assert sorted(rep["objects"]) == sorted(["Floor", "Ceiling", "BackWall", "RedWall", "GreenWall",
                                             "Light", "ShortBlock", "TallBlock"])


def test_cli_patches_arrays(addon, cli_bake):
    scenes = importlib.import_module(f"{addon.__name__}.core.builtin_scenes")
    z = np.load(cli_bake["patches"])
    n = len(z["areas"])
    for k, shape in (("centers", (n, 3)), ("normals", (n, 3)), ("radiosity", (n, 3)), ("emission", (n, 3)),
                     ("reflectance", (n, 3)), ("object", (n,))):
        assert z[k].shape == shape, k
    obj = z["object"]
    # the ceiling light has emission strength 12 in white: radiance 12; its Base Color is black,
    # so it reflects only off its specular layer (Cycles' glossy albedo, 0.0374 for a Principled
    # BSDF's defaults, bounced by the solve: core/mesh/specular.py): a hair above 12
    np.testing.assert_allclose(z["emission"][obj == "Light"], 12.0)
    np.testing.assert_allclose(z["reflectance"][obj == "Light"], 0.0374, atol=5e-4)
    light = z["radiosity"][obj == "Light"]
    assert np.all(light >= 12.0) and np.all(light < 12.0 + 0.0374 * 2.0), light
    # the red wall's Principled BSDF: Cycles' diffuse albedo of CORNELL_RED (its specular layer
    # takes a few percent, the same in every band) plus that layer's glossy albedo (the light's,
    # whose Base Color is black), the same on every patch
    red = z["reflectance"][obj == "RedWall"]
    np.testing.assert_allclose(red, np.tile(red[0], (len(red), 1)), atol=1e-6)
    ratio = (red[0] - z["reflectance"][obj == "Light"][0]) / np.asarray(scenes.CORNELL_RED)
    assert 0.9 < ratio.min() and ratio.max() <= 1.0 and np.ptp(ratio) < 0.01, ratio
    # the light's back, a hair over it and facing the ceiling (it shines and reflects there: a
    # single plane is two-sided, core/mesh/backs.py), is patches of its own; nothing else has one
    back = np.char.endswith(obj.astype(str), " (back)")
    assert set(obj[back]) == {"Light (back)"}
    np.testing.assert_allclose(z["areas"][back].sum(), 0.25, rtol=1e-9)
    np.testing.assert_allclose(z["normals"][back], np.tile([0, 0, 1.0], (back.sum(), 1)), atol=1e-9)
    np.testing.assert_allclose(z["areas"][~back].sum(), 5 * 4 + 0.25 + z["areas"][np.isin(obj, ["ShortBlock", "TallBlock"])].sum(), rtol=1e-9)
    np.testing.assert_allclose(z["areas"][obj == "Floor"].sum(), 4.0, rtol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(z["normals"], axis=1), 1.0, rtol=1e-9)
    floor_n = z["normals"][obj == "Floor"]
    np.testing.assert_allclose(floor_n, np.tile([0, 0, 1.0], (len(floor_n), 1)), atol=1e-9)


def test_operator_and_cli_agree(addon, cornell_blend, cli_bake):
    import bpy

    bpy.ops.wm.open_mainfile(filepath=cornell_blend)
    for o in bpy.context.view_layer.objects:
        o.select_set(o.type == "MESH")
    assert bpy.ops.object.radiosity_bake(patch_size=0.25, resolution=32, element_size=0.0) == {"FINISHED"}
    op = baked_attributes(bpy)
    bpy.ops.wm.open_mainfile(filepath=cli_bake["blend"])
    cli = baked_attributes(bpy)
    assert sorted(op) == sorted(cli) and len(op) == 8
    worst = 0.0
    for name in op:
        np.testing.assert_array_equal(op[name][0], cli[name][0])
        a, b = op[name][1], cli[name][1]
        worst = max(worst, float(np.max(np.abs(a - b) / np.maximum(np.abs(a), 1e-3))))
    assert worst < 1e-6, worst
    # the CLI's .blend keeps the originals, hidden, next to the copies
    assert bpy.data.objects["Floor"].hide_get() and "Radiosity" in bpy.data.collections


def test_obj_input_closed_box_furnace(addon, tmp_path):
    """An .obj room (inward faces, Kd 0.5, Ke 0.5 from the .mtl) through the whole CLI path:
    in a closed room B = E / (1 - rho) = 1.0 on every patch."""
    (tmp_path / "room.mtl").write_text("newmtl grey\nKd 0.5 0.5 0.5\nKe 0.5 0.5 0.5\n")
    (tmp_path / "room.obj").write_text(
        "mtllib room.mtl\no Room\n"
        + "".join(f"v {x} {y} {z}\n" for x, y, z in [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0),
                                                     (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)])
        + "usemtl grey\nf 1 2 3 4\nf 5 8 7 6\nf 1 5 6 2\nf 2 6 7 3\nf 3 7 8 4\nf 4 8 5 1\n")
    rc, out, err = run(addon, ["bake", str(tmp_path / "room.obj"), "--patches", str(tmp_path / "p.npz"),
                               "-o", str(tmp_path / "room.glb"), "--patch-size", "0.25", "--resolution", "32",
                               "--report", str(tmp_path / "r.json")])
    assert rc == 0, err
    z = np.load(tmp_path / "p.npz")
    import bpy

    if bpy.app.version < (4, 5, 0) and not z["emission"].any():
        # Blender 4.2's OBJ importer gives Ke as Emission Color at Emission Strength 0 (4.5 and 5.0:
        # strength 1): no light, in Cycles too. The bake says so instead of going dark silently.
        notes = json.loads((tmp_path / "r.json").read_text())["notes"]
        assert any("grey" in n and "strength" in n for n in notes), notes
        pytest.skip(f"Blender {bpy.app.version_string}: the OBJ importer leaves Ke at emission strength 0")
    np.testing.assert_allclose(z["reflectance"], 0.5, atol=1e-6)
    np.testing.assert_allclose(z["emission"], 0.5, atol=1e-6)
    np.testing.assert_allclose(z["radiosity"], 1.0, atol=2e-3)
    doc, accessor = read_gltf(str(tmp_path / "room.glb"))
    attrs = doc["meshes"][0]["primitives"][0]["attributes"]
    col, pos = accessor(attrs["COLOR_0"]), accessor(attrs["POSITION"])
    # every vertex, corners and edges of the room included (the paper's furnace holds there too)
    assert len(col) >= 6 * 25
    np.testing.assert_allclose(col[:, :3], 1.0, atol=5e-3)


def test_gltf_input_and_objects_option(addon, empty_scene, tmp_path):
    """A .gltf scene in; only --objects are written, the other mesh still lights them."""
    bpy = empty_scene
    bpy.ops.mesh.primitive_plane_add(size=2)
    bpy.context.active_object.name = "Ground"
    bpy.ops.mesh.primitive_plane_add(size=1, location=(0, 0, 1), rotation=(np.pi, 0, 0))
    lamp = bpy.context.active_object
    lamp.name = "Panel"
    m = bpy.data.materials.new("Glow")
    b = node_tree(m).nodes["Principled BSDF"]
    b.inputs["Emission Color"].default_value = (1, 1, 1, 1)
    b.inputs["Emission Strength"].default_value = 2.0
    lamp.data.materials.append(m)
    src = str(tmp_path / "scene.gltf")
    bpy.ops.export_scene.gltf(filepath=src, export_format="GLTF_SEPARATE")
    out = str(tmp_path / "baked.glb")
    rc, stdout, err = run(addon, ["bake", src, "-o", out, "--objects", "Ground", "--patch-size", "0.5",
                                  "--resolution", "16", "--report", str(tmp_path / "r.json")])
    assert rc == 0, err
    rep = json.load(open(tmp_path / "r.json"))
    assert rep["objects"] == ["Ground"] and rep["occluders"] == ["Panel"]
    doc, accessor = read_gltf(out)
    assert [n["name"] for n in doc["nodes"]] == ["Ground.radiosity"]
    col = accessor(doc["meshes"][0]["primitives"][0]["attributes"]["COLOR_0"])
    assert col.min() > 0.01   # lit by the panel it did not bake


def test_cli_errors_one_line_on_stderr(addon, cornell_blend, tmp_path):
    rc, out, err = run(addon, ["bake", str(tmp_path / "missing.blend"), "-o", str(tmp_path / "x.glb")])
    assert rc == 1 and err.count("\n") == 1 and err.startswith("hemicube_radiosity: error: input file not found")
    rc, out, err = run(addon, ["bake", cornell_blend])   # would bake and write nothing
    assert rc == 2 and err.startswith("hemicube_radiosity: error: nothing would be written") and err.count("\n") == 1
    rc, out, err = run(addon, ["bake", cornell_blend, "--objects", "Nope", "-o", str(tmp_path / "x.glb"), *BAKE_ARGS])
    assert rc == 1 and err == "hemicube_radiosity: error: no object named 'Nope' in the input\n"
    rc, out, err = run(addon, ["bake", cornell_blend, "-o", str(tmp_path / "x.fbx")])
    assert rc == 2 and "unsupported output" in err and err.count("\n") == 1
    rc, out, err = run(addon, ["bake", cornell_blend, "--resolution", "31"])
    assert rc == 2 and "even" in err and err.count("\n") == 1
    rc, out, err = run(addon, ["--help"])   # argparse would sys.exit: the handler returns instead
    assert rc == 0


def test_argparse_errors_print_the_usage_line_once_then_one_error_line(addon, cornell_blend):
    rc, out, err = run(addon, ["bake", cornell_blend, "--method", "magic"])
    assert rc == 2 and out == ""
    usage, error = err.splitlines()
    assert usage == "usage: hemicube_radiosity bake INPUT [-o OUTPUT ...] [options]  (--help lists them)"
    assert error.startswith("hemicube_radiosity bake: error: argument --method: invalid choice: 'magic'")
    rc, out, err = run(addon, ["bake"])
    assert rc == 2 and err.splitlines()[1] == "hemicube_radiosity bake: error: the following arguments are required: INPUT"
    rc, out, err = run(addon, ["bak", "x.blend"])
    usage, error = err.splitlines()
    assert rc == 2 and usage.startswith("usage: hemicube_radiosity [-h] {bake,demo,batch}")
    assert error.startswith("hemicube_radiosity: error: argument command: invalid choice: 'bak'")


def test_python_m_quiet_glb_from_another_directory(addon, cornell_blend, tmp_path):
    """``-q``: nothing at all on stdout (no stage lines, notes, or Blender's own lines), nothing on
    stderr when it works; the real exit status. Through bin/hemicube-radiosity from another
    directory. On Blender 4.2 this is also the exit-0-after-glTF-export check (its bpy module
    crashes at interpreter shutdown after the glTF exporter ran: __main__ leaves before that)."""
    env = dict(os.environ, HEMICUBE_PYTHON=sys.executable)
    env.pop("PYTHONPATH", None)
    cmd = [os.path.join(ROOT, "bin", "hemicube-radiosity"), "bake", cornell_blend, "-o", "baked.glb",
           "--report", "r.json", "--patch-size", "0.5", "--resolution", "8", "--element-size", "0"]
    p = subprocess.run([*cmd, "-q"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert (p.returncode, p.stdout, p.stderr) == (0, "", "")
    assert read_gltf(str(tmp_path / "baked.glb"))[0]["nodes"]
    p = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert "radiosity: done in" in p.stdout and f"radiosity: wrote {tmp_path / 'baked.glb'}" in p.stdout


def test_registered_command_and_python_m(addon, tmp_path):
    blender = sub(addon, "blender")
    assert blender._cli_handle is not None
    assert blender.cli_command(["bake", str(tmp_path / "none.glb"), "-o", str(tmp_path / "x.glb")]) == 1
    # python -m with the bpy module, in a fresh process: real exit status and stderr line
    env = dict(os.environ, PYTHONPATH=ROOT)
    p = subprocess.run([sys.executable, "-m", "hemicube_radiosity", "bake", str(tmp_path / "none.obj"),
                        "-o", str(tmp_path / "x.glb")],
                       cwd=str(tmp_path), env=env, capture_output=True, text=True, timeout=120)
    assert p.returncode == 1
    assert p.stderr.strip().splitlines()[-1].startswith("hemicube_radiosity: error: input file not found")


def test_demo_command_writes_glb_and_png(addon, tmp_path):
    import struct

    rc, out, err = run(addon, ["demo", "--output-dir", str(tmp_path), "--patch-size", "0.5", "--resolution", "16",
                               "--render-size", "48", "--samples", "1"])
    assert rc == 0, err
    glb, png = tmp_path / "cornell.glb", tmp_path / "cornell.png"
    assert f"wrote {glb}" in out and f"wrote {png}" in out
    doc, accessor = read_gltf(str(glb))
    assert len(doc["nodes"]) == 8 and "KHR_materials_unlit" in doc["extensionsUsed"]
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and struct.unpack(">II", data[16:24]) == (48, 48)
    rep = json.load(open(tmp_path / "cornell_report.json"))
    assert rep["timings"]["render"] > 0 and rep["patches"] > 50
    # the demo says no note and no warning: one summary line with what was solved and written
    assert " note: " not in out and " warning: " not in out, out
    assert rep["warnings"] == [] and rep["notes"] == []
    # the Cornell box: 5 walls, the light and two blocks of 5 faces
    assert rep["faces"] == 16 and rep["patches_solved"] == rep["solved"] > 50
    assert rep["output_vertices"] == sum(v["vertices"] for v in rep["per_object"].values())
    said = [ln for ln in out.splitlines() if "patches solved" in ln]
    assert said == [f"radiosity: Radiosity: {rep['patches_solved']:,} patches solved from 16 faces, "
                    f"{rep['output_vertices']:,} output vertices; " + said[0].split("; ", 1)[1]], out


@pytest.mark.parametrize("gather", ["0", "64"])
def test_detail_size_bakes_a_finer_mesh_over_coarse_patches(addon, cornell_blend, tmp_path, gather):
    """--element-size: the solve runs on 0.5 m patches, the written mesh is cut to 0.125 m (and
    along the blocks' feet) and its colours follow the block's shadow on the floor that the
    coarse patches alone cannot."""
    rep = tmp_path / "r.json"
    rc, out, err = run(addon, ["bake", cornell_blend, "-o", str(tmp_path / "b.glb"), "--report", str(rep),
                               "--patch-size", "0.5", "--element-size", "0.125", "--resolution", "32",
                               "--gather-rays", gather, "--refine-levels", "0"])
    assert rc == 0, err
    r = json.loads(rep.read_text())
    assert r["elements"] >= 10 * r["patches"]     # both cut along the blocks' feet too
    per = r["per_object"]
    assert sum(v["elements"] for v in per.values()) == r["elements"]
    assert sum(v["patches"] for v in per.values()) == r["patches"]
    # 16 x 16 elements, those under the blocks' outlines cut along them (core/mesh/contact.py)
    assert 16 * 16 < per["Floor"]["elements"] < 2 * 16 * 16 and 4 * 4 < per["Floor"]["patches"] < 4 * 4 * 4
    assert r["settings"]["element_size"] == 0.125 and r["settings"]["gather_rays"] == int(gather)
    doc, accessor = read_gltf(str(tmp_path / "b.glb"))
    floor = next(m for m in doc["meshes"] if m["name"].startswith("Floor"))
    col = accessor(floor["primitives"][0]["attributes"]["COLOR_0"])[:, :3]
    pos = accessor(floor["primitives"][0]["attributes"]["POSITION"])
    assert 17 * 17 < len(pos) < 2 * 17 * 17   # a 2 m floor cut into 16 x 16 elements, and along the blocks
    lum = col @ [0.2126, 0.7152, 0.0722]
    # open floor in front (lit) against the floor in the tall block's umbra (from the light at
    # the ceiling's centre): 0.5 m patches (4 x 4 over the floor) could only blur that contrast
    x, y = pos[:, 0], -pos[:, 2]       # glTF is Y-up: Blender's y is glTF's -z
    lit = lum[(x > 1.5) & (x < 1.9) & (y > 0.1) & (y < 0.6)].mean()
    umbra = lum[(x > 1.65) & (x < 1.95) & (y > 1.65) & (y < 1.95)].mean()
    assert lit > 2.5 * umbra            # measured 3.0


def test_cli_estimate_error_reaches_the_report_and_the_summary(addon, cornell_blend, tmp_path):
    report = str(tmp_path / "r.json")
    rc, out, err = run(addon, ["bake", cornell_blend, "--report", report, "--patch-size", "0.5",
                               "--element-size", "0.25", "--gather-rays", "32", "--estimate-error"])
    assert rc == 0, err
    e = json.load(open(report))["error_estimate"]
    assert e["method"] == "detail" and 0 < e["noise"] <= e["error"] < 1
    assert e["error"] == pytest.approx(float(np.hypot(e["noise"], e["detail"])))
    assert "estimated error" in out
    assert json.load(open(report))["timings"]["estimate"] > 0
