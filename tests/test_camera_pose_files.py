"""Pose files as hand-eye data sets ship them (`pipeline.importers.pose_files`) and bad input to `robocal import
images` refused at the door: one line naming the file and the row (line) and column, exit 2, no traceback.

Row-major 4×4 base→flange matrices one per line (RWHE-Calib's RobotPosesVec.txt): the pose chain reproduces
every matrix exactly, line N goes with the image numbered N; the same detections and poses as the CSV of the
same poses.  Refused: NaN in a pose CSV, one image given two poses, roll/pitch/yaw in degrees, a quaternion
and roll/pitch/yaw both, a matrix that is not a rotation or not homogeneous, an --only name that matches no
image, and a 30000×30000 PNG (judged from its header: never decoded).  ≈ 5 s CPU.
"""

import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from pipeline.camera.detect import MAX_PIXELS, detect_image, header_size
from pipeline.camera.start import flange_poses
from pipeline.errors import RobocalError
from pipeline.importers.images import pose_chain, select
from pipeline.importers.pose_files import read_poses
from pipeline.measurements.camera import CameraModel
from pipeline.models.urdf_arm import UrdfArm

ROBOCAL = str(Path(sys.executable).parent / "robocal")
REAL = Path(__file__).resolve().parents[2] / "shared" / "real-data" / "handeye_rwhe_kuka2"
MODEL = CameraModel(UrdfArm(pose_chain()))


def _matrices(path: Path, T: np.ndarray, sep: str = "\t", n: int = 16) -> Path:
    path.write_text("".join(sep.join(f"{v:.12f}" for v in t.ravel()[:n]) + "\n" for t in T))
    return path


def _T(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    T = np.zeros((len(R), 4, 4))
    T[:, :3, :3], T[:, :3, 3], T[:, 3, 3] = R, t, 1.0
    return T


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(1, 6), st.sampled_from(["\t", " ", ", "]), st.sampled_from([16, 12]))
def test_matrix_lines_give_the_pose_chain_every_matrix(tmp_path_factory, seed, n, sep, width):
    rng = np.random.default_rng(seed)
    T = _T(Rotation.random(n, random_state=seed).as_matrix(), rng.uniform(-2, 2, (n, 3)))
    s = read_poses(_matrices(tmp_path_factory.mktemp("m") / "RobotPosesVec.txt", T, sep, width))
    s.bind([f"im_{i + 1:02d}.bmp" for i in range(n)])
    q = np.array([s.lookup(f"im_{i + 1:02d}.bmp") for i in range(n)])
    np.testing.assert_allclose(flange_poses(MODEL, MODEL.nominal(), q), T, atol=1e-9)


def test_line_numbering_comments_and_zero_based_names(tmp_path):
    T = _T(np.repeat(np.eye(3)[None], 3, 0), np.arange(9.0).reshape(3, 3) / 10)
    p = tmp_path / "poses.txt"
    p.write_text("# T_base_flange, row-major\n\n" + "".join(" ".join(map(str, t.ravel())) + "  # a pose\n" for t in T))
    s = read_poses(p)
    s.bind(["im_01.png", "im_03.png"])  # 1-based: line N ↔ image numbered N
    assert np.allclose(s.lookup("im_03.png")[:3], T[2, :3, 3]) and s.lookup("im_04.png") is None
    assert "numbered 4" in s.missing("im_04.png") and "1-based" in s.rule()
    s.bind(["0.png", "1.png", "2.png"])  # an image numbered 0: 0-based
    assert np.allclose(s.lookup("0.png")[:3], T[0, :3, 3]) and "0-based" in s.rule()
    assert s.lookup("board.png") is None and "holds no number" in s.missing("board.png")


@pytest.mark.skipif(not REAL.is_dir(), reason="../shared/real-data/handeye_rwhe_kuka2 is absent (real KUKA poses)")
def test_the_kuka_pose_file_as_shipped_matches_its_matrices():
    s = read_poses(REAL / "RobotPosesVec.txt")
    T = np.loadtxt(REAL / "RobotPosesVec.txt").reshape(-1, 4, 4)  # SOURCE.md: row-major T_base_flange
    s.bind([p.name for p in REAL.glob("im_*.bmp")])
    q = np.array([s.lookup(f"im_{k:02d}.bmp") for k in (1, 5, 28)])
    np.testing.assert_allclose(flange_poses(MODEL, MODEL.nominal(), q), T[[0, 4, 27]], atol=1e-12)


