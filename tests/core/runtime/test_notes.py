"""Notes and warnings as a person reads them (core/runtime/notes.py): one line per kind naming
its subjects, warnings first, nothing said twice, a line of one subject as it was written."""
from hemicube_radiosity.core.runtime.notes import Note, grouped, note, subject_and_kind, warning


def test_a_note_is_its_line():
    n = note("material 'Chrome'", "specular not baked", detail="metallic 1")
    assert n == "material 'Chrome': specular not baked (metallic 1)" and isinstance(n, str)
    assert (n.subject, n.kind, n.warning) == ("material 'Chrome'", "specular not baked", False)
    w = warning("nothing lights the scene")
    assert w == "nothing lights the scene" and w.subject is None and w.warning


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
             warning("cannot be read", "image 'a.png'", detail="/x/a.png"),
             note("material 'Gold'", kind, detail="0.3"),
             "Wall: no material; grey 0.8",
             note("material 'Chrome'", kind, detail="0.02"),        # a second object: said once
             warning("cannot be read", "image 'b.png'"),
             "refined 3 patches into 9"]
    g = grouped(lines)
    assert g.warnings == ("images 'a.png' and 'b.png': cannot be read",)
    assert g.notes == ("Floor and Wall: no material; grey 0.8",
                       f"materials 'Chrome' and 'Gold': {kind}",
                       "refined 3 patches into 9")
    assert [lv for lv, _ in g.lines()] == ["warning", "note", "note", "note"]


def test_one_subject_keeps_its_line_and_many_are_counted():
    g = grouped([note("light 'Key'", "spread ignored", detail="30 deg")])
    assert g.notes == ("light 'Key': spread ignored (30 deg)",)
    many = grouped([note(f"Box{i}", "no material; grey 0.8") for i in range(10)] + ["Box3: no material; grey 0.8"])
    assert many.notes == ("Box0, Box1, Box2, Box3 and 6 more: no material; grey 0.8",)
    mixed = grouped([note("Floor", "k"), note("material 'M'", "k")])
    assert mixed.notes == ("Floor and material 'M': k",)
    assert grouped([]).lines() == [] and isinstance(Note("x"), str)
