"""`robocal plan SYSTEM`: choose M measurement poses out of N candidates (D-optimal)."""

from __future__ import annotations

import importlib
from pathlib import Path

from typing import Literal

import typer
from rich.markup import escape

from pipeline.cli import PLAN, app, err


def candidate_module(system: str):
    """The planner part of `system`'s declaration (e.g. pipeline.plan.arc_welder), which offers
    `candidates(n, seed) -> (model, table)` and optionally `measured(n, seed)`."""
    from pipeline.errors import RobocalError
    from pipeline.systems.registry import declaration

    planner = declaration(system).planner
    if planner is None:
        raise RobocalError(f"no pose candidates for system {system!r} yet (pipeline/plan/)")
    return importlib.import_module(planner)


def write_plan(out: Path, doc: dict) -> None:
    """The plan / campaign JSON (`pipeline.plan.campaign.write_document`)."""
    from pipeline.plan.campaign import write_document

    write_document(out, doc)


@app.command("plan", rich_help_panel=PLAN)
def plan_cmd(
    system: str = typer.Argument(..., help="System, e.g. arc-welder."),
    candidates: int = typer.Option(1000, "--candidates", min=2, help="Number of candidate poses N."),
    select_m: int = typer.Option(30, "--select", min=1, help="Number of poses M to keep."),
    out: Path = typer.Option(..., "--out", help="Plan file to write (JSON)."),
    seed: int = typer.Option(0, "--seed", help="Seed of the candidate generation."),
    check: int = typer.Option(0, "--check", min=0, help="Also compare, on a simulated campaign, the held-out RMS of "
                                                        "the planned set with this many random sets (0 = skip)."),
    margin: float = typer.Option(0.010, "--margin", min=0.0, help="Touch: predicted contacts at least this far (m) "
                                 "inside every face edge (narrow faces: 35 % of their width)."),
    stages: int = typer.Option(1, "--stages", min=1, max=2, help="2: write a short first stage (--first-stage "
                               "contacts most likely to land; scanner: operator poses); calibrate it (robocal run), "
                               "then plan the rest with --after."),
    first_stage: int = typer.Option(None, "--first-stage", min=3, help="Contacts in the first stage of --stages 2 "
                                     "(default 15; scanner: poses, default 4)."),
    after: Path = typer.Option(None, "--after", help="Touch, scanner: plan the next stage on the run directory of the stages "
                               "so far (robocal run REC --out RUN_DIR): its contacts, updated model and uncertainty."),
    backlash: bool = typer.Option(False, "--backlash", help="Touch, one stage: plan for every joint's backlash too "
                                  "(D-optimal over the geometry and each joint's play, whose sign is the search's turn "
                                  "of the joint)."),
    urdf: Path = typer.Option(None, "--urdf", help="System urdf: the robot description (URDF)."),
    root: str = typer.Option(None, "--root", help="System urdf: root link of the chain."),
    tip: str = typer.Option(None, "--tip", help="System urdf: tip link of the chain."),
    measure: Literal["point", "pose"] = typer.Option("point", "--measure", help="System urdf: point | pose (what is measured at each "
                                "configuration: a tracker target, or a 6-D pose)."),
    target: str = typer.Option(None, "--target", help="System camera: the board (as robocal import images), "
                               "e.g. chessboard:9x6:0.03."),
    camera_on: Literal["tip", "world"] = typer.Option("tip", "--camera-on", help="System camera: tip (eye-in-hand) or world (eye-to-hand)."),
    lens: Literal["pinhole", "fisheye"] = typer.Option("pinhole", "--lens", help="System camera: pinhole or fisheye."),
    n_dist: int = typer.Option(5, "--distortion-terms", help="System camera: distortion terms of the model (4, 5, 8)."),
    image_size: str = typer.Option("640x480", "--image-size", help="System camera: WIDTHxHEIGHT, px."),
    focal_px: float = typer.Option(None, "--focal-px", min=1.0, help="System camera: nominal focal length, px "
                                   "(default: the image width)."),
    home: str = typer.Option(None, "--home", help="System camera: q1,…,qn rad, where the camera sees the board's "
                             "centre straight on at --distance."),
    distance_m: float = typer.Option(0.5, "--distance-m", min=0.01, help="System camera: board distance at --home, m."),
    hand_eye: str = typer.Option(None, "--hand-eye", help="System camera: the tool frame x,y,z (m),roll,pitch,yaw "
                                 "(rad): flange → camera (tip), flange → board (world); default on the flange's z axis."),
    fit_groups: str = typer.Option("joint offsets", "--fit", help="System camera: parameter groups planned for with the "
                                   "registration (intrinsics, hand-eye, board), comma-separated; '' for none."),
    max_tilt_rad: float = typer.Option(0.7, "--max-tilt-rad", min=0.0, max=1.2, help="System camera: largest angle "
                                       "between the optical axis and the board's normal, rad."),
    margin_px: float = typer.Option(30.0, "--margin-px", min=0.0, help="System camera: every corner at least this far "
                                    "inside the image (nominal model), px."),
) -> None:
    """D-optimal pose selection: greedy + Fedorov exchange with rank-1 (Sherman–Morrison) updates.
    For the arc welder the output is an executable campaign (schemas/campaign.schema.json)."""
    from pipeline.errors import at_most

    for option, value in (("--candidates", candidates), ("--select", select_m), ("--check", check), ("--first-stage", first_stage),):
        at_most(option, value)
    import numpy as np

    from pipeline.recording.output import check_output

    check_output(out, "plan")  # before any work: never over a file robocal did not create
    if system == "camera":
        from pipeline.cli.plan_camera import CameraOptions, plan_camera

        w = image_size.lower().split("x")[0]
        focal = focal_px if focal_px is not None else (float(w) if w.strip().isdigit() else 640.0)
        opts = CameraOptions(target, camera_on, lens, n_dist, image_size, focal, home, distance_m, hand_eye,
                             fit_groups, max_tilt_rad, margin_px)
        return plan_camera(urdf, root, tip, opts, candidates, select_m, out, seed, check)
    if system == "urdf":
        return plan_urdf(urdf, root, tip, measure, candidates, select_m, out, seed, check)
    if hasattr(candidate_module(system), "touch_campaign"):
        from pipeline.plan.arc_welder import touch_campaign

        if check:
            err.print("[yellow]--check is not run for touch campaigns: benchmarks/bench_plan_campaign.py executes "
                      "planned and random campaigns on the true robot[/]")
        doc = touch_campaign(candidates, select_m, seed, margin, stages, first_stage or 15, after, backlash=backlash)
        write_plan(out, doc)
        p = [m.get("landing_probability", 1.0) for m in doc["measurements"]]
        err.print(f"stage {doc['stage']} of {doc['stages']}: {len(doc['measurements'])} measurements planned from "
                  f"{doc['n_candidates']} candidates in {doc['selection_s']:.3f} s; predicted landing probability "
                  f"min {min(p):.3f}, mean {np.mean(p):.3f}; margin {margin * 1e3:.1f} mm")
        if bal := doc.get("approach_balance"):
            err.print("approach from both sides (rarer side's share of the contacts): " + ", ".join(
                f"{j} {b['rarer_share']:.0%}" for j, b in bal["joints"].items()), highlight=False, soft_wrap=True)
        for w in doc.get("warnings", []):
            err.print(f"[yellow]warning:[/] {escape(w)}", highlight=False, soft_wrap=True)
        if doc["stage"] < doc["stages"]:
            err.print(f"next: robocal simulate {system} --campaign {out} --out REC.mcap (or run it on the robot); "
                      f"robocal run REC.mcap --out RUN; robocal plan {system} --after RUN --select N --out NEXT.json")
        print(out)
        return

    from pipeline.identify.model import take
    from pipeline.plan.doptimal import logdet_info, scale
    from pipeline.plan.select import compare, plan

    mod = candidate_module(system)
    if hasattr(mod, "plan_poses") and (stages == 2 or after is not None):  # the scanner in stages
        return _scanner_stage(mod, system, out, candidates, select_m, seed, stages, first_stage, after)
    with err.status(f"generating {candidates} candidates…"):
        model, table = mod.candidates(candidates, seed)
    if hasattr(mod, "plan_poses"):  # measurements grouped by pose (the scanner's crossings)
        sel, free = mod.plan_poses(model, table, select_m)
        doc = {"kind": "robocal.campaign", "version": 1, "system": system, "stage": 1, "stages": 1,
               "n_candidates": candidates, "select": select_m, "seed": seed,
               "criterion": "D-optimal over poses: log det of the free parameters' information (scaled columns)",
               "free_parameters": [n for n, f in zip(model.parameter_names(), free) if f],
               "logdet": sel.logdet, "greedy_logdet": sel.greedy_logdet, "exchanges": sel.exchanges,
               "selection_s": sel.elapsed_s, **mod.pose_campaign(table, sel.index)}
        write_plan(out, doc)
        err.print(f"selected {select_m} of {candidates} candidate poses in {sel.elapsed_s:.3f} s (log det "
                  f"{sel.logdet:.2f}; greedy {sel.greedy_logdet:.2f}; {sel.exchanges} exchanges)")
        print(out)
        return
    p = plan(model, table, select_m)
    s = p.selection
    J = model.jacobian(model.nominal(), table)[:, :, p.free]
    As, _ = scale(J)
    rng = np.random.default_rng(seed)
    rand = [logdet_info(As, rng.choice(len(As), select_m, replace=False)) for _ in range(20)]
    rows = []
    for i in s.index:
        rows.append({"candidate": int(i), **{k: (v[i].tolist() if isinstance(v[i], np.ndarray) else
                                                 (v[i].item() if hasattr(v[i], "item") else v[i]))
                                             for k, v in table.items() if k not in ("record",)}})
    doc = {"system": system, "n_candidates": len(As), "select": select_m, "seed": seed,
           "criterion": "D-optimal: log det of the information matrix of the free parameters (scaled columns)",
           "free_parameters": [n for n, f in zip(model.parameter_names(), p.free) if f],
           "logdet": s.logdet, "greedy_logdet": s.greedy_logdet, "exchanges": s.exchanges,
           "selection_s": s.elapsed_s, "random_logdet_median": float(np.median(rand)),
           "observability": p.observability, "selected": rows}
    if check:
        if not hasattr(mod, "measured"):
            err.print(f"[yellow]no simulator for {system}: --check skipped[/]")
        else:
            with err.status("simulating a measured campaign for the check…"):
                mmodel, mt = mod.measured(candidates + 100, seed + 1)
            n = len(mt["record"])
            doc["check"] = compare(mmodel, take(mt, np.arange(n - 100)), take(mt, np.arange(n - 100, n)),
                                   select_m, n_random=check, seed=seed)
    if hasattr(mod, "pose_campaign"):  # an executable campaign (schemas/campaign.schema.json)
        doc = {"kind": "robocal.campaign", "version": 1, **doc, "stage": 1, "stages": 1,
               **mod.pose_campaign(table, s.index)}
    write_plan(out, doc)
    err.print(f"selected {select_m} of {len(As)} candidates in {s.elapsed_s:.3f} s "
              f"(log det {s.logdet:.2f}; greedy {s.greedy_logdet:.2f}; {s.exchanges} exchanges; "
              f"median of 20 random sets {np.median(rand):.2f}); O1 {p.observability['O1']:.4f}")
    if "check" in doc:
        c = doc["check"]
        err.print(f"held-out RMS: planned {c['planned_holdout_rms_m'] * 1e3:.4f} mm, random median "
                  f"{c['random_median_m'] * 1e3:.4f} mm ({c['planned_rank_among_random']} of {check} random sets better)")
    print(out)


