"""The peers' own held-out protocols on real data, every model evaluated by `pipeline.evaluate`.

* FIGAROH's frozen TIAGo protocol (`figaroh_tiago_sessions/SOURCE.md`): fit on the 2021-11-30 session only,
  evaluate on the other three without refitting (registration included).  Target: FIGAROH's full model,
  3.07 / 2.83 / 2.44 mm (norm of the 3-D error, RMS).
* MUKCa's protocol on panda_2 (`mukca_panda/SOURCE.md`): fit on one placement, evaluate on the others by
  the spread of the ball centres about their socket's mean and the socket-distance error; MUKCa's own
  calibrated URDF evaluated by the same code.

Models compared: registration only (nominal robot), robocal's group selection (`groups`, k-fold over rows;
`--model-choice groups`), every group free (`all`), shrinkage toward nominal (`shrinkage`: what `robocal run`'s
default, auto, takes on these imports; scale by leaving out whole
sockets where the recording has several, else GCV; with the gravity-compliance families `robocal run`
offers by default, each kept only if admissible and of least score: `pipeline.identify.physics_choice`);
` rigid`: the same choice on the rigid model (no gravity terms); `+tool`: the tool point estimated too
(MUKCa frees its ball joint).  Time: CPU seconds of the model choice and of one plain fit of the chosen
model, and their ratio (shrinkage: the least of `REPEAT` runs); `--run-timing`: wall and CPU seconds of the
whole `robocal run` (every stage) on the TIAGo training session, default (auto: shrinkage) and
`--model-choice groups`.

    python benchmarks/bench_real_data.py --protocols tiago-sessions,mukca [--mukca-train front_center] [--run-timing]
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from pipeline.evaluate.apply import evaluate
from pipeline.evaluate.calibrated import Calibrated, from_urdf
from pipeline.identify.complexity import fixed_for, select
from pipeline.identify.least_squares import FitOptions, fit
from pipeline.identify.shrinkage_fit import shrunk_fit
from pipeline.recording.reader import read_recording
from pipeline.recording.schemas import META_CAMPAIGN, META_URDF
from pipeline.systems.registry import detect

SESSIONS = ("2021-11-30", "2021-11-26", "2021-11-30-1403", "2021-11-30-1504")
FIGAROH = {"registration only (9)": (4.87, 4.58, 4.22), "joint offsets (14)": (4.23, 4.09, 3.83),
           "full (31)": (3.07, 2.83, 2.44)}
# The protocol's posture groups of each held-out session, relative to the training postures: repeated (every
# joint within 0.01 rad or m of a training posture), new (not repeated, every joint inside the training range
# widened by 0.05), out of range (extrapolation).  FIGAROH's published figures per group (norm of the 3-D error,
# RMS, mm; 11-26 / 11-30 14:03 / 11-30 15:04) and its posture counts, which the definition below reproduces.
POSTURE_GROUPS = ("repeated", "new", "out of range")
FIGAROH_GROUPS = {"registration only (9)": ((3.93, 3.48, 3.25), (5.12, 4.85, 4.73), (7.34, 7.23, 6.35)),
                  "joint offsets (14)": ((3.31, 3.08, 2.84), (4.47, 4.29, 4.13), (6.53, 6.61, 6.21)),
                  "full (31)": ((2.34, 2.03, 1.91), (2.84, 2.75, 2.64), (5.31, 5.01, 3.77))}
FIGAROH_GROUP_COUNTS = ((37, 37, 35), (16, 17, 16), (9, 9, 8))
REPEAT = 5  # runs of the shrinkage choice and of its plain fit timed (the least CPU s reported)
PLACEMENTS = ("front_center", "back_left", "back_right", "front_left", "front_right", "high", "mid-high",
              "mid_left", "mid_right")


def _robocal(*args: str) -> None:
    subprocess.run([str(Path(sys.executable).parent / "robocal"), *map(str, args)], check=True, capture_output=True)


def tiago_recordings(real: Path, tmp: Path) -> list[Path]:
    out = []
    for s in SESSIONS:
        p = tmp / f"tiago_{s}.mcap"
        _robocal("import", "csv", real / "figaroh_tiago_sessions" / f"qualisys_{s}_static_postures.csv", "--urdf",
                 real / "figaroh_tiago_mocap" / "tiago_48_schunk.urdf", "--root", "base_footprint", "--tip",
                 "wrist_ft_tool_link", "--measure", "point", "--position-cols", "x1,y1,z1", "--out", p)
        out.append(p)
    return out


def panda_recording(real: Path, tmp: Path, place: str, robot: str = "panda_2") -> Path:
    d = real / "mukca_panda"
    p = tmp / f"{robot}_{place}.mcap"
    _robocal("import", "csv", *[d / "data" / robot / place / f"hole_{k}.csv" for k in (0, 1)], "--urdf",
             d / "urdf" / "panda.urdf", "--root", "panda_link0", "--tip", "ball_link", "--measure", "coincidence",
             "--group-from", "parent/file", "--columns", ",".join(f"panda_joint{i}" for i in range(1, 8)),
             "--distance", f"{place}/hole_0:{place}/hole_1:0.05", "--out", p)
    return p


def models(train_path: Path, choices: tuple[str, ...], folds: int = 5):
    """{choice: (Calibrated, choice CPU s, one plain fit CPU s, note)} fitted on `train_path` only."""
    from pipeline.accuracy.prior import prior_sigma

    import dataclasses

    from pipeline.systems.registry import load_with_physics

    rec = read_recording(train_path)
    system = detect(rec)
    rigid_model, rigid_data = system.load(rec)
    auto_model, auto_data = load_with_physics(system, rec, "auto", None)  # robocal run's default gravity terms
    out = {}
    for c in choices:
        rigid = "rigid" in c or not c.startswith(("shrinkage", "groups"))
        base_model, data = (rigid_model, rigid_data) if rigid else (auto_model, auto_data)
        # "+tool": the tool point (Panda: the ball centre) estimated too, as MUKCa does (its config frees ball_joint)
        if c.endswith("+tool") and not hasattr(base_model, "fit_tool"):
            continue  # no tool point to free (point data estimate it anyway)
        model = dataclasses.replace(base_model, fit_tool=True) if c.endswith("+tool") else base_model
        prior = prior_sigma(model)[0]
        groups = [g for g in model.groups() if not g.startswith("_")]
        t0 = time.process_time()
        note = ""
        if c == "registration only":
            fixed = fixed_for(model, ["registration"])
        elif c == "groups":
            sel = select(model, data, k=folds, options=FitOptions(prior_sigma=prior))
            fixed, note = sel.fixed, "+".join(sel.kept[1:]) or "—"
        elif c.startswith("all"):
            fixed = fixed_for(model, groups)
        if c.startswith("shrinkage"):  # a fraction of a second: CPU s the least of REPEAT runs (the box is shared)
            t_choice, t_fit = np.inf, np.inf
            for _ in range(REPEAT):
                t0 = time.process_time()
                f, s, _ = shrunk_fit(model, data, FitOptions(prior_sigma=prior), k=2)
                t_choice = min(t_choice, time.process_time() - t0)
                on = tuple((s.physics or {}).get("terms", ()))
                t1 = time.process_time()
                fit(model, data, FitOptions(fixed=tuple(n for n in fixed_for(model, groups) if n not in on),
                                            before=False, prior_sigma=prior))
                t_fit = min(t_fit, time.process_time() - t1)
            x = f.x
            note = (f"μ {s.mu_m * 1e3:.3g} mm, {s.dof:.1f} eff. parameters, {len(s.implausible)} beyond 3σ"
                    + (f", physics: {s.physics['chosen']}" if s.physics else ""))
        else:
            t_choice = time.process_time() - t0
            t1 = time.process_time()
            x = fit(model, data, FitOptions(fixed=fixed, before=False, prior_sigma=prior)).x
            t_fit = time.process_time() - t1
        cal = Calibrated(train_path, model.parameter_names(), x, np.ones(x.size, bool), dict(rec.metadata[META_URDF]),
                         dict(rec.metadata[META_CAMPAIGN]), str(train_path))
        out[c] = (cal, t_choice, t_fit, note)
        print(f"  {c}: choice {t_choice:.2f} s CPU, one plain fit {t_fit:.2f} s CPU {note}", file=sys.stderr)
    return out


def posture_groups(q_train: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Index into `POSTURE_GROUPS` of each posture `q` (n, joints; rad or m) relative to the training postures
    `q_train` (m, joints): 0 repeated, 1 new inside the training range, 2 out of range."""
    repeated = (np.abs(q[:, None, :] - q_train[None, :, :]).max(axis=2) <= 0.01).any(axis=1)
    lo, hi = q_train.min(axis=0) - 0.05, q_train.max(axis=0) + 0.05
    inside = np.all((q >= lo) & (q <= hi), axis=1)
    return np.where(repeated, 0, np.where(inside, 1, 2))


