"""`robocal simulate delta-tracker`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from typing import Literal

import typer

from pipeline.cli import err, force_option, simulate_app


@simulate_app.command("delta-tracker")
def delta_tracker_cmd(
    out: Path = typer.Option(..., "--out", help="Recording to write (MCAP)."),
    truth: Path = typer.Option(None, "--truth", help="Where to write TRUTH.json (true parameters, noise, realised errors)."),
    seed: int = typer.Option(0, "--seed", help="Random seed (true errors, tracker placement, noise)."),
    noise_scale: float = typer.Option(1.0, "--noise-scale", min=0.0, help="Multiplies every error source; 0 turns all off."),
    tracker_sigma: float = typer.Option(2e-5, "--tracker-sigma", min=0.0, help="Tracker noise, 1σ per axis, m."),
    truth_model: Literal["simplified", "full"] = typer.Option("simplified", "--truth-model",
                                    help="simplified (β' only, seed eq. 3) or full (adds axis direction errors and unequal rods)."),
    grid: tuple[int, int, int] = typer.Option((3, 3, 3), "--grid", help="Grid points along x, y, z (seed 003: 3 3 3)."),
    spacing: tuple[float, float, float] = typer.Option((0.150, 0.150, 0.040), "--spacing", help="Grid spacing x y z, m."),
    points: int = typer.Option(None, "--points", min=4, help="Random points in the grid's box instead of the grid."),
    effect: list[str] = typer.Option([], "--effect", help="Inject an effect into the TRUE robot/tracker: NAME=VALUE[,VALUE][@LOCATION] "
                                     "(backlash@A1..A3 rad, actuator_scale@A1..A3, axis_yaw|axis_tilt@leg1..3 rad, "
                                     "unequal_rods@leg1..3 m, thermal_drift=vx,vy,vz m/s, tracker_scale; "
                                     "bump=A@A2:CENTRE_RAD is outside the library). Repeatable; goes to TRUTH.json only."),
    both_sides: bool = typer.Option(False, "--both-sides", help="Approach every point from both sides of each actuator."),
    passes: int = typer.Option(1, "--passes", min=1, help="Visit the point list this many times (alternating order)."),
    warmup: float = typer.Option(0.0, "--warmup-s", min=0.0, help="Idle warm-up before the first point, s."),
    warm_up: str = typer.Option("", "--warm-up", help="Thermal: the robot warms as ΔT∞·(1 − exp(−t/τ)), given as TAU_S,DT_K; "
                                "an injected thermal_drift=GX,GY,GZ is then in m/K of that rise."),
    temperature_sensor: bool = typer.Option(False, "--temperature-sensor", help="Thermal: log a temperature sensor "
                                            "(1 Hz, 0.05 K noise) on /arm/temperature."),
    model_variant: str = typer.Option(None, "--model-variant", help="Error model the recording's robot metadata asks "
                                      "identification for (simplified, extended); default: none (simplified)."),
    campaign_file: Path = typer.Option(None, "--campaign", help="Execute this planned pose campaign "
                                       "(robocal plan delta-tracker --out) instead of the grid."),
    force: bool = force_option(),
) -> None:
    """Laser-tracker campaign of seed 003's 90° Delta robot."""
    from pipeline.errors import at_most

    for option, value in (("--points", points), ("--passes", passes),):
        at_most(option, value)
    from pipeline.errors import RobocalError
    from pipeline.models.delta import Delta
    from pipeline.recording.output import check_outputs, claim_outputs
    from pipeline.simulate.delta_recording import write
    from pipeline.simulate.delta_tracker import TRUTH_MODELS, Campaign, Noise, random_truth

    check_outputs(force, out=out, truth=truth)  # before any work: an existing recording only with --force
    if truth_model not in TRUTH_MODELS:
        raise RobocalError(f"--truth-model must be one of {', '.join(TRUTH_MODELS)}, not {truth_model!r}")
    if model_variant not in (None, "simplified", "extended"):
        raise RobocalError(f"--model-variant must be simplified or extended, not {model_variant!r}")
    if min(grid) < 1:
        raise RobocalError("--grid needs at least 1 point along each axis")
    delta = Delta()
    true = random_truth(np.random.default_rng(seed + 1_000_003), truth_model)
    campaign = Campaign(grid=tuple(grid), spacing_m=tuple(spacing), points=points, seed=seed)
    if campaign_file is not None:  # the planned actuator angles, commanded as their nominal platform points
        from dataclasses import replace as _replace

        from pipeline.models import delta as dm
        from pipeline.plan.delta_tracker import read_pose_campaign

        p_cmd, ok = dm.forward(delta, np.zeros(27), read_pose_campaign(campaign_file))
        if not np.all(ok):
            raise RobocalError(f"{campaign_file}: measurement {int(np.flatnonzero(~ok)[0])}: the legs cannot close "
                               "at these actuator angles")
        campaign = _replace(campaign, targets_m=tuple(map(tuple, p_cmd.tolist())))
    noise = Noise(tracker_sigma_m=tracker_sigma, scale=noise_scale)
    out.parent.mkdir(parents=True, exist_ok=True)
    if truth is not None:
        truth.parent.mkdir(parents=True, exist_ok=True)
    from pipeline.simulate.delta_tracker import Variations, check_effects
    from pipeline.simulate.effects import parse_effect

    from pipeline.simulate.thermal import parse_warm_up

    try:
        injected = tuple(parse_effect(e) for e in effect)
        check_effects(injected)
        warm = parse_warm_up(warm_up)
    except ValueError as e:
        raise RobocalError(str(e)) from None
    variations = Variations(both_sides=both_sides, passes=passes, warmup_s=warmup,
                            warm_up=(warm.tau_s, warm.rise_k) if warm else (), temperature_sensor=temperature_sensor)
    claim_outputs(force, out=out, truth=truth)  # with --force the old files kept as NAME.bak
    with err.status("simulating the tracker campaign…"):
        sim = write(out, delta, true, campaign, noise, truth, injected, variations, model_variant)
    err.print(f"wrote {out} ({sim.stream_t_ns.size} encoder samples, {sim.t_ns.size} tracker points, "
              f"truth model {truth_model}; tracker noise RMS {sim.tracker_noise_rms_m * 1e3:.4f} mm per axis)")
