"""DIR/run.rrd: the run as a rerun recording (rerun-sdk 0.41).

Entities (lengths m unless the name says mm; times on the recording's own ``time`` timeline, ns
since the Unix epoch; the solver on the ``iteration`` sequence):

- ``world/…`` the jig frame {W}: system geometry from the per-system hook (arc welder: jig
  blocks and faces), ``world/tips/nominal`` and ``world/tips/calibrated`` (the model's 3-D
  points at every measurement), ``world/residuals/…`` residual vectors, ``world/robot/poses``
  (the calibrated arm at a few measurement poses) and ``world/robot/live`` (the arm following
  the encoder stream on ``time``);
- ``encoder/joints`` the encoder stream (rad, one series per joint) on ``time``;
- ``residuals/<before|after|holdout>_mm/<group>`` residuals per face/channel on ``time``;
- ``solver/rms_mm`` the cost (RMS) of each solver evaluation on ``iteration``;
- ``summary`` a markdown text document of the headline figures.

Per-system hooks: module ``pipeline.visualize.<system>`` (``-`` → ``_``) with
``log_system(rec, model, table, x_before, x_after)``; called if present.
"""

from __future__ import annotations

import importlib
import inspect
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from pipeline.report.artefacts import RunArtefacts, residual_matrix
from pipeline.visualize import robot, scene
from pipeline.visualize.scene import entity_part
from pipeline.visualize.source import align, model_and_table

TIMELINE = "time"
ITERATION = "iteration"
NOMINAL_RGB = (220, 80, 60)
CALIBRATED_RGB = (40, 160, 90)
HOLDOUT_RGB = (230, 150, 30)
MEASURED_RGB = (250, 200, 0)
ROBOT_RATE_HZ = 5.0
APP_ID = "robocal"


def _palette(n: int) -> list[tuple[int, int, int]]:
    base = [(31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189), (140, 86, 75),
            (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207)]
    return [base[i % len(base)] for i in range(n)]


def _component_colors(rgb: tuple[int, int, int], k: int) -> list[tuple[int, int, int]]:
    """Distinct colours for the k components of one group: red / green / blue tinted by the group."""
    base = [(214, 39, 40), (44, 160, 44), (31, 119, 180)] + _palette(max(k - 3, 1))
    return [tuple(int(0.75 * b + 0.25 * g) for b, g in zip(base[i], rgb)) for i in range(k)]


def _times(ns: np.ndarray) -> rr.TimeColumn:
    return rr.TimeColumn(TIMELINE, timestamp=np.asarray(ns, np.int64).astype("datetime64[ns]"))


def log_encoder(rec: rr.RecordingStream, encoder: dict[str, np.ndarray]) -> list[str]:
    """The encoder stream on `time`: one entity `encoder/joints` with one scalar series per joint (rad)."""
    t = np.asarray(encoder["t_ns"], np.int64)
    joints = [c[2:] for c in encoder if c.startswith("q_")]
    path = "encoder/joints"
    rec.log(path, rr.SeriesLines(colors=_palette(len(joints)), names=[f"{n} (rad)" for n in joints]), static=True)
    q = np.column_stack([np.asarray(encoder[f"q_{n}"], float) for n in joints])
    rec.send_columns(path, indexes=[_times(t)], columns=rr.Scalars.columns(scalars=q))
    return [path]


def log_residual_series(rec: rr.RecordingStream, art: RunArtefacts) -> list[str]:
    """Residuals (mm) per group and kind on `time`, one point per measurement and component."""
    res = art.residuals
    t = np.asarray(res["timestamp_ns"], np.int64)
    groups = np.asarray(res.get("group", np.full(t.size, "all"))).astype(str)
    paths = []
    for kind in ("before", "after", "holdout"):
        R = residual_matrix(res, kind) * 1e3
        if R.shape[1] == 0:
            continue
        for g, rgb in zip(sorted(set(groups)), _palette(len(set(groups)))):
            m = (groups == g) & np.all(np.isfinite(R), axis=1)
            if not m.any():
                continue
            path = f"residuals/{kind}_mm/{entity_part(g)}"
            k = R.shape[1]
            names = [f"{g} {kind}"] if k == 1 else [f"{g} {kind} {'xyz'[i] if k == 3 else i}" for i in range(k)]
            colors = [rgb] if k == 1 else _component_colors(rgb, k)  # x/y/z told apart
            rec.log(path, rr.SeriesPoints(colors=colors, names=names, marker_sizes=[3.0] * k), static=True)
            rec.send_columns(path, indexes=[_times(t[m])], columns=rr.Scalars.columns(scalars=R[m]))
            paths.append(path)
    return paths


