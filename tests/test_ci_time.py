"""tests/ci_time.py: which files form one unit of work on the xdist workers, the order the units are
handed out in, and which files a CI run warns of or fails for their CPU time."""

from __future__ import annotations

import json

import ci_time


def test_a_file_is_its_own_unit_unless_it_names_a_group_or_a_shared_fixture(tmp_path, monkeypatch):
    monkeypatch.setattr(ci_time, "ROOT", tmp_path)
    monkeypatch.setattr(ci_time, "_units", {})
    (tmp_path / "tests").mkdir()
    (tmp_path / "tests" / "test_a.py").write_text("def test_x():\n    pass\n")
    (tmp_path / "tests" / "test_b.py").write_text('import pytest\npytestmark = pytest.mark.xdist_group(name="ports")\n')
    (tmp_path / "tests" / "test_c.py").write_text("def test_y(tiago_frozen_protocol):\n    pass\n")
    assert ci_time.unit_of_file("tests/test_a.py") == "tests/test_a.py"
    assert ci_time.unit_of_file("tests/test_b.py") == "ports"
    assert ci_time.unit_of_file("tests/test_c.py") == "tiago_frozen_protocol"
    assert ci_time.unit_of_file("tests/test_gone.py") == "tests/test_gone.py"  # unreadable: its own unit


class _Item:
    def __init__(self, nodeid):
        self.nodeid = nodeid


def test_units_are_ordered_heaviest_first_keeping_each_unit_s_own_order(tmp_path, monkeypatch):
    costs = tmp_path / "ci_costs.json"
    costs.write_text(json.dumps({"tests/test_light.py": 2.0, "tests/test_heavy.py": 90.0, "tests/test_new.py": None}))
    monkeypatch.setattr(ci_time, "COSTS", costs)
    monkeypatch.setattr(ci_time, "_units", {})
    items = [_Item(n) for n in ("tests/test_light.py::a", "tests/test_new.py::a", "tests/test_heavy.py::b",
                                "tests/test_heavy.py::a", "tests/test_new.py::b")]
    ci_time.pytest_collection_modifyitems(None, items)
    assert [i.nodeid for i in items] == ["tests/test_heavy.py::b", "tests/test_heavy.py::a", "tests/test_new.py::a",
                                         "tests/test_new.py::b", "tests/test_light.py::a"]


def test_over_the_allowance_is_a_warning_and_far_over_a_failure_where_the_cost_is_known(tmp_path, monkeypatch):
    costs = tmp_path / "ci_costs.json"
    costs.write_text(json.dumps({"tests/test_known.py": 40.0, "tests/test_unmeasured.py": None}))
    monkeypatch.setattr(ci_time, "COSTS", costs)
    recorded = ci_time.recorded_costs()
    assert ci_time.allowance("tests/test_known.py", recorded) == 60.0  # 1.5 × its recorded cost
    assert ci_time.allowance("tests/test_new.py", recorded) == ci_time.ALLOWANCE_S

    class Tally:
        cpu = {"tests/test_known.py": 200.0, "tests/test_unmeasured.py": 500.0, "tests/test_new.py": 95.0,
               "tests/test_small.py": 31.0, "tests/test_fine.py": 5.0}
    over, failing = ci_time._over(Tally, recorded)
    assert set(over) == {"tests/test_known.py", "tests/test_unmeasured.py", "tests/test_new.py", "tests/test_small.py"}
    assert set(failing) == {"tests/test_known.py", "tests/test_new.py"}  # > 3 × 60 s; > 3 × 30 s


def test_the_recorded_costs_load():
    recorded = ci_time.recorded_costs()
    assert recorded, "tests/ci_costs.json is missing or damaged"
    assert all(f.startswith("tests/test_") and f.endswith(".py") for f in recorded)
    assert all(v is None or v >= 0 for v in recorded.values())