def tiago_figures(real: Path, tmp: Path, choices: tuple[str, ...]) -> dict:
    """{choice: ([fit session, 11-26, 11-30 14:03, 11-30 15:04] norm of the 3-D error RMS m, choice CPU s,
    one fit CPU s, note, [per held-out session: RMS m of each posture group])}, and the posture-group counts."""
    from pipeline.systems import urdf_robot

    paths = tiago_recordings(real, tmp)
    recs = [read_recording(p) for p in paths]
    qs = [np.asarray(urdf_robot.load(r)[1]["joint_positions"], float) for r in recs]
    groups = [posture_groups(qs[0], q) for q in qs[1:]]
    out = {}
    for c, (cal, tc, tf, note) in models(paths[0], choices).items():
        res = evaluate(cal, recs)
        by_group = [[float(np.sqrt(np.mean(d["rows"].norm[g == k] ** 2))) if np.any(g == k) else float("nan")
                     for k in range(len(POSTURE_GROUPS))] for d, g in zip(res[1:], groups)]
        out[c] = ([d["rms_3d_m"] for d in res], tc, tf, note, by_group)
    counts = [[int(np.sum(g == k)) for g in groups] for k in range(len(POSTURE_GROUPS))]
    return out, counts


def run_timing(train: Path, out: Path, *args: str) -> tuple[float, float]:
    """(wall s, CPU s) of one whole `robocal run` (every stage) of `train`."""
    import resource

    c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    _robocal("run", train, "--out", out, *args)
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.perf_counter() - t0, (c1.ru_utime - c0.ru_utime) + (c1.ru_stime - c0.ru_stime)