def log_solver(rec: rr.RecordingStream, history: list[float]) -> str:
    """Cost (RMS, mm) of each solver evaluation on the `iteration` sequence."""
    path = "solver/rms_mm"
    rec.log(path, rr.SeriesLines(colors=[(90, 90, 200)], names=["RMS per evaluation (mm)"]), static=True)
    if history:
        rec.send_columns(path, indexes=[rr.TimeColumn(ITERATION, sequence=np.arange(len(history)))],
                         columns=rr.Scalars.columns(scalars=np.asarray(history, float) * 1e3))
    return path


def arrow_scale(residuals: np.ndarray, longest_m: float = 0.1) -> int:
    """Magnification of residual arrows: 100, 10 or 1, the largest that keeps the longest arrow
    within `longest_m` (µm residuals ×100; a real robot's mm residuals ×10)."""
    r = np.asarray(residuals, float)
    big = float(np.nanmax(np.linalg.norm(r, axis=1))) if r.size else 0.0
    for k in (100, 10):
        if k * big <= longest_m:
            return k
    return 1


def log_points(rec: rr.RecordingStream, model, table: dict, x_before: np.ndarray, x_after: np.ndarray,
               residual_after: np.ndarray | None = None) -> list[str]:
    """The model's 3-D points at every measurement, nominal and calibrated; residual vectors when the
    residual is itself a 3-D point difference (residual_dim 3)."""
    p0, _ = model.points(x_before, table)
    p1, _ = model.points(x_after, table)
    labels = [f"#{int(r)}" for r in table.get("record", np.arange(len(p0)))]
    rec.log("world/tips/nominal", rr.Points3D(p0, colors=[NOMINAL_RGB], radii=[0.002], labels=labels,
                                               show_labels=False), static=True)
    rec.log("world/tips/calibrated", rr.Points3D(p1, colors=[CALIBRATED_RGB], radii=[0.002], labels=labels,
                                                  show_labels=False), static=True)
    rec.log("world/tips/correction", rr.LineStrips3D(np.stack([p0, p1], axis=1), colors=[(120, 120, 120)],
                                                      radii=[0.0004]), static=True)
    paths = ["world/tips/nominal", "world/tips/calibrated", "world/tips/correction"]
    measured = np.asarray(table.get("position", np.zeros((0, 3))), float)
    if measured.shape == p1.shape:  # what the instrument measured (point, pose), in the same frame
        rec.log("world/measured", rr.Points3D(measured, colors=[MEASURED_RGB], radii=[0.003], labels=labels,
                                              show_labels=False), static=True)
        paths.append("world/measured")
    if residual_after is not None and getattr(model, "residual_dim", 0) == 3 and len(residual_after) == len(p1):
        k = arrow_scale(residual_after)
        rec.log(f"world/residuals/after_x{k}", rr.Arrows3D(origins=p1, vectors=-k * residual_after,
                                                           colors=[CALIBRATED_RGB]), static=True)
        paths.append(f"world/residuals/after_x{k}")
    # the measurement being made, on the recording's timeline (one column send, not a log call per row)
    t = np.asarray(table.get("timestamp_ns", []), np.int64)
    if t.size == len(p1) and t.size:
        rec.log("world/tips/current", rr.Points3D.from_fields(colors=[(250, 200, 0)], radii=[0.005]), static=True)
        rr.send_columns("world/tips/current", indexes=[rr.TimeColumn(TIMELINE, timestamp=t.astype("datetime64[ns]"))],
                        columns=rr.Points3D.columns(positions=p1, labels=labels), recording=rec)
        paths.append("world/tips/current")
    return paths


def arm_vector(model, arm, x: np.ndarray) -> np.ndarray | None:
    """The arm's own parameter vector inside the model's x: the model's `arm_vector(x)` if it has
    one, else x itself or its leading slice when the parameter names match the arm's; else None."""
    if hasattr(model, "arm_vector"):
        return np.asarray(model.arm_vector(x), float)
    names = arm.parameter_names()
    have = list(model.parameter_names())
    if have[: len(names)] == names:
        return np.asarray(x, float)[: len(names)]
    return None


