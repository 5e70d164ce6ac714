"""Reading a run directory: the artefacts of the stages before the report (docs/reference/artefacts.md).

`load_run` is the only function here that touches files; it returns a `RunArtefacts` of plain
numpy arrays and dicts that the pure figure functions take.  Optional artefacts (observe,
validate, diagnose, the encoder stream) are None when their stage has not run.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pipeline.errors import RobocalError

STAGES = ("ingest", "validate", "identify", "observe", "accuracy", "diagnose")


@dataclass
class RunArtefacts:
    """Everything the report and the rerun recording are drawn from (SI units)."""

    run_dir: Path
    fit: dict  # identify/fit.json
    residuals: dict[str, np.ndarray]  # identify/residuals.parquet as columns
    history: list[float]  # identify/history.json
    model: dict | None = None  # identify/model.json (calibrated model)
    recording: dict = field(default_factory=dict)  # ingest/recording.json
    measurements: dict[str, np.ndarray] | None = None  # ingest/measurements.parquet
    encoder: dict[str, np.ndarray] | None = None  # ingest/encoder.parquet
    validate: dict | None = None  # validate/validate.json
    observe: dict | None = None  # observe/observe.json
    diagnosis: dict | None = None  # diagnose/diagnosis.json (or DIR/diagnosis.json)
    accuracy: dict | None = None  # accuracy/accuracy.json (the accuracy map and the verdict)
    stages: dict[str, dict] = field(default_factory=dict)  # <stage>/stage.json

    @property
    def system(self) -> str:
        return str(self.recording.get("system", "unknown"))

    @property
    def residual_dim(self) -> int:
        return len(residual_components(self.residuals, "after"))

    @property
    def used(self) -> np.ndarray:
        """Mask of the measurements the fit used (False: rejected as outliers)."""
        n = len(self.residuals["record"])
        u = self.residuals.get("used")
        return np.ones(n, bool) if u is None else np.asarray(u, bool)

    @property
    def source(self) -> dict:
        """{"path", "sha256"} of the input recording, from recording.json or the ingest stage."""
        src = dict(self.recording.get("source") or {})
        src.setdefault("sha256", self.recording.get("sha256"))
        src.setdefault("path", self.recording.get("path") or self.stages.get("ingest", {}).get("params", {}).get("recording"))
        return src

    @property
    def metadata(self) -> dict:
        m = (self.recording or {}).get("metadata")
        return m if isinstance(m, dict) else {}

    def prismatic_joints(self) -> frozenset[str]:
        """Names of the robot's prismatic joints (readings in m), from the recording's URDF."""
        import xml.etree.ElementTree as ET

        text = (self.metadata.get("robocal.urdf") or {}).get("urdf")
        if not isinstance(text, str):
            return frozenset()
        try:
            root = ET.fromstring(text.encode())
        except ET.ParseError:
            return frozenset()
        return frozenset(j.get("name") for j in root.findall("joint") if j.get("type") == "prismatic")

    def robot_name(self) -> str:
        """A URDF robot's own name (its URDF's robot name), else the system's name."""
        import re

        text = (self.metadata.get("robocal.urdf") or {}).get("urdf")
        found = re.search(r"<robot[^>]*\bname=[\"']([^\"']+)", text) if isinstance(text, str) else None
        return found.group(1) if found else self.system

    def joint_columns(self) -> dict[str, np.ndarray]:
        """Joint angles (rad) of each measurement by joint name, from `q_<joint>` columns or a
        `joint_positions` (n, n_joints) column; empty if the measurements carry no joints."""
        meas = self.measurements or {}
        out = {c[2:]: np.asarray(v, float) for c, v in meas.items() if c.startswith("q_")}
        jp = meas.get("joint_positions")
        if not out and jp is not None and np.ndim(jp) == 2:
            names = list((self.recording.get("encoder") or {}).get("joints") or [])
            if len(names) != jp.shape[1]:  # no encoder stream: the campaign's (the URDF's) joint names
                names = list(self.metadata.get("robocal.campaign", {}).get("joint_names") or [])
            if len(names) != jp.shape[1]:
                names = [f"J{i + 1}" for i in range(jp.shape[1])]
            out = {n: np.asarray(jp[:, i], float) for i, n in enumerate(names)}
        return out


def residual_components(res: dict[str, np.ndarray], kind: str) -> list[str]:
    """Column names `<kind>_<k>` in k order (kind: before, after, holdout)."""
    cols = [c for c in res if c.startswith(kind + "_") and c[len(kind) + 1:].isdigit()]
    return sorted(cols, key=lambda c: int(c[len(kind) + 1:]))


def residual_matrix(res: dict[str, np.ndarray], kind: str) -> np.ndarray:
    """(n, k) residuals of one kind, m."""
    cols = residual_components(res, kind)
    if not cols:
        return np.zeros((len(res.get("record", [])), 0))
    return np.column_stack([np.asarray(res[c], float) for c in cols])


def _json(path: Path) -> dict | list | None:
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text())
    except ValueError as e:
        raise RobocalError(f"{path}: not valid JSON ({e})") from None


def _parquet(path: Path) -> dict[str, np.ndarray] | None:
    if not path.is_file():
        return None
    import pyarrow.parquet as pq

    t = pq.read_table(path)
    try:  # the pipeline's reader restores k-vector columns (e.g. joint_positions (n, 6))
        from pipeline.stages.artefacts import from_arrow
    except ImportError:
        return {name: t.column(name).to_numpy(zero_copy_only=False) for name in t.column_names}
    return from_arrow(t)


def load_run(run_dir: str | Path) -> RunArtefacts:
    """Read the artefacts of `run_dir`; identify's fit and residuals are required."""
    d = Path(run_dir)
    fit = _json(d / "identify" / "fit.json")
    res = _parquet(d / "identify" / "residuals.parquet")
    if fit is None or res is None:
        raise RobocalError(f"{d}: no identify/fit.json and identify/residuals.parquet (run `robocal identify` first)")
    diagnosis = _json(d / "diagnose" / "diagnosis.json")
    if diagnosis is None:
        diagnosis = _json(d / "diagnosis.json")
    stages = {s: doc for s in STAGES if (doc := _json(d / s / "stage.json")) is not None}
    history = _json(d / "identify" / "history.json") or []
    if isinstance(history, dict):  # {"cost_rms_m": [...]}
        history = next((v for v in history.values() if isinstance(v, list)), [])
    return RunArtefacts(
        run_dir=d, fit=fit, residuals=res, history=[float(h) for h in history],
        model=_json(d / "identify" / "model.json"), recording=_json(d / "ingest" / "recording.json") or {},
        measurements=_parquet(d / "ingest" / "measurements.parquet"),
        encoder=_parquet(d / "ingest" / "encoder.parquet"), validate=_json(d / "validate" / "validate.json"),
        observe=_json(d / "observe" / "observe.json"), diagnosis=diagnosis, stages=stages,
        accuracy=_json(d / "accuracy" / "accuracy.json"))
