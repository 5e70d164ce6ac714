"""`robocal run` and one command per stage (`robocal ingest`, `validate`, `identify`, `observe`)."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Literal, Optional

import typer
from rich.markup import escape
from rich.table import Table

from pipeline.cli import CALIBRATE, app, bag_options, console, err

BAG = bag_options.options(bag_options.RUN_PANEL)
EFF = bag_options.effort_options(bag_options.RUN_PANEL)


def _log(line: str) -> None:
    name, _, rest = line.partition(": ")
    colour = "green" if rest.startswith("cached") else "cyan"
    err.print(f"[bold]{name}[/]: [{colour}]{rest}[/]", highlight=False)


def _summary(run_dir: Path, failed: bool = False) -> None:
    """The run's figures from DIR/results.json (a folder robocal wrote); `failed`: the run stopped,
    so whatever the file says, the status is fail."""
    from pipeline.report.labels import residual_text
    from pipeline.stages.artefacts import read_json
    from pipeline.stages.runfolder import is_run_folder

    p = run_dir / "results.json"
    if not p.is_file() or not is_run_folder(run_dir):
        return
    try:
        doc = read_json(p)
        s = doc["summary"]
    except (OSError, ValueError, KeyError, TypeError):
        return
    if failed:
        s["status"] = "fail"
    mm = lambda v: "—" if v is None else f"{v * 1e3:.4f} mm"  # noqa: E731
    res = lambda v: residual_text(v, s.get("residual_unit"), none="—")  # noqa: E731 — px for a camera
    t = Table(title=f"robocal run — {run_dir}")
    t.add_column("figure")
    t.add_column("value", justify="right")
    rows = [("system", s.get("system", "—")), ("status", s.get("status", "—")),
            ("measurements used / recorded", f"{s.get('n_used', '—')} / {s.get('n_measurements', '—')}"),
            ("RMS before", res(s.get("rms_before_m"))), ("RMS after", res(s.get("rms_after_m"))),
            ("held-out RMS", res(s.get("holdout_rms_m"))),
            ("parameters identified / total", f"{s.get('n_identifiable', '—')} / {s.get('n_parameters', '—')}")]
    if s.get("family") == "dynamics":  # torques, N·m (N for a prismatic joint)
        nm = lambda v: "—" if v is None else f"{v:.4f} N·m"  # noqa: E731
        rows = [("system", "urdf (dynamics)"), ("status", s.get("status", "—")),
                ("samples", str(s.get("n_measurements", "—"))),
                ("torque RMS after (fit)", nm(s.get("rms_after_Nm"))),
                ("held-out torque RMS (contiguous blocks)", nm(s.get("holdout_rms_Nm"))),
                ("base parameters / parameters", f"{s.get('n_identifiable', '—')} / {s.get('n_parameters', '—')}"),
                ("condition number (base regressor, scaled)", f"{s.get('condition_number', float('nan')):.1f}"),
                ("model choice (held-out arbiter)", str(s.get("model_choice_label", "—")))]
    elif s.get("rms_3d_after_m") is not None:  # the figure other tools publish: norm of each 3-D error, RMS
        rows[3:3] = [("RMS of the 3-D error before / after", f"{mm(s.get('rms_3d_before_m'))} / {mm(s['rms_3d_after_m'])}"),
                     ("held-out RMS of the 3-D error (" + ("whole groups left out" if str(s.get("holdout_kind", "")
                      ).startswith("whole") else "k-fold, within this recording") + ")", mm(s.get("holdout_rms_3d_m")))]
        rows[5:8] = [(f"{k} (per axis)", v) for k, v in rows[5:8]]
    if isinstance(s.get("correction"), dict) and not s["correction"].get("applied", True):
        rows.insert(2, ("correction", "NONE APPLIED: the nominal robot was kept"))
    if isinstance(s.get("prior_class"), dict):  # the robot class whose compliance prior judged the estimates
        pc = s["prior_class"]
        rows.append(("prior (robot class)", f"{pc.get('class')}: compliance σ {pc.get('compliance_sigma', 0):.3g} "
                     f"rad/(N·m) ({'auto' if pc.get('asked') == 'auto' else '--robot-class'})"))
    if isinstance(s.get("model_choice"), dict):  # URDF robots: which route the model choice took
        mc = s["model_choice"]
        rows.append(("model choice", f"{mc.get('route')} (--model-choice {mc.get('asked')})"))
    diag = doc.get("stages", {}).get("diagnose", {}).get("summary", {})
    if "findings" in diag:  # what the geometric model left out (the diagnosis)
        found = ", ".join(diag["findings"]) or "none"
        rows.append(("diagnosis: effects found", found))
        if diag.get("unexplained"):
            rows.append(("diagnosis: unexplained structure", "yes (see report)"))
        if diag["findings"] and diag.get("holdout_rms_after_m") is not None:
            rows.append(("held-out RMS with the effects modelled", res(diag["holdout_rms_after_m"])))
    if s.get("predicted_map_rms_1sigma_m") is not None:
        rows.append(("predicted accuracy over the workspace (1σ RMS / worst 95 %)",
                     f"{mm(s['predicted_map_rms_1sigma_m'])} / {mm(s.get('predicted_map_max_bound95_m'))}"))
    if s.get("predicted_new_measurement_rms_3d_m") is not None:
        from pipeline.calibrate import NEW_LABEL

        rows.append((NEW_LABEL, mm(s["predicted_new_measurement_rms_3d_m"])))
    for k, v in rows:
        t.add_row(k, str(v))
    console(stderr=True).print(t)
    for w in doc.get("warnings", []):
        err.print(f"[yellow]warning:[/] {escape(w)}", highlight=False, soft_wrap=True)
    if s.get("status_reason"):
        colour = "red" if s.get("status") in ("insufficient", "fail") else "yellow"
        err.print(f"[{colour}]{s.get('status')}:[/] {s['status_reason']}", highlight=False, soft_wrap=True)
    if s.get("status_advice"):
        err.print(f"advice: {s['status_advice']}", highlight=False, soft_wrap=True)
    if diag.get("unseen"):  # whatever the diagnosis's status: the sizes that could have hidden on this campaign
        from pipeline.diagnose.document.unseen import summary_lines

        err.print("diagnosis, effects looked for and the size each could have had unseen:", highlight=False)
        for line in summary_lines(diag["unseen"], width=3):
            err.print(f"  {line}", highlight=False, soft_wrap=True)
    for label, f in (("report", "report.html"), ("rerun", "run.rrd")):
        if (run_dir / f).is_file():
            err.print(f"{label}: {run_dir / f}" + (f"  (open with: robocal view {run_dir})" if label == "rerun" else ""),
                      highlight=False, soft_wrap=True)


def accuracy_params(prior: list[str] | None, tolerance: str | None, previous: Path | None,
                    targets: Path | None) -> dict:
    """Parameters of the accuracy stage from the command line (SI)."""
    from pipeline.accuracy.prior import parse_overrides, parse_quantity
    from pipeline.errors import RobocalError

    p: dict = {}
    if prior:
        p["prior"] = parse_overrides(prior)
    if tolerance is not None:
        p["tolerance_m"] = parse_quantity(tolerance, "--tolerance")
        if p["tolerance_m"] <= 0:
            raise RobocalError(f"--tolerance {tolerance!r}: must be positive")
    if previous is not None:
        if not previous.is_dir():
            raise RobocalError(f"{previous}: no such run folder (--previous)")
        p["previous"] = str(previous.resolve())
    if targets is not None:
        p["targets"] = str(targets.resolve())
    return p


def strict_exit(status: str | None, strict: bool) -> None:
    """Under --strict, a calibration that is not `pass` (or `warn`) exits 1."""
    if strict and status in ("insufficient", "fail"):
        err.print(f"robocal: --strict: status {status}", highlight=False)
        raise typer.Exit(1)


def _params(loss: str | None, f_scale: float | None, reject: float | None, folds: int | None,
            outlier_flag: float | None = None, gap_factor: float | None = None) -> dict[str, dict]:
    p: dict[str, dict] = {"identify": {}, "validate": {}}
    if loss is not None:
        p["identify"]["loss"] = loss
    if f_scale is not None:
        p["identify"]["f_scale_m"] = f_scale
    if reject is not None:
        p["identify"]["outlier_threshold"] = reject
    if folds is not None:
        p["identify"]["folds"] = folds
    if outlier_flag is not None:
        p["validate"]["outlier_threshold"] = outlier_flag
    if gap_factor is not None:
        p["validate"]["gap_factor"] = gap_factor
    return p


LOSS = typer.Option(None, "--loss", help="identify: robust loss.", show_default="linear")
F_SCALE = typer.Option(None, "--f-scale-m", help="identify: robust-loss scale, m.", show_default="1e-4")
REJECT = typer.Option(None, "--reject", help="identify: reject measurements beyond this many robust σ (MAD); 0 = off (default 5).")
FOLDS = typer.Option(None, "--folds", min=2, help="identify: folds of the held-out cross-validation (default 5).")
FORCE = typer.Option(False, "--force", help="Run even if cached.")
MODEL = "Model (physics terms)"
PHYSICS = typer.Option(None, "--physics", rich_help_panel=MODEL, help="Physics terms of a URDF robot (point data): "
                       "auto (default: each family kept when held-out error improves), none, or a list of "
                       "joint-compliance, lateral-compliance, load-compliance, encoder-eccentricity, joint-scale, joint-coupling, backlash.")
PAYLOAD = typer.Option(None, "--payload", rich_help_panel=MODEL, help="A mass carried besides the URDF's links: "
                       "KG@LINK or KG@LINK:X,Y,Z (m, link frame); repeatable.")
ACCURACY = "Accuracy (predicted over the workspace)"
PRIOR = typer.Option(None, "--prior", rich_help_panel=ACCURACY, help="Prior 1σ of parameters held at nominal: NAME=SIGMA, NAME a parameter, "
                     "pattern (J*.beta) or kind (length, angle, frame_translation, frame_rotation, pixel); "
                     "SIGMA SI or with a unit (0.5mm, 0.2deg). Repeatable.")
TOLERANCE = typer.Option(None, "--tolerance", rich_help_panel=ACCURACY, help="Required accuracy (e.g. 0.1mm): fail if the 95 % bound exceeds it "
                         "anywhere on the accuracy map.")
PREVIOUS = typer.Option(None, "--previous", rich_help_panel=ACCURACY, help="A previous run folder of the same robot: report parameters that "
                        "moved by more than 3σ.")
TARGETS = typer.Option(None, "--targets", rich_help_panel=ACCURACY, help="CSV of x,y,z (m) where the accuracy map is evaluated "
                       "(default: a grid over the jig volume / workspace).")
STRICT = typer.Option(False, "--strict", help="Exit 1 unless the status is pass (or warn): insufficient data or "
                      "tolerance not met.")


def in_panel(option: typer.models.OptionInfo, panel: str) -> typer.models.OptionInfo:
    """A copy of `option` shown under help panel `panel` (the original keeps its own)."""
    shown = copy.copy(option)
    shown.rich_help_panel = panel
    return shown


IDENTIFY, VALIDATE = "Identify", "Validate"
MODEL_CHOICE_HELP = ("auto: shrinkage for a single-chain URDF robot measured in lengths, groups for the "
                     "seed systems, trees and cameras; groups (keep groups that lower held-out error); "
                     "shrinkage (every parameter pulled toward nominal by its prior; scale by leaving out whole "
                     "sessions/placements, else by the evidence per parameter family).")


@app.command("run", rich_help_panel=CALIBRATE)
def run_cmd(
    recordings: list[Path] = typer.Argument(..., metavar="REC", help="Recording (MCAP) of a calibration "
                                             "campaign, or a ROS 2 bag; several recordings of one robot are calibrated "
                                             "together (sessions)."),
    registration: Literal["shared", "per-recording"] = typer.Option("shared", "--registration", rich_help_panel=IDENTIFY,
                                     help="Several recordings: shared (one instrument frame) or per-recording."),
    model_choice: Literal["auto", "groups", "shrinkage"] = typer.Option("auto", "--model-choice", rich_help_panel=IDENTIFY, help=MODEL_CHOICE_HELP),
    robot_class: Literal["auto", "industrial", "collaborative", "torque-controlled"] = typer.Option(
        "auto", "--robot-class", rich_help_panel=IDENTIFY, help="Prior of the compliances: industrial, collaborative "
        "or torque-controlled (softer); auto: the stiffest class the estimates fit, said in the summary."),
    out: Path = typer.Option(..., "--out", help="Run folder: DIR/<stage>/ per stage, DIR/results.json."),
    loss: Optional[Literal["linear", "huber", "soft_l1"]] = in_panel(LOSS, IDENTIFY), f_scale: Optional[float] = in_panel(F_SCALE, IDENTIFY),
    reject: Optional[float] = in_panel(REJECT, IDENTIFY), folds: Optional[int] = in_panel(FOLDS, IDENTIFY),
    flag: Optional[float] = typer.Option(None, "--flag-outliers", rich_help_panel=VALIDATE,
                                         help="validate: flag residuals beyond this many robust σ (default 6)."),
    gap_factor: Optional[float] = typer.Option(None, "--gap-factor", rich_help_panel=VALIDATE,
                                               help="validate: a gap is this many sample periods (default 5)."),
    force: bool = FORCE,
    only: Optional[str] = typer.Option(None, "--stages", help="Comma-separated stages to run (default: all available)."),
    prior: Optional[list[str]] = PRIOR, tolerance: Optional[str] = TOLERANCE, previous: Optional[Path] = PREVIOUS,
    targets: Optional[Path] = TARGETS, strict: bool = STRICT,
    urdf: Optional[Path] = typer.Option(None, "--urdf", rich_help_panel=bag_options.RUN_PANEL,
                                        help="ROS 2 bag: the robot's URDF or .xacro (default: the bag's own "
                                             "/robot_description; docs/guide/import-ros2.md)."),
    root: Optional[str] = typer.Option(None, "--root", help="ROS 2 bag: root link of the calibrated chain.",
                                       rich_help_panel=bag_options.RUN_PANEL),
    tip: Optional[str] = typer.Option(None, "--tip", help="ROS 2 bag: tip link of the calibrated chain (not with "
                                      "--measure-topic LINK=TOPIC, whose links are the tips).",
                                      rich_help_panel=bag_options.RUN_PANEL),
    joint_topic: str = BAG["joint_topic"], measure_topic: Optional[list[str]] = BAG["measure_topic"],
    coupled: Optional[list[str]] = bag_options.options()["coupled"],
    coupling_wins: bool = bag_options.options()["coupling_wins"],
    measure: Optional[Literal["point", "pose", "effort"]] = BAG["measure"], window_s: float = BAG["window_s"], max_speed: float = BAG["max_speed"],
    time_source: Literal["header", "log"] = BAG["time"], sigma_m: float = BAG["sigma_m"], sigma_rad: float = BAG["sigma_rad"],
    effort_scale: list[str] = EFF["effort_scale"], effort_offset: list[str] = EFF["effort_offset"],
    effort_mix: list[str] = EFF["effort_mix"], effort_joints: str = EFF["effort_joints"],
    effort_units: Optional[Literal["Nm", "raw"]] = EFF["effort_units"],
    position_scale: list[str] = EFF["position_scale"], position_offset: list[str] = EFF["position_offset"],
    position_mix: list[str] = EFF["position_mix"],
    physics: Optional[str] = PHYSICS, payload: Optional[list[str]] = PAYLOAD,
    target: Optional[str] = typer.Option(None, "--target", rich_help_panel=bag_options.RUN_PANEL,
                                         help="ROS 2 camera bag: the board its images show (as `robocal import "
                                              "ros2 --target`; more camera options there)."),
    camera_on: Literal["tip", "world"] = typer.Option("tip", "--camera-on", rich_help_panel=bag_options.RUN_PANEL,
                                  help="ROS 2 camera bag: tip (eye-in-hand) or world (eye-to-hand)."),
    clock_bound: float = typer.Option(0.1, "--clock-offset-bound-s", min=0.0, rich_help_panel=bag_options.RUN_PANEL,
                                      help="ROS 2 camera bag: how far the camera's clock may be off the joints' (s)."),
    mesh_path: Optional[list[Path]] = typer.Option(None, "--mesh-path", help="report: a folder where the URDF's "
                                                    "package://PKG/… meshes are (repeatable; also ROS_PACKAGE_PATH, "
                                                    "AMENT_PREFIX_PATH): run.rrd draws them, primitives otherwise."),
) -> None:
    """Run every stage (ingest, validate, identify, observe, then diagnose and report when
    available); stages whose inputs and parameters did not change are cached.  A ROS 2 bag is
    imported first (into DIR/import/recording.mcap; --urdf, --root, --tip, topics: docs/guide/import-ros2.md)."""
    import time

    from pipeline.stages.runner import run_pipeline

    t0 = time.perf_counter()
    from pipeline.importers.merge import merged_input

    recording = merged_input(recordings, out, registration)
    from pipeline.ros2.importer import Robot, run_input
    from pipeline.ros2.points import BagSpec

    mt, tips = bag_options.measure_topics(measure_topic, tip, bag=False)
    spec = BagSpec(joint_topic=joint_topic, measure_topic=mt, measure=measure, window_s=window_s,
                   max_speed=max_speed, time=time_source, tips=tips)
    cam = None
    if target is not None:  # a camera bag: Image / CompressedImage + CameraInfo + JointState
        from pipeline.ros2.camera import CameraSpec

        cam = CameraSpec(target=target, mount=camera_on, clock_bound_s=clock_bound)
    robot = None
    if urdf or root or tip or coupled or coupling_wins:
        robot = Robot(urdf, root or "", tip, tuple(coupled or ()), coupling_wins)
    effort = bag_options.effort_spec(effort_scale, effort_offset, effort_mix, effort_joints, effort_units,
                                     (position_scale, position_offset, position_mix))
    recording = run_input(recording, out, robot, spec, cam, sigma_m, sigma_rad, say=bag_options.say,
                          effort=None if effort == bag_options.effort_spec((), (), (), "", None) else effort)
    ok = False
    params = _params(loss, f_scale, reject, folds, flag, gap_factor)
    params["accuracy"] = accuracy_params(prior, tolerance, previous, targets)
    if mesh_path:
        params["report"] = {"mesh_path": [str(p.resolve()) for p in mesh_path]}
    from pipeline.identify.route import check

    if check(model_choice) != "auto":  # auto (default) is resolved by identify; no key: seed runs' caches unchanged
        params["identify"]["model_choice"] = model_choice
    from pipeline.accuracy.prior import check_class

    if check_class(robot_class) != "auto":  # auto (default): no key, caches unchanged
        params["identify"]["robot_class"] = check_class(robot_class)
    if "prior" in params["accuracy"]:  # identify judges a parameter freed off the nominal geometry against it too
        params["identify"]["prior"] = params["accuracy"]["prior"]
    if physics is not None or payload:  # the model's gravity terms (default auto), chosen at ingest for every stage
        from pipeline.physics.payload import check_physics_input

        for w in check_physics_input(recording, physics, payload):  # one line before any stage, not a failed run
            err.print(f"[yellow]warning:[/] {escape(w)}", highlight=False, soft_wrap=True)
        params.setdefault("ingest", {}).update({"physics": physics, "payload": list(payload or [])})
    try:
        outs = run_pipeline(recording, out, params, force=force, log=_log,
                            stages=[s.strip() for s in only.split(",")] if only else None)
        ok = True
    finally:
        _summary(out, failed=not ok)
    n_cached = sum(o.cached for o in outs)
    what = "nothing to do: every stage cached" if n_cached == len(outs) else f"{len(outs) - n_cached} stage(s) ran"
    err.print(f"{what} ({time.perf_counter() - t0:.2f} s); results: {out / 'results.json'}")
    from pipeline.stages.artefacts import read_json

    if (out / "results.json").is_file():
        strict_exit(read_json(out / "results.json")["summary"].get("status"), strict)


@app.command("ingest", rich_help_panel=CALIBRATE)
def ingest_cmd(recording: Path = typer.Argument(..., help="Recording (MCAP)."),
               out: Path = typer.Option(..., "--out", help="Run folder."), force: bool = FORCE) -> None:
    """MCAP → Parquet under DIR/ingest/ (encoder stream, channel tables, measurements with motion context)."""
    from pipeline.errors import RobocalError
    from pipeline.stages.runner import run_stage

    if not recording.is_file():
        raise RobocalError(f"{recording}: no such file")
    out.mkdir(parents=True, exist_ok=True)
    run_stage(out, "ingest", {}, recording=recording, force=force, log=_log)


@app.command("validate", rich_help_panel=CALIBRATE)
def validate_cmd(out: Path = typer.Option(..., "--out", help="Run folder (after `robocal ingest`)."),
                 flag: Optional[float] = typer.Option(None, "--flag-outliers", help="Robust σ beyond which a residual is flagged (default 6)."),
                 gap_factor: Optional[float] = typer.Option(None, "--gap-factor", help="Sample periods that make a gap (default 5)."),
                 force: bool = FORCE) -> None:
    """Named checks (schema, time, duplicates, NaN/inf, joint limits, faces, outliers) → DIR/validate/."""
    from pipeline.stages.artefacts import read_json
    from pipeline.stages.runner import run_stage

    try:
        run_stage(out, "validate", _params(None, None, None, None, flag, gap_factor)["validate"], force=force, log=_log)
    finally:
        p = out / "validate" / "validate.json"
        if p.is_file():
            colour = {"pass": "green", "warn": "yellow", "fail": "red"}
            for c in read_json(p)["checks"]:
                if c["status"] != "pass":
                    err.print(f"[{colour[c['status']]}]{c['status']}[/] {c['name']}: {c['message']}", highlight=False, soft_wrap=True)


@app.command("identify", rich_help_panel=CALIBRATE)
def identify_cmd(out: Path = typer.Option(..., "--out", help="Run folder (after `robocal validate`)."),
                 loss: Optional[str] = LOSS, f_scale: Optional[float] = F_SCALE, reject: Optional[float] = REJECT,
                 folds: Optional[int] = FOLDS, force: bool = FORCE) -> None:
    """Identify the model → DIR/identify/ (fit.json, residuals.parquet, history.json, model.json)."""
    from pipeline.stages.runner import run_stage

    run_stage(out, "identify", _params(loss, f_scale, reject, folds)["identify"], force=force, log=_log)
    _summary(out)


@app.command("observe", rich_help_panel=CALIBRATE)
def observe_cmd(out: Path = typer.Option(..., "--out", help="Run folder (after `robocal identify`)."),
                force: bool = FORCE) -> None:
    """Observability → DIR/observe/observe.json (singular values, O1..O5, correlations, predicted accuracy)."""
    from pipeline.stages.runner import run_stage

    run_stage(out, "observe", {}, force=force, log=_log)