def log_arm(rec: rr.RecordingStream, arm, x_after: np.ndarray, table: dict,
            encoder: dict[str, np.ndarray] | None) -> list[str]:
    """A serial arm as line strips: at a few measurement poses (static) and following the encoder
    stream at `ROBOT_RATE_HZ` on `time`."""
    q = np.asarray(table["joint_positions"], float)
    pick = scene.pick_poses(len(q), 5)
    lines = scene.arm_polylines(x_after, q[pick])
    rec.log("world/robot/poses", rr.LineStrips3D(lines, colors=[(110, 110, 140)], radii=[0.004],
                                                 labels=[f"pose #{int(table['record'][i])}" for i in pick]),
            static=True)
    paths = ["world/robot/poses"]
    names = [j.name for j in arm.joints]
    if encoder is not None and all(f"q_{n}" in encoder for n in names):
        t = np.asarray(encoder["t_ns"], np.int64)
        idx = scene.decimate(t, ROBOT_RATE_HZ)
        qs = np.column_stack([np.asarray(encoder[f"q_{n}"], float)[idx] for n in names])
        live = scene.arm_polylines(x_after, qs)
        rec.log("world/robot/live", rr.LineStrips3D.from_fields(colors=[(60, 60, 200)], radii=[0.006]),
                static=True)
        rec.send_columns("world/robot/live", indexes=[_times(t[idx])],
                         columns=rr.LineStrips3D.columns(strips=live).partition(np.ones(len(idx), int)))
        paths.append("world/robot/live")
    return paths


def call_system_hook(rec: rr.RecordingStream, system: str, model, table: dict, x_before: np.ndarray,
                     x_after: np.ndarray, art: RunArtefacts) -> str | None:
    """Call `log_system` of the visualizer part of `system`'s declaration (`pipeline.systems.catalog`)
    if it has one; returns the visualizer's name."""
    from pipeline.systems.catalog import CATALOG

    name = CATALOG[system].visualizer if system in CATALOG else None
    if name is None:
        return None
    mod = importlib.import_module(name)
    hook = getattr(mod, "log_system", None)
    if hook is None:
        return None
    kwargs: dict[str, Any] = {}
    if "artefacts" in inspect.signature(hook).parameters:
        kwargs["artefacts"] = art
    hook(rec, model, table, x_before, x_after, **kwargs)
    return name


def summary_markdown(art: RunArtefacts, figures: dict[str, Any]) -> str:
    """Headline figures as markdown for the `summary` text view."""
    from pipeline.report.labels import residual_text

    unit = figures.get("residual_unit") or (art.fit or {}).get("residual_unit")  # px for a camera
    mm = lambda v: residual_text(v, unit, none="n/a")  # noqa: E731
    name = art.robot_name()
    return "\n".join([
        f"# robocal run — {name}" + (f" ({art.system})" if name != art.system else ""), "",
        f"- measurements: {figures.get('n_measurements')}",
        f"- RMS before: {mm(figures.get('rms_before_m'))}",
        f"- RMS after: {mm(figures.get('rms_after_m'))}",
        f"- held-out RMS: {mm(figures.get('holdout_rms_m'))}",
        f"- parameters identified / total: {figures.get('n_identifiable')} / {figures.get('n_parameters')}",
        "", "Red: nominal model's points and robot; green points, blue robot: calibrated; yellow: measured.",
        "Arrows: residual vectors after calibration, magnified (×k in the entity name).",
        "The solver plot uses the `iteration` timeline (select it in the time panel).",
    ])


def diagnosis_markdown(doc: dict) -> str:
    """Findings, not-identifiable effects and unexplained structure of diagnosis.json as markdown."""
    from pipeline.report.diagnosis import finding_rows

    lines = ["# Diagnosis", ""]
    rows = finding_rows(doc)
    lines += [f"- **{r['effect']}** at {r['location']}: {r['parameters']} ({r['confidence']})" for r in rows] or [
        "No finding: no left-out effect detected."]
    b, a = doc.get("holdout_rms_before_m"), doc.get("holdout_rms_after_m")
    if isinstance(b, (int, float)) and isinstance(a, (int, float)):
        lines += ["", f"Held-out RMS {b * 1e3:.4f} mm → {a * 1e3:.4f} mm."]
    where = doc.get("unexplained_where") or []
    if where:
        lines += ["", "Unexplained structure in: " + ", ".join(str(w.get("variable")) for w in where)]
    return "\n".join(lines)


def blueprint(has_scene: bool, image_view: str | None = None) -> rrb.Blueprint:
    """Layout: 3-D scene left; encoder, residuals and solver/summary right; time panel on `time`;
    `image_view` (a camera run): the entity of one image shown in 2-D first among the bottom tabs."""
    first = [rrb.Spatial2DView(origin=image_view, name="Image: detected (yellow), reprojected (green) corners, "
                               "residuals (red, magnified) px")] if image_view else []
    right = rrb.Vertical(
        rrb.TimeSeriesView(origin="/encoder", name="Joint readings (rad; prismatic m)"),
        rrb.Tabs(rrb.TimeSeriesView(origin="/residuals/after_mm", name="Residuals after (mm)"),
                 rrb.TimeSeriesView(origin="/residuals/before_mm", name="Residuals before (mm)"),
                 rrb.TimeSeriesView(origin="/residuals/holdout_mm", name="Residuals held out (mm)")),
        rrb.Tabs(*first, rrb.TextDocumentView(origin="/summary", name="Summary"),
                 rrb.TextDocumentView(origin="/accuracy", name="Accuracy"),
                 rrb.TextDocumentView(origin="/diagnosis", name="Diagnosis"),
                 rrb.TimeSeriesView(origin="/diagnosis/plots", name="Diagnosis plots (timeline: diagnosis x <nn>)"),
                 rrb.TimeSeriesView(origin="/solver", name="Solver RMS per evaluation (mm), timeline: iteration")),
    )
    if has_scene:
        body = rrb.Horizontal(rrb.Spatial3DView(origin="/world", name="Jig, robot and tool tips (m)"), right,
                              column_shares=[3, 2])
    else:
        body = right
    return rrb.Blueprint(body, rrb.TimePanel(timeline=TIMELINE), collapse_panels=False)


