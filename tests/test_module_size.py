"""House rule: one module per concept, none over 400 lines, in folders a newcomer can read
(`pipeline/diagnose/` keeps at most eight entries at its top level: its door, `method.py` (the method's steps),
`stage.py` and its sub-packages)."""

from __future__ import annotations

from pathlib import Path

PIPELINE = Path(__file__).resolve().parents[1] / "pipeline"
MAX_LINES = 400
MAX_DIAGNOSE_TOP = 8


def test_no_pipeline_module_is_over_400_lines():
    sizes = {str(p.relative_to(PIPELINE)): len(p.read_text(encoding="utf-8").splitlines())
             for p in sorted(PIPELINE.rglob("*.py"))}
    assert len(sizes) > 100  # the package is where it is, sub-packages included
    assert any("/" in name for name in sizes)
    assert {name: n for name, n in sizes.items() if n > MAX_LINES} == {}


def test_diagnose_top_level_is_small():
    entries = sorted(p.name for p in (PIPELINE / "diagnose").iterdir() if p.name != "__pycache__")
    assert "__init__.py" in entries and "method.py" in entries and "stage.py" in entries
    assert len(entries) <= MAX_DIAGNOSE_TOP, entries
    for sub in ("library", "inference", "verdict", "adapters"):
        assert (PIPELINE / "diagnose" / sub / "__init__.py").is_file(), sub
