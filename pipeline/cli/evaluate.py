"""`robocal evaluate RUN_DIR REC.mcap … --out DIR`: a calibrated model on recordings it was not fitted to."""

from __future__ import annotations

from pathlib import Path

from typing import Literal

import typer
from rich.table import Table

from pipeline.cli import CALIBRATE, app, console, err

MARKER = ".robocal-evaluation"


def _claim(out: Path) -> None:
    """Create `out`, or reuse one robocal's evaluate wrote; refuse a non-empty folder of the user's."""
    from pipeline.errors import RobocalError

    if out.exists() and not out.is_dir():
        raise RobocalError(f"{out}: --out is a file, not a folder")
    if out.is_dir() and any(out.iterdir()) and not (out / MARKER).is_file():
        raise RobocalError(f"{out}: a non-empty folder robocal evaluate did not write (choose a new --out)")
    out.mkdir(parents=True, exist_ok=True)
    (out / MARKER).write_text("robocal evaluate output: evaluate may replace evaluation.json, errors.parquet and "
                              "report.html\n")


def _mm(v) -> str:
    return "—" if v is None else f"{v * 1e3:.3f}"


def _px(v) -> str:
    return "—" if v is None else f"{v:.3f}"


def _table(results: list[dict], title: str) -> Table:
    measure = results[0]["measure"] if results else "point"
    t = Table(title=title)
    plane, camera = measure == "plane", measure == "camera"
    heads = (["recording / group", "n", "RMS along normal mm", "mean |d| mm", "max |d| mm"] if plane else
             ["recording / image", "corners", "RMS of the 2-D reprojection error px", "mean 2-D px", "max 2-D px",
              "RMS per axis px"] if camera else
             ["recording / group", "n", "RMS of the 3-D error mm", "mean 3-D mm", "max 3-D mm", "RMS per axis mm"])
    if measure == "coincidence":
        heads.append("socket distance error mm")
    for h in heads:
        t.add_column(h, justify="left" if h.startswith("recording") else "right")

    def row(name: str, d: dict, dist: str | None = None) -> list[str]:
        if plane:
            return [name, str(d.get("n", 0)), _mm(d.get("rms_normal_m")), _mm(d.get("mean_abs_normal_m")),
                    _mm(d.get("max_abs_normal_m"))]
        if camera:
            return [name, str(d.get("n", 0))] + [_px(d.get(k)) for k in ("rms_2d_px", "mean_2d_px", "max_2d_px",
                                                                          "rms_axis_px")]
        cells = [name, str(d.get("n", 0)), _mm(d.get("rms_3d_m")), _mm(d.get("mean_3d_m")), _mm(d.get("max_3d_m")),
                 _mm(d.get("rms_axis_m"))]
        return cells + ([dist or ""] if measure == "coincidence" else [])

    for r in results:
        dist = ", ".join(f"{v * 1e3:+.3f}" for v in r.get("distances", {}).values()) or None
        t.add_row(*row(Path(r["path"]).name, r, dist))
        if len(r.get("groups", {})) > 1:
            for g, d in r["groups"].items():
                t.add_row(*row(f"  {g}", d))
        for g, d in (r.get("postures") or {}).items():
            t.add_row(*row(f"  {g.replace('_', ' ')} postures", d))
    return t


