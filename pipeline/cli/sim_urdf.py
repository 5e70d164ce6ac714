"""`robocal simulate urdf`: a campaign of any URDF robot, any measurement type."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import typer

from pipeline.cli import err, simulate_app


@simulate_app.command("urdf")
def urdf_cmd(
    urdf: Path = typer.Option(..., "--urdf", help="Robot description (URDF)."),
    root: str = typer.Option(..., "--root", help="Root link of the chain."),
    tip: str = typer.Option(..., "--tip", help="Tip link of the chain."),
    measure: str = typer.Option("point", "--measure", help="point | pose | plane | coincidence."),
    out: Path = typer.Option(..., "--out", help="Recording to write (MCAP)."),
    truth: Path = typer.Option(None, "--truth", help="Where to write TRUTH.json (the true parameter vector)."),
    poses: int = typer.Option(60, "--poses", min=4, help="Measurements (configurations tried, for plane/coincidence)."),
    error_mm: float = typer.Option(1.0, "--error-mm", min=0.0, help="1σ error of every joint-origin translation, mm."),
    error_deg: float = typer.Option(0.2, "--error-deg", min=0.0, help="1σ error of every origin rotation and offset, deg."),
    noise_mm: float = typer.Option(0.02, "--noise-mm", min=0.0, help="Measurement noise, 1σ per axis, mm."),
    noise_deg: float = typer.Option(0.01, "--noise-deg", min=0.0,
                                    help="Pose: orientation noise; plane/coincidence: joint reading noise, deg."),
    groups: int = typer.Option(4, "--groups", min=1, help="Coincidence: fixed points (sockets)."),
    seed: int = typer.Option(0, "--seed", help="Random seed (truth, configurations, noise)."),
    campaign_file: Path = typer.Option(None, "--campaign",
                                       help="Execute this planned campaign (CAMPAIGN.json, measurement: pose) "
                                            "instead of random configurations."),
) -> None:
    """Random truth (errors of the stated size) and a campaign (random configurations, or a planned
    CAMPAIGN.json executed on the true robot), written as a URDF recording."""
    from pipeline.errors import RobocalError
    from pipeline.importers.recording import write_urdf_recording
    from pipeline.models import urdf as urdf_mod
    from pipeline.models.urdf_arm import UrdfArm
    from pipeline.plan.campaign import read_pose
    from pipeline.simulate.urdf_robot import campaign, random_truth
    from pipeline.systems.urdf_robot import model_for

    if measure not in ("point", "pose", "plane", "coincidence"):
        raise RobocalError(f"--measure {measure!r}: expected point, pose, plane or coincidence")
    desc = urdf_mod.read(urdf, root, tip)
    arm = UrdfArm(desc)
    model = model_for(arm, measure, {}, [f"socket{i}" for i in range(groups)])
    rng = np.random.default_rng(seed)
    x = random_truth(model, rng, error_mm * 1e-3, np.radians(error_deg), registration=measure in ("point", "pose"))
    q = None if campaign_file is None else read_pose(campaign_file, "urdf", list(arm.joint_names))
    table, tr = campaign(model, x, poses, seed, measure, noise_mm * 1e-3, np.radians(noise_deg), n_groups=groups, q=q)
    camp: dict = {"simulated": True, "robot_id": f"{desc.name}-sim-{seed}"}
    if campaign_file is not None:
        camp["campaign_file"] = str(campaign_file)
    if measure == "plane":
        camp["planes"] = [{**p, "known": True} for p in tr.planes]
    if measure == "pose":
        camp |= {"sigma_m": max(noise_mm * 1e-3, 1e-6), "sigma_rad": max(np.radians(noise_deg), 1e-6)}
    n = write_urdf_recording(out, desc, measure, camp, table)
    if truth is not None:
        names = model.parameter_names()
        truth.write_text(json.dumps({"parameters": dict(zip(names, map(float, x[:len(names)]))),
                                     "planes": tr.planes, "points": tr.points.tolist(),
                                     "noise_mm": noise_mm, "noise_deg": noise_deg}, indent=1) + "\n")
    err.print(f"simulated {n} {measure} measurements of {desc.name} ({root} → {tip}) into {out}", highlight=False)
