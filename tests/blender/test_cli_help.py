"""``bake --help`` read line by line: every setting's flag is there once, its help says what that
flag does (a flag that turns a switch off says what turning it off does, not what the switch does
when on), its default is the schema's, and parsing the flag changes exactly that setting."""
import re

import pytest

from hemicube_radiosity.blender.cli.parser import bake_settings, build_parser, setting_flag
from hemicube_radiosity.core.settings import BakeSettings, schema

COMMANDS = ("bake", "demo", "batch")
ARGS = {"bake": ["in.blend"], "demo": [], "batch": ["in.blend", "--out-dir", "out"]}


def help_text(monkeypatch, command):
    monkeypatch.setenv("COLUMNS", "4000")    # one line per option's help: no wrapping
    parser = build_parser()
    sub = parser._subparsers._group_actions[0].choices[command]
    return sub.format_help()


def option_help(text):
    """{flag: its help} from argparse's help text: an option's line starts with '  -'; its help
    follows the invocation on that line or on the next (indented) line."""
    out, flag = {}, None
    for line in text.splitlines():
        m = re.match(r"^  (-\S+(?:, --\S+)?)(?: (\S+|\{[^}]*\}))?(?:\s{2,}(.*))?$", line)
        if m and line.startswith("  -"):
            flag = m.group(1).split(", ")[-1]
            out[flag] = (m.group(3) or "").strip()
        elif flag and line.startswith(" " * 10) and not out[flag]:
            out[flag] = line.strip()
    return out


def other_value(s):
    """A value of setting ``s`` other than its default, as text for the command line."""
    if s.values is not None:
        return next(v for v in s.values if v != s.default)
    if s.meta.get("size"):
        return "0.5"
    if s.type is str:
        return "somewhere" if s.name == "cache_dir" else "Baked"
    if s.type is int:
        lo = s.meta.get("min", 0)
        v = (s.default or lo) + 2
        return str(min(v, s.meta.get("max", v)))
    return repr(float(s.meta.get("min", 0.0)) + 0.5 if s.default == 0 else s.default / 2)


@pytest.mark.parametrize("command", COMMANDS)
def test_every_flag_says_what_it_does(monkeypatch, command):
    text = help_text(monkeypatch, command)
    helps = option_help(text)
    assert "(default None)" not in text and "(default )" not in text
    base = vars(build_parser().parse_args([command, *ARGS[command]]))
    for s in schema():
        flag = setting_flag(s)
        assert text.count(f"  {flag} ") + text.count(f"  {flag}\n") == 1, flag
        h = helps[flag]
        if s.type is bool:
            want = s.meta["off"] if s.default else s.help
            assert h == want, (flag, h)
            if s.default:   # the flag turns the switch off: its help must not be the switch's own
                assert flag.startswith(("--no-", "--one-")) and h != s.help
            args = vars(build_parser().parse_args([command, *ARGS[command], flag]))
            assert args[s.name] is (not s.default), flag
        else:
            assert h.startswith(s.help), (flag, h)
            if s.default in (None, ""):
                assert "(default" not in h[len(s.help):], (flag, h)
            else:
                assert h.endswith(f"(default {s.default})"), (flag, h)
            v = other_value(s)
            args = vars(build_parser().parse_args([command, *ARGS[command], flag, v]))
            assert str(args[s.name]).lower() == v.lower() or float(args[s.name]) == float(v), (flag, v)
        changed = {k for k in base if args[k] != base[k]}
        assert changed == {s.name}, (flag, changed)
        extra = ["--element-size", "0"] if s.name == "direct" else []   # finer elements need exact
        bake_settings(build_parser().parse_args([command, *ARGS[command], *extra, *(
            [flag] if s.type is bool else [flag, other_value(s)])]))   # valid settings


def test_negated_switches_and_defaults_spelled_out(monkeypatch):
    helps = option_help(help_text(monkeypatch, "bake"))
    assert helps["--no-lights"].startswith("Ignore light objects and the world")
    assert "take part as occluders" not in helps["--no-others"]
    assert helps["--one-sided-emission"].startswith("Emissive faces light their front only")
    assert helps["--rotate-seed"].endswith("(default: no rotation)")
    assert helps["--cache"].endswith("reused across sessions")
    assert helps["--patch-size"].endswith("(default auto)")
    s = bake_settings(build_parser().parse_args(["bake", "x.blend", "--no-lights", "--no-group-faces"]))
    assert (s.use_lights, s.group_faces, s.include_others) == (False, False, True)
    assert BakeSettings().use_lights is True
