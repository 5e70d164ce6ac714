"""FIGAROH itself on the shared real datasets' every-5th splits: run in FIGAROH's own virtual environment.

Not a robocal module (it imports no robocal code, and robocal does not depend on FIGAROH): FIGAROH
(`pip install figaroh`, 1.0.x) is installed in a separate venv and this script is run with that venv's Python;
`benchmarks/bench_real_data.py --protocols every5 --figaroh-python …` runs it and prints FIGAROH's figures beside
robocal's default on the same rows.  Per dataset and split (rows 0, 5, 10, … held out and the rest fitted:
``every5``; the complement: those rows fitted, the rest held out: ``complement``), FIGAROH's `BaseCalibration`
is configured as its examples configure the robot (chain, marker, measured components, frames estimated) and
fitted with each estimation method that needs no robot-specific sizes — ``structural`` (its default: the
structural base parameters, fitted freely) and ``map_cv`` (every joint parameter under a Gaussian prior whose
scale is chosen by FIGAROH's own k-fold cross-validation over the training postures) — then its own validation
(`_compute_validation_metrics`: the calibrated model applied to the held-out rows, frames as calibrated, no
refit) gives the figure: the RMS of the norm of the 3-D position error (mm), and its mean.

MATE's planes: FIGAROH's core fits points or poses only; its upstream plane example (`examples/mate/
calibration_plane.py` of figaroh-plus) fits the three planes' known coordinates with FIGAROH's forward
kinematics (`calc_updated_fkm`, full parameters, frames estimated, the base frame regularised with 0.01).  That
protocol is run here with FIGAROH's functions: the figure is the RMS of the plane-normal error (mm), as robocal
reports a plane's residual.

    ../figaroh-venv/bin/python benchmarks/figaroh_every5.py [--data ../shared/real-data] [--only tiago,ur10,mate]

Prints one JSON object per line: {dataset, split, method, n_train, n_test, rms_3d_mm, mean_3d_mm, parameters}.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

warnings.filterwarnings("ignore")

ROOT = Path(__file__).resolve().parents[1]
SPLITS = ("every5", "complement")
METHODS = ("structural", "map_cv")
POINT = {  # dataset → (CSV, URDF, joints, tool frame, marker's reference joint, measured components, base, tool pose)
    "tiago": ("figaroh_tiago_mocap/qualysis_base_hand_calibration.csv", "figaroh_tiago_mocap/tiago_48_schunk.urdf",
              ["torso_lift_joint"] + [f"arm_{i}_joint" for i in range(1, 8)], "wrist_ft_tool_link", "arm_7_joint",
              [True, True, True, False, False, False], [0.0908, 0.08, 0.0, -1.57, 0.0, 0.0],
              [0.2163, 0.03484, 0.004, 0.0, -1.57, -1.57]),
    "ur10": ("figaroh_ur10_pose/calibration.csv", "figaroh_ur10_pose/ur10_robot.urdf",
             ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
              "wrist_3_joint"], "wrist_3_link", "wrist_3_joint", [True] * 6, [0.0] * 6, [0.0] * 6),
    # FIGAROH's TALOS example (figaroh-examples `examples/talos`: its CSV and URDF, not in the shared data; give the
    # folder holding talos_left_arm_02_10_contact.csv and talos_full_v2.urdf with --talos)
    "talos": ("talos_left_arm_02_10_contact.csv", "talos_full_v2.urdf",
              ["torso_1_joint", "torso_2_joint"] + [f"arm_left_{i}_joint" for i in range(1, 8)],
              "gripper_left_base_link", "arm_left_7_joint", [True, True, True, False, False, False], [0.0] * 6,
              [0.0] * 6),
}


def split_rows(n: int, split: str) -> tuple[np.ndarray, np.ndarray]:
    """(fitted rows, held-out rows): rows 0, 5, 10, … held out (``every5``) or fitted (``complement``)."""
    every = np.arange(0, n, 5)
    rest = np.setdiff1d(np.arange(n), every)
    return (rest, every) if split == "every5" else (every, rest)


def bare_urdf(src: Path, out: Path) -> Path:
    """The URDF without its visual and collision elements (their meshes are not shipped with the data)."""
    text = re.sub(r"<(visual|collision)\b.*?</\1>", "", src.read_text(), flags=re.S)
    out.write_text(text)
    return out


def _yaml(name, joints, tool, ref_joint, dof, base_pose, tool_pose, train, test, method) -> str:
    js = ", ".join(f'"{j}"' for j in joints)
    return f"""robot:
  name: "{name}"
  properties:
    joints:
      active_joints: [{js}]
