# SPDX-License-Identifier: GPL-3.0-or-later
"""The command line's words: the parser of ``bake``, ``demo`` and ``batch``, one option per bake
setting, and the one error type the commands raise.

The bake settings' options are generated from the core schema (``core/settings.py``): every
setting has one, named ``--field-name`` unless the schema says otherwise (:func:`setting_flag`).
A bad argument is a :class:`CLIError` of status 2 carrying the command's usage line; argparse is
never let to ``sys.exit`` (the command may run inside Blender).
"""
from __future__ import annotations

import argparse
import os

from ...core.runtime.errors import RadiosityError
from ...core.runtime.parallel import cpu_count
from ...core.settings import BakeSettings, schema
from ..export import EXPORTERS

__all__ = ["PROG", "INPUT_EXT", "BATCH_FORMATS", "CLIError", "setting_flag", "add_setting_options",
           "build_parser", "bake_settings"]

PROG = "hemicube_radiosity"
INPUT_EXT = (".blend", ".obj", ".gltf", ".glb", ".ply")
BATCH_FORMATS = ("glb", "gltf", "blend")


class CLIError(RadiosityError):
    """A user error on the command line: printed as one line, exit status ``status``; ``usage``
    (argparse's errors) is printed on the line before."""

    def __init__(self, message, status=1, usage=None, prog=PROG):
        super().__init__(message)
        self.status = status
        self.usage = usage
        self.prog = prog


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # never sys.exit from inside Blender: main() prints it
        raise CLIError(message, status=2, usage=self.format_usage().strip(), prog=self.prog)


def _number(kind, lowest, expected, auto=False):
    """An argparse type: a ``kind`` (int or float) >= ``lowest``, or 'auto' where allowed."""
    def parse(text):
        if auto and text == "auto":
            return text
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None
        if v < lowest:
            raise argparse.ArgumentTypeError(f"must be >= {lowest}, got {v:g}")
        return v
    return parse


_size = _number(float, 0, "'auto' or a number", auto=True)        # a size: 'auto' or >= 0
_positive_int = _number(int, 1, "a whole number")                   # a count: >= 1


def setting_flag(s):
    """The command-line option of setting ``s``: ``--field-name`` unless the schema names another."""
    return s.meta.get("cli", "--" + s.name.replace("_", "-"))


def add_setting_options(p):
    """One option per setting of the core schema, with its default, choices and help. A switch
    that is on by default gets a flag that turns it off, helped by the schema's ``off`` sentence
    (what turning it off does), not by the switch's own; a setting whose default is nothing
    (None, '') says no default."""
    for s in schema():
        flag = setting_flag(s)
        if s.type is bool:
            help = (s.meta["off"] if s.default else s.help).replace("%", "%%")
            action = "store_false" if s.default else "store_true"
            p.add_argument(flag, dest=s.name, action=action, default=s.default, help=help)
            continue
        help = s.help.replace("%", "%%")
        if s.default not in (None, ""):
            help += " (default %(default)s)"
        kw = dict(dest=s.name, default=s.default, help=help)
        if s.choices is not None:
            kw.update(choices=s.values, type=str.lower)
        elif s.meta.get("size"):
            kw.update(type=_size, metavar="S")
        else:
            kw.update(type=s.type, metavar=s.name.split("_")[-1].upper())
        p.add_argument(flag, **kw)


def build_parser():
    p = _Parser(prog=PROG, description="Hemi-cube radiosity baking with Blender (bpy).")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    b = sub.add_parser("bake", help="bake a scene file", description="Bake a .blend/.obj/.gltf/.glb/.ply.",
                       usage="%(prog)s INPUT [-o OUTPUT ...] [options]  (--help lists them)")
    b.add_argument("input", metavar="INPUT", help="scene file: " + ", ".join(INPUT_EXT))
    b.add_argument("-o", "--output", action="append", default=[], metavar="OUTPUT",
                   help="file to write, by extension: " + "; ".join(
                       f"{ext} {what}" for ext, (_, what, _) in EXPORTERS.items()) + " (repeatable)")
    b.add_argument("--objects", nargs="+", metavar="NAME",
                   help="objects to bake (default: every visible mesh); other visible meshes "
                        "still occlude and emit unless --no-others")
    m = sub.add_parser("demo", help="bake the Cornell box demo and render a preview",
                       description="Build the Cornell box, bake it, write cornell.glb and cornell.png.",
                       usage="%(prog)s [--output-dir DIR] [options]  (--help lists them)")
    m.add_argument("--output-dir", default=os.path.join("demo", "out"), metavar="DIR")
    m.add_argument("--render-size", type=int, default=512, metavar="PX", help="PNG size (default %(default)s)")
    m.add_argument("--samples", type=int, default=16, help="Cycles samples for the PNG (default %(default)s)")
    m.add_argument("--no-render", action="store_true", help="skip the PNG")
    for q in (b, m):
        q.add_argument("--report", metavar="REPORT.json", help="write the bake report (a .json output)")
        q.add_argument("--patches", metavar="PATCHES.npz", help="write per-patch arrays (a .npz output)")
    t = sub.add_parser("batch", help="bake many files, one worker process each",
                       description="Bake every FILE in its own process (python -m hemicube_radiosity "
                                   "bake, or Blender itself inside Blender), N at a time, into "
                                   "DIR/NAME.FORMAT with DIR/NAME.json as its report. Unchanged files "
                                   "(same content, same settings) are skipped unless --force.",
                       usage="%(prog)s FILE [FILE ...] --out-dir DIR [-j N] [options]  (--help lists them)")
    t.add_argument("files", nargs="+", metavar="FILE", help="scene files: " + ", ".join(INPUT_EXT))
    t.add_argument("--out-dir", required=True, metavar="DIR", help="where NAME.FORMAT and NAME.json go")
    t.add_argument("-j", "--jobs", type=_positive_int, default=cpu_count(), metavar="N",
                   help="files baked at once (default: the number of cores, %(default)s here)")
    t.add_argument("--format", choices=BATCH_FORMATS, default="glb", type=str.lower,
                   help="output format (default %(default)s)")
    t.add_argument("--force", action="store_true", help="bake even the files whose last bake is current")
    t.add_argument("--timeout", type=float, default=None, metavar="SECONDS",
                   help="stop a file's worker after this long and count the file as failed")
    for q in (b, m, t):
        q.add_argument("-q", "--quiet", action="store_true",
                       help="print nothing on stdout (no stage lines, notes or Blender output); errors only")
        add_setting_options(q)
    return p


def bake_settings(args) -> BakeSettings:
    """The bake settings of parsed ``args``, validated (a bad value is a usage error)."""
    s = BakeSettings.from_mapping(args)
    try:
        s.validate()
    except RadiosityError as ex:
        raise CLIError(str(ex), status=2) from None
    return s
