"""Residuals orders of magnitude above the instrument: `fail` naming the likely cause (units, swapped
columns, wrong chain), from a short fit — never an open-ended solve.  Data: yourdfpy's kinematics of
the r6 arm (`yourdfpy_points`), written as CSV with the mistakes a user makes, through `robocal import csv`."""

from __future__ import annotations

import json

import pytest

from conftest import run_cli
from r6_robot import BARE_URDF
from yourdfpy_points import campaign, write_csv


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    d = tmp_path_factory.mktemp("units")
    (d / "r6.urdf").write_text(BARE_URDF)
    return d, campaign(60, seed=7)


def _import(d, name, q, p, *flags, tip="l6", **kw):
    csv = write_csv(d / f"{name}.csv", q, p, **kw)
    out = d / f"{name}.mcap"
    r = run_cli("import", "csv", csv, "--urdf", d / "r6.urdf", "--root", "b", "--tip", tip, "--measure", "point",
                "--sigma-m", "2e-5", "--out", out, *flags)
    assert r.returncode == 0, r.stderr
    return out


@pytest.mark.parametrize("name,kw,flags,cause", [
    ("m_as_mm", {}, ("--length-units", "mm"), "lengths are in m but were read as mm"),
    ("mm_as_m", {"length_scale": 1e3}, (), "lengths are in mm but were read as m"),
    ("rad_as_deg", {}, ("--joint-units", "deg"), "joint angles are in radians but were read as degrees"),
    ("xy_swapped", {"swap": (0, 1)}, (), "the position columns are mirrored: two of x, y, z swapped"),
])
def test_wrong_units_and_columns_fail_naming_the_cause(data, name, kw, flags, cause):
    d, (q, p) = data
    rec = _import(d, name, q, p, *flags, **kw)
    r = run_cli("calibrate", rec, "--out", d / f"cal_{name}", "--folds", "2")
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr[-1500:]
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and str(rec) in lines[0] and f"likely cause: {cause}" in lines[0], r.stderr
    assert not (d / f"cal_{name}" / "results.json").exists()


def test_the_wrong_chain_is_named_when_no_unit_explains_it(data):
    """Measured at l6 but imported as a chain ending at l4 (two joints short): no mix-up undone fits."""
    d, (q, p) = data
    from pipeline.recording.reader import read_recording
    from pipeline.systems.registry import detect
    from pipeline.validate.plausibility import screen

    rec = read_recording(_import(d, "good", q, p))
    model, table = detect(rec).load(rec)
    ok = screen(model, table, {"sigma_m": 2e-5})
    assert ok["status"] == "pass" and ok["rms_m"] < 5e-5
    # the l4 chain: the same points, the joints of j5 and j6 ignored by the chain (columns dropped)
    csv = d / "short.csv"
    rows = (d / "good.csv").read_text().splitlines()
    csv.write_text("\n".join(",".join(r.split(",")[:7]) for r in rows) + "\n")
    out = d / "short.mcap"
    r = run_cli("import", "csv", csv, "--urdf", d / "r6.urdf", "--root", "b", "--tip", "l4", "--measure", "point",
                "--sigma-m", "2e-5", "--out", out)
    assert r.returncode == 0, r.stderr
    rec = read_recording(out)
    model, table = detect(rec).load(rec)
    bad = screen(model, table, {"sigma_m": 2e-5})
    assert bad["status"] == "fail" and bad["cause"] == "chain" and "wrong chain" in bad["message"]


def test_run_fails_in_validate_with_the_cause(data, tmp_path):
    d, (q, p) = data
    rec = _import(d, "swap_run", q, p, swap=(0, 2))
    r = run_cli("run", rec, "--out", tmp_path / "run", "--folds", "2")
    assert r.returncode != 0 and "Traceback" not in r.stderr
    val = json.loads((tmp_path / "run" / "validate" / "validate.json").read_text())
    fails = [c for c in val["checks"] if c["status"] == "fail"]
    assert [c["name"] for c in fails] == ["plausibility"]
    assert "the position columns are mirrored: two of x, y, z swapped" in fails[0]["message"]
    assert not (tmp_path / "run" / "identify" / "fit.json").exists()
