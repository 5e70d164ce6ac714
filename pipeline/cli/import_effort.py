"""`robocal import csv --measure effort`: joint position / velocity / effort logs → a dynamics recording.

The recording (`pipeline.importers.effort_recording`) holds the URDF, the chain, the logs as its encoder
stream and the campaign's ``effort`` declaration."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.errors import RobocalError

T0_NS = 1_700_000_000_000_000_000  # the recording's clock origin (times in the CSV are relative, s)


def parse_rows(text: str) -> tuple[int, int | None]:
    """``A:B`` → (A, B); ``A:`` → (A, None); '' → (0, None)."""
    if not text:
        return 0, None
    a, sep, b = text.partition(":")
    try:
        lo, hi = int(a or 0), (int(b) if b else None)
    except ValueError:
        raise RobocalError(f"--rows {text!r}: expected A:B, zero-based data rows (B excluded)") from None
    if not sep or lo < 0 or (hi is not None and hi <= lo):
        raise RobocalError(f"--rows {text!r}: expected A:B with 0 ≤ A < B")
    return lo, hi


def import_effort(files: list[Path], urdf: Path, root: str, tip: list[str], out: Path, velocity_csv, effort_csv,
                  scale: list[str], offset: list[str], mix: list[str], fit_joints: str, units, rows: str,
                  time_col: str, robot_id: str, force: bool = False, rate: float | None = None,
                  positions: tuple = ((), (), ())) -> None:
    from pipeline.cli.bag_options import say
    from pipeline.importers.csv_effort import read_logs
    from pipeline.importers.effort_recording import EffortSpec, write_effort_recording
    from pipeline.importers.joint_readings import PositionSpec, declaration
    from pipeline.recording.output import claim_output
    from pipeline.models import urdf as urdf_mod

    if len(files) != 1:
        raise RobocalError("--measure effort takes one position (or whole) table; give the others with "
                           "--velocity-csv / --effort-csv")
    if len(tip) != 1 or "=" in tip[0]:
        raise RobocalError("--measure effort takes one --tip LINK (the chain's end)")
    ins = {Path(f).resolve() for f in [files[0], velocity_csv, effort_csv] if f}
    if out.exists() and out.resolve() in ins:
        raise RobocalError(f"{out}: --out is one of the input files")
    desc = urdf_mod.read(urdf, root, tip[0])
    a, b = parse_rows(rows)
    pos_doc = declaration(PositionSpec(*(tuple(x) for x in positions)), desc.joint_names)
    logs = read_logs(files[0], desc, velocity_csv, effort_csv, time_col, (a, b), rate, pos_doc)
    t_ns = T0_NS + np.round(logs.pop("t_s") * 1e9).astype(np.int64)
    claim_output(out, force=force)  # with --force the old recording kept as NAME.bak
    write_effort_recording(out, desc, {"t_ns": t_ns, **logs}, str(urdf),
                           EffortSpec(tuple(scale), tuple(offset), tuple(mix), fit_joints, units),
                           {"source_files": [str(f) for f in (files[0], velocity_csv, effort_csv) if f],
                            "rows": [a, a + len(t_ns)], **({"rate_hz": rate} if rate else {}),
                            **({"positions": pos_doc} if pos_doc else {})}, robot_id, say)
