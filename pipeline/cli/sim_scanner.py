"""`robocal simulate scorbot-scanner`."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import typer

from pipeline.cli import err, force_option, simulate_app


@simulate_app.command("scorbot-scanner")
def scorbot_scanner_cmd(
    out: Path = typer.Option(..., "--out", help="Recording to write (MCAP)."),
    truth: Path = typer.Option(None, "--truth", help="Where to write TRUTH.json (true scanner and arm, noise)."),
    seed: int = typer.Option(0, "--seed", help="Random seed (poses, noise, random truth)."),
    noise_scale: float = typer.Option(1.0, "--noise-scale", min=0.0, help="Multiplies every error source; 0 turns all off."),
    random_errors: bool = typer.Option(False, "--random-errors", help="Draw the scanner truth uniformly within the Table 2 bounds instead of Table 2's estimates."),
    poses: int = typer.Option(5, "--poses", min=1, help="Robot poses (the paper: 5)."),
    corners: int = typer.Option(5, "--corners", min=1, help="Corner crossings picked per pose (the paper: 5)."),
    joint_offset_deg: float = typer.Option(0.0, "--joint-offset-errors", min=0.0, help="1σ of true joint offset errors, deg (for joint identification)."),
    effect: list[str] = typer.Option([], "--effect", help="Inject an effect into the TRUE camera/arm: NAME=VALUE[,VALUE][@LOCATION] "
                                     "(radial_k2 1/m^4, tangential_distortion=p1,p2 1/m, stripe_peak_bias px, time_offset s, "
                                     "joint_offset@J1..J5 rad, joint_scale@J1..J5). Repeatable; goes to TRUTH.json only."),
    capture_speed: float = typer.Option(0.0, "--capture-speed", min=0.0, help="Joint speed (rad/s) of a sweep through each pose during the capture (exposes a camera time offset)."),
    spread: bool = typer.Option(False, "--spread", help="Stripe rows over 10-90 %% of the image and crossings spread along the stripe (exposes lens distortion)."),
    robot_id: str = typer.Option("sim-scorbot-scanner", "--robot-id", help="Robot identity written to the campaign metadata."),
    campaign_file: list[Path] = typer.Option([], "--campaign", help="Execute a planned campaign (robocal plan scorbot-scanner): "
                                             "each pose servoed onto its grid line from its planned joints on the true arm "
                                             "(a first stage's operator poses: jogged onto the nearest line). Repeat for the "
                                             "stages of a staged campaign: run back to back, one recording."),
    force: bool = force_option(),
) -> None:
    """Laser-stripe scanner on a SCORBOT-ER VII (seed 001): stripe crossings of a printed 30 mm grid."""
    from pipeline.errors import at_most

    for option, value in (("--poses", poses), ("--corners", corners),):
        at_most(option, value)
    from pipeline.recording.schemas import META_CAMPAIGN, META_FIXTURE, META_ROBOT
    from pipeline.recording.writer import write_campaign
    from pipeline.simulate import scorbot_scanner as sim
    from pipeline.errors import RobocalError
    from pipeline.simulate.effects import parse_effect
    from pipeline.recording.output import check_outputs, claim_outputs, generated
    from pipeline.systems import scorbot_scanner as sc

    check_outputs(force, out=out, truth=truth)  # before any work: an existing recording only with --force
    try:
        injected = tuple(parse_effect(e) for e in effect)
        sim.check_effects(injected)
    except ValueError as e:
        raise RobocalError(str(e)) from None
    nominal = sc.nominal_arm()
    rng = np.random.default_rng(seed + 1_000_003)
    arm_true = nominal
    if joint_offset_deg > 0:
        x = nominal.vector()
        x[6 + 5 * np.arange(nominal.n_joints)] += rng.normal(0, np.radians(joint_offset_deg), nominal.n_joints)
        arm_true = nominal.with_vector(x)
    planned = None
    if campaign_file:
        from pipeline.plan.scorbot_scanner import read_campaign

        planned = [p for f in campaign_file for p in read_campaign(f)]
        poses = len(planned)
    campaign, noise, pattern = sim.Campaign(poses=poses, corners=corners, seed=seed, capture_speed_rad_s=capture_speed, spread=spread), sim.Noise(scale=noise_scale), sim.Pattern()
    with err.status(f"simulating {poses} poses x {corners} corners…"):
        for attempt in range(50):
            s_true = sc.random_scanner(rng) if random_errors else sc.reference_scanner()
            try:
                result = sim.simulate(nominal, arm_true, s_true, campaign, noise, pattern, effects=injected,
                                      planned=planned)
                break
            except RuntimeError:
                if not random_errors:
                    raise
        else:
            raise RuntimeError("no usable random scanner truth in 50 draws")
    if planned is not None and len(result.observations) < 3:
        raise RobocalError(f"{', '.join(map(str, campaign_file))}: only {len(result.observations)} of {len(planned)} planned poses found "
                           "their grid line on the true robot (a calibration needs ≥ 3)")
    lo, hi = sc.bounds()
    meta = {META_ROBOT: nominal.to_dict(), META_FIXTURE: pattern.to_dict(),
            META_CAMPAIGN: {"system": sc.SYSTEM, "simulated": True, "poses": poses, "corners_per_pose": corners,
                           "robot_id": robot_id},
            sc.META_SCANNER: {"image_width_px": sc.IMAGE_SIZE_PX[0], "image_height_px": sc.IMAGE_SIZE_PX[1],
                              "bounds": {n: [float(a), float(b)] for n, a, b in zip(sc.cam.SCANNER_NAMES, lo, hi)},
                              "nominal": {n: float(v) for n, v in zip(sc.cam.SCANNER_NAMES, sc.nominal_scanner())},
                              "source": "seed 001 Table 2 (bounds); nominal = middle of each bound"}}
    out.parent.mkdir(parents=True, exist_ok=True)
    claim_outputs(force, out=out, truth=truth)  # with --force the old files kept as NAME.bak
    write_campaign(out, meta, (result.stream_t_ns, result.stream_q, [j.name for j in nominal.joints]),
                   sim.stripe_messages(result, pattern))
    if truth is not None:
        truth.parent.mkdir(parents=True, exist_ok=True)
        truth.write_text(json.dumps(generated(sim.truth_document(arm_true, s_true, noise, campaign, result, injected)), indent=2) + "\n")
    err.print(f"wrote {out} ({result.stream_t_ns.size} encoder samples, {len(result.observations)} stripe "
              f"observations, {sum(len(o.corner_idx) for o in result.observations)} corner crossings)")
    if result.misses:
        err.print(f"[yellow]{len(result.misses)} planned pose(s) found no usable stripe on the true robot: "
                  f"{', '.join(map(str, result.misses))}[/]")