def tiago(real: Path, tmp: Path, choices: tuple[str, ...], timing: bool = False) -> None:
    print("\n### FIGAROH's frozen TIAGo protocol: fit on 2021-11-30, evaluate on the others without refitting\n")
    print("| model | fit session | 11-26 | 11-30 14:03 | 11-30 15:04 | choice s CPU | one fit s CPU | choice / fit | note |")
    print("|---|---|---|---|---|---|---|---|---|")
    figures, counts = tiago_figures(real, tmp, choices)
    for c, (r, tc, tf, note, _) in figures.items():
        ratio = f"{tc / tf:.1f}×" if tf > 0 else "—"
        print(f"| robocal {c} | " + " | ".join(f"{v * 1e3:.2f}" for v in r) + f" | {tc:.2f} | {tf:.2f} | {ratio} | {note} |")
    for k, v in FIGAROH.items():
        print(f"| FIGAROH {k} (published) | — | " + " | ".join(f"{x:.2f}" for x in v) + " | | | | |")
    print("\nmm: norm of the 3-D error, RMS over postures (target: ≤ FIGAROH full on every held-out session)")
    print("\nBy the protocol's posture groups (11-26 / 11-30 14:03 / 11-30 15:04; postures in brackets, FIGAROH's "
          "published counts " + ", ".join(f"{n}: {'/'.join(map(str, c))}" for n, c in
                                          zip(POSTURE_GROUPS, FIGAROH_GROUP_COUNTS)) + "):\n")
    print("| model | " + " | ".join(f"{n} ({'/'.join(map(str, c))})" for n, c in zip(POSTURE_GROUPS, counts))
          + " |\n|---|---|---|---|")
    for c, (*_, by_group) in figures.items():
        print(f"| robocal {c} | " + " | ".join(" / ".join(f"{s[k] * 1e3:.2f}" for s in by_group)
                                             for k in range(len(POSTURE_GROUPS))) + " |")
    for k, v in FIGAROH_GROUPS.items():
        print(f"| FIGAROH {k} (published) | " + " | ".join(" / ".join(f"{x:.2f}" for x in g) for g in v) + " |")
    if timing:
        train = tmp / f"tiago_{SESSIONS[0]}.mcap"
        for label, args in (("default (auto: shrinkage)", ()), ("--model-choice groups", ("--model-choice", "groups"))):
            wall, cpu = run_timing(train, tmp / f"run-{len(args)}", *args)
            print(f"whole `robocal run` {label} on the training session: {wall:.1f} s wall, {cpu:.1f} s CPU")


