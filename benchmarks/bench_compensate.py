"""Benchmark: compensating a program of Cartesian targets (arc welder, Delta); target < 1 s for 10 000.

Targets: the nominal model's poses at joint configurations over the arc welder's jig workspace
(approach configurations of a touch-candidate pool, reused cyclically with small joint jitter),
the calibrated model the paper's Table 2 truth (~24 mm of correction).  `--n` sets the size (0: skip).

`--accuracy-seeds N [--first-seed S] [--systems arc-welder,delta,urdf]`: N calibrations per system, each
compensating 1 000 new targets and run on the true robot: true RMS vs the predicted 1σ RMS and the 95 %
bound on one calibration's RMS (docs/guide/compensate.md, "Predicted accuracy").

`--delta-extended N`: only the Delta calibrated with the extended model, N targets (timing, round trip).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from pipeline.compensate.serial import SerialArmKinematics, compensate
from pipeline.models import serial_arm
from pipeline.simulate.arc_welder import IK_SEEDS
from pipeline.systems import arc_welder as aw


def workspace_configs(n: int, seed: int = 0) -> np.ndarray:
    """n joint configurations around the jig (nominal IK of touch candidates, jittered by 0.05 rad)."""
    from pipeline.models.jig import stepped_block
    from pipeline.plan.touch import pool

    nominal = aw.nominal_arm()
    base = pool(nominal, stepped_block(), min(n, 300), seed=seed, margin_m=0.0).q_contact
    rng = np.random.default_rng(seed)
    q = base[np.arange(n) % base.shape[0]] + rng.normal(0, 0.05, (n, base.shape[1]))
    return np.clip(q, nominal.lower, nominal.upper)


FIXTURE = True  # --no-fixture: the fit's covariance alone (the jig taken as exact)


def rms(v: np.ndarray) -> float:
    return float(np.sqrt(np.mean(v**2)))


def judge(f, Jp: np.ndarray, after: np.ndarray, cov: np.ndarray | None = None) -> dict:
    """One calibration: the true RMS 3-D error of its compensated program, the predicted RMS (1σ:
    sqrt of the mean trace of Jp Σ Jpᵀ) and the 95 % bound on one calibration's RMS
    (`pipeline.accuracy.propagate.rms_bound`: generalized χ² of δθ ~ N(0, Σ), σ̂ on its dof)."""
    from pipeline.accuracy.propagate import rms_bound

    Jp = Jp[:, :, f.free]
    cov = f.cov if cov is None else cov
    dof = int(f.residuals_after.size - f.free.sum())
    pred = float(np.sqrt(np.einsum("nip,pq,niq->", Jp, cov, Jp) / Jp.shape[0]))
    return {"true": rms(after), "pred": pred, "bound95": rms_bound(Jp, cov, 0.95, dof)}


def arc_welder_seed(s: int) -> tuple[float, dict]:
    """Arc welder: Table 2 truth, a default 100-contact campaign (seed s) with noise, 1 000 pose
    targets around the jig (nominal joints given as hints)."""
    from pipeline.accuracy.propagate import fixture_covariance
    from pipeline.identify.least_squares import fit
    from pipeline.models.jig import stepped_block
    from pipeline.plan.arc_welder import table_of
    from pipeline.simulate.arc_welder import Campaign, Noise, simulate

    nominal, truth = aw.nominal_arm(), aw.reference_truth()
    kin, model = SerialArmKinematics.of(nominal), aw.TouchModel(nominal)
    q = workspace_configs(1000, seed=99)
    R, p = serial_arm.forward(nominal.vector(), q)
    jig = stepped_block()
    table = table_of(simulate(nominal, truth, jig, Campaign(contacts=100, seed=s), Noise()))
    f = fit(model, table)
    c = compensate(kin, nominal.vector(), f.x, p, R, IK_SEEDS, hint=q)
    # the jig's machining tolerance (per face, shared by its contacts) on top of σ̂²(JᵀJ)⁻¹
    Jf = model.jacobian(f.x, table).reshape(-1, f.x.size)[:, f.free]
    cov = f.cov + fixture_covariance(Jf, table["face"], 1, jig.tolerance_m) if FIXTURE else f.cov
    ok = c.status == "ok"
    after = np.linalg.norm(serial_arm.tip_position(truth.vector(), c.q[ok]) - p[ok], axis=1)
    before = np.linalg.norm(serial_arm.tip_position(truth.vector(), q) - p, axis=1)
    return rms(before), judge(f, model.points(f.x, {"joint_positions": c.q[ok]})[1], after, cov) | {"ok": int(ok.sum())}


def delta_seed(s: int) -> tuple[float, dict]:
    """Delta: random truth (seed s), the paper's 27-point grid with its own tracker noise (campaign seed s),
    1 000 new targets over the workspace in {T}."""
    from pipeline.compensate import delta as cd
    from pipeline.identify.least_squares import fit
    from pipeline.models import delta as dm
    from pipeline.models.delta import Delta
    from pipeline.simulate import delta_tracker as dsim
    from pipeline.systems import delta_tracker as dt

    tr = dsim.random_truth(np.random.default_rng(s))
    sm = dsim.simulate(Delta(), tr, dsim.Campaign(seed=s), dsim.Noise())
    model = dt.TrackerModel()
    f = fit(model, {"joint_positions": sm.q, "point": sm.point_t})
    val = dsim.simulate(Delta(), tr, dsim.Campaign(points=1000, seed=1000 + s), dsim.Noise(scale=0.0))
    Rt, t = dt.registration_matrix(tr.registration)

    def true_t(theta):
        return (dm.full_forward(Delta(), tr.beta, theta, extended=True)[0] - t) @ Rt

    targets = true_t(val.q)
    c = cd.compensate(model, f.nominal, f.x, targets)
    ok = c.status == "ok"
    after = np.linalg.norm(true_t(c.q[ok]) - targets[ok], axis=1)
    before = np.linalg.norm(true_t(c.q_nominal[ok]) - targets[ok], axis=1)
    return rms(before), judge(f, model.points(f.x, {"joint_positions": c.q[ok]})[1], after) | {"ok": int(ok.sum())}


_REAL = Path(__file__).resolve().parents[2] / "shared" / "real-data"  # ../shared/real-data of the checkout
UR10 = _REAL / "figaroh_ur10_pose" / "ur10_robot.urdf"


def urdf_seed(s: int, error_m: float = 4e-3, error_rad: float = 8e-3) -> tuple[float, dict]:
    """A URDF arm (the UR10 of ../shared/real-data, else the tests' 6R) with random joint-origin errors
    (N(0, 4 mm) and N(0, 8 mrad): ~20 mm at the tool, seed s), 100 tracker points at random
    configurations (50 µm noise per axis) in the robot's base frame, 1 000 new pose targets at random
    configurations over the whole joint range (nominal joints given as hints)."""
    from pipeline.compensate.serial import ChainKinematics
    from pipeline.identify.least_squares import FitOptions, fit
    from pipeline.measurements.point import PointModel
    from pipeline.models import urdf
    from pipeline.models.urdf_arm import UrdfArm
    from pipeline.plan.urdf_robot import configurations
    from pipeline.simulate.urdf_robot import campaign, random_truth

    if UR10.is_file():
        arm = UrdfArm(urdf.read(UR10, "base_link", "wrist_3_link"))
    else:
        sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
        from test_compensate import URDF

        arm = UrdfArm(urdf.parse(URDF, "base", "tool"))
    if not getattr(urdf_seed, "said", False):  # once per run: which arm the figures are of
        urdf_seed.said = True
        print(f"urdf arm: {'UR10 (' + str(UR10) + ')' if UR10.is_file() else 'the tests 6R arm (UR10 file missing)'}",
              flush=True)
    model = PointModel(arm)
    kin = ChainKinematics.of(arm)
    x_true = random_truth(model, np.random.default_rng(s), error_m, error_rad, registration=False)
    table, _ = campaign(model, x_true, 100, s, "point", noise_m=5e-5)
    f = fit(model, table, FitOptions(before=False))
    q = configurations(arm, 1000, 10_000 + s)
    x0 = model.nominal()
    R, p = kin.pose(x0, q)
    c = compensate(kin, x0, f.x, p, R, np.zeros((1, kin.n_joints)), hint=q)
    ok = c.status == "ok"
    after = np.linalg.norm(kin.pose(x_true, c.q[ok])[1] - p[ok], axis=1)
    before = np.linalg.norm(kin.pose(x_true, q)[1] - p, axis=1)
    return rms(before), judge(f, model.points(f.x, {"joint_positions": c.q[ok]})[1], after) | {"ok": int(ok.sum())}


def accuracy(seeds: int, first: int = 0, systems: str = "arc-welder,delta,urdf") -> None:
    """The compensated program on the true robot vs the calibration's predicted accuracy, 1 000 new
    targets, over `seeds` calibrations per system: true/predicted (1σ RMS), the mean of true²/predicted²
    (1 if the prediction is unbiased), how often the true RMS is within 1.2× the prediction and within
    the 95 % bound, and against that bound (the stated predicted accuracy): how often within 1.2× it, and
    how far above the truth it lies (bound/true: an informative bound is not many times the truth)."""
    runs = {"arc-welder": arc_welder_seed, "delta": delta_seed, "urdf": urdf_seed}
    for name in systems.split(","):
        rows = []
        for s in range(first, first + seeds):
            before, r = runs[name](s)
            rows.append(r)
            print(f"{name} seed {s}: uncompensated {before * 1e3:.2f} mm -> compensated {r['true'] * 1e3:.4f} mm RMS "
                  f"(predicted 1σ {r['pred'] * 1e3:.4f} mm, ratio {r['true'] / r['pred']:.2f}; 95 % bound "
                  f"{r['bound95'] * 1e3:.4f} mm); {r['ok']} of 1000 ok", flush=True)
        ratio = np.array([r["true"] / r["pred"] for r in rows])
        r2 = ratio**2
        tight = np.array([r["bound95"] / r["true"] for r in rows])  # how far the stated bound is above the truth
        print(f"{name}: {seeds} calibrations (seeds {first}-{first + seeds - 1}): true/predicted median {np.median(ratio):.2f}, "
              f"range {ratio.min():.2f}-{ratio.max():.2f}; mean true²/predicted² {r2.mean():.2f} ± {r2.std(ddof=1) / np.sqrt(seeds):.2f} "
              f"(1 = unbiased); <= 1.2× predicted in {int((ratio <= 1.2).sum())} of {seeds}; <= 95 % bound in "
              f"{sum(r['true'] <= r['bound95'] for r in rows)} of {seeds} (bound/predicted median "
              f"{np.median([r['bound95'] / r['pred'] for r in rows]):.2f}); the stated predicted accuracy (the 95 % "
              f"bound): true <= 1.2× it in {sum(r['true'] <= 1.2 * r['bound95'] for r in rows)} of {seeds}, "
              f"bound/true median {np.median(tight):.2f}, range {tight.min():.2f}-{tight.max():.2f}", flush=True)


def delta_extended_speed(n: int, repeats: int) -> None:
    """The Delta calibrated with the extended model (a random `full` truth taken as the calibration):
    n platform-point targets over the campaign box in {T}, damped Newton from the β' closed form."""
    from pipeline.compensate import delta as cd
    from pipeline.measurements.registration import registration_matrix
    from pipeline.models import delta as dm
    from pipeline.simulate import delta_tracker as sim
    from pipeline.systems.delta_tracker import TrackerModel

    truth = sim.random_truth(np.random.default_rng(5), "full")
    model = TrackerModel(variant="extended")
    x = model.nominal()
    x[:36], x[36:42] = truth.beta, truth.registration
    box = np.random.default_rng(1).uniform([-0.15, -0.15, -0.79], [0.15, 0.15, -0.71], (n, 3))
    theta, _ = dm.inverse(model.delta, np.zeros(27), box)
    p, _, _ = dm.full_forward(model.delta, truth.beta, theta, extended=True)
    R, t = registration_matrix(truth.registration)
    targets = (p - t) @ R
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        c = cd.compensate(model, model.nominal(), x, targets)
        times.append(time.perf_counter() - t0)
    ok = c.status == "ok"
    pr, _, _ = dm.full_forward(model.delta, truth.beta, c.q[ok], extended=True)
    counts = {s: int((c.status == s).sum()) for s in sorted(set(c.status))}
    print(f"delta extended model, {n} platform-point targets: best {min(times):.3f} s wall, median "
          f"{np.median(times):.3f} s; {counts}; round trip max {np.abs(pr - p[ok]).max():.2e} m")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--accuracy-seeds", type=int, default=0, help="also the true-robot accuracy over this many calibrations")
    ap.add_argument("--first-seed", type=int, default=0, help="first calibration seed of --accuracy-seeds")
    ap.add_argument("--systems", default="arc-welder,delta,urdf", help="systems of --accuracy-seeds")
    ap.add_argument("--n", type=int, default=10_000)
    ap.add_argument("--delta-extended", type=int, default=0, metavar="N",
                    help="only time the extended Delta model's compensation of N targets (nothing else runs)")
    ap.add_argument("--no-fixture", action="store_true", help="arc welder: leave the jig's machining tolerance out of Σ")
    a = ap.parse_args()
    global FIXTURE
    FIXTURE = not a.no_fixture
    if a.delta_extended:
        delta_extended_speed(a.delta_extended, a.repeats)
        return
    if a.accuracy_seeds:
        accuracy(a.accuracy_seeds, a.first_seed, a.systems)
        if a.n == 0:
            return
    nominal, truth = aw.nominal_arm(), aw.reference_truth()
    kin = SerialArmKinematics.of(nominal)
    q = workspace_configs(a.n)
    R, p = serial_arm.forward(nominal.vector(), q)
    for label, hint in (("with the program's nominal joints (q_<joint> columns)", q), ("nominal IK from 8 seeds", None)):
        times, cpu = [], []
        for _ in range(a.repeats):
            t, tc = time.perf_counter(), time.process_time()
            c = compensate(kin, nominal.vector(), truth.vector(), p, R, IK_SEEDS, hint=hint)
            times.append(time.perf_counter() - t)
            cpu.append(time.process_time() - tc)
        ok = c.status == "ok"
        Rt, pt = serial_arm.forward(truth.vector(), c.q[ok])
        counts = {s: int((c.status == s).sum()) for s in sorted(set(c.status))}
        print(f"arc welder, {a.n} pose targets, {label}: best {min(times):.3f} s wall ({min(cpu):.3f} s CPU), "
              f"median {np.median(times):.3f} s; "
              f"{counts}; round trip max {np.abs(pt - p[ok]).max():.2e} m; median correction "
              f"{np.median(c.correction_m[ok]) * 1e3:.2f} mm")


if __name__ == "__main__":
    main()
