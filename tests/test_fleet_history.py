"""Fleet history: steps, trends and tolerance on synthetic series (exact positions, false-flag control),
and end to end on a simulated fleet — 3 robots × 9 monthly campaigns, one robot with a step in a joint
offset at month 5, one with a slow drift of a link length, one unchanged — reprocessed on Dask, the page
flags exactly those, rendered by headless Chromium."""

from __future__ import annotations

import json
import re
import subprocess
from datetime import datetime, timezone

import numpy as np
import pytest

from pipeline.fleet.history import fleet_history, robot_history
from reprocess_support import BIN, ENV, FAST, chromium

MONTH_NS = int(30.44 * 86400e9)
T0 = int(datetime(2026, 1, 1, tzinfo=timezone.utc).timestamp() * 1e9)


def rows_of(series: dict[str, np.ndarray], std: float = 1e-4, robot: str = "r", dof: int = 60, **extra) -> list[dict]:
    n = len(next(iter(series.values())))
    return [{"recording": f"{robot}/{k:02d}.mcap", "robot_id": robot, "status": "pass", "campaign_start_ns": T0 + k * MONTH_NS,
             "n_identifiable": len(series), "residual_dof": dof, "holdout_rms_m": 5e-5,
             "parameters": [{"name": p, "unit": "m", "nominal": 0.0, "estimate": float(x[k]), "std": std,
                             "identifiable": True} for p, x in series.items()], **extra}
            for k in range(n)]


def noise(rng, n=12, k=20, std=1e-4) -> dict[str, np.ndarray]:
    return {f"p{i}": rng.normal(0, std, n) for i in range(k)}


def test_a_large_step_is_flagged_where_it_is_and_rarely_anywhere_else():
    """Every 15–40σ step is flagged at its month; flags elsewhere (19 pure-noise parameters) come at
    the family rate α = 1 % per robot, not more (counted over 120 seeded robots)."""
    rng = np.random.default_rng(2024)
    extra = 0
    for seed in range(120):
        at, size, sign = int(rng.integers(1, 12)), float(rng.uniform(15, 40)), int(rng.choice([-1, 1]))
        s = noise(np.random.default_rng(seed))
        s["p3"] = s["p3"] + np.where(np.arange(12) >= at, sign * size * 1e-4, 0.0)
        h = robot_history("r", rows_of(s), None)
        flags = [(x["param"], x["index"]) for x in h.steps]
        assert ("p3", at) in flags, (seed, flags)
        assert all(x["threshold"] >= 3.0 for x in h.steps)
        assert not any(t["param"] == "p3" for t in h.trends)  # a step is not a trend (segments)
        extra += len(flags) > 1 or bool(h.trends)
    assert extra <= 4, extra  # ≤ 3.3 %: binomial(120, 1 %) exceeds 4 with probability 0.8 %


def test_pure_noise_raises_few_flags_and_a_small_step_none():
    """False flags on pure noise at the family rate (α = 1 % per robot: ≤ 6 of 300 robots), and a
    1σ step hardly ever (≤ 1 %)."""
    bad = small = 0
    for seed in range(300):
        s = noise(np.random.default_rng(seed))
        s["p0"] = s["p0"] + np.where(np.arange(12) >= 6, 1.5e-4, 0.0)  # 1.06σ of the difference
        h = robot_history("r", rows_of(s), 1e-4)
        small += any(x["param"] == "p0" for x in h.steps)
        bad += bool(h.steps or h.trends or h.tolerance)
    assert bad <= 6, bad  # binomial(300, 1 %) exceeds 6 with probability 3 %
    assert small <= 3, small


def test_drift_is_a_trend_not_a_step():
    rng = np.random.default_rng(1)
    s = noise(rng)
    s["p5"] = s["p5"] + 1e-4 * np.arange(12)  # 1σ per month: each step 0.7σ of a difference
    h = robot_history("r", rows_of(s), None)
    assert h.steps == [] and [t["param"] for t in h.trends] == ["p5"]
    assert abs(h.trends[0]["slope_per_year"] - 1e-4 * 365.25 * 86400e9 / MONTH_NS) < 4 * h.trends[0]["se_per_year"]


def test_tolerance_failed_and_insufficient_rows():
    rng = np.random.default_rng(2)
    rows = rows_of(noise(rng))
    rows[4]["holdout_rms_m"] = 3e-4
    rows[5] = rows[5] | {"status": "fail", "error": "validate failed", "parameters": []}
    rows[6] = rows[6] | {"n_identifiable": 12}
    rows.append({"recording": "other.mcap", "robot_id": None, "status": "error", "error": "not an MCAP file"})
    hs = {h.robot_id: h for h in fleet_history(rows, tolerance_m=2e-4)}
    h = hs["r"]
    assert [t["recording"] for t in h.tolerance] == ["r/04.mcap"]
    assert [r["recording"] for r in h.failed] == ["r/05.mcap"]
    assert [r["recording"] for r in h.insufficient] == ["r/06.mcap"] and "identifiable" in h.insufficient[0]["reason"]
    assert len(h.usable) == 10 and [r["recording"] for r in hs["(no robot id)"].failed] == ["other.mcap"]


