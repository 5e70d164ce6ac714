"""No import circles: a static check over the `import` statements (module level and inside
functions alike) of every module of a package under `pipeline/`.  A circle is reported as the list
of modules that import one another round.  Parametrised by package so the check can be widened."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ["pipeline.diagnose"]  # packages held free of import circles (each cycle inside them fails)


def modules(package: str) -> dict[str, Path]:
    """Dotted module name → file of every module in `package` (its __init__ as the package name)."""
    base = ROOT.joinpath(*package.split("."))
    out = {}
    for p in sorted(base.rglob("*.py")):
        parts = list(p.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


def imports(name: str, path: Path, known: set[str]) -> set[str]:
    """The modules of `known` that module `name` imports (`from a import b` counts as a.b when a.b is
    a module, else as a; relative imports resolved against `name`'s package)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    pkg = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = pkg.split(".")[: len(pkg.split(".")) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in node.names]
        else:
            continue
        for t in targets:
            while t and t not in known:  # `import a.b.c` of a non-module attribute: its module
                t = t.rpartition(".")[0]
            if t and t != name:
                out.add(t)
    return out


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan), each sorted."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
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
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_check_finds_a_circle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


@pytest.mark.parametrize("package", PACKAGES)
def test_no_import_cycle(package):
    mods = modules(package)
    assert len(mods) > 1, f"{package}: no modules found"
    known = set(mods)
    graph = {name: imports(name, path, known) for name, path in mods.items()}
    assert cycles(graph) == []


def test_library_does_not_pull_the_diagnosis_machinery():
    """The physics terms are importable by identification without the diagnosis: nothing under
    `pipeline.diagnose.library` imports its inference, verdict, adapters or document."""
    mods = modules("pipeline.diagnose")
    known = set(mods)
    for name, path in mods.items():
        if name.startswith("pipeline.diagnose.library"):
            bad = {m for m in imports(name, path, known) if not m.startswith("pipeline.diagnose.library")}
            assert bad == set(), (name, bad)
