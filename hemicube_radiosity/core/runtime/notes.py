"""What a bake says besides its result: notes and warnings, and the few lines they make.

Every stage and reader says what it approximated as one short line (a ``str``), most of them
``"<subject>: <what>"``, the subject an object, a material, a light or the world. A
:class:`Note` is such a line that also knows its subject, its kind (the line without its
subject, which repeats across objects) and whether it is a **warning**: something that changes the
result in a way the user should act on (nothing lights the scene, an object or a light left out,
a shader that is not modelled). A plain ``str`` is a note whose subject is what comes before its
first ``": "`` when that looks like a name.

:func:`grouped` turns the lines of a bake into what a person reads: warnings first, then notes,
one line per kind with the subjects it concerns ("'Chrome', 'Metal' and 'Glass': specular ...").
The CLI, the panel and the report all show these lines; the report keeps every line as well.

Every warning names its **topic**: the section of ``docs/troubleshooting.md`` (:data:`TOPICS`)
whose table gives its cause and what to change; :func:`help_line` says where that is, once per
topic after the warnings (``tests/core/runtime/test_notes.py`` checks each warning's text is in
its section).
"""
from __future__ import annotations

import re
from dataclasses import dataclass

__all__ = ["Note", "warning", "note", "Grouped", "grouped", "subject_and_kind", "TOPICS", "HELP_DOC",
           "help_line", "help_url"]

#: The troubleshooting page (in the repository, not in the extension's zip) and its sections a
#: warning's ``topic`` names: topic -> the section's heading.
HELP_DOC = "docs/troubleshooting.md"
HELP_SITE = "https://github.com/hemicube-radiosity/hemicube_radiosity/blob/main/"
TOPICS = {
    "materials": "Materials (the bake goes on)",
    "scene": "Scene and lights",
}

# a subject before ': ': an object's name, "light 'X'", "material 'X'", "world" (no sentence)
_SUBJECT = re.compile(r"^((?:light |material |object )?'[^']+'|[\w.\-]+(?: [\w.\-]+){0,2}|world): (.+)$")


class Note(str):
    """A line of text (``str(note)`` is the line, so every check on text works) with its
    ``subject`` (``None``: the whole bake), its ``kind`` (the line without the subject: lines of
    one kind are said once with all their subjects) and ``warning`` (it changes the result)."""

    subject: str | None
    kind: str
    warning: bool
    topic: str | None

    def __new__(cls, text, subject=None, kind=None, warning=False, topic=None):
        if topic is not None and topic not in TOPICS:
            raise ValueError(f"unknown topic {topic!r}: one of {sorted(TOPICS)}")
        self = super().__new__(cls, text)
        self.subject, self.kind, self.warning = subject, kind if kind is not None else text, warning
        self.topic = topic
        return self


def note(subject, kind, warning=False, detail="", topic=None) -> Note:
    """The line ``"<subject>: <kind> (<detail>)"`` (without the subject when it is None, without
    the brackets when there is no detail). The detail is in the line, not in the kind: lines that
    differ only there are said as one grouped line. ``topic``: a key of :data:`TOPICS`."""
    text = kind if not detail else f"{kind} ({detail})"
    return Note(text if subject is None else f"{subject}: {text}", subject, kind, warning, topic)


def warning(text, subject=None, detail="", *, topic) -> Note:
    """A warning: ``text`` changes the result in a way the user should act on; ``topic`` (a key
    of :data:`TOPICS`) is where the troubleshooting page says what to change."""
    return note(subject, text, warning=True, detail=detail, topic=topic)


def help_url(topic) -> str:
    """The troubleshooting section of ``topic`` on the project's site (GitHub's heading anchor:
    lower case, spaces as hyphens, punctuation dropped)."""
    title = TOPICS[topic]
    anchor = re.sub(r"[^\w\- ]", "", title.lower()).replace(" ", "-")
    return f"{HELP_SITE}{HELP_DOC}#{anchor}"


def help_line(topic) -> str:
    """What to read about the warnings of ``topic``: the page, its section and the address."""
    return f"what to change: {HELP_DOC}, '{TOPICS[topic]}' ({help_url(topic)})"


def subject_and_kind(line) -> tuple:
    """(subject or None, kind, warning) of a note line: a :class:`Note`'s own, else parsed from
    ``"<subject>: <kind>"`` where the subject is a name (up to three words, or quoted)."""
    if isinstance(line, Note):
        return line.subject, line.kind, line.warning
    m = _SUBJECT.match(line)
    if m is None or m.group(1) in ("note", "warning"):
        return None, line, False
    return m.group(1), m.group(2), False


@dataclass(frozen=True)
class Grouped:
    """The lines a person reads: ``warnings`` and ``notes``, one line per kind each;
    ``topics`` the warnings' troubleshooting topics, each once, in the order first said."""

    warnings: tuple
    notes: tuple
    topics: tuple = ()

    def lines(self):
        """[(level, text)], warnings first, then where to read about them (level 'help', one
        line per topic), then the notes: level is 'warning', 'help' or 'note'."""
        return ([("warning", w) for w in self.warnings] + [("help", help_line(t)) for t in self.topics]
                + [("note", n) for n in self.notes])


_KINDS = ("material", "image", "light", "object")


def _names(subjects, limit=4):
    """'A', 'B' and 'C' (the first ``limit``, then how many more); subjects of one kind of thing
    say it once: "materials 'A' and 'B'"."""
    word = next((w for w in _KINDS if all(s.startswith(w + " '") for s in subjects)), None)
    if word is not None and len(subjects) > 1:
        subjects = [s[len(word) + 1:] for s in subjects]
    shown = list(subjects[:limit])
    if len(subjects) > limit:
        out = ", ".join(shown) + f" and {len(subjects) - limit} more"
    else:
        out = shown[0] if len(shown) == 1 else ", ".join(shown[:-1]) + " and " + shown[-1]
    return out if word is None or len(subjects) == 1 else f"{word}s {out}"


def grouped(lines, limit=4) -> Grouped:
    """Warnings and notes of ``lines``, one line per kind in the order first said, each naming
    its subjects (the first ``limit`` of them, then how many more); a line said twice is said
    once. A kind said of one subject keeps its line as it was written."""
    order, by_kind, first, topics = [], {}, {}, []
    for line in lines:
        subject, kind, warn = subject_and_kind(line)
        topic = getattr(line, "topic", None)
        if warn and topic is not None and topic not in topics:
            topics.append(topic)
        key = (warn, kind)
        if key not in by_kind:
            by_kind[key], first[key] = [], str(line)
            order.append(key)
        if subject not in by_kind[key]:
            by_kind[key].append(subject)
    out = {True: [], False: []}
    for key in order:
        subjects = by_kind[key]
        named = [s for s in subjects if s is not None]
        if len(subjects) == 1:
            out[key[0]].append(first[key])          # as written, its detail too
        else:
            out[key[0]].append(f"{_names(named, limit)}: {key[1]}" if named else key[1])
    return Grouped(tuple(out[True]), tuple(out[False]), tuple(topics))
