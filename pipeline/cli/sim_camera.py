"""`robocal simulate camera`: execute a planned camera campaign (`robocal plan camera`) on a
simulated true cell — one image rendered by OpenCV at each planned configuration
(`pipeline.simulate.camera_images`) and the joints CSV `robocal import images --joints` reads."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import typer

from pipeline.cli import err, force_option, simulate_app


def cell_of(path: Path, doc: dict):
    """(model, nominal x, URDF description) of a camera campaign document (one-line errors)."""
    from pipeline.errors import RobocalError
    from pipeline.measurements.camera import CameraModel
    from pipeline.models import urdf as urdf_mod
    from pipeline.models.urdf_arm import UrdfArm

    cam, u = doc.get("camera"), doc.get("urdf")
    if doc.get("instrument") != "camera" or not isinstance(cam, dict) or not isinstance(u, dict):
        raise RobocalError(f"{path}: not a camera campaign (robocal plan camera writes one)")
    urdf = Path(u.get("path", ""))
    if not urdf.is_file() and (path.parent / urdf).is_file():
        urdf = path.parent / urdf
    desc = urdf_mod.read(urdf, u.get("root"), u.get("tip"))
    try:
        k = np.array(list(cam["intrinsics"].values()), float)
        model = CameraModel(UrdfArm(desc), mount=cam["mount"], lens=cam["lens"], n_dist=k.size - 4,
                            image_size=tuple(int(v) for v in cam["image_size"]))
        x = model.nominal().copy()
        names = model.parameter_names()
        it, ib = names.index("tool.x"), names.index("base.x")
        x[it:it + 6], x[ib:ib + 6], x[model.n_kin:] = cam["hand_eye"], cam["board_frame"], k
    except (KeyError, TypeError, ValueError) as e:
        raise RobocalError(f"{path}: camera: {type(e).__name__}: {e}") from None
    return model, x, desc


@simulate_app.command("camera")
def camera_cmd(
    campaign_file: Path = typer.Option(..., "--campaign", help="The planned camera campaign (robocal plan camera)."),
    out: Path = typer.Option(..., "--out", help="Folder to write the images and joints.csv into (new or empty)."),
    truth: Path = typer.Option(None, "--truth", help="Where to write TRUTH.json (the true parameter vector)."),
    seed: int = typer.Option(0, "--seed", help="Random seed (truth, image noise)."),
    noise: float = typer.Option(2.0, "--noise-grey", min=0.0, help="Grey-level noise of the images, 1σ of 255."),
    blur_px: float = typer.Option(0.6, "--blur-px", min=0.0, help="Gaussian blur of the images, σ px."),
    force: bool = force_option("truth file"),
) -> None:
    """Render the planned images on a true cell: the campaign's nominal cell plus errors
    (`pipeline.plan.camera_check.true_cell`: joint offsets, hand-eye, board, intrinsics, a lens)."""
    from pipeline.camera.targets import parse as parse_target
    from pipeline.errors import RobocalError
    from pipeline.plan.camera_check import true_cell
    from pipeline.plan.campaign import load_document, read_pose
    from pipeline.recording.output import check_outputs, claim_outputs, generated
    from pipeline.simulate.camera_images import write_campaign

    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise RobocalError(f"--out {out}: exists and is not an empty folder (robocal writes the images into a new one)")
    check_outputs(force, truth=truth)  # an existing truth file only with --force (kept as NAME.bak)
    doc = load_document(campaign_file)
    model, x, desc = cell_of(campaign_file, doc)
    q = read_pose(campaign_file, "urdf", list(desc.joint_names))
    target = parse_target(doc["camera"].get("target", ""))
    names = model.parameter_names()
    free = set(doc.get("free_parameters") or names)
    rng = np.random.default_rng(seed)
    x_true = true_cell(model, x, rng, tuple(n for n in names if n not in free))
    with err.status(f"rendering {len(q)} images…"):
        files = write_campaign(out, model, x_true, q, target, rng, blur_px=blur_px, noise=noise)
    if truth is not None:
        truth.parent.mkdir(parents=True, exist_ok=True)
        claim_outputs(force, truth=truth)
        truth.write_text(json.dumps(generated({"parameters": dict(zip(names, map(float, x_true))),
                                               "campaign_file": str(campaign_file), "seed": seed}), indent=1))
    err.print(f"{len(files)} images of {target.spec} rendered at the planned joints into {out}; next: robocal import "
              f"images {out} --target {target.spec} --joints {out / 'joints.csv'} --urdf URDF --root {desc.root} "
              f"--tip {desc.tip} --camera-on {model.mount}", highlight=False, soft_wrap=True)
    print(out)