def _scanner_stage(mod, system: str, out: Path, candidates: int, select_m: int, seed: int, stages: int,
                   first_stage: int, after: Path | None) -> None:
    """The scanner's two stages: a first stage of operator poses, or the next stage on a run."""
    if after is not None:
        with err.status(f"refitting {after} and drawing {candidates} candidates on the estimate…"):
            doc = mod.after(after, select_m, n=candidates, seed=seed)
        stage = {"stage": 2, "stages": 2}
    else:
        doc = mod.first_stage(first_stage or 4, seed=seed)
        stage = {"stage": 1, "stages": 2}
    write_plan(out, {"kind": "robocal.campaign", "version": 1, "system": system, **stage, "n_candidates": candidates,
                     "select": len(doc["measurements"]), "seed": seed, **doc})
    if after is not None:
        err.print(f"stage 2 of 2: {len(doc['measurements'])} poses planned I-optimal on the estimate from "
                  f"{doc['earlier_measurements']} crossings in {doc['selection_s']:.3f} s; predicted RMS 3-D error "
                  f"{doc['predicted_rms_3d_error_m'] * 1e3:.4f} mm over the candidates' crossings (optimistic: independent-error "
                  f"model; measured ≈ 1.3× it)")
    else:
        err.print(f"stage 1 of 2: {len(doc['measurements'])} operator poses (spread over aim, stand-off, tilt, roll); "
                  f"next: robocal simulate {system} --campaign {out} --out REC.mcap (or take them on the robot); "
                  f"robocal run REC.mcap --out RUN; robocal plan {system} --after RUN --select N --out NEXT.json")
    print(out)


