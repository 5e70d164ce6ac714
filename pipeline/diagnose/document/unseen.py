"""What the campaign could not have seen: for every effect of the library that was looked for, the size it could
have had and still gone unseen on this campaign, in the unit people think in, and the campaign that would reveal it.

Every status carries it — `clean` above all: "no effect found" means "none larger than these sizes".  One entry per
effect and place (the forms of one effect — a backlash's plays, a growth's time constants — are one entry: the
form that sees the smallest size), from the gate (`inference.gate`):

- ``could_have_gone_unseen``: the gate's minimum detectable size, (z₁₋α/(2m) + z₀.₈)·σ / s_min(S⊥) (+ its
  immaterial tolerance): an effect this large is found with 80 % probability at the family's α; smaller ones can
  hide in the noise.  Parameter units (SI) and, in ``display``, the unit a user reads (mrad, µm, rad/(N·m), ppm …);
- ``testable``: false when this campaign cannot separate the effect from the geometry or a look-alike at any
  plausible size (then ``reason``), ``found``: it is among the findings;
- ``reveal``: the campaign change that would show it (`robocal plan arc-welder --backlash` for a backlash, a second
  payload for a compliance, …; the library's advice otherwise).
"""

from __future__ import annotations

import numpy as np

POWER = 0.8  # the detection probability at `could_have_gone_unseen` (the gate's z₀.₈)

# SI unit → (factor, display unit)
DISPLAY = {
    "rad": (1e3, "mrad"), "m": (1e6, "µm"), "rad/(N*m)": (1.0, "rad/(N·m)"), "1": (1e6, "ppm"),
    "rad/rad": (1e3, "mrad/rad"), "rad/rad^2": (1e3, "mrad/rad²"), "m/s": (1e6 * 3600, "µm/h"),
    "m/K": (1e6, "µm/K"), "s": (1e3, "ms"), "1/s": (1e6 * 3600, "ppm/h"), "1/K": (1e6, "ppm/K"),
    "1/m": (1.0, "1/m"), "px": (1.0, "px"),
}

# campaign changes that robocal itself can plan, per (system, effect)
PLANS = {
    ("arc-welder", "backlash"): "robocal plan arc-welder --backlash --select 115 --out plan.json (approach each "
                                "joint from both sides)",
    ("arc-welder", "joint_compliance"): "a second payload: touch the same points with another payload (e.g. 0 and "
                                        "6 kg), logged on /arm/payload",
}


def display(value: float | None, unit: str) -> str:
    """A size in the unit people read ("0.12 mrad", "3.4e-06 rad/(N·m)")."""
    if value is None or not np.isfinite(value):
        return "not testable"
    k, u = DISPLAY.get(unit, (1.0, unit))
    v = value * k
    if 100 <= abs(v) < 1e5:
        return f"{v:.0f} {u}"
    return f"{v:.2g} {u}" if 1e-2 <= abs(v) < 100 else f"{v:.2e} {u}"


def base_location(location: str) -> str:
    """The place of a form (`J3 (play ≥ 1 mrad)` → `J3`)."""
    return str(location).split(" (")[0]


def unseen(gates: list, findings: list[dict], system: str = "") -> list[dict]:
    """The entries of the module docstring, in library order (one per effect and place)."""
    found = {(f["effect"], base_location(f["location"])) for f in findings}
    out: dict[tuple[str, str, str], dict] = {}
    plain = {(g.effect.name, str(g.effect.location), g.effect.units[0]) for g in gates}
    for g in gates:
        e = g.effect
        base = base_location(e.location)
        key = (e.name, base, e.units[0])  # forms in other units (a quadratic coupling) are entries of their own
        mds = float(g.min_detectable) if g.identifiable and np.isfinite(g.min_detectable) else None
        entry = out.get(key)
        if entry is not None and (mds is None or (entry["could_have_gone_unseen"] is not None
                                                  and entry["could_have_gone_unseen"] <= mds)):
            continue
        where = base if key in plain else str(e.location)
        out[key] = {"effect": e.name, "location": where, "form": str(e.location) if str(e.location) != where else None,
                    "testable": mds is not None, "found": (e.name, base) in found, "could_have_gone_unseen": mds,
                    "unit": e.units[0], "plausible_max": e.plausible,
                    "display": display(mds, e.units[0]),
                    "power": POWER, "reason": None if mds is not None else g.reason,
                    "reveal": PLANS.get((system, e.name), e.advice)}
    return list(out.values())


def summary_lines(entries: list[dict], width: int = 6) -> list[str]:
    """One line per effect: each place's size (the found ones marked), then what would reveal the places this
    campaign could not test — the CLI's and the report's text."""
    lines = []
    names = list(dict.fromkeys(e["effect"] for e in entries))
    for name in names:
        es = [e for e in entries if e["effect"] == name]
        shown = [f"{e['location']} {'found' if e['found'] else '≤ ' + e['display']}" for e in es if e["testable"]]
        blind = [e["location"] for e in es if not e["testable"]]
        text = ", ".join(shown[:width]) + (f" (+{len(shown) - width} more)" if len(shown) > width else "")
        if blind:
            text += ("; " if text else "") + f"not testable at {', '.join(blind[:width])}" + (
                " …" if len(blind) > width else "") + f" — {es[0]['reveal']}"
        lines.append(f"{name}: {text}")
    return lines
