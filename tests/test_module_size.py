"""House rule: one module per concept, none over ~400 lines."""

from __future__ import annotations

from pathlib import Path

DIAGNOSE = Path(__file__).resolve().parents[1] / "pipeline" / "diagnose"


def test_no_diagnose_module_is_over_400_lines():
    sizes = {p.name: len(p.read_text(encoding="utf-8").splitlines()) for p in sorted(DIAGNOSE.glob("*.py"))}
    assert len(sizes) > 20  # the package is where it is
    assert {name: n for name, n in sizes.items() if n > 400} == {}
