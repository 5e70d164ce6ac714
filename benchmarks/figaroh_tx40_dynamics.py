"""FIGAROH's own Staubli TX40 dynamics identification, run by FIGAROH on figaroh-examples' TX40 log (a
side-by-side column of benchmarks/bench_tx40_dynamics.py).  Run with the Python of a venv holding `figaroh`
(never robocal's); robocal's code is not imported.

    FIGAROH_PYTHON benchmarks/figaroh_tx40_dynamics.py --examples CHECKOUT MODE

CHECKOUT is a figaroh-examples tree holding ``examples/staubli_TX40`` (its ``utils/staubli_tx40_tools.py``
TX40Identification, ``config/TX40_config.yaml``, ``urdf/``, ``data/``).  The set-up is upstream
identification.py's (load_robot, TX40Identification(robot, config), initialize(truncate), solve(decimate=True,
wls=False)) in a temporary copy of that folder (the URDF without <visual>/<collision>: no meshes needed).  MODE:

- ``train``: every row, upstream's own run: its training RMSE (N·m, on its decimated torques) and base
  parameters;
- ``split A B C D``: fit rows [A, B), then FIGAROH's own validation path on rows [C, D) (the TX40 loader given
  those rows: its motor → joint conversion, 100 Hz filtering, torque conversion, border trimming).

Prints one JSON line: per joint and pooled held-out RMS (N·m), base parameters, training RMSE, and the rows its
validation path scored (it trims 5 × the filter order of torque rows at each end and pairs the rest with the
positions from the segment's start: a torque row i is scored against position row i − 20).
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

import pandas as pd

JOINTS = [f"joint_{i}" for i in range(1, 7)]


def workspace(examples: Path, tmp: Path) -> Path:
    """examples/staubli_tx40 of a temporary tree: config, utils, the URDF without meshes, the data linked."""
    src = examples / "examples" / "staubli_TX40"
    tx = tmp / "examples" / "staubli_tx40"  # upstream imports examples.staubli_tx40 (lower case)
    shutil.copytree(src / "config", tx / "config")
    shutil.copytree(examples / "examples" / "templates", tmp / "examples" / "templates")
    # FIGAROH 1.0 refuses the legacy flat config upstream's TX40 still ships: converted by FIGAROH's own tool
    from figaroh.utils.config_migration import main as migrate

    with contextlib.redirect_stdout(io.StringIO()):
        migrate(["--input", str(tx / "config" / "TX40_config.yaml"), "--output", str(tx / "config" / "TX40_unified.yaml")])
    shutil.copytree(src / "utils", tx / "utils")
    (tx / "urdf").mkdir()
    (tx / "data").mkdir()
    for p in (tmp / "examples", tx):
        (p / "__init__.py").touch()
    text = (src / "urdf" / "tx40_mdh_modified.urdf").read_text()
    (tx / "urdf" / "tx40_mdh_modified.urdf").write_text(
        re.sub(r"<visual>.*?</visual>|<collision>.*?</collision>", "", text, flags=re.S))
    for f in ("curr_data.csv", "pos_read_data.csv"):
        os.symlink((src / "data" / f).resolve(), tx / "data" / f)
    return tx


def identification(tmp: Path):
    sys.path.insert(0, str(tmp))
    from examples.staubli_tx40.utils.staubli_tx40_tools import TX40Identification

    class Rows(TX40Identification):
        """Upstream's adapter whose loader reads another folder's files when asked (its validation path)."""

        def load_trajectory_data(self, data_source=None):
            if data_source is None:
                return super().load_trajectory_data()
            here = os.getcwd()
            try:
                os.chdir(data_source)
                return super().load_trajectory_data()
            finally:
                os.chdir(here)

    return Rows


def run(Rows, tx: Path, truncate, validation=None):
    from figaroh.tools.robot import load_robot

    robot = load_robot(str(tx / "urdf" / "tx40_mdh_modified.urdf"), load_by_urdf=True, package_dirs=str(tx / "urdf"))
    ident = Rows(robot, str(tx / "config" / "TX40_unified.yaml"))
    ident.identif_config["validation_data_file"] = validation
    ident.initialize(truncate=truncate)
    if validation and not ident._val_available:
        raise RuntimeError(f"validation data not loaded: {validation}")
    ident.solve(decimate=True, plotting=False, save_results=False, wls=False)
    return ident


def write_rows(tx: Path, folder: Path, a: int, b: int) -> None:
    (folder / "data").mkdir(parents=True, exist_ok=True)
    for f in ("curr_data.csv", "pos_read_data.csv"):
        pd.read_csv(tx / "data" / f).iloc[a:b].to_csv(folder / "data" / f, index=False)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--examples", type=Path, required=True, help="figaroh-examples tree with examples/staubli_TX40")
    ap.add_argument("mode", nargs="+", help="train | split A B C D")
    args = ap.parse_args()
    mode = args.mode[0]
    out: dict = {"mode": mode}
    quiet = contextlib.redirect_stdout(io.StringIO())
    with tempfile.TemporaryDirectory() as tmp:
        tx = workspace(args.examples.resolve(), Path(tmp))
        Rows = identification(Path(tmp))
        os.chdir(tx)  # upstream's loader reads data/*.csv from the working directory
        if mode == "train":
            with quiet:
                ident = run(Rows, tx, None)
            out.update(train_rmse=float(ident.rms_error), n_base=int(len(ident.phi_base)),
                       correlation=float(ident.correlation), n_samples=int(ident.num_samples),
                       ts=float(ident.identif_config["ts"]),
                       reduction_ratio=[float(r) for r in ident.identif_config["reduction_ratio"]],
                       cutoff_hz=float(ident.filter_config["filter_params"]["f_butter"]))
        elif mode == "split":
            a, b, c, d = (int(x) for x in args.mode[1:5])
            held = Path(tmp) / "held"
            write_rows(tx, held, c, d)
            with quiet:
                ident = run(Rows, tx, (a, b), validation=str(held))
                m = ident._compute_validation_metrics()
            per = {j: m["per_joint"][j]["rmse_identified"] for j in JOINTS}
            nb = 5 * 4  # upstream's _remove_border_effects: 5 × the Butterworth order, each end
            out.update(train_rmse=float(ident.rms_error), n_base=int(len(ident.phi_base)), per_joint=per,
                       pooled=float(m["rmse_identified"]), nominal_pooled=float(m["rmse_nominal"]),
                       nominal_per_joint={j: m["per_joint"][j]["rmse_nominal"] for j in JOINTS},
                       fit_rows=[a, b], scored_torque_rows=[c + nb, d - nb], n_scored=int(ident._val_num_samples))
        else:
            raise SystemExit(f"unknown mode {mode!r}: train | split A B C D")
    print(json.dumps(out))


if __name__ == "__main__":
    main()
