"""The calibrated model a run folder holds: parameter names and values, and the robot it describes.

Two kinds of folder hold one: a `robocal run` folder (``identify/fit.json``: names, estimates; the
recording's metadata from ingest's ``messages.parquet``, so the recording itself may have moved)
and a `robocal calibrate` output folder (``results.json``: ``parameters``, ``source.path`` — the
recording is read again for its metadata).  Only URDF-robot calibrations are evaluated here.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.errors import RobocalError
from pipeline.recording.schemas import META_CAMPAIGN, META_URDF


@dataclass(frozen=True)
class Calibrated:
    """A calibrated URDF-robot model (SI values) and the metadata of the recording it was fitted to."""

    run_dir: Path
    names: list[str]
    x: np.ndarray
    free: np.ndarray  # (P,) bool: estimated (True) or held at its start value
    urdf: dict  # robocal.urdf metadata: urdf text, root, tip
    campaign: dict  # robocal.campaign metadata of the calibration's (first) recording
    recording: str  # the calibration's recording (as given to run / calibrate)
    q_train: np.ndarray | None = None  # (m, joints) rad / m: the postures it was fitted on, where known


    def values(self) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.names, self.x)}


def _from_run(run_dir: Path) -> Calibrated:
    from pipeline.stages.artefacts import read_json
    from pipeline.stages.ingest import load_system, recording_info

    fit = read_json(run_dir / "identify" / "fit.json")
    info = recording_info(run_dir)
    if info.get("system") != "urdf":
        raise RobocalError(f"{run_dir}: a calibration of system {info.get('system')!r}; evaluate takes URDF robots")
    _, _, rec = load_system(run_dir)
    return Calibrated(run_dir, list(fit["names"]), np.asarray(fit["x"], float), np.asarray(fit["free"], bool),
                      dict(rec.metadata.get(META_URDF) or {}), dict(rec.metadata.get(META_CAMPAIGN) or {}),
                      str(info.get("source", {}).get("path", "")), training_postures(rec))


def training_postures(rec) -> np.ndarray | None:
    """(m, joints) rad / m: the joint positions of `rec`'s measurement rows (not distance rows), or None where
    the recording's rows cannot be read as one URDF chain's table."""
    from pipeline.systems import urdf_robot

    try:
        _, table = urdf_robot.load(rec)
    except (RobocalError, KeyError, ValueError):
        return None
    q = np.asarray(table["joint_positions"], float)
    kind = np.asarray(table.get("kind", np.zeros(len(q), int)), int)
    return q[kind == 0] if q.ndim == 2 else None


def _from_calibrate(run_dir: Path) -> Calibrated:
    from pipeline.recording.reader import read_recording
    from pipeline.stages.artefacts import read_json

    doc = read_json(run_dir / "results.json")
    if doc.get("system") != "urdf":
        raise RobocalError(f"{run_dir}: a calibration of system {doc.get('system')!r}; evaluate takes URDF robots")
    rows = doc["parameters"]
    path = str(doc.get("source", {}).get("path", ""))
    if not Path(path).is_file():
        raise RobocalError(f"{run_dir}/results.json: the calibration's recording {path!r} is not there any more "
                           "(its robot description is needed)")
    rec = read_recording(path)
    return Calibrated(run_dir, [r["name"] for r in rows], np.array([r["estimate"] for r in rows], float),
                      np.array([r["identifiable"] for r in rows], bool), dict(rec.metadata.get(META_URDF) or {}),
                      dict(rec.metadata.get(META_CAMPAIGN) or {}), path, training_postures(rec))


def read_calibrated(run_dir: str | Path) -> Calibrated:
    """The calibrated model of `run_dir` (see module docstring); a folder without one is an error."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise RobocalError(f"{run_dir}: no such run folder")
    if (run_dir / "identify" / "fit.json").is_file():
        return _from_run(run_dir)
    res = run_dir / "results.json"
    if res.is_file() and (run_dir / "model.json").is_file():
        try:
            return _from_calibrate(run_dir)
        except (KeyError, TypeError, ValueError) as e:
            raise RobocalError(f"{res}: no calibrated model in it ({type(e).__name__}: {e})") from None
    raise RobocalError(f"{run_dir}: no calibrated model (no identify/fit.json of `robocal run`, no results.json + "
                       "model.json of `robocal calibrate`: did the identify stage run?)")


def from_urdf(path: str | Path, root: str, tip: str, measure: str) -> Calibrated:
    """A URDF taken as calibrated (its nominal geometry, identity instrument frame and tool): another
    tool's calibrated robot, evaluated by the same code as robocal's (`apply.evaluate`)."""
    from pipeline.models import urdf
    from pipeline.models.urdf_arm import UrdfArm

    desc = urdf.read(path, root, tip)
    arm = UrdfArm(desc)
    return Calibrated(Path(path), arm.parameter_names(), arm.vector(), np.zeros(len(arm.vector()), bool),
                      {"urdf": desc.urdf, "root": root, "tip": tip}, {"system": "urdf", "measure": measure},
                      str(path))
