"""Code, docs and README explain what a thing is: readers of robocal have no issue tracker, so no text
cites an issue or pull-request number ("issue 18", "#20", "session 9") in place of saying what it means."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CITATION = re.compile(r"\b[Ii]ssues? ?#?\d+|\(#\d+\)|(?<![\w&:])#\d{1,3}\b(?![0-9a-fA-F])|\bsession \d+\b")


def _texts():
    for folder, pattern in (("pipeline", "*.py"), ("docs", "*.md"), ("tests", "*.py"), ("benchmarks", "*.py")):
        yield from sorted((ROOT / folder).rglob(pattern))
    yield ROOT / "README.md"


def test_no_issue_numbers_in_code_docs_or_readme():
    hits = []
    for path in _texts():
        if path.name == Path(__file__).name:
            continue
        for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if CITATION.search(line):
                hits.append(f"{path.relative_to(ROOT)}:{i}: {line.strip()[:100]}")
    assert hits == [], "\n".join(hits[:20])


def test_the_pattern_catches_citations():
    for text in ("see issue 18", "Issue #20 says", "fixed (#31)", "as in #7,", "session 11: cut"):
        assert CITATION.search(text), text
    for text in ("color #ff00aa", "color:#222;", "row 12", "#include", "&#8203;", "sessions 2021"):
        assert not CITATION.search(text), text
