"""Dynamics identification on a robot robocal was not built on — figaroh-examples' real Staubli TX40 excitation
log — side by side with FIGAROH on the same rows and the same contiguous splits, per joint and pooled (N·m).

    PYTHONPATH=. .venv/bin/python benchmarks/bench_tx40_dynamics.py --tx40 DIR
    PYTHONPATH=. .venv/bin/python benchmarks/bench_tx40_dynamics.py --tx40 DIR --figaroh ../figaroh-venv/bin/python
    PYTHONPATH=. .venv/bin/python benchmarks/bench_tx40_dynamics.py --tx40 DIR \\
        --figaroh-json benchmarks/peer_figures/figaroh_tx40_dynamics.json

DIR is figaroh-examples' ``examples/staubli_TX40`` folder (``data/pos_read_data.csv``, ``data/curr_data.csv``,
``urdf/tx40_mdh_modified.urdf``; default $ROBOCAL_TX40).  The log: 45 000 rows at 5 kHz (FIGAROH's ts =
0.2 ms, no time column), motor-side encoder angles and motor currents of six joints, reductions [32, 32, 45,
−48, 45, 32], motor 6 turning joints 5 and 6.  robocal reads it as the guide's `robocal import csv` does
(`--rate 5000`, `--position-scale` 1/N, `--position-mix joint_6=joint_6-32/45*joint_5`, `--position-offset`
joint_2 −π/2, joint_3 +π/2, `--effort-scale` N, `--effort-mix joint_5=45*joint_5+32*joint_6`: FIGAROH's own
conversion, its motor constant 1 N·m/A) and identifies as `robocal run` does (the log decimated to 500 Hz,
the held-out model choice).  FIGAROH (`benchmarks/figaroh_tx40_dynamics.py`, run by FIGAROH's Python): its
TX40Identification with its config, fitted on the same rows, scored by its own validation path.

Scored: the raw converted torque at the recorded 5 kHz, on the torque rows FIGAROH's validation path scores
(it trims 20 rows at each end of the held-out segment), robocal's prediction without refitting; beside them the
torque's content above 100 Hz alone (FIGAROH's cut-off: what no smooth model of the motion predicts).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import time
from pathlib import Path

import numpy as np

from pipeline.dynamics import effort as E
from pipeline.dynamics import identify as I
from pipeline.dynamics import rigid_body as RB
from pipeline.dynamics import signals
from pipeline.importers import joint_readings as JR
from pipeline.importers.csv_effort import read_logs
from pipeline.models import urdf as U

JOINTS = [f"joint_{i}" for i in range(1, 7)]
RATE_HZ = 5000.0
POSITION_SCALE = "joint_1=1/32,joint_2=1/32,joint_3=1/45,joint_4=-1/48,joint_5=1/45,joint_6=1/32"
POSITION_MIX = "joint_6=joint_6-32/45*joint_5"
POSITION_OFFSET = "joint_2=-pi/2,joint_3=pi/2"
EFFORT_SCALE = "joint_1=32,joint_2=32,joint_3=45,joint_4=-48,joint_5=1,joint_6=32"
EFFORT_MIX = "joint_5=45*joint_5+32*joint_6"
N_ROWS = 45_000
SPLITS = {"forward": (0, 31_500, 31_500, 45_000), "backward": (13_500, 45_000, 0, 13_500)}  # fit [A,B), test [C,D)
BORDER = 20  # FIGAROH's TX40 trims 5 × its Butterworth order of torque rows at each end
FIGAROH_PYTHON = Path(os.environ.get("FIGAROH_PYTHON", "../figaroh-venv/bin/python"))
PEER_JSON = Path(__file__).with_name("peer_figures") / "figaroh_tx40_dynamics.json"


def load(folder: Path):
    """(t, q, τ, rigid body, coupled motors) read as `robocal import csv` reads them with the guide's words."""
    desc = U.read(folder / "urdf" / "tx40_mdh_modified.urdf", "base_link", "link_6")
    J = desc.joint_names
    pos = JR.declaration(JR.PositionSpec((POSITION_SCALE,), (POSITION_OFFSET,), (POSITION_MIX,)), J)
    L = read_logs(folder / "data" / "pos_read_data.csv", desc, None, folder / "data" / "curr_data.csv",
                  rate=RATE_HZ, positions=pos)
    doc = E.declaration(J, E.parse_pairs("--effort-scale", [EFFORT_SCALE], J), {}, E.parse_mix([EFFORT_MIX], J), [])
    return L["t_s"], L["q"], E.to_torque(L["effort"], doc, J), RB.build(desc.urdf, J), JR.coupled_motors(pos, J)


def figures(r: np.ndarray) -> dict:
    out = dict(zip(JOINTS, np.sqrt(np.mean(r**2, 0)).tolist()))
    out["pooled"] = float(np.sqrt(np.mean(r**2)))
    return out


def show(title: str, cols: dict[str, dict]) -> None:
    keys = [*JOINTS, "pooled"]
    print(f"\n{title}")
    print(f"{'':24s}" + "".join(f"{k:>10s}" for k in keys))
    for name, d in cols.items():
        print(f"{name:24s}" + "".join(f"{d[k]:10.3f}" if d.get(k) is not None else f"{'—':>10s}" for k in keys))


