"""``batch``: many files, one worker process each (``python -m hemicube_radiosity bake``).

Small scenes and small settings keep each worker near a second; the workers are real processes,
so a corrupt file, a rerun and --force are exercised end to end."""
from __future__ import annotations

import importlib
import io
import json
import os
import re
import shutil
import subprocess
import sys

import pytest

from tests.support import ROOT
from tests.support.gltf import read_gltf

pytestmark = pytest.mark.blender

SMALL = ["--resolution", "8", "--patch-size", "0.5", "--element-size", "0", "--gather-rays", "0"]


def cli(addon, module="main"):
    return importlib.import_module(f"{addon.__name__}.blender.cli.{module}")


def batch(addon, *argv):
    out, err = io.StringIO(), io.StringIO()
    rc = cli(addon).main(["batch", *argv], in_blender=True, out=out, err=err)
    return rc, out.getvalue(), err.getvalue()


def statuses(out):
    """{file name: status} from the summary table."""
    lines = out.splitlines()
    head = next(i for i, ln in enumerate(lines) if ln.startswith("file "))
    rows = {}
    for ln in lines[head + 1:]:
        if ln.startswith("radiosity: "):
            break
        name, status = ln.split()[:2]
        rows[name] = status
    return rows


@pytest.fixture(scope="module")
def scenes(addon, tmp_path_factory):
    """Two good .blend files (the Cornell box, the second with a dimmer light) and a corrupt one."""
    import bpy

    d = tmp_path_factory.mktemp("batch_in")
    demo = importlib.import_module(f"{addon.__name__}.blender.demo")
    bpy.ops.wm.read_homefile(use_empty=True)
    demo.build_cornell_box(bpy.context)
    bpy.ops.wm.save_as_mainfile(filepath=str(d / "box_a.blend"))
    bpy.data.objects["Light"].active_material.node_tree.nodes["Principled BSDF"].inputs[
        "Emission Strength"].default_value = 3.0
    bpy.ops.wm.save_as_mainfile(filepath=str(d / "box_b.blend"))
    (d / "broken.blend").write_bytes(b"BLENDER-v300 this is not a blend file" * 10)
    return {k: str(d / f"{k}.blend") for k in ("box_a", "box_b", "broken")}


def test_a_corrupt_file_fails_alone_then_reruns_skip_and_force_bakes(addon, scenes, tmp_path):
    out_dir = tmp_path / "out"
    files = [scenes["box_a"], scenes["broken"], scenes["box_b"]]
    rc, out, err = batch(addon, *files, "--out-dir", str(out_dir), "-j", "2", *SMALL)
    assert rc == 1, out + err
    assert statuses(out) == {"box_a.blend": "ok", "broken.blend": "failed", "box_b.blend": "ok"}
    # one line per file while it runs, then the table and the counts
    assert sum(ln.startswith("[") for ln in out.splitlines()) == 3
    assert "2 baked, 0 skipped, 1 failed" in out
    # the failure: one stderr line naming the file, and its worker's output kept in a log
    (line,) = err.splitlines()
    assert line.startswith(f"hemicube_radiosity: error: {scenes['broken']}: cannot read") and "broken.log" in line
    log = (out_dir / "broken.log").read_text()
    assert log.startswith("$ ") and "# exit status 1" in log and "error: cannot read" in log
    assert not (out_dir / "broken.glb").exists() and not (out_dir / "broken.json").exists()
    # the good ones: a glTF with colours, and a report with the settings given and the batch key
    light = {}
    for name in ("box_a", "box_b"):
        rep = json.loads((out_dir / f"{name}.json").read_text())
        assert rep["settings"]["resolution"] == 8 and rep["settings"]["gather_rays"] == 0
        assert rep["settings"]["patch_size"] == 0.5 and rep["settings"]["element_size"] is None
        assert len(rep["batch"]["key"]) == 64 and rep["batch"]["input"] == scenes[name]
        doc, accessor = read_gltf(str(out_dir / f"{name}.glb"))
        assert len(doc["nodes"]) == 8
        floor = next(m for m in doc["meshes"] if m["name"].startswith("Floor"))
        light[name] = accessor(floor["primitives"][0]["attributes"]["COLOR_0"])[:, :3].mean()
    assert light["box_b"] == pytest.approx(light["box_a"] * 3 / 12, rel=1e-3)   # linear in the light

    # rerun, nothing changed: no worker runs, the outputs stay as they were
    mtimes = {p.name: p.stat().st_mtime_ns for p in out_dir.iterdir()}
    rc, out, err = batch(addon, scenes["box_a"], scenes["box_b"], "--out-dir", str(out_dir), *SMALL)
    assert rc == 0, err
    assert statuses(out) == {"box_a.blend": "skipped", "box_b.blend": "skipped"}
    assert {p.name: p.stat().st_mtime_ns for p in out_dir.iterdir()} == mtimes

    # a changed input is baked again (same name, other content); the unchanged one is skipped
    shutil.copy(scenes["box_a"], tmp_path / "box_b.blend")
    rc, out, err = batch(addon, scenes["box_a"], str(tmp_path / "box_b.blend"), "--out-dir", str(out_dir), *SMALL)
    assert rc == 0 and statuses(out) == {"box_a.blend": "skipped", "box_b.blend": "ok"}, out + err
    # other settings are a change too
    rc, out, err = batch(addon, scenes["box_a"], "--out-dir", str(out_dir), *SMALL, "--solver", "jacobi", "-q")
    assert rc == 0 and out == "" and err == ""
    assert json.loads((out_dir / "box_a.json").read_text())["settings"]["solver"] == "jacobi"
    rc, out, err = batch(addon, scenes["box_a"], "--out-dir", str(out_dir), *SMALL, "--solver", "jacobi")
    assert statuses(out) == {"box_a.blend": "skipped"}
    # --force bakes even what is current
    rc, out, err = batch(addon, scenes["box_a"], "--out-dir", str(out_dir), *SMALL, "--solver", "jacobi",
                         "--force")
    assert rc == 0 and statuses(out) == {"box_a.blend": "ok"}


