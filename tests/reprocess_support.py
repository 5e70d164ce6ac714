"""Helpers of the archive-reprocess tests: small recordings in a nested archive, a real Dask
scheduler and workers on loopback."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

from pipeline.recording.schemas import META_CAMPAIGN
from pipeline_support import base_campaign, write

BIN = Path(sys.executable).parent
ENV = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
FAST = "ingest,validate,identify"


def small_archive(root: Path, robots: int = 4, months: int = 5, contacts: int = 12) -> list[Path]:
    """`robots × months` small recordings (the bundled campaign's first contacts), nested as
    ROBOT/YYYY-MM/campaign.mcap, each robot's identity in its campaign metadata."""
    out = []
    for r in range(robots):
        meta, js, contacts_ = base_campaign(contacts)
        meta[META_CAMPAIGN] = {**meta[META_CAMPAIGN], "robot_id": f"robot-{r + 1}"}
        first = root / f"robot-{r + 1}" / "2026-01" / "campaign.mcap"
        first.parent.mkdir(parents=True)
        write(first, meta, js, contacts_)
        out.append(first)
        for m in range(2, months + 1):
            p = root / f"robot-{r + 1}" / f"2026-{m:02d}" / "campaign.mcap"
            p.parent.mkdir(parents=True)
            shutil.copyfile(first, p)
            out.append(p)
    return out


def cli(*args, **kw) -> subprocess.Popen:
    return subprocess.Popen([str(BIN / "robocal"), *map(str, args)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=ENV, start_new_session=True, **kw)


def kill_group(p: subprocess.Popen) -> None:
    """SIGKILL a process we started and everything of its session (its local cluster's workers)."""
    try:
        os.killpg(p.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    p.wait(timeout=30)


class DaskCluster:
    """`dask scheduler` + `dask worker` processes (no nanny: a killed worker stays dead) on 127.0.0.1."""

    def __init__(self, tmp: Path, workers: int = 2, scheduler_env: dict | None = None) -> None:
        self.file = tmp / "scheduler.json"
        self.procs: list[subprocess.Popen] = []
        self.sched = subprocess.Popen([str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", "0",
                                       "--no-dashboard", "--scheduler-file", str(self.file)],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                      env={**ENV, **(scheduler_env or {})}, start_new_session=True)
        self.procs.append(self.sched)
        t0 = time.monotonic()
        while not self.file.is_file() or not self.file.read_text().strip():
            if time.monotonic() - t0 > 60 or self.sched.poll() is not None:
                self.close()
                raise RuntimeError("dask scheduler did not start")
            time.sleep(0.1)
        self.address = json.loads(self.file.read_text())["address"]
        self.workers = [subprocess.Popen([str(BIN / "dask"), "worker", self.address, "--nthreads", "1",
                                          "--no-nanny", "--no-dashboard", "--host", "127.0.0.1"],
                                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=ENV,
                                         start_new_session=True) for _ in range(workers)]
        self.procs += self.workers

    def close(self) -> None:
        for p in self.procs:
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        for p in self.procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(timeout=10)


def chromium(args: list[str], tmp: Path) -> subprocess.CompletedProcess:
    """Headless Chromium (Debian's, `make chromium`); the test skips, saying why, where it is missing."""
    import pytest

    exe = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if exe is None:
        pytest.skip("chromium not found (install it with `make chromium`, or apt-get install chromium)")
    base = [exe, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
            "--disable-background-networking", "--disable-component-update", "--disable-sync",
            f"--user-data-dir={tmp / 'profile'}"]
    return subprocess.run(base + args, capture_output=True, text=True, timeout=120)
