"""`robocal import images` on rendered images: targets, states by joints or poses, and bad input
(a target that does not match, images without a pose, an image of another size, a damaged file):
one line, exit 2, the usable images listed; with --skip-bad the rest is imported."""

import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from r6_robot import BARE_URDF  # noqa: E402

from pipeline.camera.detect import detect_image  # noqa: E402
from pipeline.camera.targets import parse as parse_target  # noqa: E402
from pipeline.measurements.camera import CameraModel  # noqa: E402
from pipeline.models.urdf import parse  # noqa: E402
from pipeline.models.urdf_arm import UrdfArm  # noqa: E402
from pipeline.recording.reader import read_recording  # noqa: E402
from pipeline.simulate import camera_images as ci  # noqa: E402
from pipeline.systems import urdf_robot  # noqa: E402

ROBOCAL = str(Path(sys.executable).parent / "robocal")
TARGET = "chessboard:9x6:0.03"


@pytest.fixture(scope="module")
def images(tmp_path_factory):
    """Six rendered views of a 9×6 board from the 6R arm (eye-in-hand), joints.csv, and r6.urdf."""
    tmp = tmp_path_factory.mktemp("cam")
    model = CameraModel(UrdfArm(parse(BARE_URDF, "b", "l6")), mount="tip", image_size=(640, 480))
    tgt = parse_target(TARGET)
    rng = np.random.default_rng(7)
    k = np.array([520.0, 522.0, 318.0, 242.0, -0.2, 0.05, 0.0, 0.0, 0.0])
    qh = np.array([0.0, 0.6, -1.2, 0.0, 0.8, 0.0])
    x = ci.truth(model, qh, k, tgt, rng)
    ci.write_campaign(tmp / "img", model, x, ci.poses(model, x, qh, 6, tgt, rng), tgt, rng)
    (tmp / "r6.urdf").write_text(BARE_URDF)
    return tmp


def _run(*args):
    return subprocess.run([ROBOCAL, "import", "images", *map(str, args)], capture_output=True, text=True, timeout=300)


def _joints(tmp, folder, out, *extra):
    return _run(folder, "--target", TARGET, "--joints", folder / "joints.csv", "--urdf", tmp / "r6.urdf",
                "--root", "b", "--tip", "l6", "--workers", "1", "--out", out, *extra)


@pytest.fixture(scope="module")
def imported(images, tmp_path_factory) -> Path:
    """The six views imported by joints (images kept): one import for the two tests that read it."""
    out = tmp_path_factory.mktemp("imported") / "rec.mcap"
    r = _joints(images, images / "img", out, "--keep-images")
    assert r.returncode == 0, r.stderr
    return out


def test_import_writes_every_corner_with_its_joints(images, imported):
    rec = read_recording(imported)
    model, table = urdf_robot.load(rec)
    assert model.mount == "tip" and model.image_size == (640, 480)
    assert len(np.unique(table["image"])) == 6 and len(table["corner"]) == 6 * 54
    d = detect_image(images / "img" / "img_000.png", TARGET)
    np.testing.assert_array_equal(table["pixel"][table["image"] == 0], d.pixels)  # stored as detected
    with open(imported, "rb") as f:  # the images are kept byte for byte
        from mcap.reader import make_reader

        att = {a.name: a.data for a in make_reader(f).iter_attachments()}
    assert att["img_003.png"] == (images / "img" / "img_003.png").read_bytes()


def test_a_target_that_does_not_match(images, tmp_path):
    r = _run(images / "img", "--target", "chessboard:7x5:0.03", "--joints", images / "img" / "joints.csv",
             "--urdf", images / "r6.urdf", "--root", "b", "--tip", "l6", "--workers", "1", "--out", tmp_path / "x.mcap")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    err = r.stderr.strip().splitlines()[-1]
    assert "usable in 0 of 6 images" in err and "img_000.png: not found" in err
    assert not (tmp_path / "x.mcap").exists()