def test_a_deleted_output_is_baked_again(addon, scenes, tmp_path):
    rc, out, err = batch(addon, scenes["box_a"], "--out-dir", str(tmp_path), "--format", "blend", *SMALL)
    assert rc == 0 and (tmp_path / "box_a.blend").exists(), err
    os.remove(tmp_path / "box_a.blend")
    rc, out, err = batch(addon, scenes["box_a"], "--out-dir", str(tmp_path), "--format", "blend", *SMALL)
    assert rc == 0 and statuses(out) == {"box_a.blend": "ok"}


def test_exit_codes_and_errors_before_any_work(addon, scenes, tmp_path):
    # two inputs that would write the same output: refused before anything runs
    other = tmp_path / "elsewhere"
    other.mkdir()
    shutil.copy(scenes["box_a"], other / "box_a.blend")
    rc, out, err = batch(addon, scenes["box_a"], str(other / "box_a.blend"), "--out-dir", str(tmp_path / "o"))
    assert rc == 2 and "would both write box_a.glb" in err and not (tmp_path / "o").exists()
    # argparse errors: the usage line once, then one error line
    rc, out, err = batch(addon, scenes["box_a"])
    assert rc == 2
    assert err.splitlines()[0].startswith("usage: hemicube_radiosity batch FILE")
    assert err.splitlines()[1] == "hemicube_radiosity batch: error: the following arguments are required: --out-dir"
    assert len(err.splitlines()) == 2
    rc, out, err = batch(addon, scenes["box_a"], "--out-dir", str(tmp_path), "-j", "0")
    assert rc == 2 and "argument -j/--jobs: must be >= 1" in err
    # files the parent can judge alone fail alone: missing, unsupported, would overwrite its input
    (tmp_path / "notes.txt").write_text("x")
    rc, out, err = batch(addon, str(tmp_path / "missing.obj"), str(tmp_path / "notes.txt"), "--out-dir", str(tmp_path))
    assert rc == 1 and statuses(out) == {"missing.obj": "failed", "notes.txt": "failed"}
    assert "input file not found" in err and "unsupported input" in err
    shutil.copy(scenes["box_a"], tmp_path / "same.blend")
    rc, out, err = batch(addon, str(tmp_path / "same.blend"), "--out-dir", str(tmp_path), "--format", "blend")
    assert rc == 1 and "would overwrite the input" in err


