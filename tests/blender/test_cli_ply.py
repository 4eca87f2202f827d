# SPDX-License-Identifier: GPL-3.0-or-later
"""``python -m hemicube_radiosity bake scene.ply``: Stanford PLY input through Blender's importer
(``bpy.ops.wm.ply_import``). A PLY carries geometry (and maybe vertex colours), no material: the
surfaces are Cycles' default grey 0.8, noted."""
from __future__ import annotations

import io

import numpy as np
import pytest

from tests.support.addon import sub

pytestmark = pytest.mark.blender

BOX = [(0, 0, 0), (2, 0, 0), (2, 1, 0), (0, 1, 0), (0, 0, 1), (2, 0, 1), (2, 1, 1), (0, 1, 1)]
# inward-facing faces of a 2 x 1 x 1 box, and one collapsed triangle (zero area: dropped)
FACES = [(0, 1, 2, 3), (4, 7, 6, 5), (0, 4, 5, 1), (1, 5, 6, 2), (2, 6, 7, 3), (3, 7, 4, 0), (0, 1, 1)]


def ascii_ply(path, verts, faces):
    head = ["ply", "format ascii 1.0", f"element vertex {len(verts)}", "property float x",
            "property float y", "property float z", f"element face {len(faces)}",
            "property list uchar int vertex_indices", "end_header"]
    body = [" ".join(map(str, v)) for v in verts] + [f"{len(f)} " + " ".join(map(str, f)) for f in faces]
    path.write_text("\n".join(head + body) + "\n")


def test_ply_input_bakes_its_geometry(addon, tmp_path):
    ascii_ply(tmp_path / "box.ply", BOX, FACES)
    out, err = io.StringIO(), io.StringIO()
    rc = sub(addon, "blender.cli.main").main(
        ["bake", str(tmp_path / "box.ply"), "--patches", str(tmp_path / "p.npz"), "--patch-size", "0.5",
         "--resolution", "16", "--element-size", "0"], in_blender=True, out=out, err=err)
    assert rc == 0, err.getvalue()
    z = np.load(tmp_path / "p.npz")
    # the box's 10 m2 of walls, every patch Cycles' default surface (no material; Blender's own
    # default, no note), no light: all dark; its specular layer bounces as diffuse light in
    # the solve (below the glossy threshold), so the patches reflect the two albedos' sum
    assert float(z["areas"].sum()) == pytest.approx(10.0, rel=1e-9)
    mats = sub(addon, "blender.read.materials")
    rho = mats.default_surface_rho() + mats.default_surface_glossy()
    np.testing.assert_allclose(z["reflectance"], rho, atol=1e-6)
    assert not z["radiosity"].any()
    assert "no material" not in out.getvalue()


def test_unsupported_input_names_ply(addon, tmp_path):
    out, err = io.StringIO(), io.StringIO()
    (tmp_path / "x.fbx").write_text("")
    rc = sub(addon, "blender.cli.main").main(["bake", str(tmp_path / "x.fbx"), "-o", str(tmp_path / "x.json")],
                                             in_blender=True, out=out, err=err)
    assert rc == 2 and "expected one of .blend, .obj, .gltf, .glb, .ply" in err.getvalue()
