"""`robocal plan camera`: D-optimal robot poses for a camera calibration (`pipeline.plan.camera`),
written as an executable pose campaign (joints per image)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.cli import err
from pipeline.errors import RobocalError


@dataclass(frozen=True)
class CameraOptions:
    """The command line's camera options, as given (strings parsed by `plan_camera`)."""

    target: str | None
    camera_on: str
    lens: str
    n_dist: int
    image_size: str
    focal_px: float
    home: str | None
    distance_m: float
    hand_eye: str | None
    fit: str
    max_tilt_rad: float
    margin_px: float


def numbers(option: str, text: str | None, n: int | None, what: str) -> np.ndarray:
    """Comma-separated finite numbers (n of them when given), else a one-line error."""
    try:
        v = np.array([float(s) for s in str(text).replace("x", ",").split(",")])
    except ValueError:
        v = np.zeros(0)
    if v.size == 0 or (n is not None and v.size != n) or not np.all(np.isfinite(v)):
        raise RobocalError(f"{option} {text!r}: expected {what}")
    return v


def plan_camera(urdf: Path | None, root: str | None, tip: str | None, o: CameraOptions, candidates: int,
                select_m: int, out: Path, seed: int, check: int) -> None:
    from pipeline.camera import projection as pj
    from pipeline.camera.targets import parse as parse_target
    from pipeline.plan.campaign import write_document as write_plan
    from pipeline.identify.complexity import fixed_for
    from pipeline.measurements.camera import CameraModel
    from pipeline.models import urdf as urdf_mod
    from pipeline.models.urdf_arm import UrdfArm
    from pipeline.plan import camera as pc

    if urdf is None or root is None or tip is None or o.target is None or o.home is None:
        raise RobocalError("robocal plan camera needs --urdf ROBOT.urdf --root LINK --tip LINK --target SPEC "
                           "--home q1,…,qn (rad: the camera sees the board's centre straight on)")
    if o.camera_on not in ("tip", "world"):
        raise RobocalError(f"--camera-on {o.camera_on!r}: expected tip (eye-in-hand) or world (eye-to-hand)")
    if o.lens not in pj.MODELS:
        raise RobocalError(f"--lens {o.lens!r}: expected pinhole or fisheye")
    try:
        pj.intrinsic_names(o.lens, o.n_dist)
    except ValueError as e:
        raise RobocalError(f"--distortion-terms {o.n_dist}: {e}") from None
    target = parse_target(o.target)
    desc = urdf_mod.read(urdf, root, tip)
    size = numbers("--image-size", o.image_size, 2, "WIDTHxHEIGHT in px, e.g. 640x480").astype(int)
    model = CameraModel(UrdfArm(desc), mount=o.camera_on, lens=o.lens, n_dist=o.n_dist, image_size=tuple(size))
    q_home = numbers("--home", o.home, model.kin.n_joints, f"{model.kin.n_joints} joint positions in rad "
                     f"({', '.join(desc.joint_names)})")
    he = None if o.hand_eye is None else numbers("--hand-eye", o.hand_eye, 6, "x,y,z (m),roll,pitch,yaw (rad)")
    w, h = size
    k = np.r_[o.focal_px, o.focal_px, (w - 1) / 2, (h - 1) / 2, np.zeros(o.n_dist)]
    setup = pc.Setup(target, k, q_home, o.distance_m, he)
    x = pc.nominal(model, setup)
    groups = [g.strip() for g in o.fit.split(",") if g.strip()]
    unknown = [g for g in groups if g not in model.groups()]
    if unknown:
        raise RobocalError(f"--fit {o.fit!r}: no group {unknown[0]!r}; groups: {', '.join(model.groups())}")
    fixed = fixed_for(model, ["registration", *groups])
    rng = np.random.default_rng(seed)
    with err.status(f"drawing {candidates} reachable views that see the whole board…"):
        try:
            cand = pc.candidate_views(model, x, setup, candidates, rng, o.max_tilt_rad, o.margin_px)
        except RuntimeError as e:
            raise RobocalError(str(e)) from None
    with err.status(f"planning {select_m} of {candidates} images…"):
        sel, free = pc.plan_images(model, x, cand, target, select_m, fixed)
    doc = {"kind": "robocal.campaign", "version": 1, "system": "urdf", "stage": 1, "stages": 1,
           "n_candidates": candidates, "select": select_m, "seed": seed, "views_drawn": cand.drawn,
           "criterion": "D-optimal over images: log det of the free parameters' information, an image's corners "
                        "stacked (independent corners, px; scaled columns)",
           "free_parameters": [n for n, f in zip(model.parameter_names(), free) if f],
           "logdet": sel.logdet, "greedy_logdet": sel.greedy_logdet, "exchanges": sel.exchanges,
           "selection_s": sel.elapsed_s, **pc.campaign_part(desc, cand, sel.index, setup, model, x, str(urdf))}
    if check:
        from pipeline.plan import camera_check as cc

        held = tuple(n for n, f in zip(model.parameter_names(), free) if not f)
        truth = cc.true_cell(model, x, np.random.default_rng(seed + 1), held)
        with err.status(f"checking against {check} random sets on a simulated truth…"):
            doc["check"] = cc.compare(model, truth, cand.q, sel.index, target, free, n_random=check, seed=seed + 2, draws=3)
    write_plan(out, doc)
    tilt = np.degrees(cand.tilt[sel.index])
    err.print(f"{desc.name} ({root} → {tip}), camera on {o.camera_on}: selected {select_m} of {candidates} reachable "
              f"views ({cand.drawn} drawn) in {sel.elapsed_s:.3f} s (log det {sel.logdet:.2f}; "
              f"{len(doc['free_parameters'])} free parameters); tilts {tilt.min():.0f}–{tilt.max():.0f}°, every corner "
              f"≥ {cand.border_px[sel.index].min():.0f} px inside the image", highlight=False)
    if "check" in doc:
        c = doc["check"]
        err.print(f"simulated truth, {c['noise_px']} px noise, {c['draws']} draws: stated σ {c['sigma_ratio_planned']:.2f}× the median "
                  f"random set's (random median {np.median(c['sigma_ratio_random']):.2f}×); true error "
                  f"{c['error_planned']:.2f} (random median {np.median(c['error_random']):.2f}) in those σ; hand-eye "
                  f"{c['hand_eye_error_mm_planned']:.3f} mm (random median "
                  f"{np.median(c['hand_eye_error_mm_random']):.3f} mm)", highlight=False)
    print(out)
