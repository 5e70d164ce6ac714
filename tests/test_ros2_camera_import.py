"""`robocal import ros2 BAG --target …`: camera bags written with rosbags' own Writer (CDR by its
typestore) from images OpenCV renders of a simulated 6R arm: JointState + Image (mono8, bgr8, rgb8) or
CompressedImage (png, jpeg) + CameraInfo.  The images are paired with the joint states by stillness
despite a camera clock 0.3 s ahead; the reported clock-offset range holds the true offset; the joint
fit recovers the truth within its stated σ.  Bad input (no CameraInfo, an unsupported encoding, a
corrupt JPEG, an image of another size than CameraInfo says): one line naming the bag, topic and
record, exit 2, no traceback, the usable images listed."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

sys.path.insert(0, str(Path(__file__).parent))
from r6_robot import BARE_URDF  # noqa: E402

from pipeline.camera.targets import parse as parse_target  # noqa: E402
from pipeline.camera.uncertainty import clustered_fit  # noqa: E402
from pipeline.cli import app, load_commands  # noqa: E402
from pipeline.identify.complexity import fixed_for  # noqa: E402
from pipeline.identify.least_squares import FitOptions  # noqa: E402
from pipeline.ros2.images import header_stamp, typestore  # noqa: E402
from pipeline.measurements.camera import CameraModel  # noqa: E402
from pipeline.models.urdf import parse  # noqa: E402
from pipeline.models.urdf_arm import UrdfArm  # noqa: E402
from pipeline.recording.reader import read_recording  # noqa: E402
from pipeline.simulate import camera_images as ci  # noqa: E402
from pipeline.simulate.ros2_camera_bag import CameraBagLayout, write_camera_bag  # noqa: E402
from pipeline.systems import urdf_robot  # noqa: E402
from real_data import real_data

# extended (`make test-extended`, outside CI's 20-minute budget): a camera bag through import and run; CI keeps test_ros2_import, test_camera_import and the camera guide's KUKA commands
pytestmark = pytest.mark.extended

ROBOCAL = str(Path(sys.executable).parent / "robocal")
TARGET = "chessboard:9x6:0.03"
K_TRUE = np.array([520.0, 522.0, 318.0, 242.0, -0.25, 0.09, 0.001, -0.0005, -0.01])
Q_HOME = np.array([0.0, 0.6, -1.2, 0.0, 0.8, 0.0])
OFFSET_S = 0.3  # the camera's clock ahead of the controller's


def _truth(mount: str = "tip", seed: int = 3):
    model = CameraModel(UrdfArm(parse(BARE_URDF, "b", "l6")), mount=mount, n_dist=5, image_size=(640, 480))
    tgt = parse_target(TARGET)
    rng = np.random.default_rng(seed)
    x = ci.truth(model, Q_HOME, K_TRUE, tgt, rng)
    nominal = model.nominal()
    for i, nm in enumerate(model.parameter_names()):  # offset errors of j2 and j3 only (as test_camera_simulated)
        if nm.startswith(("j1.", "j4.", "j5.", "j6.")) or nm.endswith((".rx", ".ry", ".rz")) or (
                nm.endswith((".x", ".y", ".z")) and not nm.startswith(("base.", "tool."))):
            x[i] = nominal[i]
    return model, tgt, rng, x


# a factory calibration's CameraInfo: near the truth, not it (the calibration's start, not its answer)
INFO_K = tuple(K_TRUE[:9] + np.array([6.0, -5.0, 4.0, -3.0, 0.03, -0.02, 0.0, 0.0, 0.0]))


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    """14 stops seen mid-dwell plus 2 images mid-move, mono8, camera clock 0.3 s ahead."""
    tmp = tmp_path_factory.mktemp("cambag")
    model, tgt, rng, x = _truth()
    q = ci.poses(model, x, Q_HOME, 16, tgt, rng)
    layout = CameraBagLayout(dwell_s=3.0, clock_offset_s=OFFSET_S, moving=(4, 11), info_k=INFO_K[:9])
    sim = write_camera_bag(tmp / "bag", model, x, q, tgt, rng, layout)
    (tmp / "r6.urdf").write_text(BARE_URDF)
    return {"tmp": tmp, "model": model, "x": x, "q": q, "tgt": tgt, "sim": sim, "rng": rng}


def _cli(bag, urdf, out, *extra, workers=1):
    load_commands(["import"])
    return CliRunner().invoke(app, ["import", "ros2", str(bag), "--urdf", str(urdf), "--root", "b", "--tip", "l6",
                                    "--target", TARGET, "--distortion-terms", "5", "--workers", str(workers),
                                    "--out", str(out), *map(str, extra)])


def _run(bag, urdf, out, *extra):
    return subprocess.run([ROBOCAL, "import", "ros2", str(bag), "--urdf", str(urdf), "--root", "b", "--tip", "l6",
                           "--target", TARGET, "--distortion-terms", "5", "--workers", "1", "--out", str(out),
                           *map(str, extra)], capture_output=True, text=True, timeout=300)


def test_bag_calibrates_to_the_truth_within_stated_sigma(campaign):
    tmp = campaign["tmp"]
    r = _cli(tmp / "bag", tmp / "r6.urdf", tmp / "rec.mcap", "--clock-offset-bound-s", "0.4", workers=2)  # the pool
    assert r.exit_code == 0, r.output
    assert "record 4" in r.output and "record 11" in r.output and "moving" in r.output
    rec = read_recording(tmp / "rec.mcap")
    camp = rec.metadata["robocal.campaign"]
    clock = camp["ros2"]["clock_offset"]
    lo, hi = clock["consistent_s"]
    assert lo <= OFFSET_S <= hi and lo <= 0 <= hi  # the offsets every paired image stands still for
    assert abs(clock["estimate_s"] - OFFSET_S) < 0.1  # images taken mid-stop: the plateau's middle
    assert camp["ros2"]["image_records"] == [i for i in range(16) if i not in (4, 11)]
    assert camp["start_intrinsics"] == pytest.approx(list(INFO_K[:9]))
    assert camp["image_size"] == [640, 480]
    model, data = urdf_robot.load(rec)
    assert model.k_start == pytest.approx(INFO_K[:9]) and model.mount == "tip"
    q_used = np.delete(campaign["sim"]["q_image"], [4, 11], axis=0)
    img = np.unique(data["image"])
    assert len(img) == 14 and np.allclose(data["joint_positions"][np.searchsorted(data["image"], img)], q_used, atol=1e-9)
    fixed = fixed_for(model, ["registration", "lens k3", "joint offsets"]) + ("j1.offset", "j6.offset")
    f = clustered_fit(model, data, FitOptions(fixed=fixed, before=False))[0]
    names = np.array(f.names)
    z = (f.x - campaign["x"])[f.free] / f.std[f.free]
    worst = int(np.argmax(np.abs(z)))
    assert np.all(np.abs(z) < 4), f"{names[f.free][worst]}: {z[worst]:+.1f} σ off the truth"
    for p in ("camera.fx", "camera.k1", "tool.x", "tool.roll", "j2.offset", "j3.offset"):
        assert p in names[f.free], f"{p} was not identified"
    assert np.sqrt(np.mean(f.residuals_after**2)) < 0.15  # px: the detector's noise floor


def test_a_wrong_clock_offset_unpairs_the_stop_images(campaign, tmp_path):
    """A wrong known offset (−1.3 s: every stamp moved 1.3 s later, past the end of its stop): the
    images taken at the stops no longer stand still around their stamps, so they are listed as taken
    while moving and left out; too few remain, exit 2."""
    tmp = campaign["tmp"]
    r = _run(tmp / "bag", tmp / "r6.urdf", tmp_path / "rec.mcap", "--clock-offset-s", "-1.3")
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr and "usable in 2 of 2 paired images" in r.stderr
    for i in (0, 1, 2, 3, 5):
        assert f"record {i} at " in r.stderr and "moving" in r.stderr
    assert not (tmp_path / "rec.mcap").exists()


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """Five stops rendered once, reused by every small bag (the same images in every encoding)."""
    model, tgt, rng, x = _truth(seed=5)
    q = ci.poses(model, x, Q_HOME, 5, tgt, rng)
    tmp = tmp_path_factory.mktemp("small")
    sim = write_camera_bag(tmp / "mono8", model, x, q, tgt, rng, CameraBagLayout())
    (tmp / "r6.urdf").write_text(BARE_URDF)
    return {"tmp": tmp, "model": model, "x": x, "q": q, "tgt": tgt, "images": sim["images"], "rng": rng}


def _pixels(path):
    _, data = urdf_robot.load(read_recording(path))
    return data["pixel"], data["corner"]


@pytest.mark.parametrize("encoding,storage", [("bgr8", "mcap"), ("rgb8", "mcap"), ("png", "mcap"), ("jpeg", "mcap"),
                                              ("mono8", "sqlite3")])
def test_encodings_give_the_mono8_corners(small, encoding, storage, tmp_path):
    tmp = small["tmp"]
    if not (tmp / "mono8.mcap").exists():
        assert _cli(tmp / "mono8", tmp / "r6.urdf", tmp / "mono8.mcap").exit_code == 0
    write_camera_bag(tmp_path / "bag", small["model"], small["x"], small["q"], small["tgt"], small["rng"],
                     CameraBagLayout(encoding=encoding), storage=storage, images=small["images"])
    r = _cli(tmp_path / "bag", tmp / "r6.urdf", tmp_path / "rec.mcap")
    assert r.exit_code == 0, r.output
    px, ids = _pixels(tmp_path / "rec.mcap")
    px0, ids0 = _pixels(tmp / "mono8.mcap")
    assert np.array_equal(ids, ids0)
    err = np.abs(px - px0).max()
    assert err < (0.25 if encoding == "jpeg" else 1e-9), err  # lossless encodings: the very same grey image


@pytest.mark.parametrize("damage,needle", [
    ({"info_k": None}, "no sensor_msgs/msg/CameraInfo topic"),
    ({"bad": {2: "encoding"}}, "record 2: unsupported encoding: encoding 'yuv422'"),
    ({"bad": {3: "corrupt"}, "encoding": "jpeg"}, "record 3: unreadable"),
    ({"bad": {1: "size"}}, "record 1: wrong size: 320x240 px, CameraInfo says 640x480 px"),
])
def test_bad_camera_input_is_one_line_naming_bag_topic_record(small, damage, needle, tmp_path):
    tmp = small["tmp"]
    layout = CameraBagLayout(**damage)
    sim = write_camera_bag(tmp_path / "bag", small["model"], small["x"], small["q"], small["tgt"], small["rng"],
                           layout, images=small["images"])
    r = _run(tmp_path / "bag", tmp / "r6.urdf", tmp_path / "rec.mcap")
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr
    last = [ln for ln in r.stderr.splitlines() if ln.strip()][-1]
    assert needle in last and str(tmp_path / "bag") in last and sim["topic"] in last, last
    assert "usable: " in last and f"{sim['topic']}#{0}" in last  # the usable images still listed
    assert not (tmp_path / "rec.mcap").exists()  # nothing written
    if "bad" in damage:  # --skip-bad imports the rest
        r = _run(tmp_path / "bag", tmp / "r6.urdf", tmp_path / "rec.mcap", "--skip-bad")
        assert r.returncode == 0, r.stderr
        camp = read_recording(tmp_path / "rec.mcap").metadata["robocal.campaign"]
        bad = next(iter(damage["bad"]))
        assert [s["image"] for s in camp["skipped"]] == [f"{sim['topic']}#{bad}"]
        assert len(camp["images"]) == 4


@settings(max_examples=60, deadline=None)
@given(st.integers(-2**31, 2**31 - 1), st.integers(0, 999_999_999), st.text(max_size=12))
def test_header_stamp_read_from_cdr_bytes_is_the_decoded_stamp(sec, nsec, frame):
    store = typestore()
    T = store.types
    hdr = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), frame_id=frame)
    msg = T["sensor_msgs/msg/CompressedImage"](header=hdr, format="png", data=np.zeros(3, np.uint8))
    data = bytes(store.serialize_cdr(msg, "sensor_msgs/msg/CompressedImage"))
    back = store.deserialize_cdr(data, "sensor_msgs/msg/CompressedImage").header.stamp
    assert header_stamp(data) == back.sec * 1_000_000_000 + back.nanosec
    assert header_stamp(data[:8]) is None


KUKA = real_data() / "handeye_rwhe_kuka2"


@pytest.mark.skipif(not KUKA.is_dir(), reason=f"real KUKA eye-in-hand images not found at {KUKA} (shared/real-data)")
def test_real_kuka_images_through_a_bag_give_the_images_import(tmp_path):
    """The 16 real KUKA images (1920×1200, 24×17-corner board; shared/real-data, see its SOURCE.md) and the
    controller's flange poses as the joints of `import images`' pose chain, written into a bag (PNG
    CompressedImage of the images' grey levels, an uncalibrated CameraInfo: K all zero) → the same corners,
    pixels and poses as `robocal import images --poses` on the folder."""
    import cv2
    from scipy.spatial.transform import Rotation

    from pipeline.importers.images import pose_chain
    from pipeline.simulate.ros2_camera_bag import write_images_bag

    target = "chessboard:24x17:0.015"
    files = sorted(KUKA.glob("im_*.bmp"))
    rows = np.loadtxt(KUKA / "RobotPosesVec.txt")
    T = np.array([rows[int(f.stem[3:]) - 1].reshape(4, 4) for f in files])
    q = np.c_[T[:, :3, 3], Rotation.from_matrix(T[:, :3, :3]).as_euler("ZYX")]  # x, y, z, yaw, pitch, roll
    grey = [cv2.imread(str(f), cv2.IMREAD_GRAYSCALE) for f in files]
    size = (grey[0].shape[1], grey[0].shape[0])
    desc = pose_chain()
    (tmp_path / "pose.urdf").write_text(desc.urdf)
    write_images_bag(tmp_path / "bag", desc.joint_names, q, lambda i, _: grey[i], size, np.zeros(9),
                     CameraBagLayout(encoding="png", dwell_s=2.0))
    r = subprocess.run([ROBOCAL, "import", "ros2", str(tmp_path / "bag"), "--urdf", str(tmp_path / "pose.urdf"),
                        "--root", "base", "--tip", "flange", "--target", target, "--distortion-terms", "5",
                        "--kinematics-known", "--out", str(tmp_path / "bag.mcap")], capture_output=True, text=True,
                       timeout=900)
    assert r.returncode == 0, r.stderr
    assert "K is all zero" in r.stderr and f"imported {len(files)} of {len(files)} paired images" in r.stderr
    csv = ["image,x,y,z,qx,qy,qz,qw"] + [f"{f.name}," + ",".join(repr(float(v)) for v in (
        *t[:3, 3], *Rotation.from_matrix(t[:3, :3]).as_quat())) for f, t in zip(files, T)]
    (tmp_path / "poses.csv").write_text("\n".join(csv) + "\n")
    r = subprocess.run([ROBOCAL, "import", "images", str(KUKA), "--target", target, "--poses", str(tmp_path / "poses.csv"),
                        "--distortion-terms", "5", "--out", str(tmp_path / "img.mcap")], capture_output=True, text=True,
                       timeout=900)
    assert r.returncode == 0, r.stderr
    (mb, b), (mi, i) = (urdf_robot.load(read_recording(tmp_path / n)) for n in ("bag.mcap", "img.mcap"))
    assert mb.kinematics_known and mi.kinematics_known and mb.image_size == mi.image_size == size
    assert mb.k_start is None  # an uncalibrated CameraInfo gives the size only
    assert np.array_equal(b["image"], i["image"]) and np.array_equal(b["corner"], i["corner"])
    assert np.array_equal(b["pixel"], i["pixel"])  # PNG is lossless: the very grey levels, the very corners
    assert np.allclose(b["joint_positions"], i["joint_positions"], atol=1e-9)


def test_images_without_the_board_or_blurred_are_listed_with_the_reason(small, tmp_path):
    """Not bad input: a blank image (no board) and an out-of-focus one are listed with their reason and
    left out (the campaign's ``skipped``); the other three are imported."""
    tmp = small["tmp"]
    sim = write_camera_bag(tmp_path / "bag", small["model"], small["x"], small["q"], small["tgt"], small["rng"],
                           CameraBagLayout(bad={1: "blank", 3: "blur"}), images=small["images"])
    r = _cli(tmp_path / "bag", tmp / "r6.urdf", tmp_path / "rec.mcap")
    assert r.exit_code == 0, r.output
    topic = sim["topic"]
    assert f"{topic}#{1}: not found: no 9x6-corner chessboard found — not used" in r.output
    assert f"{topic}#{3}: blurred: edges " in r.output
    camp = read_recording(tmp_path / "rec.mcap").metadata["robocal.campaign"]
    assert {s["image"]: s["status"] for s in camp["skipped"]} == {f"{topic}#{1}": "not found", f"{topic}#{3}": "blurred"}
    assert camp["images"] == [f"{topic}#{i}" for i in (0, 2, 4)]


def test_robocal_run_on_a_camera_bag_imports_then_calibrates(small, tmp_path):
    """`robocal run BAG --target …`: the bag imported into DIR/import/recording.mcap, then ingest →
    identify; the figures in px."""
    import json

    tmp = small["tmp"]
    run = subprocess.run([ROBOCAL, "run", str(tmp / "mono8"), "--urdf", str(tmp / "r6.urdf"), "--root", "b", "--tip",
                          "l6", "--target", TARGET, "--out", str(tmp_path / "run"), "--stages",
                          "ingest,validate,identify", "--folds", "3"], capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr
    assert "imported 5 of 5 paired images" in run.stderr
    camp = read_recording(tmp_path / "run" / "import" / "recording.mcap").metadata["robocal.campaign"]
    assert camp["measure"] == "camera" and camp["ros2"]["image_topic"] == "/camera/image_raw"
    summary = json.loads((tmp_path / "run" / "results.json").read_text())["summary"]
    assert summary["residual_unit"] == "px" and summary["rms_after_m"] < 0.2  # px


def test_a_camera_bag_cut_short_keeps_every_complete_image(small, tmp_path):
    """A recorder killed mid-bag (the MCAP cut at 90 %, inside its last chunk, no footer): the images whose chunks are complete are
    imported — their corners the very ones of the whole bag — and the import says, per topic, how many
    messages were lost; the recording carries the loss (ingest's status is then warn, never pass)."""
    import shutil

    tmp = small["tmp"]
    if not (tmp / "mono8.mcap").exists():
        assert _cli(tmp / "mono8", tmp / "r6.urdf", tmp / "mono8.mcap").exit_code == 0
    (tmp_path / "cut").mkdir()
    shutil.copy(tmp / "mono8" / "metadata.yaml", tmp_path / "cut" / "metadata.yaml")
    storage = next((tmp / "mono8").glob("*.mcap"))
    whole = storage.read_bytes()
    (tmp_path / "cut" / storage.name).write_bytes(whole[: len(whole) * 9 // 10])  # inside the last chunk
    r = _run(tmp_path / "cut", tmp / "r6.urdf", tmp_path / "rec.mcap")
    assert r.returncode == 0, r.stderr
    assert "damaged ROS 2 bag" in r.stderr and "/camera/image_raw: " in r.stderr and " messages lost (" in r.stderr
    camp = read_recording(tmp_path / "rec.mcap").metadata["robocal.campaign"]
    full = read_recording(tmp / "mono8.mcap").metadata["robocal.campaign"]
    assert 0 < len(camp["images"]) < len(full["images"]) and set(camp["images"]) <= set(full["images"])
    assert any("messages lost" in w for w in camp["data_lost"])
    px, ids = _pixels(tmp_path / "rec.mcap")
    px0, ids0 = _pixels(tmp / "mono8.mcap")
    n = len(ids)
    assert np.array_equal(ids, ids0[:n]) and np.array_equal(px, px0[:n])  # the salvaged images lose nothing