@pytest.mark.parametrize("damage", ["no pose", "other size", "corrupt"])
def test_bad_images_fail_naming_them_and_listing_the_usable(images, tmp_path, damage):
    folder = tmp_path / "img"
    shutil.copytree(images / "img", folder)
    if damage == "no pose":
        lines = (folder / "joints.csv").read_text().splitlines()
        (folder / "joints.csv").write_text("\n".join(l for l in lines if not l.startswith("img_002")) + "\n")
        bad, what = "img_002.png", "no state"
    elif damage == "other size":
        cv2.imwrite(str(folder / "img_002.png"), cv2.resize(cv2.imread(str(folder / "img_002.png")), (800, 600)))
        bad, what = "img_002.png", "wrong size"
    else:
        (folder / "img_002.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"\0" * 100)
        bad, what = "img_002.png", "unreadable"
    r = _joints(images, folder, tmp_path / "x.mcap")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    last = r.stderr.strip().splitlines()[-1]
    assert f"{bad}: {what}" in last and "usable: 5 of 6 images" in last and "img_000.png" in last
    assert not (tmp_path / "x.mcap").exists()
    r = _joints(images, folder, tmp_path / "y.mcap", "--skip-bad")
    assert r.returncode == 0, r.stderr
    camp = read_recording(tmp_path / "y.mcap").meta("robocal.campaign")
    assert bad not in camp["images"] and len(camp["images"]) == 5
    assert [s["image"] for s in camp["skipped"]] == [bad]


def test_poses_csv_gives_the_pose_chain(images, tmp_path):
    """Flange poses instead of joints: the six-joint pose chain reproduces them exactly."""
    from pipeline.camera.start import flange_poses
    from pipeline.importers.images import pose_chain
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(0)
    R = Rotation.random(6, random_state=1)
    t = rng.uniform(-1, 1, (6, 3))
    q = R.as_quat()
    rows = ["image,x,y,z,qx,qy,qz,qw"] + [f"img_{i:03d}.png," + ",".join(repr(float(v)) for v in [*t[i], *q[i]]) for i in range(6)]
    (tmp_path / "poses.csv").write_text("\n".join(rows) + "\n")
    from pipeline.importers.pose_files import read_poses

    states = read_poses(tmp_path / "poses.csv")
    model = CameraModel(UrdfArm(pose_chain()))
    T = flange_poses(model, model.nominal(), np.array([states.lookup(f"img_{i:03d}.png") for i in range(6)]))
    np.testing.assert_allclose(T[:, :3, :3], R.as_matrix(), atol=1e-12)
    np.testing.assert_allclose(T[:, :3, 3], t, atol=1e-12)
    r = _run(images / "img", "--target", TARGET, "--poses", tmp_path / "poses.csv", "--workers", "1",
             "--out", tmp_path / "p.mcap")
    assert r.returncode == 0, r.stderr
    model, _ = urdf_robot.load(read_recording(tmp_path / "p.mcap"))
    assert model.kinematics_known and "_known kinematics" in model.groups()


def test_charuco_and_aprilgrid_boards_are_found(tmp_path):
    """OpenCV's own board images (generateImage), warped: every corner found, ids as the board numbers them."""
    for spec in ("charuco:7x5:0.04:0.03:DICT_5X5_100", "aprilgrid:6x4:0.04:0.3:DICT_APRILTAG_36h11"):
        tgt = parse_target(spec)
        img = tgt.board.generateImage((1000, 720), marginSize=40)
        H = np.array([[0.9, 0.08, 60], [-0.05, 0.85, 50], [2e-5, 1e-5, 1.0]])
        warped = cv2.warpPerspective(img, H, (1100, 800), borderValue=255)
        f = tmp_path / f"{tgt.kind}.png"
        cv2.imwrite(str(f), warped)
        d = detect_image(f, tgt)
        assert d.status == "ok", (spec, d.status, d.reason)
        assert np.array_equal(d.ids, np.arange(tgt.n_corners))


@pytest.mark.extended  # `make test-extended`: a full run on the imported images; CI keeps the camera guide's KUKA import → run → evaluate
def test_robocal_run_calibrates_the_imported_recording(imported, tmp_path):
    """ingest → validate → identify on a camera recording (6 views of an arm with origin errors the
    registration cannot absorb): residuals and held-out error in px, model selection explained,
    the jackknife σ of the fitted parameters in fit.json."""
    import json

    run = subprocess.run([ROBOCAL, "run", str(imported), "--out", str(tmp_path / "run"),
                          "--stages", "ingest,validate,identify", "--folds", "3"], capture_output=True, text=True,
                         timeout=900)
    assert run.returncode == 0, run.stderr
    fit = json.loads((tmp_path / "run" / "identify" / "fit.json").read_text())
    assert fit["residual_dim"] == 2 and fit["n_measurements"] == 6 * 54
    assert fit["rms_after_m"] < 1.5 and 0 < fit["holdout_rms_m"] < 3.0  # px (the residual unit of a camera)
    assert fit["model_selection"]["explanation"][0].startswith("registration only")
    sig = fit["extra"]["jackknife_sigma"]
    assert {"camera.fx", "tool.x"} <= set(sig) and all(v > 0 for v in sig.values())
    assert fit["extra"]["images"] == 6
    # every residual figure of a camera is px: fit.json, results.json and the run's summary table say so
    assert fit["residual_unit"] == "px" and " px" in fit["model_selection"]["explanation"][0]
    assert json.loads((tmp_path / "run" / "results.json").read_text())["summary"]["residual_unit"] == "px"
    rows = {ln.split("│")[1].strip(): ln.split("│")[2].strip() for ln in run.stderr.splitlines() if ln.count("│") >= 3}
    for k, v in (("RMS after", fit["rms_after_m"]), ("held-out RMS", fit["holdout_rms_m"])):
        assert rows[k] == f"{v:.4f} px", (k, rows[k])