def _png_header(path: Path, w: int, h: int) -> Path:
    """A PNG whose header states w×h px (grey, 8 bit) with one tiny IDAT: decoding it would need w·h bytes."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))
                     + chunk(b"IDAT", zlib.compress(b"\x00" * 64)) + chunk(b"IEND", b""))
    return path


def test_a_huge_image_is_judged_from_its_header(tmp_path):
    p = _png_header(tmp_path / "im_01.png", 30000, 30000)
    assert header_size(p) == (30000, 30000) and 30000 * 30000 > MAX_PIXELS
    d = detect_image(p, "chessboard:9x6:0.03")
    assert d.status == "too large" and "30000x30000" in d.reason


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """Three small grey images im_01…im_03 (no board: the state files are read, and refused, before detection)."""
    import cv2

    f = tmp_path_factory.mktemp("imgs")
    for i in (1, 2, 3):
        cv2.imwrite(str(f / f"im_{i:02d}.png"), np.full((48, 64), 128, np.uint8))
    return f


def _run(folder: Path, tmp: Path, *args) -> subprocess.CompletedProcess:
    return subprocess.run([ROBOCAL, "import", "images", str(folder), "--target", "chessboard:9x6:0.03",
                           "--workers", "1", "--out", str(tmp / "x.mcap"), *map(str, args)],
                          capture_output=True, text=True, timeout=300)


CSV_HEAD = "image,x,y,z,roll,pitch,yaw\n"
CASES = {  # file text → what the one line must name
    "nan": (CSV_HEAD + "im_01,0.1,nan,0.3,0.1,0,0\n", ["row 2", "'y'", "not a finite number"]),
    "empty": (CSV_HEAD + "im_01,0.1,,0.3,0.1,0,0\n", ["row 2", "'y'", "empty"]),
    "duplicate": (CSV_HEAD + "im_01,0.1,0.2,0.3,0.1,0,0\nim_02,0.1,0.2,0.3,0.1,0,0\nim_01.png,0.1,0.2,0.4,0.1,0,0\n",
                  ["rows 2 and 4", "im_01", "two different poses"]),
    "degrees": (CSV_HEAD + "im_01,0.1,0.2,0.3,157,0,0\n", ["row 2", "'roll'", "degrees"]),
    "both": ("image,x,y,z,qx,qy,qz,qw,roll,pitch,yaw\nim_01,0.1,0.2,0.3,0,0,0,1,0,0,0\n",
             ["qx, qy, qz, qw and roll, pitch, yaw", "once"]),
    "not a rotation": ("1 0 0 0.1  0 2 0 0.2  0 0 1 0.3  0 0 0 1\n", ["line 1", "not a rotation"]),
    "not homogeneous": ("1 0 0 0.1  0 1 0 0.2  0 0 1 0.3  1 0 0 1\n", ["line 1", "not 0 0 0 1"]),
    "eight numbers": ("1 0 0 0.1 0 1 0 0.2\n", ["line 1", "8 numbers"]),
}


@pytest.mark.parametrize("case", list(CASES))
def test_bad_pose_files_are_refused_in_one_line(case, folder, tmp_path, capsys, monkeypatch):
    """In process through the console entry point (`pipeline.cli.main`, what the robocal script runs)."""
    from pipeline.cli import main

    text, words = CASES[case]
    p = tmp_path / ("poses.txt" if text[0].isdigit() else "poses.csv")
    p.write_text(text)
    monkeypatch.setattr(sys, "argv", ["robocal", "import", "images", str(folder), "--target", "chessboard:9x6:0.03",
                                      "--poses", str(p), "--out", str(tmp_path / "x.mcap")])
    with pytest.raises(SystemExit) as e:
        main()
    err = capsys.readouterr().err.strip()
    assert e.value.code == 2 and len(err.splitlines()) == 1 and str(p) in err, err
    for w in words:
        assert w in err, (w, err)
    assert not (tmp_path / "x.mcap").exists()


def test_the_robocal_script_refuses_in_one_line_with_no_traceback(folder, tmp_path):
    """The installed script itself: a NaN pose, an unknown --only name, a 30000×30000 image among good ones."""
    (tmp_path / "p.csv").write_text(CSV_HEAD + "im_01,0.1,0.2,0.3,0.1,0,0\nim_02,nan,0.2,0.3,0.1,0,0\n")
    r = _run(folder, tmp_path, "--poses", tmp_path / "p.csv")
    errors = [ln for ln in r.stderr.splitlines() if ln.startswith("robocal: error")]
    assert r.returncode == 2 and "Traceback" not in r.stderr and len(errors) == 1
    assert f"{tmp_path / 'p.csv'}: row 3: column 'x' is 'nan'" in errors[0]
    (tmp_path / "ok.csv").write_text(CSV_HEAD + "".join(f"im_{i:02d},0.1,0.2,0.3,0.1,0,0\n" for i in (1, 2, 3)))
    r = _run(folder, tmp_path, "--poses", tmp_path / "ok.csv", "--only", "im_01,im_7")
    assert r.returncode == 2 and "--only 'im_7': no image" in r.stderr and "Traceback" not in r.stderr
    big = tmp_path / "big"
    big.mkdir()
    for f in folder.iterdir():
        (big / f.name).write_bytes(f.read_bytes())
    _png_header(big / "im_02.png", 30000, 30000)
    r = subprocess.run(["/usr/bin/time", "-f", "maxrss_kb %M", ROBOCAL, "import", "images", str(big), "--target",
                        "chessboard:9x6:0.03", "--workers", "1", "--poses", str(tmp_path / "ok.csv"), "--out",
                        str(tmp_path / "x.mcap")], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "im_02.png: too large: 30000x30000 px" in r.stderr and "Traceback" not in r.stderr
    assert int(r.stderr.rsplit("maxrss_kb", 1)[1].split()[0]) < 600_000  # never decoded (it would take 900 MB)


def test_only_and_exclude_select_images():
    files = [Path(f"im_{i:02d}.bmp") for i in (1, 3, 5, 14)]
    assert select(files, exclude="im_05,im_14") == files[:2]
    assert select(files, only="im_0*") == files[:3]
    assert select(files, only="im_05.bmp,im_14") == files[2:]
    with pytest.raises(RobocalError, match="--exclude 'im_99'"):
        select(files, exclude="im_99")
