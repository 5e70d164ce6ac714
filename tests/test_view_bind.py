"""`robocal view` opens the real rerun viewer (under a virtual X display) and the viewer's server
listens on 127.0.0.1 only, not on every interface."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

PORT = 9876  # the rerun viewer's default server port


def _listening(port: int) -> set[str]:
    """Addresses (hex, as in /proc/net/tcp*) with a socket listening on `port`."""
    found = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            lines = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            local, state = line.split()[1], line.split()[3]
            addr, p = local.split(":")
            if state == "0A" and int(p, 16) == port:
                found.add(addr)
    return found


def _pids_with(arg: str) -> list[int]:
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                if arg.encode() in (d / "cmdline").read_bytes().split(b"\0"):
                    out.append(int(d.name))
            except OSError:
                pass
    return out


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/net/tcp")
def test_view_starts_the_viewer_listening_on_localhost_only(tmp_path):
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        pytest.skip("Xvfb not found (apt-get install xvfb): the viewer needs a display")
    if _listening(PORT):
        pytest.skip(f"port {PORT} is already in use (another rerun viewer?)")
    import rerun as rr

    rrd = tmp_path / "run.rrd"
    rec = rr.RecordingStream("robocal-view-test")
    rec.save(str(rrd))
    rec.log("points", rr.Points3D([[0.0, 0.0, 0.0]]))
    rec.flush()
    display = f":{90 + os.getpid() % 400}"
    x = subprocess.Popen([xvfb, display, "-screen", "0", "640x480x24"], stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL)
    viewers: list[int] = []
    try:
        time.sleep(1.0)
        env = {**os.environ, "DISPLAY": display}
        exe = Path(sys.executable).with_name("robocal")
        log = tmp_path / "view.log"  # a file, not a pipe: the viewer keeps its inherited output open
        with open(log, "w") as f:
            code = subprocess.run([str(exe), "view", str(tmp_path)], env=env, stdout=f, stderr=f, timeout=60).returncode
        assert code == 0, log.read_text()
        assert "opened" in log.read_text()
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not _listening(PORT):
            time.sleep(0.5)
        viewers = _pids_with(str(rrd))
        addrs = _listening(PORT)
        assert viewers, "no rerun viewer process for the recording"
        assert addrs, f"the viewer never listened on port {PORT}"
        assert addrs == {"0100007F"}, addrs  # 127.0.0.1 only; 00000000 would be every interface
    finally:
        for pid in viewers or _pids_with(str(rrd)):
            try:
                os.kill(pid, 15)
            except ProcessLookupError:
                pass
        x.terminate()
        x.wait(timeout=10)
    deadline = time.monotonic() + 10  # the viewer is gone: nothing is left listening
    while time.monotonic() < deadline and _listening(PORT):
        time.sleep(0.2)
    assert not _listening(PORT)
