"""The documentation holds together: every relative link of README.md and docs/**/*.md reaches a file that exists
(and, for a `#anchor` into a Markdown page, a heading of that page, slugged as GitHub does), and every
`docs/….md` path named in the code, tests and benchmarks exists — so moving a page without fixing what points at
it fails here, naming the file and the link."""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
LINK = re.compile(r"\]\(([^)#\s]*)(#[^)\s]+)?\)")


def pages() -> list[Path]:
    return [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def anchors(page: Path) -> set[str]:
    text = re.sub(r"^```.*?^```", "", page.read_text(), flags=re.S | re.M)  # headings, not code comments
    return {slug(h) for h in re.findall(r"^#+ (.*)$", text, flags=re.M)}


def test_slug_matches_github():
    assert slug("Figures on the bundled recordings (`make reprocess`)") == "figures-on-the-bundled-recordings-make-reprocess"
    assert slug("The latest round: the one-off start, cut") == "the-latest-round-the-one-off-start-cut"


def test_every_relative_link_resolves():
    broken = []
    for page in pages():
        prose = re.sub(r"^```.*?^```", "", page.read_text(), flags=re.S | re.M)  # code in a block is not a link
        for m in LINK.finditer(prose):
            target, anchor = m.group(1), m.group(2)
            if target.startswith(("http:", "https:", "mailto:")):
                continue
            path = (page.parent / target).resolve() if target else page
            if not path.exists():
                broken.append(f"{page.relative_to(REPO)}: {m.group(0)} (no such file)")
            elif anchor and path.suffix == ".md" and anchor[1:] not in anchors(path):
                broken.append(f"{page.relative_to(REPO)}: {m.group(0)} (no such heading)")
    assert not broken, "\n".join(broken)


def test_docs_paths_named_in_code_exist():
    missing = []
    for folder in ("pipeline", "tests", "benchmarks"):
        for f in sorted((REPO / folder).rglob("*.py")):
            for path in re.findall(r"\bdocs/[\w/.-]+?\.md\b", f.read_text()):
                if not (REPO / path).exists():
                    missing.append(f"{f.relative_to(REPO)}: {path}")
    assert not missing, "\n".join(missing)
