"""What a campaign could not have seen (`diagnose.document.unseen`): every status — `clean` above all — carries
each effect looked for, the size it could have had unseen on this campaign in the unit people read, and the
campaign change that would reveal it, in `robocal diagnose`'s summary, `robocal run`'s, results.json and the
report."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from conftest import run_cli

from pipeline.diagnose.document import unseen

REC = Path(__file__).resolve().parents[1] / "recordings" / "arc-welder-touch.mcap"


@dataclass(frozen=True)
class _Effect:
    name: str
    location: str
    units: tuple
    plausible: float = 1.0
    advice: str = "do this"
    data: dict = field(default_factory=dict)


@dataclass
class _Gate:
    effect: _Effect
    identifiable: bool
    min_detectable: float
    reason: str = ""


def test_forms_are_one_entry_at_their_smallest_size_and_units_are_the_readers():
    g = [_Gate(_Effect("backlash", "J3", ("rad",)), True, 2e-4),
         _Gate(_Effect("backlash", "J3 (play ≥ 1 mrad)", ("rad",)), True, 1.2e-4),
         _Gate(_Effect("backlash", "J6", ("rad",)), False, np.inf, "fully absorbed by the geometry"),
         _Gate(_Effect("joint_coupling", "J2->J3", ("rad/rad",)), True, 4e-4),
         _Gate(_Effect("joint_coupling", "J2->J3 (quadratic)", ("rad/rad^2",)), True, 5e-4),
         _Gate(_Effect("joint_compliance", "J2", ("rad/(N*m)",)), True, 1.7e-5),
         _Gate(_Effect("trigger_pretravel", "touch sensor", ("m",)), True, 7.7e-5)]
    es = unseen.unseen(g, [{"effect": "joint_compliance", "location": "J2"}], "arc-welder")
    by = {(e["effect"], e["location"]): e for e in es}
    assert by[("backlash", "J3")]["could_have_gone_unseen"] == 1.2e-4 and by[("backlash", "J3")]["display"] == "0.12 mrad"
    assert by[("backlash", "J3")]["form"] == "J3 (play ≥ 1 mrad)"
    assert not by[("backlash", "J6")]["testable"] and by[("backlash", "J6")]["reason"].startswith("fully absorbed")
    assert by[("backlash", "J6")]["reveal"].startswith("robocal plan arc-welder --backlash")
    # a form in other units is an entry of its own
    assert by[("joint_coupling", "J2->J3")]["display"] == "0.4 mrad/rad"
    assert by[("joint_coupling", "J2->J3 (quadratic)")]["display"] == "0.5 mrad/rad²"
    assert by[("joint_compliance", "J2")]["found"] and by[("joint_compliance", "J2")]["display"] == "1.70e-05 rad/(N·m)"
    assert "second payload" in by[("joint_compliance", "J2")]["reveal"]
    assert by[("trigger_pretravel", "touch sensor")]["display"] == "77 µm"
    lines = unseen.summary_lines(es)
    assert any(ln.startswith("backlash: J3 ≤ 0.12 mrad; not testable at J6 — robocal plan") for ln in lines), lines
    assert any(ln.startswith("joint_compliance: J2 found") for ln in lines), lines


@pytest.fixture(scope="module")
def diagnosed(tmp_path_factory):
    out = tmp_path_factory.mktemp("unseen") / "d"
    return run_cli("diagnose", REC, "--out", out, "--bootstrap", "0"), json.loads((out / "diagnosis.json").read_text())


def test_a_clean_diagnosis_says_what_could_have_gone_unseen(diagnosed):
    """The bundled recording diagnoses `clean`; its summary still lists every effect looked for with the size
    that could hide on it (80 % power: the gate's figure for that effect and place) and what would reveal the rest."""
    p, doc = diagnosed
    assert p.returncode == 0, p.stderr
    assert doc["status"] == "clean"
    names = {c["effect"] for c in doc["candidates"]}
    assert {e["effect"] for e in doc["unseen"]} == names
    cand = {(c["effect"], c["location"]): c for c in doc["candidates"]}
    for e in doc["unseen"]:
        assert not e["found"]
        if e["testable"]:
            same = [c["min_detectable"] for (n, loc), c in cand.items()
                    if n == e["effect"] and loc.split(" (")[0] == e["location"].split(" (")[0] and c["identifiable"]
                    and c["unit"] == e["unit"]]
            assert np.isclose(e["could_have_gone_unseen"], min(same)), e
        else:
            assert e["reason"] and e["reveal"]
    text = p.stdout
    assert "could have had unseen" in text
    bl = next(ln for ln in text.splitlines() if ln.strip().startswith("backlash:"))
    assert "mrad" in bl and "robocal plan arc-welder --backlash" in bl
    assert "rad/(N·m)" in next(ln for ln in text.splitlines() if ln.strip().startswith("joint_compliance:"))


def test_run_carries_it_to_results_json_the_summary_and_the_report(tmp_path):
    out = tmp_path / "run"
    p = run_cli("run", REC, "--out", out)
    assert p.returncode == 0, p.stderr
    s = json.loads((out / "results.json").read_text())["stages"]["diagnose"]["summary"]
    assert s["status"] == "clean" and s["unseen"]
    j3 = next(e for e in s["unseen"] if (e["effect"], e["location"]) == ("backlash", "J3"))
    assert j3["testable"] and j3["unit"] == "rad" and j3["display"].endswith("mrad")
    assert "size each could have had unseen" in p.stderr and f"J3 ≤ {j3['display']}" in p.stderr
    html = (out / "report.html").read_text()
    assert "What this campaign could not have seen" in html and j3["display"] in html
