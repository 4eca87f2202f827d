"""The layout the code promises, checked over its source (``ast``; nothing is imported but the
stage list): core modules and every function stay small, the luminance weights are written
once, no module imports another's private name, the modules import each other without a
cycle, the core never imports bpy, the map in ``core/__init__.py`` names every stage of
``pipeline.STAGES`` with an entry function that exists, and every path that
``docs/CONTRIBUTING.md`` and the README's layout table name exists.

    .venv/bin/python -m pytest -q tests/test_layout.py
"""
from __future__ import annotations

import ast
import importlib
import os
import re

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PKG = "hemicube_radiosity"
MAX_CORE_LINES = 500


def _modules():
    """{dotted module name: path} of every module of the package."""
    out = {}
    for folder, _, files in os.walk(os.path.join(ROOT, PKG)):
        for f in files:
            if f.endswith(".py"):
                path = os.path.join(folder, f)
                name = os.path.relpath(path, ROOT)[:-3].replace(os.sep, ".")
                out[name.removesuffix(".__init__")] = path
    return out


MODULES = _modules()


def _imports(name, path):
    """[(imported module, [names], line)] of every import in the module, at any depth."""
    tree = ast.parse(open(path, encoding="utf-8").read())
    package = name if path.endswith("__init__.py") else name.rsplit(".", 1)[0]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[:len(parts) - node.level + 1] + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            found.append((base, [a.name for a in node.names], node.lineno))
        elif isinstance(node, ast.Import):
            found += [(a.name, [], node.lineno) for a in node.names]
    return found


def _edges():
    """{module: {module it imports}} within the package (``from . import x`` counts as x)."""
    graph = {}
    for name, path in MODULES.items():
        deps = set()
        for base, names, _ in _imports(name, path):
            for n in names:
                if f"{base}.{n}" in MODULES:
                    deps.add(f"{base}.{n}")
            if base in MODULES and not all(f"{base}.{n}" in MODULES for n in names or ["?"]):
                deps.add(base)
        graph[name] = deps - {name}
    return graph


def test_core_modules_stay_small():
    big = {n: sum(1 for _ in open(p, encoding="utf-8")) for n, p in MODULES.items() if n.startswith(f"{PKG}.core")}
    over = {n: lines for n, lines in big.items() if lines > MAX_CORE_LINES}
    assert not over, f"core modules over {MAX_CORE_LINES} lines: {over}"


MAX_FUNCTION_LINES = 60


