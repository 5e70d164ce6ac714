"""`robocal simulate dynamics`: a dynamics campaign (joint positions, velocities, efforts) of a URDF robot
with known truth — perturbed inertials, friction, rotor inertia and injected physics — along a planned or a
random excitation."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import typer

from pipeline.cli import err, simulate_app


@simulate_app.command("dynamics")
def dynamics_cmd(
    urdf: Path = typer.Option(..., "--urdf", help="Robot description (URDF) with <inertial> and <limit> elements."),
    root: str = typer.Option(..., "--root", help="Root link of the chain."),
    tip: str = typer.Option(..., "--tip", help="Tip link of the chain."),
    out: Path = typer.Option(..., "--out", help="Recording to write (MCAP)."),
    truth: Path = typer.Option(None, "--truth", help="Where to write TRUTH.json (true parameters and effects)."),
    fit_joints: str = typer.Option("", "--effort-joints", help="Joints whose torque is fitted, comma-separated "
                                   "(default: every joint of the chain)."),
    trajectory: Path = typer.Option(None, "--trajectory", help="Run this trajectory (a CSV of robocal plan excitation: "
                                    "t, JOINT_position …) instead of a random excitation."),
    duration_s: float = typer.Option(60.0, "--duration-s", min=1.0, help="Random excitation: length, s."),
    rate_hz: float = typer.Option(100.0, "--rate-hz", min=5.0, help="Random excitation: sample rate, Hz."),
    max_acceleration: float = typer.Option(2.0, "--max-acceleration", min=1e-3, help="Random excitation: |q̈| limit "
                                           "of every joint, rad/s² (m/s²)."),
    effort_noise: float = typer.Option(0.05, "--effort-noise", min=0.0, help="Effort noise, 1σ per sample, N·m (N)."),
    inertia_error: float = typer.Option(0.1, "--inertia-error", min=0.0, max=0.9, help="Each link's mass and inertia "
                                        "× (1 + U(±e)), its centre of mass moved by U(±e) × 5 cm per axis."),
    effect: list[str] = typer.Option([], "--effect", help="Physics beyond the model, NAME:JOINT=VALUE (repeatable): "
                                     "stribeck, asymmetric_coulomb, load_friction, friction_drift, position_torque, "
                                     "cable_spring, drive_scale, joint_elasticity; time_offset=δ (s)."),
    seed: int = typer.Option(0, "--seed", help="Random seed (truth, trajectory, noise)."),
) -> None:
    """Random truth and an excitation run on it; the efforts written in N·m (N) as `robocal import csv
    --measure effort --effort-units Nm` would; the truth only in TRUTH.json."""
    from pipeline.cli.import_effort import T0_NS
    from pipeline.importers.effort_recording import EffortSpec, write_effort_recording
    from pipeline.dynamics.rigid_body import build
    from pipeline.errors import RobocalError
    from pipeline.models import urdf as urdf_mod
    from pipeline.plan import excitation as X
    from pipeline.plan import excitation_files as XF
    from pipeline.recording.output import check_output, distinct_outputs, generated
    from pipeline.simulate import dynamics_campaign as S

    if truth is not None:
        check_output(truth, "truth")
        distinct_outputs(out=out, truth=truth)
    desc = urdf_mod.read(urdf, root, tip)
    joints = list(desc.joint_names)
    fitted = [j.strip() for j in fit_joints.split(",") if j.strip()] or joints
    bad = [j for j in fitted if j not in joints]
    if bad:
        raise RobocalError(f"--effort-joints: {', '.join(bad)} not in the chain ({', '.join(joints)})")
    rb = build(desc.urdf, joints, str(urdf))
    fit = np.isin(joints, fitted)
    effects = S.parse_effects(effect, joints, fitted)
    lim = XF.limits_of(desc.urdf, joints, max_acceleration, source=str(urdf))
    if trajectory is not None:
        t, q, v, a = XF.read_csv(trajectory, joints)
        if v is None or a is None:  # a table of positions only: its derivatives on its own clock
            v = np.gradient(q, t, axis=0, edge_order=2)
            a = np.gradient(v, t, axis=0, edge_order=2)
        if XF.violations(q, v, a, X.Limits(lim.lower, lim.upper, lim.velocity * 1.05, np.full(len(joints), np.inf))):
            raise RobocalError(f"{trajectory}: the trajectory leaves the URDF's position or velocity limits")
    else:
        rng = np.random.default_rng(seed)
        period = min(10.0, duration_s / 2)
        f = X.feasible(period, *X.random_shape(len(joints), 5, rng), lim)
        t, q, v, a = XF.sample(f, rate_hz, max(int((duration_s - 4.0) // period), 1), 2.0)
    base = S.random_truth(rb, fit, seed, inertia_error)
    tr = S.Truth(base.pi, base.fv, base.fc, base.f0, base.ia, effects)
    tau = S.efforts(rb, tr, fit, t, q, v, a, effort_noise, seed, (lim.lower, lim.upper))
    logs = {"t_ns": T0_NS + np.round(t * 1e9).astype(np.int64), "q": q, "v": v, "effort": tau}
    write_effort_recording(out, desc, logs, str(urdf), EffortSpec(joints=",".join(fitted), units="Nm"),
                           {"simulated": True, **({"trajectory_file": str(trajectory)} if trajectory else {})},
                           f"{desc.name}-sim-{seed}")
    if truth is not None:
        truth.parent.mkdir(parents=True, exist_ok=True)
        truth.write_text(json.dumps(generated(S.truth_document(rb, tr, fit, seed, effort_noise)), indent=1) + "\n")
    err.print(f"simulated {t.size} samples ({t[-1] - t[0]:.1f} s) of {desc.name}'s dynamics with "
              f"{len(effects)} injected effect(s) into {out}", highlight=False)