# ---- the simulated fleet, end to end ---------------------------------------------------------------

STEP = ("arc-02", "J3.theta_offset", 5, 5e-3)  # 0.29° at month 5
DRIFT = ("arc-03", "J2.a", 8e-5)  # 0.08 mm per month
# Three robots (the step, the drift, one unchanged control) over nine months, not a larger fleet over a
# year: each robot's history is judged on its own, so more robots add only more clean controls, and the
# false-flag rate is measured on hundreds of seeded robots above.  At 60 contacts and nine months the step
# is ≈ 37σ (4 months before it, 5 after) and the drift's slope ≈ 17σ, so the end-to-end run still places
# both exactly (simulating the campaigns is most of this fixture's time).
ROBOTS, MONTHS = 3, 9


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    from pipeline.fleet.simulate import Change, FleetSpec, simulate_fleet

    root = tmp_path_factory.mktemp("fleet")
    spec = FleetSpec(robots=ROBOTS, months=MONTHS, contacts=60, seed=0,
                     changes=(Change(1, STEP[1], STEP[3], "step", STEP[2]), Change(2, DRIFT[1], DRIFT[2], "drift")))
    simulate_fleet(root / "archive", spec, workers=2)
    p = subprocess.run([str(BIN / "robocal"), "reprocess", root / "archive", "--out", root / "out", "--workers", "2",
                        "--stages", FAST], capture_output=True, text=True, env=ENV, timeout=900)
    assert p.returncode == 0, p.stderr
    page = root / "fleet.html"
    p = subprocess.run([str(BIN / "robocal"), "fleet", root / "out", "--out", page, "--tolerance-m", "2.5e-4"],
                       capture_output=True, text=True, env=ENV, timeout=600)
    assert p.returncode == 0, p.stderr
    return root, page


@pytest.mark.extended  # `make test-extended`: the 27-campaign fleet through Dask; CI keeps test_reprocess_archive
def test_the_fleet_page_flags_exactly_the_step_and_the_drift(fleet):
    root, page = fleet
    doc = json.loads(page.with_suffix(".json").read_text())
    assert doc["generator"].startswith("robocal/")
    flags = doc["robots"]
    assert sorted(flags) == [f"arc-0{i}" for i in range(1, ROBOTS + 1)]
    for rid, f in flags.items():
        assert f["calibrations"] == MONTHS and f["failed"] == [] and f["tolerance"] == []
        assert f["steps"] == [] or rid == STEP[0], (rid, f["steps"])
        assert f["trends"] == [] or rid == DRIFT[0], (rid, f["trends"])
    (step,) = flags[STEP[0]]["steps"]
    assert step["param"] == STEP[1] and step["recording"] == "arc-02/2026-05/campaign.mcap"
    assert abs(step["delta"] - STEP[3]) < 4 * step["sigma"]
    (trend,) = flags[DRIFT[0]]["trends"]
    per_year = DRIFT[2] * 12  # campaigns one month apart
    assert trend["param"] == DRIFT[1] and abs(trend["slope_per_year"] - per_year) < 4 * trend["se_per_year"]
    html = page.read_text()
    assert "<script" not in html and not re.search(r'(src|href)="(https?:)?//', html)
    assert re.search(r'<tr class="step" data-param="J3.theta_offset" data-date="2026-05-01">', html)
    assert re.search(r'<tr class="trend" data-param="J2.a">', html)
    for i in range(1, ROBOTS + 1):
        assert f'<figure id="fig-params-arc-0{i}" class="plot"><svg' in html
        assert f'<figure id="fig-accuracy-arc-0{i}" class="plot"><svg' in html


@pytest.mark.extended  # `make test-extended`: the 27-campaign fleet through Dask; CI keeps test_reprocess_archive
def test_a_tight_tolerance_is_flagged(fleet):
    from pipeline.fleet.dataset import read_results

    root, _ = fleet
    hs = fleet_history(read_results(root / "out").to_pylist(), tolerance_m=1e-5)
    assert [len(h.tolerance) for h in hs] == [MONTHS] * ROBOTS
    assert [len(h.steps) for h in hs] == [0, 1, 0] and [len(h.trends) for h in hs] == [0, 0, 1]


@pytest.mark.extended  # `make test-extended`: the 27-campaign fleet through Dask; CI keeps test_reprocess_archive
def test_the_fleet_page_renders_in_chromium(fleet, tmp_path):
    root, page = fleet
    dom = chromium(["--dump-dom", page.as_uri()], tmp_path)
    assert dom.returncode == 0, dom.stderr
    sections = re.findall(r'<section id="robot-(arc-\d+)" class="robot" data-robot="[^"]+" data-steps="(\d+)" '
                          r'data-trends="(\d+)"', dom.stdout)
    assert sections == [("arc-01", "0", "0"), ("arc-02", "1", "0"), ("arc-03", "0", "1")]
    shot = tmp_path / "fleet.png"
    r = chromium(["--window-size=1200,2400", f"--screenshot={shot}", page.as_uri()], tmp_path)
    assert r.returncode == 0 and shot.stat().st_size > 50_000  # a rendered page, not a blank one
    from PIL import Image

    px = np.asarray(Image.open(shot).convert("L"))
    assert px.std() > 20