tasks:
  calibration:
    enabled: true
    parameters:
      calibration_level: "full_params"
      include_non_geometric: false
      outlier_threshold: 0.05
      estimation:
        method: "{method}"
    kinematics:
      base_frame: "universe"
      tool_frame: "{tool}"
    measurements:
      markers:
        - name: "marker"
          reference_joint: "{ref_joint}"
          measurable_dof: [{", ".join("true" if d else "false" for d in dof)}]
          sensor_type: "mocap"
      poses:
        base_pose: {list(base_pose)}
        tool_pose: {list(tool_pose)}
    data:
      source_file: "{train}"
      validation_data_file: "{test}"
      number_of_samples: 500
"""


def run_point(data: Path, name: str, split: str, method: str, tmp: Path) -> dict:
    """FIGAROH's calibration of a point / pose dataset on one split, validated on the held-out rows."""
    from figaroh.calibration.base_calibration import BaseCalibration
    from figaroh.tools.robot import load_robot

    csv, urdf, joints, tool, ref, dof, base_pose, tool_pose = POINT[name]
    lines = (data / csv).read_text().splitlines()
    header, rows = lines[0], lines[1:]
    fit, held = split_rows(len(rows), split)
    train, test = tmp / f"{name}_{split}_train.csv", tmp / f"{name}_{split}_test.csv"
    train.write_text("\n".join([header] + [rows[i] for i in fit]) + "\n")
    test.write_text("\n".join([header] + [rows[i] for i in held]) + "\n")
    cfg = tmp / f"{name}_{split}_{method}.yaml"
    cfg.write_text(_yaml(name, joints, tool, ref, dof, base_pose, tool_pose, train, test, method))
    robot = load_robot(str(bare_urdf(data / urdf, tmp / f"{name}.urdf")), load_by_urdf=True)

    class Calibration(BaseCalibration):  # FIGAROH's default cost (its log-map residuals, unit weighting)
        pass

    c = Calibration(robot, str(cfg))
    c.calib_config["known_baseframe"] = False  # as FIGAROH's examples: the frames are estimated
    c.calib_config["known_tipframe"] = False
    c.initialize()
    c.solve(enable_logging=False)
    m = c._compute_validation_metrics()
    assert m["validation_source"] == "validation_data", m["validation_source"]
    pos = np.asarray([m["error_fitted_per_dof"][k] for k in ("X (mm)", "Y (mm)", "Z (mm)")], float)
    norm = np.sqrt(np.sum(pos**2, axis=0))
    return {"rms_3d_mm": float(np.sqrt(np.mean(norm**2))), "mean_3d_mm": float(np.mean(norm)),
            "rms_3d_mm_figaroh": float(m["pos_rmse_calibrated_mm"]), "n_train": len(fit), "n_test": len(held),
            "parameters": len(c.calib_config["param_name"])}


