"""A changed set of identified parameters between two calibrations is news: listed on its own (history,
page, fleet.json), and a step found across it carries the change; `--tolerance` takes SI metres or a
unit, as `run --tolerance` does."""

from __future__ import annotations

import json

import numpy as np

from pipeline.fleet.history import fleet_history, free_set_changes


OTHERS = tuple(f"b{k}" for k in range(18))  # so that holding one parameter keeps the campaign usable (≥ 90 %)
ALL = ("a",) + OTHERS + ("c",)


def _row(i: int, x: float, names: tuple[str, ...], std: float = 1e-5) -> dict:
    names = tuple(n for n in ALL if n in names or n in OTHERS)
    params = [{"name": n, "unit": "m", "estimate": x if n == "a" else 0.0, "std": std, "identifiable": True}
              for n in names]
    params += [{"name": n, "unit": "m", "estimate": 0.0, "std": None, "identifiable": False}
               for n in ALL if n not in names]
    return {"robot_id": "r1", "recording": f"m{i:02d}.mcap", "campaign_start_ns": (i + 1) * 30 * 86400 * 10**9,
            "status": "pass", "parameters": params, "n_identifiable": len(names), "residual_dof": 50,
            "holdout_rms_m": 1e-4}


def test_a_changed_free_set_is_listed_and_marks_a_step_across_it():
    rows = [_row(i, 0.0, ("a", "b", "c")) for i in range(4)]
    rows += [_row(4, 5e-4, ("a", "b"))] + [_row(i, 5e-4, ("a", "b")) for i in range(5, 8)]
    (h,) = fleet_history(rows)
    (c,) = h.free_set_changes
    assert c["recording"] == "m04.mcap" and c["held"] == ["c"] and c["freed"] == []
    (s,) = h.steps  # 50σ jump of "a" where "c" stopped being fitted: reported, with the change
    assert s["recording"] == "m04.mcap" and s["free_set_change"] == {"freed": [], "held": ["c"]}
    # the same jump with an unchanged set is a step
    rows2 = [_row(i, 0.0 if i < 4 else 5e-4, ("a", "b")) for i in range(8)]
    (h2,) = fleet_history(rows2)
    assert [(s["param"], s["recording"]) for s in h2.steps] == [("a", "m04.mcap")] and h2.free_set_changes == []
    assert "free_set_change" not in h2.steps[0]
    assert free_set_changes(rows2) == []


def test_fleet_cli_lists_the_change_and_reads_tolerance_with_units(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    from conftest import run_cli

    rows = [_row(i, 0.0, ("a", "b", "c")) for i in range(3)] + [_row(i, 5e-4, ("a", "b")) for i in range(3, 6)]
    for r in rows:
        r["holdout_rms_m"] = 3e-4 if r["recording"] == "m05.mcap" else 1e-4
    from pipeline.fleet.dataset import SCHEMA

    full = [{f.name: r.get(f.name) for f in SCHEMA} | {"path": r["recording"], "robot_id_source": "campaign"}
            for r in rows]
    path = tmp_path / "results.parquet"
    pq.write_table(pa.Table.from_pylist(full, schema=SCHEMA), path)
    out = tmp_path / "fleet.html"
    p = run_cli("fleet", path, "--out", out, "--tolerance", "0.25mm")
    assert p.returncode == 0, p.stderr
    doc = json.loads(out.with_suffix(".json").read_text())["robots"]["r1"]
    assert doc["free_set_changes"][0]["held"] == ["c"]
    assert [st["free_set_change"]["held"] for st in doc["steps"]] == [["c"]]  # the step m02 → m03 carries it
    assert [t["recording"] for t in doc["tolerance"]] == ["m05.mcap"]  # 0.3 mm > 0.25 mm
    assert "Identified parameters changed" in out.read_text() and "identified set changed" in p.stderr
    p2 = run_cli("fleet", path, "--out", tmp_path / "f2.html", "--tolerance", "2.5e-4")  # SI metres
    assert p2.returncode == 0 and json.loads((tmp_path / "f2.json").read_text())["robots"]["r1"]["tolerance"] == \
        doc["tolerance"]
    p3 = run_cli("fleet", path, "--out", tmp_path / "f3.html", "--tolerance", "abc")
    assert p3.returncode == 2 and "--tolerance" in p3.stderr and "Traceback" not in p3.stderr
    assert np.isfinite(doc["tolerance"][0]["holdout_rms_m"])
