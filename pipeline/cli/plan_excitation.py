"""`robocal plan excitation`: a Fourier excitation trajectory for dynamics identification (the work of
`pipeline.plan.excitation`), written as a CSV table (t and per joint position, velocity, acceleration), its
coefficients and figures beside it (the same name, .json: period, a, b, per-joint scale and offset, the limits,
the condition numbers) and, with --bag, a ROS 2 bag of one JointTrajectory."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.cli import err


@dataclass(frozen=True)
class ExcitationOptions:
    """`robocal plan excitation`'s options: Fourier harmonics per joint, the fundamental period (s), periods
    written, sample rate (Hz), acceleration limit (rad/s², m/s² for a prismatic joint), the fraction of the URDF's
    velocity limits used, the joints fitted (comma-separated names, empty: all), optimiser starts and iterations,
    the ROS 2 bag to write (or None) and the rest before and after the motion (s)."""

    harmonics: int = 5
    period_s: float = 10.0
    periods: int = 3
    rate_hz: float = 100.0
    max_acceleration: float = 2.0
    velocity_scale: float = 1.0
    fit_joints: str = ""
    starts: int = 3
    iterations: int = 60
    bag: Path | None = None
    rest_s: float = 2.0


def _ours(csv: Path, sidecar: Path) -> bool:
    """The table was written by robocal plan excitation: the robocal-marked JSON beside it names it."""
    import json

    from pipeline.recording.output import written_by_robocal

    try:
        return written_by_robocal(sidecar) and json.loads(sidecar.read_text()).get("csv") == csv.name
    except (OSError, ValueError):
        return False


def plan_excitation(urdf: Path, root: str, tip: str, o: ExcitationOptions, out: Path, seed: int) -> None:
    from pipeline.dynamics import design
    from pipeline.dynamics.rigid_body import build
    from pipeline.errors import RobocalError
    from pipeline.models import urdf as urdf_mod
    from pipeline.plan import excitation as X
    from pipeline.plan import excitation_files as XF
    from pipeline.plan.campaign import write_document
    from pipeline.recording.output import check_output

    if urdf is None or root is None or tip is None:
        raise RobocalError("robocal plan excitation needs --urdf, --root and --tip")
    sidecar = out.with_suffix(".json")
    if sidecar.resolve() == out.resolve():
        raise RobocalError(f"--out {out}: name the trajectory table .csv (its coefficients go beside it, .json)")
    check_output(sidecar, "plan")
    if out.exists() and out.stat().st_size and not _ours(out, sidecar):
        raise RobocalError(f"{out}: exists and was not written by robocal plan excitation (its {sidecar.name} does "
                           "not name it): not replaced")
    if o.bag is not None and o.bag.exists():
        raise RobocalError(f"--bag {o.bag}: exists (a ROS 2 bag is a new folder; robocal never replaces one)")
    if o.harmonics < 2:
        raise RobocalError("--harmonics: at least 2 (the last one keeps the trajectory starting at rest)")
    desc = urdf_mod.read(urdf, root, tip)
    joints = list(desc.joint_names)
    fitted = [j.strip() for j in o.fit_joints.split(",") if j.strip()] or joints
    bad = [j for j in fitted if j not in joints]
    if bad:
        raise RobocalError(f"--effort-joints: {', '.join(bad)} not in the chain ({', '.join(joints)})")
    rb = build(desc.urdf, joints, str(urdf))
    lim = XF.limits_of(desc.urdf, joints, o.max_acceleration, o.velocity_scale, source=str(urdf))
    collide, note = XF.self_collision(desc.urdf, joints, [str(Path(urdf).resolve().parent)])
    obj = X.Objective(rb, np.isin(joints, fitted), design.Terms(), collide=collide)
    say = lambda s: err.print(f"plan excitation: {s}", highlight=False)  # noqa: E731
    say(f"self-collision: {note}")
    f, cond, cond_random = X.optimise(obj, lim, o.period_s, o.harmonics, o.starts, o.iterations, seed, progress=say)
    if not np.isfinite(cond):
        raise RobocalError("no collision-free excitation found: fewer harmonics, a lower --max-acceleration, or "
                           "narrower joint ranges")
    t, q, v, a = XF.sample(f, o.rate_hz, o.periods, o.rest_s)
    bad = XF.violations(q, v, a, lim)
    if bad:  # the scale is set on a dense grid; a sampled point beyond it is a defect, never written
        raise RobocalError(f"planned trajectory leaves its limits: {'; '.join(bad)}")
    XF.write_csv(out, joints, t, q, v, a)
    write_document(sidecar, {"kind": "robocal.excitation", "version": 1, "joints": joints, "effort_joints": fitted,
                             "period_s": f.period, "harmonics": o.harmonics, "a": f.a.tolist(), "b": f.b.tolist(),
                             "scale": f.scale.tolist(), "q0": f.q0.tolist(), "periods": o.periods, "rest_s": o.rest_s,
                             "rate_hz": o.rate_hz, "limits": {"lower": lim.lower.tolist(), "upper": lim.upper.tolist(),
                                                              "velocity": lim.velocity.tolist(),
                                                              "acceleration": lim.acceleration.tolist(),
                                                              "margin": lim.margin},
                             "condition_number": cond, "condition_number_random": cond_random,
                             "self_collision": note, "seed": seed, "csv": out.name,
                             **({"bag": str(o.bag)} if o.bag is not None else {})})
    if o.bag is not None:
        XF.write_bag(o.bag, joints, t, q, v, a)
    err.print(f"excitation of {', '.join(joints)}: {o.harmonics} harmonics of {o.period_s:g} s, {o.periods} periods "
              f"between {o.rest_s:g} s rests, {t.size} samples at {o.rate_hz:g} Hz; condition number of the base "
              f"regressor {cond:.1f} (a random Fourier trajectory of the same limits: {cond_random:.1f})",
              highlight=False, soft_wrap=True)
    print(out)