def run_mate(data: Path, split: str, tmp: Path) -> dict:
    """FIGAROH's plane protocol for MATE (module docstring) on one split: each plane's rows split alike."""
    from scipy.optimize import least_squares

    from figaroh.calibration.calibration_tools import calc_updated_fkm
    from figaroh.calibration.base_calibration import BaseCalibration
    from figaroh.tools.robot import load_robot

    d = data / "figaroh_mate_planes"
    robot = load_robot(str(bare_urdf(d / "mate.urdf", tmp / "mate.urdf")), load_by_urdf=True)
    joints = ["q_1", "q_2", "q_3"]
    planes = []
    for k, axis in enumerate("xyz"):
        lines = (d / f"10_points_{axis}.csv").read_text().splitlines()
        header, rows = lines[0], lines[1:]
        fit, held = split_rows(len(rows), split)
        dof = [i == k for i in range(3)] + [False] * 3
        parts = {}
        for part, idx in (("train", fit), ("test", held)):
            # FIGAROH's CSV reader wants x1,y1,z1: the plane's coordinate in its own column, the others unused (0)
            cols = header.split(",")
            out = ["x1,y1,z1," + ",".join(joints)]
            for i in idx:
                v = dict(zip(cols, rows[i].split(",")))
                xyz = ["0", "0", "0"]
                xyz[k] = v[f"{axis}1"]
                out.append(",".join(xyz + [str(np.deg2rad(float(v[j]))) for j in joints]))
            p = tmp / f"mate_{axis}_{split}_{part}.csv"
            p.write_text("\n".join(out) + "\n")
            parts[part] = p
        cfg = tmp / f"mate_{axis}_{split}.yaml"
        cfg.write_text(_yaml("mate", joints, "end_effector", "q_3", dof, [0.0] * 6, [0.0] * 6, parts["train"],
                             parts["test"], "structural").replace('"universe"', '"Base"'))
        c = BaseCalibration.__new__(BaseCalibration)
        BaseCalibration.__init__(c, robot, str(cfg))
        c.calib_config["known_baseframe"] = False
        c.calib_config["known_tipframe"] = False
        c.load_data_set()
        c._load_validation_data(str(parts["test"]))
        planes.append(c)
    ref = BaseCalibration.__new__(BaseCalibration)  # the parameters of the three planes together (upstream: xyz)
    cfg = tmp / f"mate_xyz_{split}.yaml"
    cfg.write_text(_yaml("mate", joints, "end_effector", "q_3", [True] * 3 + [False] * 3, [0.0] * 6, [0.0] * 6,
                         tmp / f"mate_x_{split}_train.csv", tmp / f"mate_x_{split}_test.csv", "structural"
                         ).replace('"universe"', '"Base"'))
    BaseCalibration.__init__(ref, robot, str(cfg))
    ref.calib_config["known_baseframe"] = False
    ref.calib_config["known_tipframe"] = False
    ref.load_data_set()
    ref.create_param_list()  # full parameters of the chain, frames estimated
    names = ref.calib_config["param_name"]
    for c in planes:
        c.calib_config["param_name"] = names

    def predicted(var, c, q):
        return calc_updated_fkm(c.model, c.data, var, q, dict(c.calib_config, NbSample=len(q)))

    def cost(var):  # the planes' known coordinates; the base frame regularised (0.01), as upstream
        res = [c.PEE_measured - predicted(var, c, c.q_measured) for c in planes]
        return np.concatenate(res + [np.sqrt(0.01) * var[:6]])

    sol = least_squares(cost, np.zeros(len(names)), method="lm")
    err = np.concatenate([c._PEE_val - predicted(sol.x, c, c._q_val) for c in planes])
    return {"rms_3d_mm": float(np.sqrt(np.mean(err**2)) * 1e3), "mean_3d_mm": float(np.mean(np.abs(err)) * 1e3),
            "n_train": int(sum(len(c.q_measured) for c in planes)),
            "n_test": int(sum(len(c._q_val) for c in planes)), "parameters": len(names),
            "figure": "RMS of the plane-normal error"}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "real-data")
    ap.add_argument("--only", default="tiago,ur10,mate")
    ap.add_argument("--talos", type=Path, default=None, help="folder with FIGAROH's TALOS example files (--only talos)")
    a = ap.parse_args()
    import contextlib
    import io

    with tempfile.TemporaryDirectory() as t:
        tmp = Path(t)
        for name in a.only.split(","):
            for split in SPLITS:
                for method in (METHODS if name in POINT else ("plane protocol",)):
                    try:
                        with contextlib.redirect_stdout(io.StringIO()):  # FIGAROH's own report
                            r = (run_point(a.talos if name == "talos" else a.data, name, split, method, tmp)
                                 if name in POINT
                                 else run_mate(a.data, split, tmp))
                    except Exception as e:  # a method FIGAROH refuses on this split (too few rows): said, not hidden
                        r = {"error": f"{type(e).__name__}: {str(e).splitlines()[-1][:300]}"}
                    print(json.dumps({"dataset": name, "split": split, "method": method, **r}), flush=True)


if __name__ == "__main__":
    sys.exit(main())
