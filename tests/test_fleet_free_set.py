"""A changed set of identified parameters between two calibrations is news: listed on its own (history,
page, fleet.json) with the moves across it; a move across it is a step only when calibrations with the
same identified set on both sides confirm it; `--tolerance` takes SI metres or a
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


def test_a_move_across_a_changed_free_set_is_news_unless_a_common_basis_confirms_it():
    # "c" stops being fitted at m04 and "a" jumps 50σ there; no set recurs on both sides: a move, not a step
    rows = [_row(i, 0.0, ("a", "b", "c")) for i in range(4)]
    rows += [_row(i, 5e-4, ("a", "b")) for i in range(4, 8)]
    (h,) = fleet_history(rows)
    (c,) = h.free_set_changes
    assert c["recording"] == "m04.mcap" and c["held"] == ["c"] and c["freed"] == []
    assert h.steps == [] and [m["param"] for m in c["moved"]] == ["a"] and abs(c["moved"][0]["z"]) > 30
    # the truth never changed: "a" moves while "c" is held and comes back when "c" is fitted again → no step
    rows = [_row(i, 0.0, ("a", "b", "c")) for i in range(3)] + [_row(i, 5e-4, ("a", "b")) for i in range(3, 5)]
    rows += [_row(i, 0.0, ("a", "b", "c")) for i in range(5, 8)]
    (h,) = fleet_history(rows)
    assert h.steps == [] and not h.trends and len(h.free_set_changes) == 2
    assert {m["param"] for c in h.free_set_changes for m in c["moved"]} == {"a"}
    assert all(not m["checked_by"]["confirmed"] for c in h.free_set_changes for m in c["moved"] if "checked_by" in m)
    # a real step that coincides with the change: the set recurs later with the new value → confirmed step
    rows = [_row(i, 0.0, ("a", "b", "c")) for i in range(3)] + [_row(i, 5e-4, ("a", "b")) for i in range(3, 5)]
    rows += [_row(i, 5e-4, ("a", "b", "c")) for i in range(5, 8)]
    (h,) = fleet_history(rows)
    (s,) = h.steps
    assert s["param"] == "a" and s["recording"] == "m03.mcap"
    assert s["free_set_change"] == {"freed": [], "held": ["c"]}
    assert s["confirmed_by"]["from_recording"] == "m02.mcap" and s["confirmed_by"]["recording"] == "m05.mcap"
    assert s["confirmed_by"]["confirmed"]
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
    assert doc["steps"] == []  # the move m02 → m03 is not confirmed on a common basis: listed with the change
    assert [m["param"] for m in doc["free_set_changes"][0]["moved"]] == ["a"]
    assert "a (|z| " in out.read_text()
    assert [t["recording"] for t in doc["tolerance"]] == ["m05.mcap"]  # 0.3 mm > 0.25 mm
    assert "Identified parameters changed" in out.read_text() and "identified set changed" in p.stderr
    p2 = run_cli("fleet", path, "--out", tmp_path / "f2.html", "--tolerance", "2.5e-4")  # SI metres
    assert p2.returncode == 0 and json.loads((tmp_path / "f2.json").read_text())["robots"]["r1"]["tolerance"] == \
        doc["tolerance"]
    p3 = run_cli("fleet", path, "--out", tmp_path / "f3.html", "--tolerance", "abc")
    assert p3.returncode == 2 and "--tolerance" in p3.stderr and "Traceback" not in p3.stderr
    assert np.isfinite(doc["tolerance"][0]["holdout_rms_m"])
