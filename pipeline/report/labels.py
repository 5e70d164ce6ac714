"""How the report names and scales what it plots, by robot: joint names and units (rad → deg,
prismatic m → mm), the x axis of "time" plots (seconds, or the row of a table without times), the
word for a residual group, the robot's name, and plain-text tick labels on log axes."""

from __future__ import annotations

import numpy as np

ROW_EPOCH_NS = 1_700_000_000_000_000_000  # pipeline.importers.recording.T0_NS: rows of a table without times
SEED_GROUP_TITLE = "face / channel"


def joint_scale(name: str, prismatic: set[str] | frozenset[str]) -> tuple[float, str]:
    """(factor from SI, display unit) of a joint reading: deg for revolute joints, mm for prismatic."""
    return (1e3, "mm") if name in prismatic else (180.0 / np.pi, "deg")


def joints_unit_phrase(names, prismatic) -> str:
    """"deg", or "deg; prismatic joints mm" when the robot has any (figure captions)."""
    return "deg; prismatic joints mm" if any(n in prismatic for n in names) else "deg"


def is_row_index(t_ns: np.ndarray) -> bool:
    """Times that are the importer's stand-ins for a table without times: one second per row from
    its fixed epoch."""
    t = np.asarray(t_ns, np.int64)
    if t.size == 0 or t.min() < ROW_EPOCH_NS:
        return False
    d = t - ROW_EPOCH_NS
    return bool(np.all(d % 1_000_000_000 == 0) and d.max() < 10**9 * 10**7)


def time_axis(t_ns: np.ndarray) -> tuple[np.ndarray, str]:
    """x values and label of a plot against time: seconds since the first measurement, or the
    table row (from 0) when the recording has no times."""
    t = np.asarray(t_ns, np.int64)
    if t.size == 0:
        return np.zeros(0), "time since first measurement (s)"
    if is_row_index(t):
        return (t - ROW_EPOCH_NS) // 1_000_000_000 * 1.0, "measurement (table row)"
    return (t - t.min()) * 1e-9, "time since first measurement (s)"


def group_title(system: str) -> str:
    """What a residual group is: the seed systems' jig face or channel; a URDF campaign's target,
    plane or group label."""
    return "target / group" if system == "urdf" else SEED_GROUP_TITLE


def plain_log_ticks(ax, axis: str = "y") -> None:
    """Log-scale tick labels as plain text (1, 10, 0.01, 1e-05): the report renders strings without
    mathtext, so matplotlib's own ``$\\mathdefault{10^{0}}$`` labels would show raw."""
    from matplotlib.ticker import FuncFormatter, NullFormatter

    fmt = FuncFormatter(lambda v, _pos: f"{v:g}" if v > 0 else "")
    target = ax.yaxis if axis == "y" else ax.xaxis
    target.set_major_formatter(fmt)
    target.set_minor_formatter(NullFormatter())


def residual_display(unit: str | None) -> tuple[float, str]:
    """(factor from the stored value, display unit) of a run's residual figures: lengths stored in m
    are shown in mm; a camera's pixel residuals (``residual_unit`` px in fit.json and the summary)
    stay px, a dynamics diagnosis' torques (``residual_unit`` N·m) N·m."""
    return (1.0, unit) if unit in ("px", "N·m") else (1e3, "mm")


def residual_text(v: float | None, unit: str | None, digits: int = 4, none: str = "–") -> str:
    """A residual figure (RMS, max) as text in its display unit (`residual_display`)."""
    if v is None:
        return none
    k, u = residual_display(unit)
    return f"{v * k:.{digits}f} {u}"
