"""`robocal simulate urdf`: a campaign of any URDF robot, any measurement type."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Literal, Optional

import numpy as np
import typer

from pipeline.cli import err, force_option, simulate_app


@simulate_app.command("urdf")
def urdf_cmd(
    urdf: Path = typer.Option(..., "--urdf", help="Robot description (URDF)."),
    root: str = typer.Option(..., "--root", help="Root link of the chain."),
    tip: str = typer.Option(..., "--tip", help="Tip link of the chain."),
    measure: Literal["point", "pose", "plane", "coincidence"] = typer.Option("point", "--measure", help="point | pose | plane | coincidence."),
    out: Path = typer.Option(..., "--out", help="Recording to write (MCAP)."),
    truth: Path = typer.Option(None, "--truth", help="Where to write TRUTH.json (the true parameter vector)."),
    poses: int = typer.Option(60, "--poses", min=4, help="Measurements (configurations tried, for plane/coincidence)."),
    error_m: Optional[float] = typer.Option(None, "--error-m", min=0.0, help="1σ error of every joint-origin translation, "
                                            "m (default 1e-3)."),
    error_rad: Optional[float] = typer.Option(None, "--error-rad", min=0.0, help="1σ error of every origin rotation and "
                                              "offset, rad (default 0.2° = 3.49e-3)."),
    noise_m: Optional[float] = typer.Option(None, "--noise-m", min=0.0, help="Measurement noise, 1σ per axis, m "
                                            "(default 2e-5)."),
    noise_rad: Optional[float] = typer.Option(None, "--noise-rad", min=0.0, help="Pose: orientation noise; "
                                              "plane/coincidence: joint reading noise, rad (default 0.01° = 1.75e-4)."),
    error_mm: float = typer.Option(1.0, "--error-mm", min=0.0, hidden=True, help="Alias of --error-m, in mm."),
    error_deg: float = typer.Option(0.2, "--error-deg", min=0.0, hidden=True, help="Alias of --error-rad, in deg."),
    noise_mm: float = typer.Option(0.02, "--noise-mm", min=0.0, hidden=True, help="Alias of --noise-m, in mm."),
    noise_deg: float = typer.Option(0.01, "--noise-deg", min=0.0, hidden=True, help="Alias of --noise-rad, in deg."),
    groups: int = typer.Option(4, "--groups", min=1, help="Coincidence: fixed points (sockets)."),
    seed: int = typer.Option(0, "--seed", help="Random seed (truth, configurations, noise)."),
    campaign_file: Path = typer.Option(None, "--campaign",
                                       help="Execute this planned campaign (CAMPAIGN.json, measurement: pose) "
                                            "instead of random configurations."),
    drive: bool = typer.Option(False, "--drive", help="Also write the encoder stream with the drive state: "
                               "commanded positions and measured efforts (N·m) at standstill around each measurement."),
    effort_noise: float = typer.Option(0.05, "--effort-noise", min=0.0, help="--drive: effort noise, 1σ per sample, N·m."),
    compliance: str = typer.Option("", "--compliance", help="True joint compliance, e.g. j2=2e-6,j3=1e-6 "
                                   "(rad/(N·m)): deflection under gravity of the URDF's inertials and the payload."),
    payload_kg: float = typer.Option(0.0, "--payload-kg", min=0.0, help="A payload at the tip the URDF does not describe, kg."),
    payload_com: str = typer.Option("0,0,0.05", "--payload-com",
                                    help="The payload's centre of mass in the tip link's frame, m (x,y,z)."),
    force: bool = force_option(),
) -> None:
    """Random truth (errors of the stated size) and a campaign (random configurations, or a planned
    CAMPAIGN.json executed on the true robot), written as a URDF recording."""
    from pipeline.errors import at_most

    # options are SI with the unit in the name (m, rad, s); the mm / deg spellings stay as hidden aliases
    error_mm = error_mm if error_m is None else error_m * 1e3
    error_deg = error_deg if error_rad is None else float(np.degrees(error_rad))
    noise_mm = noise_mm if noise_m is None else noise_m * 1e3
    noise_deg = noise_deg if noise_rad is None else float(np.degrees(noise_rad))
    for option, value in (("--poses", poses), ("--groups", groups),):
        at_most(option, value)
    from pipeline.errors import RobocalError
    from pipeline.importers.recording import T0_NS, write_urdf_recording
    from pipeline.models import urdf as urdf_mod
    from pipeline.models.urdf_arm import UrdfArm
    from pipeline.plan.campaign import read_pose
    from pipeline.recording.joint_state_batch import COMMANDED_POSITIONS
    from pipeline.recording.output import check_outputs, claim_outputs, generated
    from pipeline.simulate import urdf_drive
    from pipeline.simulate.urdf_robot import campaign, random_truth
    from pipeline.systems.urdf_robot import model_for

    if measure not in ("point", "pose", "plane", "coincidence"):
        raise RobocalError(f"--measure {measure!r}: expected point, pose, plane or coincidence")
    check_outputs(force, out=out, truth=truth)  # before any work: an existing recording only with --force
    desc = urdf_mod.read(urdf, root, tip)
    arm = UrdfArm(desc)
    model = model_for(arm, measure, {}, [f"socket{i}" for i in range(groups)])
    rng = np.random.default_rng(seed)
    x = random_truth(model, rng, error_mm * 1e-3, np.radians(error_deg), registration=measure in ("point", "pose"))
    q = None if campaign_file is None else read_pose(campaign_file, "urdf", list(arm.joint_names))
    try:
        c = urdf_drive.parse_compliance(compliance, desc.joint_names)
    except ValueError as e:
        raise RobocalError(str(e)) from None
    try:
        com = np.array([float(v) for v in payload_com.split(",")])
    except ValueError:
        com = np.zeros(0)
    if com.shape != (3,) or not np.all(np.isfinite(com)):
        raise RobocalError(f"--payload-com {payload_com!r}: expected x,y,z in m")
    payload = (payload_kg, com) if payload_kg > 0 else None
    if (c.any() or payload) and measure not in ("point", "pose"):
        raise RobocalError(f"--compliance / --payload-kg: simulated for --measure point or pose, not {measure}")
    true_joints = (lambda qr: urdf_drive.deflect(desc, qr, c, payload)) if c.any() else None
    table, tr = campaign(model, x, poses, seed, measure, noise_mm * 1e-3, np.radians(noise_deg), n_groups=groups, q=q,
                         true_joints=true_joints)
    stream = None
    if drive:
        qr = table["joint_positions"]
        tau = urdf_drive.true_torques(desc, qr if true_joints is None else true_joints(qr), payload)
        table["timestamp_ns"] = T0_NS + np.arange(len(qr), dtype=np.int64) * 1_000_000_000
        stream = urdf_drive.drive_stream(table["timestamp_ns"], qr, table[COMMANDED_POSITIONS], -tau,
                                         np.random.default_rng(seed + 1), effort_noise, dwell_s=1.0)  # no gaps
    camp: dict = {"simulated": True, "robot_id": f"{desc.name}-sim-{seed}"}
    if campaign_file is not None:
        camp["campaign_file"] = str(campaign_file)
    if measure == "plane":
        camp["planes"] = [{**p, "known": True} for p in tr.planes]
    if measure == "pose":
        camp |= {"sigma_m": max(noise_mm * 1e-3, 1e-6), "sigma_rad": max(np.radians(noise_deg), 1e-6)}
    claim_outputs(force, out=out, truth=truth)  # with --force the old files kept as NAME.bak
    n = write_urdf_recording(out, desc, measure, camp, table, stream=stream)
    if truth is not None:
        truth.parent.mkdir(parents=True, exist_ok=True)
        names = model.parameter_names()
        drive_truth = {"compliance_rad_per_Nm": dict(zip(desc.joint_names, map(float, c))),
                       "payload_kg": payload_kg, "payload_com_m": com.tolist(), "effort_noise_Nm": effort_noise}
        truth.write_text(json.dumps(generated({"parameters": dict(zip(names, map(float, x[:len(names)]))),
                                     "planes": tr.planes, "points": tr.points.tolist(),
                                     "noise_mm": noise_mm, "noise_deg": noise_deg,
                                     **(drive_truth if drive or c.any() or payload else {})}), indent=1) + "\n")
    err.print(f"simulated {n} {measure} measurements of {desc.name} ({root} → {tip}) into {out}", highlight=False)
