"""`robocal import csv --measure effort`: joint position / velocity / effort logs → a dynamics recording.

The recording holds the URDF, the chain, the logs as its encoder stream (positions, logged velocities,
raw efforts: `robocal.JointStateBatch` fields 4, 10, 8) and the campaign's ``effort`` declaration (how
efforts become torques, which joints are fitted: `pipeline.dynamics.effort`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.cli import err
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
                  time_col: str, robot_id: str, force: bool = False) -> None:
    from pipeline.importers.csv_effort import read_logs
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
    logs = read_logs(files[0], desc, velocity_csv, effort_csv, time_col, (a, b))
    t_ns = T0_NS + np.round(logs.pop("t_s") * 1e9).astype(np.int64)
    claim_output(out, force=force)  # with --force the old recording kept as NAME.bak
    write_effort_recording(out, desc, {"t_ns": t_ns, **logs}, str(urdf), scale, offset, mix, fit_joints, units,
                           {"source_files": [str(f) for f in (files[0], velocity_csv, effort_csv) if f],
                            "rows": [a, a + len(t_ns)]}, robot_id)


def write_effort_recording(out: Path, desc, logs: dict, urdf_path: str, scale: list[str], offset: list[str],
                           mix: list[str], fit_joints: str, units, extra: dict, robot_id: str) -> None:
    """The recording of logs {t_ns, q, v (optional), effort} (chain order) with the effort declaration the
    command line's words give (`pipeline.dynamics.effort`)."""
    from pipeline.dynamics import effort as E
    from pipeline.importers.recording import write_urdf_recording

    joints = desc.joint_names
    sc = E.parse_pairs("--effort-scale", scale, joints)
    off = E.parse_pairs("--effort-offset", offset, joints, words=("weight",))
    if any(v == "weight" for v in off.values()):
        from pipeline.dynamics.rigid_body import build, subtree_weight

        rb = build(desc.urdf, joints, urdf_path)
        off = {j: subtree_weight(rb, j) if v == "weight" else v for j, v in off.items()}
    fit = [j.strip() for j in fit_joints.split(",") if j.strip()]
    doc = E.declaration(joints, sc, off, E.parse_mix(mix, joints), fit, units)
    campaign = {"effort": doc, **extra, "robot_id": robot_id or desc.name}
    if doc["unit"] == "unknown":
        err.print("[yellow]warning:[/] no --effort-scale or --effort-units: the effort units are recorded as unknown "
                  "(robocal run will refuse to fit torques)", highlight=False, soft_wrap=True)
    table = {"joint_positions": np.zeros((0, len(joints))), "timestamp_ns": np.zeros(0, np.int64)}
    write_urdf_recording(out, desc, "effort", campaign, table,
                         stream={"t_ns": logs["t_ns"], "q": logs["q"], "v": logs.get("v"), "effort": logs["effort"]})
    err.print(f"imported {len(logs['t_ns'])} samples of {len(joints)} joints' position"
              f"{', velocity' if logs.get('v') is not None else ''} and effort ({desc.root} → {desc.tip}; torque "
              f"fitted on {', '.join(doc['fit_joints'])}) into {out}", highlight=False, soft_wrap=True)
