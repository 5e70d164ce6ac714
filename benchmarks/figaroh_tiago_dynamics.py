"""FIGAROH's own TIAGo dynamics identification, run by FIGAROH on the shared files (a side-by-side column of
benchmarks/bench_dynamics.py).  Run with the Python of a venv holding `figaroh` (never robocal's), from a
checkout of figaroh-examples (its `examples/tiago/utils/tiago_tools.py` TiagoIdentification and
`examples/templates/`); robocal's code is not imported.

    FIGAROH_PYTHON benchmarks/figaroh_tiago_dynamics.py --examples CHECKOUT --data ../shared/real-data/figaroh_tiago_dynamics MODE

The set-up is upstream identification.py's (configure_identification: the config's drive table, the active
joints, the data files; initialize(truncate); solve(decimate=True); wls from the config), with the protocol's
config (`upstream_config.yaml`) and URDF (tiago_48_hey5.urdf, its <visual>/<collision> stripped in a temporary
copy: the meshes are not shipped).  MODE:

- ``train``: rows [921, 6791), the published training RMSE (0.884, 57 base parameters);
- ``split``: fit [921, 4900), FIGAROH's own validation path on rows [4900, 6791) written to their own folder;
- ``cv K GUARD``: contiguous-block cross-validation over [921, 6791) — block k masked out of the fit with GUARD
  samples either side (FIGAROH's TrajectoryData mask), then scored through its validation path with a mask
  keeping only the block (``--folds 0,1``: only those blocks; ``merge A.json B.json`` pools runs of disjoint
  blocks into one cross-validation).

Prints one JSON line: per fitted joint and pooled held-out RMS (N·m), base parameters, training RMSE.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import re
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

FIT = ["arm_1_joint", "arm_2_joint", "arm_3_joint", "arm_4_joint"]
LO, HI = 921, 6791


def workspace(examples: Path, data: Path, tmp: Path) -> Path:
    """examples/tiago of a temporary tree: config (the protocol's, its templates beside it), the URDF without
    meshes, the data files linked."""
    tiago = tmp / "examples" / "tiago"
    (tiago / "config").mkdir(parents=True)
    (tiago / "urdf").mkdir()
    (tiago / "data" / "identification" / "dynamic").mkdir(parents=True)
    shutil.copytree(examples / "examples" / "templates", tmp / "examples" / "templates")
    shutil.copy(data / "upstream_config.yaml", tiago / "config" / "tiago_unified_config.yaml")
    # the parser resolves a template's own `extends:` beside the config that names it
    shutil.copy(examples / "examples" / "templates" / "base_robot_config.yaml", tiago / "config")
    text = (data / "tiago_48_hey5.urdf").read_text()
    text = re.sub(r"<visual>.*?</visual>|<collision>.*?</collision>", "", text, flags=re.S)
    (tiago / "urdf" / "tiago_48_hey5.urdf").write_text(text)
    for k in ("position", "velocity", "effort"):
        os.symlink((data / "dynamic" / f"tiago_{k}.csv").resolve(),
                   tiago / "data" / "identification" / "dynamic" / f"tiago_{k}.csv")
    return tiago


def identification(examples: Path):
    sys.path.insert(0, str(examples))
    from examples.tiago.utils.tiago_tools import TiagoIdentification
    from figaroh.utils.config_parser import UnifiedConfigParser

    class Masked(TiagoIdentification):
        """Upstream's adapter with a valid-sample mask per data source (FIGAROH's TrajectoryData.mask)."""

        sample_masks: dict = {}

        def load_trajectory_data(self, data_source=None):
            traj = super().load_trajectory_data(data_source)
            m = self.sample_masks.get(data_source or "training")
            return traj if m is None else traj.with_mask(m)

    def configure(ident):  # upstream identification.py's configure_identification and load_drives
        ps = ident.identif_config
        drives = UnifiedConfigParser(str(ident._config_file_path)).parse()["robot"]["properties"]["mechanics"]["drives"]
        ps["reduction_ratio"] = {j: d["reduction_ratio"] for j, d in drives.items()}
        ps["kmotor"] = {j: d["kmotor"] for j, d in drives.items()}
        ps["active_joints"] = ps.get("active_joints", [])
        ps["act_Jid"] = [ident.model.getJointId(i) for i in ps["active_joints"]]
        ps["act_J"] = [ident.model.joints[jid] for jid in ps["act_Jid"]]
        ps["act_idxq"] = [J.idx_q for J in ps["act_J"]]
        ps["act_idxv"] = [J.idx_v for J in ps["act_J"]]
        ps["pos_data"] = "data/identification/dynamic/tiago_position.csv"
        ps["vel_data"] = "data/identification/dynamic/tiago_velocity.csv"
        ps["torque_data"] = "data/identification/dynamic/tiago_effort.csv"

    return Masked, configure


def run(Masked, configure, tiago: Path, truncate, validation=None, masks=None):
    from figaroh.tools.robot import load_robot

    robot = load_robot(str(tiago / "urdf" / "tiago_48_hey5.urdf"), load_by_urdf=True,
                       package_dirs=str(tiago / "urdf"))
    ident = Masked(robot, str(tiago / "config" / "tiago_unified_config.yaml"))
    ident.sample_masks = masks or {}
    configure(ident)
    ident.identif_config["validation_data_file"] = validation
    ident.initialize(truncate=truncate)
    if validation and not ident._val_available:
        raise RuntimeError(f"validation data not loaded: {validation}")
    ident.solve(decimate=True, plotting=False, save_results=False, html_report=False,
                wls=bool(ident.identif_config.get("wls", False)))
    return ident


def write_rows(src: Path, folder: Path, a: int, b: int) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for k in ("position", "velocity", "effort"):
        pd.read_csv(src / f"tiago_{k}.csv").iloc[a:b].to_csv(folder / f"tiago_{k}.csv", index=False)


def pooled(per: dict, keys) -> float:
    return float(np.sqrt(np.mean([per[k] ** 2 for k in keys])))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--examples", type=Path, required=True, help="figaroh-examples checkout (the repository root)")
    ap.add_argument("--data", type=Path, required=True, help="the shared figaroh_tiago_dynamics folder")
    ap.add_argument("mode", nargs="+", help="train | split | cv K GUARD")
    ap.add_argument("--folds", help="cv: only these blocks (comma-separated, from 0); `merge` pools such runs")
    args = ap.parse_args()
    mode = args.mode[0]
    if mode == "merge":  # merge FILE…: cv runs of disjoint blocks pooled as one cross-validation (no FIGAROH run)
        out = {}
        folds = [fd for path in args.mode[1:] for fd in json.loads(Path(path).read_text())["folds"]]
        n = {tuple(fd["rows"]): fd["rows"][1] - fd["rows"][0] for fd in folds}
        if len(n) != len(folds):
            raise SystemExit("merge: a block appears in two runs")
        per = {j: float(np.sqrt(sum(fd["per_joint"][j] ** 2 * n[tuple(fd["rows"])] for fd in folds) / sum(n.values())))
               for j in FIT}
        out.update(mode="cv", k=len(folds), per_joint=per, pooled=pooled(per, FIT), pooled_2_4=pooled(per, FIT[1:]),
                   folds=sorted(folds, key=lambda fd: fd["rows"]))
        print(json.dumps(out))
        return
    Masked, configure = identification(args.examples.resolve())
    src = args.data.resolve() / "dynamic"
    out: dict = {"mode": mode}
    quiet = contextlib.redirect_stdout(io.StringIO())
    with tempfile.TemporaryDirectory() as tmp:
        tiago = workspace(args.examples.resolve(), args.data.resolve(), Path(tmp))
        os.chdir(tiago)
        if mode == "train":
            with quiet:
                ident = run(Masked, configure, tiago, (LO, HI))
            out.update(train_rmse=float(ident.rms_error), n_base=int(len(ident.phi_base)))
        elif mode == "split":
            write_rows(src, Path(tmp) / "held", 4900, HI)
            with quiet:
                ident = run(Masked, configure, tiago, (LO, 4900), validation=str(Path(tmp) / "held"))
                m = ident._compute_validation_metrics()
            per = {j: m["per_joint"][j]["rmse_identified"] for j in FIT}
            out.update(train_rmse=float(ident.rms_error), n_base=int(len(ident.phi_base)), per_joint=per,
                       pooled=float(m["rmse_identified"]), pooled_2_4=pooled(per, FIT[1:]),
                       nominal_pooled=float(m["rmse_nominal"]))
        elif mode == "cv":
            k, guard = int(args.mode[1]), int(args.mode[2])
            only = [int(x) for x in args.folds.split(",")] if args.folds else list(range(k))
            n = HI - LO
            edges = np.linspace(0, n, k + 1).round().astype(int)
            total = len(pd.read_csv(src / "tiago_position.csv", usecols=[0]))
            write_rows(src, Path(tmp) / "held", LO, HI)
            sq, count, folds = {j: 0.0 for j in FIT}, 0, []
            for f in only:
                a, b = int(edges[f]), int(edges[f + 1])
                train = np.zeros(total, bool)
                train[LO:HI] = True
                train[LO + max(a - guard, 0):LO + b + guard] = False
                held = np.zeros(n, bool)
                held[a:b] = True
                with quiet:
                    ident = run(Masked, configure, tiago, (LO, HI), validation=str(Path(tmp) / "held"),
                                masks={"training": train, str(Path(tmp) / "held"): held})
                    m = ident._compute_validation_metrics()
                per = {j: m["per_joint"][j]["rmse_identified"] for j in FIT}
                for j in FIT:
                    sq[j] += per[j] ** 2 * (b - a)
                count += b - a
                folds.append({"rows": [LO + a, LO + b], "per_joint": per, "pooled": float(m["rmse_identified"])})
            per = {j: float(np.sqrt(sq[j] / count)) for j in FIT}
            out.update(k=k, guard=guard, per_joint=per, pooled=pooled(per, FIT), pooled_2_4=pooled(per, FIT[1:]),
                       folds=folds)
        else:
            raise SystemExit(f"unknown mode {mode!r}: train | split | cv K GUARD | merge FILE…")
    print(json.dumps(out))


if __name__ == "__main__":
    main()