def placements(real: Path, robot: str) -> tuple[str, ...]:
    """The placements of a MUKCa unit (panda_2: `PLACEMENTS`' order; others: their folders, sorted)."""
    if robot == "panda_2":
        return PLACEMENTS
    return tuple(sorted(p.name for p in (real / "mukca_panda" / "data" / robot).iterdir() if p.is_dir()))


def mukca(real: Path, tmp: Path, choices: tuple[str, ...], train: str, robot: str = "panda_2") -> None:
    places = placements(real, robot)
    paths = [panda_recording(real, tmp, p, robot) for p in places]
    recs = [read_recording(p) for p in paths]
    i = places.index(train)
    others = [r for j, r in enumerate(recs) if j != i]
    print(f"\n### MUKCa's protocol, {robot}: fit on placement {train}, evaluate on the other {len(others)}\n")
    print("| model | fit placement: mean / RMS | other placements: mean of per-placement mean 3-D | RMS 3-D over "
          "all their rows | worst placement RMS | RMS socket-distance error | choice s CPU | one fit s CPU | "
          "choice / fit |")
    print("|---|---|---|---|---|---|---|---|---|")
    published = real / "mukca_panda" / "calibrated_urdf" / robot / "panda_calibrated.urdf"
    mk = from_urdf(published, "panda_link0", "ball_link", "coincidence") if published.is_file() else None
    rows = [(f"robocal {c}", cal, tc, tf) for c, (cal, tc, tf, _) in models(paths[i], choices).items()]
    per = {}
    for name, cal, tc, tf in rows + ([("MUKCa calibrated URDF (published)", mk, None, None)] if mk else []):
        own, *rest = evaluate(cal, [recs[i], *others])
        per[name] = [d["mean_3d_m"] for d in rest]
        n = np.array([d["n"] for d in rest])
        rms_all = np.sqrt(np.sum(n * np.array([d["rms_3d_m"] for d in rest]) ** 2) / n.sum())
        dist = np.sqrt(np.mean([d["rms_distance_error_m"] ** 2 for d in rest]))
        ratio = f"{tc / tf:.1f}×" if tc is not None and tf > 0 else "—"
        t = f"{tc:.2f} | {tf:.2f} | {ratio}" if tc is not None else "— | — | —"
        print(f"| {name} | {own['mean_3d_m'] * 1e3:.3f} / {own['rms_3d_m'] * 1e3:.3f} | "
              f"{np.mean([d['mean_3d_m'] for d in rest]) * 1e3:.3f} | {rms_all * 1e3:.3f} | "
              f"{max(d['rms_3d_m'] for d in rest) * 1e3:.3f} | {dist * 1e3:.3f} | {t} |")
    print("\nmm: ball centres about their socket's mean (MUKCa's figure: the mean), socket distance against 50 mm")
    names = [p for j, p in enumerate(places) if j != i]
    print("\nPer placement, mean 3-D (mm):\n\n| model | " + " | ".join(names) + " |\n|---|" + "---|" * len(names))
    for name, v in per.items():
        print(f"| {name} | " + " | ".join(f"{x * 1e3:.3f}" for x in v) + " |")
