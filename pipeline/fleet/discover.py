"""Recursive discovery of the recordings of an archive (glob patterns; symlinks are followed only
while their target stays inside the archive)."""

from __future__ import annotations

import fnmatch
import os
from dataclasses import dataclass
from pathlib import Path

from pipeline.errors import RobocalError

DEFAULT_PATTERNS = ("**/*.mcap",)


@dataclass(frozen=True)
class Found:
    """One recording: its path as found (inside the archive) and relative to the archive."""

    path: Path
    rel: str  # POSIX path relative to the archive root

    @property
    def run_name(self) -> str:
        """Run folder name under OUT: the relative path less `.mcap`."""
        return self.rel[:-5] if self.rel.endswith(".mcap") else self.rel


def _inside(path: Path, root: Path) -> bool:
    try:
        path.resolve().relative_to(root)
        return True
    except ValueError:
        return False


def _match(rel: str, patterns: tuple[str, ...]) -> bool:
    """`**/` also matches zero folders (so `**/*.mcap` finds top-level files)."""
    for p in patterns:
        if fnmatch.fnmatchcase(rel, p) or (p.startswith("**/") and fnmatch.fnmatchcase(rel, p[3:])):
            return True
    return False


def discover(archive: Path, patterns: tuple[str, ...] | list[str] = DEFAULT_PATTERNS) -> tuple[list[Found], list[str]]:
    """Every file of `archive` whose relative path matches one of `patterns`, sorted by relative path,
    and the paths skipped because a symlink points out of the archive (or loops).

    Folder symlinks are descended only when their target is inside the archive and not already
    visited (so a loop ends); file symlinks are kept only when their target is inside."""
    root = Path(archive)
    if not root.is_dir():
        raise RobocalError(f"{archive}: not a folder")
    real_root = root.resolve()
    pats = tuple(patterns) or DEFAULT_PATTERNS
    found: list[Found] = []
    skipped: list[str] = []
    seen_dirs = {real_root}
    stack = [root]
    while stack:
        d = stack.pop()
        try:
            entries = sorted(os.scandir(d), key=lambda e: e.name)
        except OSError as e:
            skipped.append(f"{d}: {e.strerror}")
            continue
        for e in entries:
            p = Path(e.path)
            rel = p.relative_to(root).as_posix()
            if e.is_symlink() and not p.exists():
                if _match(rel, pats):
                    skipped.append(f"{rel}: broken symlink")
                continue
            if e.is_symlink() and not _inside(p, real_root):
                skipped.append(f"{rel}: symlink out of the archive")
                continue
            if e.is_dir(follow_symlinks=True):
                real = p.resolve()
                if real in seen_dirs:
                    if e.is_symlink():
                        skipped.append(f"{rel}: symlink to a folder already searched")
                    continue
                seen_dirs.add(real)
                stack.append(p)
            elif e.is_file(follow_symlinks=True) and _match(rel, pats):
                found.append(Found(p, rel))
    found.sort(key=lambda f: f.rel)
    return found, sorted(skipped)
