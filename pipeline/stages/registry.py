"""The stages of `robocal run`, as data: adding a stage is one entry here.

A stage module offers ``run(run_dir: Path, params: dict) -> dict``: it reads the artefacts
of the stages it requires under ``run_dir/<stage>/``, writes its own under
``run_dir/<name>/`` and returns its summary (machine-readable figures, JSON-able; a
``"status": "fail"`` with a ``"reason"`` stops the run; an ``"outputs"`` list names extra
files it wrote relative to run_dir).  Modules of optional stages may be absent.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class Stage:
    name: str
    module: str  # dotted path of the module with `run(run_dir, params)`
    requires: tuple[str, ...]  # stages whose artefacts it reads (missing optional ones are skipped)
    defaults: dict[str, Any] = field(default_factory=dict)
    optional: bool = False  # skipped when its module is not importable
    help: str = ""


STAGES: tuple[Stage, ...] = (
    Stage("ingest", "pipeline.stages.ingest", (), {"context_window_s": 0.02},
          help="MCAP → Parquet: encoder stream, channel tables, measurements with motion context."),
    Stage("validate", "pipeline.stages.validate", ("ingest",),
          {"gap_factor": 5.0, "outlier_threshold": 6.0, "outlier_f_scale_m": 1e-4, "outlier_fit_max_nfev": 400},
          help="Named pass/warn/fail checks; a fail stops the run."),
    Stage("identify", "pipeline.stages.identify", ("ingest", "validate"),
          {"loss": "linear", "f_scale_m": 1e-4, "outlier_threshold": 5.0, "folds": 5, "seed": 0},
          help="Nonlinear least squares, robust loss, outlier rejection, held-out cross-validation."),
    Stage("observe", "pipeline.stages.observe", ("ingest", "identify"), {},
          help="Singular values, O1..O5, identifiable set, correlations, predicted accuracy."),
    Stage("accuracy", "pipeline.accuracy.stage", ("ingest", "identify"), {},
          help="Predicted accuracy over the workspace (priors of fixed parameters included), the verdict."),
    Stage("diagnose", "pipeline.diagnose.stage", ("ingest", "validate", "identify", "observe"), {}, optional=True,
          help="Residual diagnosis: the physics the geometric model left out."),
    Stage("report", "pipeline.report.stage", ("ingest", "validate", "identify", "observe", "accuracy", "diagnose"), {},
          optional=True, help="report.html and run.rrd."),
)

BY_NAME: dict[str, Stage] = {s.name: s for s in STAGES}
CORE_STAGES = ["ingest", "validate", "identify", "observe"]  # a calibration without its report (`--core`)
