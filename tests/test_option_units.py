"""Options are SI with the unit in their name (m, rad, s): `simulate urdf --noise-m/--error-m/--error-rad/--noise-rad`
give the same campaign, byte for byte, as the older millimetre and degree spellings kept as hidden aliases."""

from __future__ import annotations

import numpy as np
from conftest import run_cli
from r6_robot import URDF


def test_si_options_equal_the_mm_deg_aliases(tmp_path):
    urdf = tmp_path / "r6.urdf"
    urdf.write_text(URDF)
    common = ("simulate", "urdf", "--urdf", urdf, "--root", "b", "--tip", "l6", "--measure", "pose",
              "--poses", "12", "--seed", "3")
    si = run_cli(*common, "--error-m", "0.002", "--error-rad", str(np.radians(0.3)), "--noise-m", "5e-5",
                 "--noise-rad", str(np.radians(0.02)), "--out", tmp_path / "si.mcap", "--truth", tmp_path / "si.json")
    old = run_cli(*common, "--error-mm", "2", "--error-deg", "0.3", "--noise-mm", "0.05", "--noise-deg", "0.02",
                  "--out", tmp_path / "old.mcap", "--truth", tmp_path / "old.json")
    assert si.returncode == 0 and old.returncode == 0, si.stderr + old.stderr
    assert (tmp_path / "si.json").read_text() == (tmp_path / "old.json").read_text()
    assert (tmp_path / "si.mcap").read_bytes() == (tmp_path / "old.mcap").read_bytes()
    default = run_cli(*common, "--out", tmp_path / "d.mcap", "--truth", tmp_path / "d.json")
    assert default.returncode == 0 and (tmp_path / "d.json").read_text() != (tmp_path / "si.json").read_text()
    assert "--noise-mm" not in run_cli("simulate", "urdf", "--help").stdout