def figaroh_run(python: Path, examples: Path, *mode: str) -> dict:
    script = Path(__file__).with_name("figaroh_tx40_dynamics.py")
    w0 = time.perf_counter()
    r = subprocess.run([str(python), str(script), "--examples", str(examples), *mode], capture_output=True,
                       text=True, check=False, env={**os.environ, "PYTHONWARNINGS": "ignore"})
    if r.returncode:
        raise SystemExit(f"FIGAROH run {' '.join(mode)} failed:\n{r.stderr[-2000:]}")
    print(f"  FIGAROH {' '.join(mode)}: {time.perf_counter() - w0:.0f} s wall", flush=True)
    return json.loads(r.stdout.strip().splitlines()[-1])


def model_rate(t, q, tau, fit):
    """The training rows as `robocal run` models them (decimated to `signals.MODEL_RATE_HZ`)."""
    k = signals.decimation_factor(t)
    td, qd, taud = signals.decimate(t, q, tau, k)
    return I.Data(td, qd, taud, fit, decimation=k)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tx40", type=Path, default=os.environ.get("ROBOCAL_TX40"),
                    help="figaroh-examples' examples/staubli_TX40 folder (env ROBOCAL_TX40)")
    ap.add_argument("--figaroh", type=Path, help="a Python with figaroh: run FIGAROH side by side (≈ 20 s a fit)")
    ap.add_argument("--figaroh-json", type=Path, default=PEER_JSON if PEER_JSON.is_file() else None,
                    help="FIGAROH's figures of an earlier run (default: benchmarks/peer_figures/…)")
    ap.add_argument("--figaroh-save", type=Path, help="write the FIGAROH runs' figures here")
    args = ap.parse_args()
    if args.tx40 is None or not (args.tx40 / "data" / "curr_data.csv").is_file():
        print(f"the TX40 folder is absent ({args.tx40}; give --tx40 or $ROBOCAL_TX40): nothing to compare")
        return
    theirs: dict = {}
    if args.figaroh is not None:
        examples = args.tx40.resolve().parents[1]
        print("running FIGAROH (its own TX40Identification, one fit at a time) …", flush=True)
        theirs["train"] = figaroh_run(args.figaroh, examples, "train")
        for name, rows in SPLITS.items():
            theirs[name] = figaroh_run(args.figaroh, examples, "split", *map(str, rows))
        if args.figaroh_save:
            args.figaroh_save.write_text(json.dumps(theirs, indent=1) + "\n")
    elif args.figaroh_json is not None:
        theirs = json.loads(args.figaroh_json.read_text())
        print(f"FIGAROH's figures from {args.figaroh_json} (a run of benchmarks/figaroh_tx40_dynamics.py)")
    if "train" in theirs:
        tr = theirs["train"]
        print(f"FIGAROH's own run (every row): training RMSE {tr['train_rmse']:.3f} N·m on its decimated torques, "
              f"{tr['n_base']} base parameters, correlation {tr['correlation']:.4f}")

    t, q, tau, rb, motors = load(args.tx40)
    fit = np.ones(len(JOINTS), bool)
    for name, (a, b, c, d) in SPLITS.items():
        w0, c0 = time.perf_counter(), time.process_time()
        data = model_rate(t[a:b], q[a:b], tau[a:b], fit)
        f = I.identify(rb, data, I.candidates_for(data, motors))
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        pred = I.predict(rb, f, t[c:d], q[c:d], fit)
        nominal = I.nominal_torques(rb, I.Data(t[c:d], q[c:d], tau[c:d], fit), fit)
        s = slice(BORDER, (d - c) - BORDER)  # the torque rows FIGAROH's validation path scores
        cols = {"robocal": figures((pred - tau[c:d])[s])}
        if name in theirs:
            cols["FIGAROH 1.0.2 (run)"] = {**theirs[name]["per_joint"], "pooled": theirs[name]["pooled"]}
            cols["FIGAROH nominal"] = {**theirs[name]["nominal_per_joint"], "pooled": theirs[name]["nominal_pooled"]}
        cols["URDF as drawn (robocal)"] = figures((nominal - tau[c:d])[s])
        cols["torque > 100 Hz alone"] = figures((tau[c:d] - signals.lowpass(tau[c:d], RATE_HZ, 100.0))[s])
        show(f"{name} split: fitted on rows [{a}, {b}), predicting torque rows [{c + BORDER}, {d - BORDER}) at 5 kHz "
             "without refitting, raw converted torque (N·m)", cols)
        print(f"  robocal: {f.choice.label()}, {f.base.rank} base parameters; identify (decimated ×{data.decimation} "
              f"to {signals.sample_rate(data.t):.0f} Hz, {data.t.size} samples) {wall:.1f} s wall, {cpu:.1f} s CPU")
        if name in theirs:
            print(f"  FIGAROH: {theirs[name]['n_base']} base parameters, training RMSE {theirs[name]['train_rmse']:.3f} "
                  "N·m (its decimated torques)")

    data = model_rate(t, q, tau, fit)
    g = I.identify(rb, data, I.candidates_for(data, motors))
    show("contiguous-block cross-validation over the whole log (5 blocks, 0.5 s guard; robocal's own, on the "
         "torques decimated to 500 Hz; FIGAROH's TX40 loader cannot mask rows)", {"robocal": figures(g.cv_residuals)})
    print(f"  robocal: {g.choice.label()}, {g.base.rank} base parameters")


if __name__ == "__main__":
    main()
