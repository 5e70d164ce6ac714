"""The measurement model and table of a run, rebuilt from its artefacts (for drawing).

Tried in order: the system module's own ``from_ingest(recording_doc, measurements)`` if it has
one; a builder here for systems whose ingest artefacts carry everything (arc-welder: robot
model and fixture in the metadata, joints/axis/coordinate in measurements.parquet); the
pipeline's own reader (``pipeline.stages.ingest.load_system``, which re-reads the source
recording named in recording.json); finally ``params["recording"]`` with the system's ``load``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

import numpy as np

from pipeline.identify.model import MeasurementModel
from pipeline.report.artefacts import RunArtefacts

Table = dict[str, np.ndarray]


def _arc_welder(recording: dict, meas: dict[str, np.ndarray]) -> tuple[MeasurementModel, Table]:
    from pipeline.models.serial_arm import SerialArm
    from pipeline.recording.schemas import META_ROBOT
    from pipeline.systems.arc_welder import TouchModel

    arm = SerialArm.from_dict(recording["metadata"][META_ROBOT])
    if "joint_positions" in meas and np.ndim(meas["joint_positions"]) == 2:
        q = np.asarray(meas["joint_positions"], float)
    else:
        q = np.column_stack([np.asarray(meas[f"q_{j.name}"], float) for j in arm.joints])
    axis = np.asarray(meas["axis"])
    if axis.dtype.kind in "OUS":
        axis = np.array(["xyz".index(str(a)) for a in axis])
    table = {"joint_positions": q, "axis": axis.astype(int), "coordinate": np.asarray(meas["coordinate"], float),
             "record": np.asarray(meas["record"]), "timestamp_ns": np.asarray(meas["timestamp_ns"], np.int64)}
    if "face" in meas:
        table["face"] = np.asarray(meas["face"]).astype(str)
    return TouchModel(arm), table


BUILDERS: dict[str, Callable[[dict, dict], tuple[MeasurementModel, Table]]] = {"arc-welder": _arc_welder}


def _recording_path(art: RunArtefacts, params: dict[str, Any]) -> Path | None:
    cands = [params.get("recording"), art.source.get("path")]
    for c in cands:
        if isinstance(c, str) and c.endswith(".mcap") and Path(c).is_file():
            return Path(c)
    return None


def model_and_table(art: RunArtefacts, params: dict[str, Any] | None = None
                    ) -> tuple[MeasurementModel, Table] | None:
    """Model and measurement table of the run, or None when neither the artefacts nor the source
    recording can give them (the scene is then drawn without the model)."""
    params = params or {}
    system = art.system
    try:
        from pipeline.systems.registry import SYSTEMS
        mod = SYSTEMS.get(system)
    except Exception:  # a half-written system module must not stop the report
        mod = None
    if art.measurements is not None and art.recording.get("metadata"):
        builder = getattr(mod, "from_ingest", None) or BUILDERS.get(system)
        if builder is not None:
            try:
                return builder(art.recording, art.measurements)
            except (KeyError, ValueError, TypeError, IndexError):
                pass
    if art.measurements is not None:
        try:
            from pipeline.ingest.tables import model_columns
            from pipeline.stages.ingest import load_system

            _, model, _ = load_system(art.run_dir)
            return model, dict(model_columns(art.measurements))
        except Exception:  # source recording moved, or an older pipeline: fall through
            pass
    path = _recording_path(art, params)
    if path is not None and mod is not None:
        from pipeline.recording.reader import read_recording

        model, table = mod.load(read_recording(path))
        return model, dict(table)
    return None


def align(table: Table, records: np.ndarray) -> Table:
    """Rows of `table` in the order of `records` (the residual table's record column); rows whose
    record is unknown are dropped."""
    rec = np.asarray(table.get("record", np.arange(len(next(iter(table.values()))))))
    pos = {int(r): i for i, r in enumerate(rec)}
    idx = np.array([pos[int(r)] for r in records if int(r) in pos], int)
    return {k: np.asarray(v)[idx] for k, v in table.items()}