def write_rrd(art: RunArtefacts, path: str | Path, figures: dict[str, Any],
              params: dict[str, Any] | None = None) -> dict[str, Any]:
    """Write `path` (run.rrd) from the run's artefacts; returns what was logged."""
    path = Path(path)
    sha = str(art.source.get("sha256") or "")[:16] or "unknown"  # one recording id per input recording
    rec = rr.RecordingStream(APP_ID, recording_id=f"robocal-{art.system}-{sha}", send_properties=False)
    rec.set_log_time_enabled(False)
    rec.set_log_tick_enabled(False)
    path.parent.mkdir(parents=True, exist_ok=True)
    rec.save(path, default_blueprint=None)
    entities: list[str] = []
    warnings: list[str] = []
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    rec.log("summary", rr.TextDocument(summary_markdown(art, figures), media_type=rr.MediaType.MARKDOWN), static=True)
    entities.append("summary")
    if isinstance(art.diagnosis, dict):
        rec.log("diagnosis", rr.TextDocument(diagnosis_markdown(art.diagnosis), media_type=rr.MediaType.MARKDOWN),
                static=True)
        entities.append("diagnosis")
        try:  # the diagnosis's plots, each against its own x timeline (pipeline.visualize.diagnosis)
            from pipeline.visualize.diagnosis import log_diagnosis

            entities += list(log_diagnosis(rec, art.diagnosis) or [])
        except ImportError:
            pass
        except Exception as e:  # a drawing error must not lose the rest of the recording
            warnings.append(f"diagnosis plots not logged: {type(e).__name__}: {e}")
    if art.encoder is not None:
        entities += log_encoder(rec, art.encoder)
    entities += log_residual_series(rec, art)
    entities.append(log_solver(rec, art.history))
    hook = None
    built = model_and_table(art, params)
    if built is None:
        warnings.append("no model/table could be rebuilt from the artefacts; 3-D scene left out")
    else:
        model, table = built
        table = align(table, np.asarray(art.residuals["record"]))
        x_after = np.asarray(art.fit["x"], float)
        x_before = robot.nominal_registered(model, table, np.asarray(art.fit["nominal"], float), warnings)
        entities += log_points(rec, model, table, x_before, x_after, residual_matrix(art.residuals, "after"))
        entities += robot.log_robots(rec, model, table, x_before, x_after, art.encoder, warnings,
                                     mesh_path=tuple((params or {}).get("mesh_path") or ()))
        arm = getattr(model, "arm", None)
        if arm is not None and hasattr(arm, "joints") and "joint_positions" in table:
            x_arm = arm_vector(model, arm, x_after)
            if x_arm is None:
                warnings.append("the model's parameters do not start with its arm's: arm drawn from the hook only")
            else:
                entities += log_arm(rec, arm, x_arm, table, art.encoder)
        if getattr(model, "residual_unit", "") == "px" and hasattr(model, "image_size"):  # a camera: frusta, images
            from pipeline.visualize.camera import log_run

            entities += log_run(rec, art, model, table, x_after, params or {}, warnings)
        try:
            hook = call_system_hook(rec, art.system, model, table, x_before, x_after, art)
        except Exception as e:  # a drawing hook must not lose the rest of the recording
            warnings.append(f"system hook for {art.system} failed: {type(e).__name__}: {e}")
    if isinstance(art.accuracy, dict):
        try:
            from pipeline.visualize.accuracy import log_accuracy

            entities += log_accuracy(rec, art.accuracy)
        except Exception as e:  # a drawing error must not lose the rest of the recording
            warnings.append(f"accuracy map not logged: {type(e).__name__}: {e}")
    cams = [e for e in entities if e.startswith("world/base/cameras/") and e.count("/") == 3]
    rec.send_blueprint(blueprint(built is not None, "/" + cams[0] if cams else None))
    rec.flush()
    rec.disconnect()
    return {"path": str(path), "entities": entities, "system_hook": hook, "warnings": warnings}
