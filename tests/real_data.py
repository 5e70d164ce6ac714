"""Where the shared real datasets are, for the tests that use them: `$ROBOCAL_REAL_DATA` if set, else the
workplace's layout — the nearest folder `shared/real-data` beside the repository or beside one of the folders
holding it (`../shared/real-data` from a checkout; a clone nested deeper in the workplace finds the same one).
Where none is found the path returned does not exist, and each test that needs it skips, saying so."""

from __future__ import annotations

import os
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def real_data(repo: Path = REPO) -> Path:
    env = os.environ.get("ROBOCAL_REAL_DATA")
    if env:
        return Path(env)
    for d in repo.parents:
        if (d / "shared" / "real-data").is_dir():
            return d / "shared" / "real-data"
    return repo.parent / "shared" / "real-data"


REAL = real_data()