@app.command("evaluate", rich_help_panel=CALIBRATE)
def evaluate_cmd(
    run_dir: Path = typer.Argument(..., help="Run folder of `robocal run` (or output folder of `robocal calibrate`)."),
    recordings: list[Path] = typer.Argument(..., help="Recording(s) (MCAP) of the same robot to evaluate it on."),
    out: Path = typer.Option(..., "--out", help="Folder for evaluation.json, errors.parquet and report.html."),
    refit: Literal["none", "registration"] = typer.Option("none", "--refit", help="none (apply as calibrated) or registration (re-estimate "
                                                      "only the instrument frame)."),
    registration: Literal["shared", "per-recording"] = typer.Option("shared", "--registration",
                                      help="With --refit registration: shared (one frame for all) or per-recording."),
) -> None:
    """Apply a calibrated model to other recordings without refitting it: the error of every measurement."""
    from pipeline.dynamics.stage import is_dynamics_run

    if is_dynamics_run(run_dir):  # torques: held-out RMS per fitted joint and pooled, N·m
        return _evaluate_dynamics(run_dir, recordings, out)
    from pipeline.evaluate.apply import error_table, evaluate
    from pipeline.evaluate.calibrated import read_calibrated
    from pipeline.report.evaluation import POSTURES_NOTE, render
    from pipeline.recording.reader import read_recording
    from pipeline.stages.artefacts import sha256_file, write_json, write_table

    cal = read_calibrated(run_dir)
    recs = [read_recording(p) for p in recordings]
    with err.status(f"evaluating {run_dir} on {len(recs)} recording(s)…"):
        results = evaluate(cal, recs, refit=refit, registration=registration)
    _claim(out)
    docs = [{k: v for k, v in r.items() if k not in ("rows", "record", "posture")} | {"sha256": sha256_file(r["path"])}
            for r in results]
    doc = {
        "run": str(run_dir), "calibrated_on": cal.recording, "refit": refit,
        "registration": registration if refit == "registration" else "as calibrated",
        "note": ("rms_3d_m: RMS over measurements of the norm of the 3-D position error (points, poses, ball "
                 "centres about their socket's mean); rms_axis_m: RMS over the x, y, z components (= rms_3d_m/√3 "
                 "when isotropic); planes: distance along the normal; camera images: rms_2d_px, the RMS over "
                 "corners of the 2-D reprojection error (px) through the robot's pose at each image, the calibrated "
                 "hand-eye, board and intrinsics, nothing refitted per image (rms_axis_px: over u and v, "
                 "= rms_2d_px/√2 when isotropic)"),
        "postures_note": POSTURES_NOTE, "recordings": docs}
    write_json(out / "evaluation.json", doc)
    write_table(out / "errors.parquet", error_table(results))
    (out / "report.html").write_text(render(doc, error_table(results)))
    console().print(_table(results, f"robocal evaluate — {run_dir} (calibrated on {Path(cal.recording).name}), "
                                    f"not refitted{'' if refit == 'none' else ' except the registration'}"))
    print(f"evaluation: {out / 'evaluation.json'}\nerrors:     {out / 'errors.parquet'}\nreport:     {out / 'report.html'}")


def _evaluate_dynamics(run_dir: Path, recordings: list[Path], out: Path) -> None:
    """A dynamics run's predicted torques on other recordings of the robot, no refit (evaluation.json,
    torques.parquet): the held-out torque RMS per fitted joint and pooled (N·m; N for a prismatic joint)."""
    import numpy as np

    from pipeline.dynamics.stage import evaluate
    from pipeline.stages.artefacts import sha256_file, write_json, write_table

    with err.status(f"evaluating {run_dir} on {len(recordings)} recording(s)…"):
        results = evaluate(run_dir, recordings)
    _claim(out)
    keep = ("path", "measure", "n", "rms_joint_Nm", "rms_pooled_Nm", "nominal_rms_joint_Nm", "nominal_rms_pooled_Nm")
    doc = {"run": str(run_dir), "family": "dynamics", "refit": "none",
           "note": "torque RMS over the recording's samples, raw converted efforts at the recorded rate, predicted "
                   "without refitting (N·m; N for a prismatic joint); nominal: the URDF's own parameters",
           "recordings": [{k: r[k] for k in keep} | {"sha256": sha256_file(r["path"])} for r in results]}
    write_json(out / "evaluation.json", doc)
    tab = {"recording": np.concatenate([np.full(r["n"], i) for i, r in enumerate(results)]),
           "t_s": np.concatenate([r["t_s"] for r in results])}
    for k, j in enumerate(results[0]["joints"]):
        tab[f"measured_{j}"] = np.concatenate([r["measured"][:, k] for r in results])
        tab[f"predicted_{j}"] = np.concatenate([r["predicted"][:, k] for r in results])
    write_table(out / "torques.parquet", tab)
    t = Table(title=f"robocal evaluate — {run_dir}, not refitted: held-out torque RMS N·m")
    joints = results[0]["joints"]
    for h in ["recording", "n", *joints, "pooled", "URDF as drawn (pooled)"]:
        t.add_column(h, justify="left" if h == "recording" else "right")
    for r in results:
        t.add_row(Path(r["path"]).name, str(r["n"]), *(f"{r['rms_joint_Nm'][j]:.3f}" for j in joints),
                  f"{r['rms_pooled_Nm']:.3f}", f"{r['nominal_rms_pooled_Nm']:.3f}")
    console().print(t)
    print(f"evaluation: {out / 'evaluation.json'}\ntorques:    {out / 'torques.parquet'}")
