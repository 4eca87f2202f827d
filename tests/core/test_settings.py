"""One settings schema: the core's BakeSettings, the panel's properties, the operator's and the
CLI's options share every default, choice and limit; the report is the settings as used; the
panel shows every panel setting exactly once."""
from __future__ import annotations

import dataclasses
import io
import json
import types

import numpy as np
import pytest

from hemicube_radiosity.core.runtime.errors import RadiosityError, SettingsError
from hemicube_radiosity.core.settings import AUTO_SWITCH, BakeSettings, schema
from tests.support.addon import sub


def test_every_setting_has_label_help_and_a_valid_default():
    names = [f.name for f in dataclasses.fields(BakeSettings)]
    assert [s.name for s in schema()] == names
    for s in schema():
        assert s.label and s.help and len(s.help) > 10, s.name
        if s.values is not None:
            assert s.default in s.values and len(set(s.values)) == len(s.values)
    BakeSettings().validate()


@pytest.mark.parametrize("field,bad,match", [
    ("method", "magic", "unknown method"), ("solver", "cg", "unknown solver"),
    ("resolution", 31, "even"), ("resolution", 0, "hemi-cube resolution"),
    ("patch_size", -1.0, "patch size"), ("element_size", "big", "detail size"),
    ("tolerance", 0.0, "tolerance"), ("max_iterations", 0, "max iterations"),
    ("gather_rays", -1, "gather rays"), ("exposure", float("nan"), "exposure"),
])
def test_out_of_range_settings_name_themselves(field, bad, match):
    with pytest.raises(SettingsError, match=match) as ex:
        BakeSettings(**{field: bad}).validate()
    assert isinstance(ex.value, RadiosityError) and "\n" not in str(ex.value)


def test_from_mapping_reads_blender_style_values():
    s = BakeSettings.from_mapping({"method": "EMBREE", "solver": "JACOBI", AUTO_SWITCH: False,
                                   "patch_size": 0.5, "element_size": 0.0, "output_mode": "IN_PLACE"})
    assert (s.method, s.solver, s.patch_size, s.element_size, s.output_mode) == \
        ("embree", "jacobi", 0.5, None, "in_place")
    assert not s.uses_elements()                       # in place, the user's faces are the output
    auto = BakeSettings.from_mapping({AUTO_SWITCH: True, "patch_size": 0.5, "element_size": 0.1})
    assert (auto.patch_size, auto.element_size) == ("auto", "auto")
    assert BakeSettings.from_mapping({}) == BakeSettings()
    assert BakeSettings.from_mapping(types.SimpleNamespace(resolution=64)).resolution == 64


@pytest.mark.blender
def test_panel_operator_and_core_share_every_default_choice_and_limit(addon):
    import bpy

    props = sub(addon, "blender.ui.props")
    d = BakeSettings()
    group = bpy.types.Scene.bl_rna.properties["hemicube_radiosity"].fixed_type
    op = bpy.ops.object.radiosity_bake.get_rna_type()
    shown = {s.name for s in props.panel_settings()}
    assert shown == {s.name for s in schema() if s.group is not None}
    for rna in (group, op):
        assert rna.properties[AUTO_SWITCH].default is True
        for s in schema():
            if s.group is None:
                assert s.name not in rna.properties, s.name
                continue
            p = rna.properties[s.name]
            assert p.name == s.label and p.description == s.help, s.name
            if s.values is not None:
                assert [(i.identifier, i.name, i.description) for i in p.enum_items] == \
                    [(v.upper(), label, h) for v, label, h in s.choices]
                assert p.default == getattr(d, s.name).upper()
            elif s.meta.get("size"):
                assert getattr(d, s.name) == "auto" and p.default == pytest.approx(s.meta["manual"])
            else:
                assert p.default == pytest.approx(getattr(d, s.name)) if s.type is float \
                    else p.default == getattr(d, s.name), s.name
            for limit in ("min", "max", "soft_min", "soft_max"):
                if limit in s.meta:
                    assert getattr(p, {"min": "hard_min", "max": "hard_max"}.get(limit, limit)) == \
                        pytest.approx(s.meta[limit]), (s.name, limit)
    # the panel's property group, read back as settings, is the core's defaults
    scene = bpy.data.scenes[0]
    assert dataclasses.asdict(props.to_settings(scene.hemicube_radiosity)) == dataclasses.asdict(d)


@pytest.mark.blender
def test_cli_options_are_the_schema(addon):
    cli = sub(addon, "blender.cli.main")
    parser = cli.build_parser()
    args = parser.parse_args(["bake", "in.blend", "-o", "out.glb"])
    assert dataclasses.asdict(BakeSettings.from_mapping(args)) == dataclasses.asdict(BakeSettings())
    bake = next(a for a in parser._subparsers._group_actions[0].choices.items() if a[0] == "bake")[1]
    by_dest = {a.dest: a for a in bake._actions}
    for s in schema():
        a = by_dest[s.name]
        if s.values is not None:
            assert tuple(a.choices) == s.values
        assert a.default == s.default
    args = parser.parse_args(["bake", "in.blend", "-o", "x.glb", "--method", "EMBREE", "--no-lights",
                              "--patch-size", "0", "--element-size", "auto", "--light-samples", "4",
                              "--output-mode", "in_place", "--rotate-seed", "3"])
    s = BakeSettings.from_mapping(args)
    assert (s.method, s.use_lights, s.patch_size, s.element_size, s.light_samples, s.output_mode,
            s.rotate_seed) == ("embree", False, None, "auto", 4, "in_place", 3)


