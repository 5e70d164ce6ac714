"""A whole robot with its physics in the model: the independent humanoid generator (dual arm, coupled
torso, whole-tree gravity, joint and lateral compliance at static equilibrium; no robocal code) is
imported through the CSV front door and calibrated with and without the gravity terms."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import run_cli

import independent_humanoid as hu

pytest.importorskip("pinocchio")

TIPS = ("--tip", "left_hand=lx,ly,lz", "--tip", "right_hand=rx,ry,rz")
COUPLED = ("--coupled", "torso_j3=-torso_j1-torso_j2")


@pytest.fixture(scope="module")
def humanoid(tmp_path_factory):
    d = hu.write(tmp_path_factory.mktemp("humanoid") / "data", seed=11, n=160, noise_m=2e-4)
    rec = d.parent / "humanoid.mcap"
    r = run_cli("import", "csv", d / "postures.csv", "--urdf", d / "humanoid.urdf", "--root", "base", *TIPS,
                *COUPLED, "--measure", "point", "--out", rec)
    assert r.returncode == 0, r.stderr
    return rec, json.loads((d / "truth.json").read_text())


def _model(rec, physics):
    from pipeline.systems.registry import load_with_physics
    from pipeline.recording.reader import read_recording
    from pipeline.systems.registry import detect

    r = read_recording(rec)
    return load_with_physics(detect(r), r, physics, None)


def test_tree_kinematics_match_yourdfpy(humanoid):
    """Both tips of the tree model, the coupled torso joint expanded, against yourdfpy's own kinematics."""
    yourdfpy = pytest.importorskip("yourdfpy")
    rec, _ = humanoid
    model, table = _model(rec, "none")
    assert model.kin.tips == ["left_hand", "right_hand"] and "torso_j3" not in model.kin.joint_names
    urdf = yourdfpy.URDF.load(str(rec.parent / "data" / "humanoid.urdf"), load_meshes=False)
    x = model.nominal()
    q = table["joint_positions"][:4]
    for k, tip in enumerate(model.kin.tips):
        R, p = model.kin.forward(x[:model.n_kin], q, k)
        for i in range(len(q)):
            cfg = dict(zip(model.kin.joint_names, q[i]))
            cfg["torso_j3"] = -cfg["torso_j1"] - cfg["torso_j2"]
            urdf.update_cfg(cfg)
            np.testing.assert_allclose(p[i], urdf.get_transform(tip, "base")[:3, 3], atol=1e-12)


def test_physics_jacobian_matches_finite_differences(humanoid):
    rec, _ = humanoid
    model, table = _model(rec, "joint-compliance,lateral-compliance,load-compliance")
    data = {k: v[:40] for k, v in table.items()}
    rng = np.random.default_rng(0)
    x = model.initial_guess(data)
    names = model.parameter_names()
    phys = [i for i, n in enumerate(names) if n.endswith((".compliance", ".lateral1", ".lateral2"))]
    load = [i for i, n in enumerate(names) if n.endswith(".compliance_load")]  # rad/(N·m)²: δq = c·τ + h·τ|τ|
    assert len(load) == len(model.compliant) > 0
    x[phys] = rng.uniform(1e-5, 5e-5, len(phys))
    x[load] = rng.uniform(-2e-7, 2e-7, len(load))
    J = model.jacobian(x, data)
    for i in phys[::3] + load[::2] + [names.index("torso_j1.offset"), names.index("base.yaw")]:
        h = 1e-10 if i in load else 1e-7
        e = np.zeros_like(x)
        e[i] = h
        fd = (model.residuals(x + e, data) - model.residuals(x - e, data)) / (2 * h)
        assert np.abs(fd - J[:, :, i]).max() <= 1e-6 * max(1.0, np.abs(J[:, :, i]).max()), names[i]


@pytest.fixture(scope="module")
def calibrations(humanoid, tmp_path_factory):
    """The humanoid calibrated with the gravity terms and with geometry alone (no group selection)."""
    from pipeline.calibrate import calibrate
    from pipeline.identify.least_squares import FitOptions

    rec, _ = humanoid
    d = tmp_path_factory.mktemp("cal")
    phys = calibrate(rec, d / "phys", FitOptions(), select_groups=False, physics="joint-compliance,lateral-compliance")
    geo = calibrate(rec, d / "geo", FitOptions(), select_groups=False, physics="none")
    return d, phys, geo


@pytest.mark.extended  # `make test-extended`: two physics calibrations of 160 postures; CI keeps test_physics_whole, test_physics_run
def test_stiffness_recovered_and_held_out_at_the_noise_floor(humanoid, calibrations):
    """With the gravity terms: every true stiffness within 2σ, held-out at the noise floor; geometry
    alone is clearly worse on the same rows and split."""
    rec, truth = humanoid
    tmp_path, phys, geo = calibrations
    noise = truth["noise_m"]
    assert phys["holdout_rms_m"] < 1.3 * noise, phys["holdout_rms_m"]
    assert geo["holdout_rms_m"] > 3 * phys["holdout_rms_m"], (geo["holdout_rms_m"], phys["holdout_rms_m"])
    p = {r["name"]: r for r in phys["parameters"]}
    for joint, c in truth["compliance"].items():
        r = p[f"{joint}.compliance"]
        assert r["identifiable"] and abs(r["estimate"] - c) <= 2 * r["std"] + 1e-12, (joint, r, c)
    for joint, c in truth["lateral"].items():
        for a in (1, 2):
            r = p[f"{joint}.lateral{a}"]
            assert abs(r["estimate"] - c) <= 2 * r["std"] + 1e-12, (joint, a, r, c)
    side = (tmp_path / "phys" / "model.physics.yaml").read_text()
    assert "torso_j1" in side and "stiffness_Nm_per_rad" in side
    model = json.loads((tmp_path / "phys" / "model.json").read_text())
    assert model["kind"] == "urdf_tree" and model["physics"]["terms"]


