"""Notes and warnings as a person reads them (core/runtime/notes.py): one line per kind naming
its subjects, warnings first, nothing said twice, a line of one subject as it was written."""
import ast
import re
from pathlib import Path

import pytest

from hemicube_radiosity.core.runtime.notes import (
    HELP_DOC, HELP_SITE, TOPICS, Note, grouped, help_url, note, subject_and_kind, warning
)

ROOT = Path(__file__).resolve().parents[3]


def test_a_note_is_its_line():
    n = note("material 'Chrome'", "specular not baked", detail="metallic 1")
    assert n == "material 'Chrome': specular not baked (metallic 1)" and isinstance(n, str)
    assert (n.subject, n.kind, n.warning) == ("material 'Chrome'", "specular not baked", False)
    w = warning("nothing lights the scene", topic="scene")
    assert w == "nothing lights the scene" and w.subject is None and w.warning and w.topic == "scene"


def test_plain_lines_are_parsed_for_their_subject():
    assert subject_and_kind("Floor: no material; grey 0.8") == ("Floor", "no material; grey 0.8", False)
    assert subject_and_kind("light 'Key': light linking ignored") == ("light 'Key'", "light linking ignored", False)
    assert subject_and_kind("'Mesh 4': every face has zero area; left out")[0] == "'Mesh 4'"
    # a sentence is not a subject
    line = "refining where the light changes abruptly would make 9 patches: kept"
    assert subject_and_kind(line) == (None, line, False)


def test_lines_group_by_kind_with_warnings_first():
    kind = "metallic or specular reflect light not baked"
    lines = ["Floor: no material; grey 0.8",
             note("material 'Chrome'", kind, detail="0.02"),
             warning("cannot be read", "image 'a.png'", detail="/x/a.png", topic="materials"),
             note("material 'Gold'", kind, detail="0.3"),
             "Wall: no material; grey 0.8",
             note("material 'Chrome'", kind, detail="0.02"),        # a second object: said once
             warning("cannot be read", "image 'b.png'", topic="materials"),
             "refined 3 patches into 9"]
    g = grouped(lines)
    assert g.warnings == ("images 'a.png' and 'b.png': cannot be read",)
    assert g.notes == ("Floor and Wall: no material; grey 0.8",
                       f"materials 'Chrome' and 'Gold': {kind}",
                       "refined 3 patches into 9")
    assert [lv for lv, _ in g.lines()] == ["warning", "help", "note", "note", "note"]


def test_one_subject_keeps_its_line_and_many_are_counted():
    g = grouped([note("light 'Key'", "spread ignored", detail="30 deg")])
    assert g.notes == ("light 'Key': spread ignored (30 deg)",)
    many = grouped([note(f"Box{i}", "no material; grey 0.8") for i in range(10)] + ["Box3: no material; grey 0.8"])
    assert many.notes == ("Box0, Box1, Box2, Box3 and 6 more: no material; grey 0.8",)
    mixed = grouped([note("Floor", "k"), note("material 'M'", "k")])
    assert mixed.notes == ("Floor and material 'M': k",)
    assert grouped([]).lines() == [] and isinstance(Note("x"), str)


def test_warnings_name_where_to_read_about_them_once_per_topic():
    a = warning("cannot be read", "image 'a.png'", topic="materials")
    b = warning("nothing lights the scene", topic="scene")
    c = warning("cannot be read", "image 'b.png'", topic="materials")
    g = grouped([a, "Floor: no material; grey 0.8", b, c])
    assert g.topics == ("materials", "scene")
    levels = [lv for lv, _ in g.lines()]
    assert levels == ["warning", "warning", "help", "help", "note"]
    helps = [t for lv, t in g.lines() if lv == "help"]
    assert helps[0] == ("what to change: docs/troubleshooting.md, 'Materials (the bake goes on)' "
                        "(" + HELP_SITE + "docs/troubleshooting.md#materials-the-bake-goes-on)")
    assert help_url("scene").endswith("#scene-and-lights")
    with pytest.raises(ValueError, match="unknown topic"):
        warning("x", topic="nowhere")
    assert grouped(["Floor: no material; grey 0.8"]).topics == ()     # notes name no topic


def _warning_calls():
    """(file, line, topic, [literal fragments of the text]) of every warning the add-on can
    say: calls of ``warning(...)``, and of ``Note``/``note`` with a ``warning`` that may be true,
    in its source."""
    out = []
    for path in sorted(ROOT.glob("hemicube_radiosity/**/*.py")):
        if path.name == "notes.py":                       # the functions themselves
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if not isinstance(node, ast.Call):
                continue
            name = getattr(node.func, "id", getattr(node.func, "attr", None))
            kw = {k.arg: k.value for k in node.keywords}
            said = kw.get("warning")                     # Note/note(..., warning=...): may warn
            may_warn = name in ("Note", "note") and said is not None and \
                not (isinstance(said, ast.Constant) and not said.value)
            if name != "warning" and not may_warn or not node.args:
                continue
            topic = kw.get("topic")
            topic = topic.value if isinstance(topic, ast.Constant) else None
            text = node.args[0]
            parts = [text.value] if isinstance(text, ast.Constant) else \
                [v.value for v in getattr(text, "values", []) if isinstance(v, ast.Constant)]
            out.append((path.relative_to(ROOT), node.lineno, topic, parts))
    return out


def _sections():
    doc = (ROOT / HELP_DOC).read_text()
    return {m.group(1): body for m in re.finditer(r"^## ([^\n]+)\n(.*?)(?=^## |\Z)", doc, re.M | re.S)
            for body in [m.group(2)]}


def test_every_warning_has_a_topic_whose_section_gives_its_text():
    calls = _warning_calls()
    assert len(calls) >= 15                               # the warnings said today
    sections = _sections()
    assert set(TOPICS.values()) <= set(sections), "every topic is a section of the page"
    for path, line, topic, parts in calls:
        assert topic in TOPICS, f"{path}:{line}: a warning without a topic (one of {sorted(TOPICS)})"
        frags = [f.strip(" ,;:.") for p in parts for f in re.split(r"['(){}]", p)]
        frags = [f for f in frags if len(f) >= 8]
        if not frags:                                     # its text comes from elsewhere
            continue
        head = frags[0]                                   # the words that open the warning
        assert head in sections[TOPICS[topic]], \
            f"{path}:{line}: '{head}' is not in {HELP_DOC}, section '{TOPICS[topic]}'"
