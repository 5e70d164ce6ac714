"""No import circles among `pipeline.*` modules: a static scan (ast) of every `import` and
`from … import` statement, at module level and inside functions alike (an import hidden in a
function is still a circle: the two modules cannot be understood one without the other)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# Packages left out of the check (none: every module of `pipeline` is held free of import circles).
EXCLUDED: tuple[str, ...] = ()


def modules(root: Path = ROOT) -> dict[str, tuple[Path, bool]]:
    """Dotted name → (file, is a package `__init__`) of every module under root/pipeline."""
    out = {}
    for p in sorted((root / "pipeline").rglob("*.py")):
        parts = list(p.relative_to(root).with_suffix("").parts)
        package = parts[-1] == "__init__"
        out[".".join(parts[:-1] if package else parts)] = (p, package)
    return out


def _owner(name: str, mods: dict) -> str | None:
    """The module `name` refers to: itself, else the longest enclosing module (an attribute of it)."""
    parts = name.split(".")
    while parts:
        if ".".join(parts) in mods:
            return ".".join(parts)
        parts.pop()
    return None


def import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    """Module → the `pipeline` modules it imports anywhere in its source (relative imports resolved)."""
    mods = modules(root)
    graph: dict[str, set[str]] = {}
    for name, (path, package) in mods.items():
        here = name if package else name.rpartition(".")[0]
        deps: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                deps.update(m for a in node.names if (m := _owner(a.name, mods)))
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = here.split(".")[: len(here.split(".")) - (node.level - 1)]
                    base = ".".join(up + ([node.module] if node.module else []))
                for a in node.names:
                    full = f"{base}.{a.name}"
                    m = full if full in mods else _owner(base, mods)
                    if m:
                        deps.add(m)
        deps.discard(name)
        graph[name] = deps
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on.add(start)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in graph:
                    continue
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    found.append(sorted(comp))
    return found


def _excluded(name: str) -> bool:
    return any(name == e or name.startswith(e + ".") for e in EXCLUDED)


def test_no_import_cycles_among_pipeline_modules():
    graph = {m: {d for d in deps if not _excluded(d)} for m, deps in import_graph().items() if not _excluded(m)}
    found = cycles(graph)
    msg = "\n".join(" ↔ ".join(c) + ": " + "; ".join(f"{a} → {b}" for a in c for b in sorted(graph[a]) if b in c)
                    for c in found)
    assert not found, f"import cycles among pipeline modules:\n{msg}"


def test_the_scan_finds_a_cycle(tmp_path):
    """The check can fail: a two-module circle through a function-level relative import is found."""
    pkg = tmp_path / "pipeline" / "demo"
    pkg.mkdir(parents=True)
    (tmp_path / "pipeline" / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from pipeline.demo import b\n")
    (pkg / "b.py").write_text("def f():\n    from .a import x\n")
    (pkg / "c.py").write_text("import pipeline.demo.a\n")
    graph = import_graph(tmp_path)
    assert graph["pipeline.demo.b"] == {"pipeline.demo.a"}
    assert cycles(graph) == [["pipeline.demo.a", "pipeline.demo.b"]]


@pytest.mark.parametrize("excluded", EXCLUDED)
def test_excluded_packages_exist(excluded):
    """An exclusion names a real package (a stale one would silently widen nothing)."""
    assert excluded in modules()


def test_the_diagnosis_library_pulls_none_of_the_diagnosis_machinery():
    """The physics terms are importable by identification without the diagnosis: no module of
    `pipeline.diagnose.library` imports another part of `pipeline.diagnose` (inference, verdict, adapters,
    document, the method)."""
    graph = import_graph()
    lib = "pipeline.diagnose.library"
    bad = {m: sorted(d for d in deps if d.startswith("pipeline.diagnose") and not (d == lib or d.startswith(lib + ".")))
           for m, deps in graph.items() if m == lib or m.startswith(lib + ".")}
    assert len(bad) > 5
    assert {m: d for m, d in bad.items() if d} == {}
