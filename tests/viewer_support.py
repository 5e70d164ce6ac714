"""Test helper: a screenshot of the real rerun viewer, headless under Xvfb with Mesa's software
Vulkan (Debian xvfb, mesa-vulkan-drivers; `make chromium` installs them), or a skip saying what is missing."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest


def viewer_screenshot(rrd: Path, shot: Path) -> np.ndarray:
    """The viewer's 1600×1000 window showing `rrd`, as an (h, w, 3) float image in 0…1.  The viewer
    gets its own port: one already listening on rerun's default port would be handed the recording."""
    from matplotlib.image import imread

    xvfb = shutil.which("xvfb-run")
    rerun = Path(sys.executable).with_name("rerun")
    if xvfb is None or not rerun.is_file():
        pytest.skip("xvfb-run or the rerun viewer not installed (apt-get install xvfb mesa-vulkan-drivers)")
    r = subprocess.run([xvfb, "-a", "-s", "-screen 0 1600x1000x24", str(rerun), str(rrd),
                        "--window-size", "1600x1000", "--screenshot-to", str(shot), "--port", "auto"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and shot.is_file(), r.stderr[-2000:]
    return imread(shot)[..., :3]