@pytest.mark.parametrize("args, message", [
    (("--coupled", "torso_j3=-torso_j1-nowhere"), "unknown joint 'nowhere'"),
    (("--coupled", "torso_j3=-torso_j3"), "driven by itself"),
    (("--coupled", "torso_j3=-torso_j1", "--coupled", "torso_j1=torso_j3"), "itself coupled"),
    (("--tip", "nowhere=rx,ry,rz"), "'nowhere' is not in the URDF"),  # its own columns: the link is what is wrong
])
def test_bad_tree_input_is_one_line(humanoid, tmp_path, args, message):
    rec, _ = humanoid
    d = rec.parent / "data"
    tips = TIPS if "--tip" not in args else ("--tip", "left_hand=lx,ly,lz")
    r = run_cli("import", "csv", d / "postures.csv", "--urdf", d / "humanoid.urdf", "--root", "base", *tips, *args,
                "--measure", "point", "--out", tmp_path / "x.mcap")
    assert r.returncode == 2 and message in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_gravity_terms_need_inertials_and_known_payload_links(humanoid, tmp_path):
    rec, _ = humanoid
    d = rec.parent / "data"
    bare = tmp_path / "bare.urdf"
    joints, links = hu.humanoid()
    bare.write_text(hu.urdf_text(joints, [hu.Link(lk.name) for lk in links]))
    out = tmp_path / "bare.mcap"
    assert run_cli("import", "csv", d / "postures.csv", "--urdf", bare, "--root", "base", *TIPS, *COUPLED,
                   "--measure", "point", "--out", out).returncode == 0
    r = run_cli("calibrate", out, "--out", tmp_path / "c", "--physics", "joint-compliance")
    assert r.returncode == 2 and "<inertial>" in r.stderr and "Traceback" not in r.stderr, r.stderr
    r = run_cli("calibrate", rec, "--out", tmp_path / "c2", "--payload", "2@nowhere")
    assert r.returncode == 2 and "'nowhere' is not in the URDF" in r.stderr and "Traceback" not in r.stderr, r.stderr


@pytest.mark.extended  # `make test-extended`: two physics calibrations of 160 postures; CI keeps test_physics_whole, test_physics_run
def test_evaluate_carries_the_physics_to_a_new_session(humanoid, calibrations, tmp_path):
    """`robocal evaluate` applies the calibrated model, physics included, to another session of the same
    robot without refitting: the 3-D error stays at the noise floor; the geometry-only calibration's does not."""
    rec, truth = humanoid
    cal, _, _ = calibrations
    d = hu.write(tmp_path / "s2", seed=11, n=80, noise_m=2e-4, session=2)
    rec2 = tmp_path / "s2.mcap"
    assert run_cli("import", "csv", d / "postures.csv", "--urdf", d / "humanoid.urdf", "--root", "base", *TIPS,
                   *COUPLED, "--measure", "point", "--out", rec2).returncode == 0
    figures = {}
    for name in ("phys", "geo"):
        r = run_cli("evaluate", cal / name, rec2, "--out", tmp_path / f"ev_{name}")
        assert r.returncode == 0, r.stderr
        (doc,) = json.loads((tmp_path / f"ev_{name}" / "evaluation.json").read_text())["recordings"]
        figures[name] = doc["rms_3d_m"]
    floor = np.sqrt(3) * truth["noise_m"]
    assert figures["phys"] < 1.3 * floor, figures
    assert figures["geo"] > 3 * figures["phys"], figures


def test_tree_recording_carries_tf_for_every_tip(humanoid):
    """The imported tree recording's /tf (read with the mcap library, not robocal's reader) composes, root →
    each hand, to yourdfpy's forward kinematics of the URDF in the same recording, the coupled joint included."""
    yourdfpy = pytest.importorskip("yourdfpy")
    from mcap.reader import make_reader
    from scipy.spatial.transform import Rotation

    rec, _ = humanoid
    with open(rec, "rb") as f:
        reader = make_reader(f)
        urdf_text = next(json.loads(m.data)["data"] for _, _, m in reader.iter_messages(topics=["/robot_description"]))
        first = next(json.loads(m.data) for _, _, m in reader.iter_messages(topics=["/tf"]))
    import io

    urdf = yourdfpy.URDF.load(io.StringIO(urdf_text), load_meshes=False)
    parent = {t["child_frame_id"]: t for t in first["transforms"]}
    assert {"robocal_tool_left_hand", "robocal_tool_right_hand"} <= set(parent)

    def pose(frame):
        T = np.eye(4)
        while frame in parent and parent[frame]["parent_frame_id"] != "robocal_instrument":
            t = parent[frame]
            M = np.eye(4)
            M[:3, :3] = Rotation.from_quat([t["rotation"][k] for k in "xyzw"]).as_matrix()
            M[:3, 3] = [t["translation"][k] for k in "xyz"]
            T = M @ T
            frame = t["parent_frame_id"]
        return T

    model, table = _model(rec, "none")
    cfg = dict(zip(model.kin.joint_names, table["joint_positions"][0]))
    cfg["torso_j3"] = -cfg["torso_j1"] - cfg["torso_j2"]
    urdf.update_cfg(cfg)
    for tip in ("left_hand", "right_hand"):
        np.testing.assert_allclose(pose(tip), urdf.get_transform(tip, "base"), atol=1e-9)