def test_python_m_batch_from_another_directory(addon, scenes, tmp_path):
    """The real process: exit status 1 when a file fails, 0 when all are baked; run from a
    directory that is not the repository, through bin/hemicube-radiosity."""
    env = dict(os.environ, HEMICUBE_PYTHON=sys.executable)
    env.pop("PYTHONPATH", None)
    wrapper = os.path.join(ROOT, "bin", "hemicube-radiosity")
    p = subprocess.run([wrapper, "batch", scenes["broken"], "--out-dir", "out", "-q"],
                       cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert p.returncode == 1 and p.stdout == "", p.stdout + p.stderr
    assert p.stderr.startswith(f"hemicube_radiosity: error: {scenes['broken']}: cannot read")
    p = subprocess.run([wrapper, "batch", scenes["box_a"], "--out-dir", "out", *SMALL],
                       cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stdout + p.stderr
    assert (tmp_path / "out" / "box_a.glb").exists() and "1 baked, 0 skipped, 0 failed" in p.stdout


def test_worker_gets_the_settings_it_was_given(addon):
    """What a worker is told re-parses to the very settings the batch parsed (every type of
    option: switches, choices, sizes, numbers, strings), and defaults are not repeated."""
    c = cli(addon, "batch")
    p = cli(addon, "parser")
    cpu_count = importlib.import_module(f"{addon.__name__}.core.runtime.parallel").cpu_count
    argv = ["batch", "x.blend", "--out-dir", "o", "--no-lights", "--method", "EMBREE", "--patch-size", "0.3",
            "--element-size", "0", "--resolution", "16", "--tolerance", "1e-5", "--cache", "/tmp/ff cache",
            "--attribute", "Col", "--rotate-seed", "3"]
    args = p.build_parser().parse_args(argv)
    words = c.setting_argv(args)
    again = p.build_parser().parse_args(["bake", "x.blend", *words])
    assert p.BakeSettings.from_mapping(again) == p.BakeSettings.from_mapping(args)
    assert "--max-patches" not in words and "--no-others" not in words
    assert c.setting_argv(p.build_parser().parse_args(["batch", "x.blend", "--out-dir", "o"])) == []
    # two files at once on this machine's cores share them; a given --workers is kept
    two = p.build_parser().parse_args(["batch", "x.blend", "--out-dir", "o", "-j", "2"])
    assert c.batch_worker_argv(two) == ["--workers", str(max(1, cpu_count() // 2))]
    kept = p.build_parser().parse_args(["batch", "x.blend", "--out-dir", "o", "-j", "2", "--workers", "3"])
    assert c.batch_worker_argv(kept) == ["--workers", "3"]
    cmd, env = c.worker_command(["x.blend"])
    assert cmd[:4] == [sys.executable, "-m", "hemicube_radiosity", "bake"]
    assert os.path.realpath(env["PYTHONPATH"].split(os.pathsep)[0]) == os.path.realpath(ROOT)
    # inside Blender: Blender itself runs the registered command of this very add-on
    cmd, env = c.worker_command(["x.blend", "-o", "x.glb"], blender="/opt/blender/blender")
    addon_module = addon.__name__.rsplit(".", 1)[0]          # bl_ext.<repo>.hemicube_radiosity
    assert cmd == ["/opt/blender/blender", "--background", "--addons", addon_module,
                   "-c", "hemicube_radiosity", "bake", "x.blend", "-o", "x.glb"]


FLAMENCO_STUBS = """
const tasks = [];
const author = {
    Task: (name, type) => ({ name, type, commands: [], addCommand(c) { this.commands.push(c); } }),
    Command: (name, params) => ({ name, params }),
};
const job = { settings: SETTINGS, addTask: (t) => tasks.push(t) };
compileJob(job);
console.log(JSON.stringify({ label: JOB_TYPE.label, keys: JOB_TYPE.settings.map((s) => s.key), tasks }));
"""


@pytest.mark.skipif(shutil.which("node") is None, reason="Node.js runs the Flamenco job script")
def test_flamenco_job_type_sends_the_batch_command(addon, tmp_path):
    """The job compiler script in docs/pipeline.md, run under Node with stand-ins for Flamenco's
    author/job objects: one blender task per file, each a command line the CLI parses."""
    doc = open(os.path.join(ROOT, "docs", "pipeline.md"), encoding="utf-8").read()
    (script,) = re.findall(r"```javascript\n(.*?)```", doc, re.S)
    settings = {"blendfile": "/farm/shots/a.blend", "extra_files": " /farm/shots/b.obj ; ",
                "out_dir": "/farm/out", "format": "glb", "bake_args": "--patch-size 0.25  --gather-rays 16",
                "force": True}
    js = tmp_path / "job.js"
    js.write_text(script + FLAMENCO_STUBS.replace("SETTINGS", json.dumps(settings)))
    p = subprocess.run(["node", str(js)], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    got = json.loads(p.stdout)
    assert got["label"] == "Hemi-cube Radiosity Bake" and "blendfile" in got["keys"]
    assert [t["name"] for t in got["tasks"]] == ["radiosity-a.blend", "radiosity-b.obj"]
    parser = cli(addon).build_parser()
    for task, file in zip(got["tasks"], ["/farm/shots/a.blend", "/farm/shots/b.obj"]):
        assert task["type"] == "blender"
        (cmd,) = task["commands"]
        c = cmd["params"]
        assert cmd["name"] == "blender-render" and c["exe"] == "{blender}" and c["exeArgs"] == "{blenderArgs}"
        # what Blender gets after its own options: -c hemicube_radiosity <argv>
        assert c["argsBefore"][:2] == ["-c", "hemicube_radiosity"]
        args = parser.parse_args([*c["argsBefore"][2:], c["blendfile"], *c["args"]])
        assert args.command == "batch" and args.files == [file] and args.out_dir == "/farm/out"
        assert args.jobs == 1 and args.format == "glb" and args.force
        assert args.patch_size == 0.25 and args.gather_rays == 16