class _Layout:
    """Records what a panel draws."""

    def __init__(self, log):
        self.log = log
        self.enabled = True

    def __getattr__(self, name):
        if name in ("column", "row"):
            return lambda *a, **k: _Layout(self.log)
        if name == "prop":
            return lambda data, prop, **k: self.log.append((prop, self.enabled))
        if name == "operator":
            return lambda idname, **k: self.log.append((idname, True))
        return lambda *a, **k: None

    def __setattr__(self, name, value):
        object.__setattr__(self, name, value)


@pytest.mark.blender
def test_panel_draws_every_setting_once_top_first_and_sizes_follow_the_switch(addon, empty_scene):
    bpy = empty_scene
    panel = sub(addon, "blender.ui.panel")
    props = sub(addon, "blender.ui.props")
    s = bpy.context.scene.hemicube_radiosity
    log = []
    panel.draw_main(_Layout(log), bpy.context)
    main = [p for p, _ in log]
    assert main[0] == AUTO_SWITCH and "object.radiosity_bake" in main
    for group, _ in panel.SUBPANELS:
        panel.draw_group(_Layout(log), s, group)
    drawn = [p for p, _ in log if not p.startswith("object.")]
    hidden_here = {"rays_per_patch"}          # shown only for the stochastic method
    expected = {x.name for x in props.panel_settings()} | {AUTO_SWITCH}
    assert set(drawn) == expected - hidden_here and len(drawn) == len(set(drawn))
    assert all(not enabled for p, enabled in log if p in ("patch_size", "element_size"))
    s.auto_size, s.method = False, "EMBREE_STOCHASTIC"
    log.clear()
    for group, _ in panel.SUBPANELS:
        panel.draw_group(_Layout(log), s, group)
    names = dict(log)
    assert names["patch_size"] and names["element_size"] and "rays_per_patch" in names
    assert "resolution" not in names
    # both places in the UI have the same sub-panels under their main panel
    for prefix in ("RENDER", "VIEW3D"):
        kids = [c for c in panel.classes if getattr(c, "bl_parent_id", "") == f"{prefix}_PT_radiosity_bake"]
        assert [c.radiosity_group for c in kids] == [g for g, _ in panel.SUBPANELS]


@pytest.mark.blender
def test_report_settings_are_the_settings_as_used(addon, tmp_path):
    import bpy

    cli = sub(addon, "blender.cli.main")
    bpy.ops.wm.read_homefile(use_empty=True)
    sub(addon, "blender.demo").build_cornell_box(bpy.context)
    blend = str(tmp_path / "in.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    rep = tmp_path / "r.json"
    out, err = io.StringIO(), io.StringIO()
    rc = cli.main(["bake", blend, "--report", str(rep), "--resolution", "16", "--gather-rays", "0"],
                  in_blender=True, out=out, err=err)
    assert rc == 0, err.getvalue()
    r = json.loads(rep.read_text())
    assert set(r["settings"]) == {s.name for s in schema()}
    assert r["settings"]["patch_size"] == pytest.approx(2 * 3 ** 0.5 / 14)   # 'auto', resolved
    assert r["settings"]["resolution"] == 16
    # every stage that ran is timed, and each printed one line
    stages = ("read", "patches", "form_factors", "direct", "solve", "vertices", "write")
    assert all(r["timings"][k] >= 0 for k in stages + ("total",))
    text = out.getvalue()
    for name in ("patches:", "form factors:", "direct light:", "solve:", "vertices:", "write:"):
        assert f"radiosity: {name}" in text, name


# ----------------------------------------------------------------------------- quality levels
def test_quality_levels_set_the_settings_left_at_their_defaults():
    from hemicube_radiosity.core.settings import QUALITY, QUALITY_LEVELS

    assert [v for v, _, _ in QUALITY_LEVELS] == list(QUALITY)
    # production is the defaults themselves: a default bake is what it was
    assert BakeSettings().with_quality() == BakeSettings()
    assert BakeSettings().patches_per_diagonal() == 14.0
    d = BakeSettings(quality="draft").with_quality()
    assert (d.resolution, d.gather_rays, d.refine_levels, d.sky_rays) == (16, 32, 1, 64)
    assert BakeSettings(quality="draft").patches_per_diagonal() == pytest.approx(0.6 * 14)
    # a setting the user changed overrides the level
    own = BakeSettings(quality="draft", resolution=64, gather_rays=0).with_quality()
    assert (own.resolution, own.gather_rays, own.refine_levels) == (64, 0, 1)
    for level in QUALITY:
        BakeSettings(quality=level).with_quality().validate()
    with pytest.raises(SettingsError, match="unknown quality 'best'"):
        BakeSettings(quality="best").validate()


def test_every_quality_level_is_exact_in_the_furnace_and_costs_in_order():
    """Closed room, E = 1, rho = 0.5 everywhere: B = E / (1 - rho) = 2 at every output vertex at
    every level (the cheaper levels are coarser, not wrong); each level cuts more than the last."""
    from hemicube_radiosity.core.builtin_scenes import closed_box, cornell_box
    from hemicube_radiosity.core.pipeline import bake
    from hemicube_radiosity.core.settings import QUALITY

    sizes = []
    for level in QUALITY:
        r = bake(closed_box(size=(1.0, 1.3, 0.8), rho=(0.5,) * 3, emission=(1.0,) * 3),
                 BakeSettings(quality=level, tolerance=1e-7, max_iterations=2000))
        np.testing.assert_allclose(r.vertex_radiosity, 2.0, rtol=2e-3, err_msg=level)
        assert r.settings.resolution == QUALITY[level]["resolution"]
        c = bake(cornell_box(), BakeSettings(quality=level))
        sizes.append((c.unknowns, len(c.elements)))
    assert all(a[0] < b[0] and a[1] < b[1] for a, b in zip(sizes, sizes[1:])), sizes