def test_functions_stay_short():
    """Every function of the package, its docstring included, fits on a screen: a longer one
    is split into named parts."""
    lengths = {}
    for name, path in MODULES.items():
        for node in ast.walk(ast.parse(open(path, encoding="utf-8").read())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lengths[f"{name}.{node.name}:{node.lineno}"] = node.end_lineno - node.lineno + 1
    assert len(lengths) > 1000, "the check sees almost no functions: it would pass on anything"
    long = {f: n for f, n in lengths.items() if n > MAX_FUNCTION_LINES}
    assert not long, f"functions over {MAX_FUNCTION_LINES} lines: {long}"


def test_no_private_name_is_imported_across_modules():
    bad = []
    for name, path in MODULES.items():
        for base, names, line in _imports(name, path):
            if base.startswith(PKG) or base == "":
                bad += [f"{name}:{line} imports {base}.{n}" for n in names
                        if n.startswith("_") and not n.startswith("__")]
    assert not bad, "\n".join(bad)


def test_modules_import_each_other_without_a_cycle():
    """Tarjan's strongly connected components over every import (module level or inside a
    function): a component of more than one module is a cycle. A package's ``__init__`` is left
    out where it only re-exports (it imports its own submodules by nature)."""
    graph = _edges()
    index, low, stack, on, cycles = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    assert not cycles, f"import cycles: {cycles}"


def test_the_core_never_imports_bpy():
    bad = [f"{n}:{line}" for n, p in MODULES.items() if n.startswith(f"{PKG}.core")
           for base, names, line in _imports(n, p) if base.split(".")[0] in ("bpy", "mathutils", "addon_utils")]
    assert not bad, bad


def test_the_core_map_names_every_stage_and_its_entry():
    """``core/__init__.py`` is the map a newcomer reads: a row per stage of ``STAGES``, in
    that order, each naming a package that exists and an entry function that exists."""
    from hemicube_radiosity.core import pipeline

    doc = importlib.import_module(f"{PKG}.core").__doc__
    rows = re.findall(r"^(\w+)\s+``(\w+)/``\s+``([\w.]+)``", doc, re.M)
    assert [r[0] for r in rows] == [name for name, _ in pipeline.STAGES]
    for stage, package, entry in rows:
        assert os.path.isdir(os.path.join(ROOT, PKG, "core", package)), package
        module, func = entry.rsplit(".", 1)
        assert callable(getattr(importlib.import_module(f"{PKG}.core.{module}"), func)), entry
    stage_functions = {name: fn for name, fn in pipeline.STAGES}
    for stage, package, entry in rows:
        module, func = entry.rsplit(".", 1)
        fn = stage_functions[stage]
        assert fn.__name__ == func and fn.__module__.endswith(f"core.{module}"), (stage, entry)


LUMA_HOME = f"{PKG}.core.util.colour"
LUMA_WEIGHTS = (0.2126, 0.7152, 0.0722)
_LUMA_TEXT = re.compile(r"(?<![\w.])0?\.(2126|7152|0722)(?!\d)")


def _luma_copies(path):
    """Lines of ``path`` that write a Rec. 709 weight out (a float constant of that value in the
    code, or the number in any text: a comment, a docstring) or bind the name ``LUMA`` by
    assignment rather than by import."""
    source = open(path, encoding="utf-8").read()
    lines = {i for i, line in enumerate(source.splitlines(), 1) if _LUMA_TEXT.search(line)}
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Constant) and isinstance(node.value, float) and node.value in LUMA_WEIGHTS:
            lines.add(node.lineno)
        targets = node.targets if isinstance(node, ast.Assign) else \
            [node.target] if isinstance(node, (ast.AnnAssign, ast.AugAssign)) else []
        if any(isinstance(t, ast.Name) and t.id == "LUMA" for t in targets):
            lines.add(node.lineno)
    return sorted(lines)


def test_the_luminance_weights_are_written_once():
    """The Rec. 709 weights live in ``core/util/colour.py``; every other module of the package
    (``blender/`` too) imports ``LUMA`` from there, so the weights cannot drift apart."""
    home = _luma_copies(MODULES[LUMA_HOME])
    assert home, "the check finds no weights even where they are defined: it would pass on anything"
    copies = [f"{n}:{line}" for n, p in MODULES.items() if n != LUMA_HOME for line in _luma_copies(p)]
    assert not copies, f"Rec. 709 weights written out again (import LUMA from {LUMA_HOME}): {copies}"


TOPS = ("hemicube_radiosity", "core", "blender", "tests", "bench", "tools", "docs", "bin")


def _paths_named(md):
    """Every backticked path in ``md`` that starts in one of the repository's own folders
    (``core/`` and ``blender/`` are read inside ``hemicube_radiosity/``)."""
    text = open(os.path.join(ROOT, md), encoding="utf-8").read()
    found = set()
    for p in re.findall(r"`([\w./-]+/[\w./-]*)`", text):
        p = p.split("::")[0].rstrip(".")
        if p.split("/")[0] not in TOPS or "*" in p:
            continue
        if p.startswith(("core/", "blender/")):
            p = f"{PKG}/{p}"
        found.add(p)
    return sorted(found)


@pytest.mark.parametrize("md", ["docs/CONTRIBUTING.md", "README.md", "docs/design.md"])
def test_every_path_the_docs_name_exists(md):
    paths = _paths_named(md)
    assert paths, f"{md} names no path: the check would pass on anything"
    missing = [p for p in paths if not os.path.exists(os.path.join(ROOT, p))]
    assert not missing, f"{md} names paths that do not exist: {missing}"