def plan_urdf(urdf: Path | None, root: str | None, tip: str | None, measure: str, candidates: int, select_m: int,
              out: Path, seed: int, check: int) -> None:
    """`robocal plan urdf`: D-optimal joint configurations of any URDF chain for point or pose measurements,
    written as an executable pose campaign (joint names from the URDF)."""
    import numpy as np

    from pipeline.errors import RobocalError
    from pipeline.models import urdf as urdf_mod
    from pipeline.models.urdf_arm import UrdfArm
    from pipeline.plan import urdf_robot as pu
    from pipeline.plan.select import compare, plan
    from pipeline.systems.urdf_robot import model_for

    if urdf is None or root is None or tip is None:
        raise RobocalError("robocal plan urdf needs --urdf ROBOT.urdf --root LINK --tip LINK")
    if measure not in ("point", "pose"):
        raise RobocalError(f"--measure {measure!r}: planning from joint configurations needs point or pose "
                           "(plane and coincidence campaigns depend on the fixture)")
    desc = urdf_mod.read(urdf, root, tip)
    model = model_for(UrdfArm(desc), measure, {})
    q = pu.configurations(model.kin, candidates, seed)
    with err.status(f"planning {select_m} of {candidates} configurations…"):
        p = plan(model, pu.table_at(model, model.nominal(), q), select_m)
    s = p.selection
    doc = {"kind": "robocal.campaign", "version": 1, "system": "urdf", "stage": 1, "stages": 1,
           "n_candidates": candidates, "select": select_m, "seed": seed,
           "criterion": "D-optimal: log det of the information matrix of the free parameters (scaled columns)",
           "free_parameters": [n for n, f in zip(model.parameter_names(), p.free) if f],
           "logdet": s.logdet, "greedy_logdet": s.greedy_logdet, "exchanges": s.exchanges,
           "selection_s": s.elapsed_s, "observability": p.observability,
           **pu.pose_campaign(desc, measure, q, s.index, str(urdf))}
    if check:
        from pipeline.simulate.urdf_robot import random_truth

        rng = np.random.default_rng(seed + 1)
        truth = random_truth(model, rng, 1e-3, np.radians(0.2))
        cand = pu.table_at(model, truth, q)
        cand["position"] = cand["position"] + rng.normal(0, 5e-5, cand["position"].shape)
        test = pu.table_at(model, truth, pu.configurations(model.kin, 300, seed + 2))
        true_tip = model.tool(truth, test["joint_positions"])[0]

        def tip_error(x: np.ndarray, t: dict) -> np.ndarray:  # 3-D tool-point error, m (instrument frame)
            return np.linalg.norm(model.tool(x, t["joint_positions"])[0] - true_tip, axis=1)

        with err.status(f"checking against {check} random sets on a simulated truth…"):
            doc["check"] = compare(model, cand, test, select_m, n_random=check, seed=seed, error=tip_error)
    write_plan(out, doc)
    err.print(f"{desc.name} ({root} → {tip}), {measure}: selected {select_m} of {candidates} configurations in "
              f"{s.elapsed_s:.3f} s (log det {s.logdet:.2f}; {len(doc['free_parameters'])} free parameters); "
              f"O1 {p.observability['O1']:.4g}", highlight=False)
    if "check" in doc:
        c = doc["check"]
        err.print(f"true 3-D tool-point error (RMS) at 300 new configurations (simulated truth, 1 mm / 0.2° errors, 50 µm noise): "
                  f"planned {c['planned_holdout_rms_m'] * 1e3:.4f} mm, random median {c['random_median_m'] * 1e3:.4f} mm "
                  f"({c['planned_rank_among_random']} of {check} random sets better)", highlight=False)
    print(out)
