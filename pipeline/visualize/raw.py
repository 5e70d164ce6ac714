"""A raw recording (.mcap, before any run) as a rerun recording with a layout: `robocal view REC.mcap`.

rerun opens an MCAP file by itself, but shows robocal's channels as raw messages in an empty
viewport.  This writes, into `cache_dir()`, an .rrd holding (frames and units as in run.rrd):

- ``world/robot/nominal/…`` the robot as built (`pipeline.visualize.robot`), seen through the
  registration "before calibration" fits (`pipeline.identify.model.uncalibrated`), moving along the
  campaign's postures on ``time``; ``world/instrument`` the instrument's axes;
- ``world/tips/nominal`` the model's tool points and ``world/measured`` the measured points (point
  and pose campaigns); the arc welder's jig (``world/jig/…``); the Delta by its own hook
  (``world/delta/…``, the nominal robot);
- ``encoder/joints`` the encoder stream, or ``encoder/postures`` the measurement postures
  (rad; prismatic joints m), and ``summary`` what the recording holds.
"""

from __future__ import annotations

import hashlib
import tempfile
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from pipeline.visualize import robot
from pipeline.visualize.rrd import APP_ID, TIMELINE, log_encoder


def cache_dir() -> Path:
    """Where the views of raw recordings are written (the recording's folder is left untouched)."""
    return Path(tempfile.gettempdir()) / "robocal-view"


def blueprint() -> rrb.Blueprint:
    return rrb.Blueprint(
        rrb.Horizontal(rrb.Spatial3DView(origin="/world", name="Robot as built and measurements (m)"),
                       rrb.Vertical(rrb.TimeSeriesView(origin="/encoder", name="Joint readings (rad; prismatic m)"),
                                    rrb.TextDocumentView(origin="/summary", name="Recording")),
                       column_shares=[3, 2]),
        rrb.TimePanel(timeline=TIMELINE), collapse_panels=False)


def write_raw_rrd(path: str | Path, out: str | Path | None = None) -> Path:
    """Write the view of recording `path` (see module docstring); returns the .rrd path."""
    from pipeline.identify.model import uncalibrated
    from pipeline.recording.reader import read_recording
    from pipeline.systems.registry import detect

    path = Path(path)
    data = path.read_bytes()
    sha = hashlib.sha256(data).hexdigest()[:16]
    out = Path(out) if out is not None else cache_dir() / f"{path.stem}-{sha}.rrd"
    out.parent.mkdir(parents=True, exist_ok=True)
    rec = read_recording(path)
    system = detect(rec)
    model, table = system.load(rec)
    table = dict(table)
    stream = None
    try:
        from pipeline.ingest.streams import joint_stream

        js = joint_stream(rec)
        stream = {"t_ns": js.t_ns, **{f"q_{n}": js.q[:, i] for i, n in enumerate(js.names)}}
    except Exception:  # a campaign without an encoder stream (CSV imports): the postures only
        stream = None
    rs = rr.RecordingStream(APP_ID, recording_id=f"robocal-raw-{sha}", send_properties=False)
    rs.set_log_time_enabled(False)
    rs.set_log_tick_enabled(False)
    rs.save(out, default_blueprint=None)
    rs.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    warnings: list[str] = []
    x0 = np.asarray(model.nominal(), float)
    try:
        x0 = np.asarray(uncalibrated(model, table), float)
    except Exception as e:  # the registration could not be fitted: the bare nominal
        warnings.append(f"registration not fitted ({type(e).__name__}); robot drawn in its own base frame")
    if stream is not None:
        log_encoder(rs, stream)
    k = robot.kinematics(model, x0)
    n = len(table.get("joint_positions", []))
    if k is not None and n:
        kin, xk = k
        if stream is None:
            robot.log_postures(rs, table, robot.joint_names_of(kin), robot.joint_units(kin))
        q, t = robot.postures(table, stream, robot.joint_names_of(kin))
        robot.log_robot(rs, kin, {"nominal": xk}, q, t)
    if hasattr(model, "points") and n:
        try:
            p0 = np.asarray(model.points(x0, table)[0], float)
            rs.log("world/tips/nominal", rr.Points3D(p0, colors=[(220, 80, 60)], radii=[0.002]), static=True)
        except Exception as e:  # noqa: BLE001 — a drawing aid only
            warnings.append(f"tool points not drawn ({type(e).__name__})")
    if "position" in table:
        rs.log("world/measured", rr.Points3D(np.asarray(table["position"], float), colors=[(250, 200, 0)],
                                             radii=[0.003]), static=True)
    if system.SYSTEM == "arc-welder":
        from pipeline.models.jig import Jig, stepped_block
        from pipeline.recording.schemas import META_FIXTURE
        from pipeline.visualize.arc_welder import log_jig

        fx = rec.metadata.get(META_FIXTURE)
        log_jig(rs, Jig.from_dict(fx) if fx else stepped_block())
    elif system.SYSTEM == "delta-tracker":  # its platform and rods: the system's own drawing, nominal = "after"
        from pipeline.visualize.rrd import call_system_hook

        try:
            call_system_hook(rs, system.SYSTEM, model, table, x0, x0, None)
        except Exception as e:  # noqa: BLE001 — a drawing aid only
            warnings.append(f"the Delta not drawn ({type(e).__name__})")
    lines = [f"# {path.name}", "", f"- system: {system.SYSTEM}", f"- measurements: {n}",
             f"- encoder samples: {0 if stream is None else len(stream['t_ns'])}", "",
             "The robot as built (red), through the registration fitted before calibration; yellow: measured points.",
             "Run `robocal run` on the recording for the calibrated robot."] + [f"- {w}" for w in warnings]
    rs.log("summary", rr.TextDocument("\n".join(lines), media_type=rr.MediaType.MARKDOWN), static=True)
    rs.send_blueprint(blueprint())
    rs.flush()
    rs.disconnect()
    return out
