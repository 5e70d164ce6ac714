"""The validate stage's checks of a dynamics recording (efforts): declared units, enough motion on the
fitted joints, a steady sample clock.  Each a `pipeline.validate.checks.Check`; a fail stops the run."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.validate import checks as C


def dynamics_checks(run_dir: Path, table: dict | None, channel: str, done: list) -> list:
    from pipeline.dynamics.stage import model_of_metadata
    from pipeline.errors import RobocalError
    from pipeline.stages.ingest import recording_info

    info = recording_info(run_dir)
    path = info["source"]["path"]
    try:
        model = model_of_metadata(info["metadata"], path)
    except RobocalError as e:
        return [C.Check("effort_declaration", C.FAIL, str(e), channel, [])]
    out = []
    if model.effort["unit"] == "unknown":
        out.append(C.Check("effort_units", C.FAIL, f"{channel}: effort units unknown: the recording declares no "
                           "effort → torque conversion (import with --effort-scale JOINT=K,… or --effort-units Nm)",
                           channel, []))
    else:
        out.append(C.Check("effort_units", C.PASS, f"efforts in {model.effort['unit']}, fitted on "
                           f"{', '.join(model.effort['fit_joints'])}", channel, []))
    if table is None or any(c.status == C.FAIL for c in done):
        return out
    t = np.asarray(table["timestamp_ns"], np.int64) * 1e-9
    dt = np.diff(t)
    med = float(np.median(dt))
    gaps = np.flatnonzero(dt > 5 * med)
    out.append(C.make("sample_clock", channel, gaps + 1, C.WARN, f"{t.size} samples at {1 / med:.1f} Hz",
                      f"gaps longer than 5 sample steps ({5 * med * 1e3:.0f} ms): filters bridge them"))
    q = np.asarray(table["joint_positions"], float)
    still = [j for k, j in enumerate(model.joints) if model.fit_mask[k] and np.ptp(q[:, k]) < 1e-3]
    out.append(C.Check("excitation", C.FAIL if still else C.PASS,
                       f"{channel}: fitted joint(s) {', '.join(still)} do not move (range < 1 mrad): their "
                       "dynamics cannot be identified" if still else "every fitted joint moves", channel, []))
    return out