def test_bad_input_is_one_line_and_exit_2(tmp_path):
    def run(*args):
        p = subprocess.run([str(BIN / "robocal"), *map(str, args)], capture_output=True, text=True, env=ENV,
                           timeout=120)
        assert p.returncode == 2 and "Traceback" not in p.stderr, p.stderr
        return p.stderr

    assert "not a folder" in run("reprocess", tmp_path / "missing", "--out", tmp_path / "o")
    (tmp_path / "empty").mkdir()
    assert "no recordings" in run("reprocess", tmp_path / "empty", "--out", tmp_path / "o")
    assert "unknown stage" in run("reprocess", tmp_path / "empty", "--out", tmp_path / "o", "--stages", "ingest,nope")
    (tmp_path / "one").mkdir()
    (tmp_path / "one" / "x.mcap").write_bytes(b"x")
    assert "no Dask scheduler answered" in run("reprocess", tmp_path / "one", "--out", tmp_path / "o",
                                               "--scheduler", "tcp://127.0.0.1:9")
    assert "no such results dataset" in run("fleet", tmp_path / "nothing", "--out", tmp_path / "f.html")
    bad = tmp_path / "res" / "results"
    bad.mkdir(parents=True)
    (bad / "part-1.parquet").write_bytes(b"PAR1 truncated")
    err = run("fleet", tmp_path / "res", "--out", tmp_path / "f.html")
    assert "part-1.parquet: not a readable Parquet part" in err and not (tmp_path / "f.html").exists()


def test_simulated_recordings_carry_the_robot_identity_and_campaign_time(tmp_path):
    from pipeline.recording.reader import read_recording
    from pipeline.recording.schemas import META_CAMPAIGN

    rec = tmp_path / "r.mcap"
    p = subprocess.run([str(BIN / "robocal"), "simulate", "arc-welder", "--out", rec, "--contacts", "10",
                        "--robot-id", "cell-7/SN-1234", "--start", "2026-07-01T08:00:00Z"],
                       capture_output=True, text=True, env=ENV, timeout=300)
    assert p.returncode == 0, p.stderr
    r = read_recording(rec, topics={"/touch/contact"})
    assert r.metadata[META_CAMPAIGN]["robot_id"] == "cell-7/SN-1234"
    t0 = int(datetime(2026, 7, 1, 8, tzinfo=timezone.utc).timestamp()) * 1_000_000_000
    ts = [m["timestamp_ns"] for m in r.messages["/touch/contact"]]
    assert t0 < min(ts) < t0 + 3600 * 10**9


def test_simulate_fleet_never_replaces_a_file_it_did_not_write(tmp_path):
    """A foreign fleet.truth.json or campaign.mcap in the archive: one line naming it, exit 2, nothing written,
    with or without --force; the fleet's own files are replaced by a second run with --force only (kept as .bak)."""
    arch = tmp_path / "arch"
    cmd = [str(BIN / "robocal"), "simulate", "fleet", "--out", str(arch), "--robots", "1", "--months", "2",
           "--contacts", "10"]
    arch.mkdir()
    (arch / "fleet.truth.json").write_text('{"mine": 1}\n')
    p = subprocess.run(cmd, capture_output=True, text=True, env=ENV, timeout=300)
    assert p.returncode == 2 and "fleet.truth.json: exists and was not written by robocal" in p.stderr, p.stderr
    assert len(p.stderr.strip().splitlines()) == 1 and "Traceback" not in p.stderr
    assert (arch / "fleet.truth.json").read_text() == '{"mine": 1}\n' and not list(arch.rglob("*.mcap"))
    (arch / "fleet.truth.json").unlink()
    p = subprocess.run(cmd, capture_output=True, text=True, env=ENV, timeout=300)
    assert p.returncode == 0, p.stderr
    first = sorted(arch.rglob("*.mcap"))
    assert len(first) == 2 and json.loads((arch / "fleet.truth.json").read_text())["generator"].startswith("robocal/")
    p = subprocess.run(cmd, capture_output=True, text=True, env=ENV, timeout=300)  # recordings are data
    assert p.returncode == 2 and "holds a truth already" in p.stderr and "--force" in p.stderr, p.stderr
    first[1].write_bytes(b"someone else's bytes")
    p = subprocess.run(cmd + ["--force"], capture_output=True, text=True, env=ENV, timeout=300)
    assert p.returncode == 2 and f"{first[1]}: exists and was not written by robocal" in p.stderr, p.stderr
    assert first[1].read_bytes() == b"someone else's bytes" and not list(arch.rglob("*.bak"))
    first[1].unlink()
    kept = first[0].read_bytes()
    p = subprocess.run(cmd + ["--force"], capture_output=True, text=True, env=ENV, timeout=300)
    assert p.returncode == 0, p.stderr  # its own recordings and truth replaced with --force, the old ones kept
    assert first[0].with_name("campaign.mcap.bak").read_bytes() == kept
    assert (arch / "fleet.truth.json.bak").is_file()
