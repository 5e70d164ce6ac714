"""Which way each joint last turns before each contact of a touch campaign, and how balanced that is.

A gear's play (backlash) is taken up by the joint's last motion before the encoders latch.  In a touch
campaign that is the search itself where the search turns the joint further than the play, else the move to
the approach pose (from the previous contact's retract, which ends at that contact's approach pose).  A
backlash shows as δq_j = −sign(last motion)·b/2: if a joint always arrives the same way, it is a constant
offset the geometry (the joint's zero) absorbs, and the campaign cannot show it.  Contacts approaching a
joint from both sides — on the same face, where the rest of the geometry varies little — are what make it
visible (the diagnosis library's advice for backlash).

Pure numpy; angles rad, search travel m, joint rates rad per m of search travel.
"""

from __future__ import annotations

import numpy as np

from pipeline.diagnose.library.joint import PLAY_RAD as FORM_PLAYS_RAD

PLAY_RAD = max(FORM_PLAYS_RAD)  # the largest play the diagnosis's backlash forms test, rad
ONE_SIDED = 0.2  # a joint approached from its rarer side at fewer than this share of the contacts is named


def last_motion_signs(q_approach: np.ndarray, dq: np.ndarray, travel: np.ndarray,
                      play_rad: float = PLAY_RAD) -> tuple[np.ndarray, np.ndarray]:
    """(signs (n, nj) in {−1, 0, +1}, by_search (n, nj) bool): the sign of each joint's last motion before
    each latch, in execution order.  By the search (`dq`·`travel`) where it turns the joint by more than
    `play_rad`; else by the move from the previous contact's approach pose (0 for the first contact, or when
    the joint does not move)."""
    q_approach = np.asarray(q_approach, float)
    search = np.asarray(dq, float) * np.asarray(travel, float)[:, None]
    by_search = np.abs(search) > play_rad
    move = np.diff(q_approach, axis=0, prepend=q_approach[:1])
    signs = np.where(by_search, np.sign(search), np.sign(np.where(np.abs(move) > play_rad, move, 0.0)))
    return signs.astype(int), by_search


def balance(signs: np.ndarray, faces: np.ndarray, joint_names: list[str]) -> dict[str, dict]:
    """Per joint: contacts approaching it positively / negatively / unknown, the rarer side's share of the
    known ones (0.5 balanced, 0 one-sided), and on how many of the faces touched it is approached both
    ways."""
    faces = np.asarray(faces)
    out = {}
    for j, name in enumerate(joint_names):
        s = signs[:, j]
        pos, neg = int(np.sum(s > 0)), int(np.sum(s < 0))
        both = sum(bool(np.any(s[faces == f] > 0) and np.any(s[faces == f] < 0)) for f in np.unique(faces))
        out[name] = {"positive": pos, "negative": neg, "unknown": int(np.sum(s == 0)),
                     "rarer_share": round(min(pos, neg) / max(pos + neg, 1), 3),
                     "faces_both_ways": int(both), "faces": int(np.unique(faces).size)}
    return out


def balance_warning(bal: dict[str, dict], one_sided: float = ONE_SIDED) -> str | None:
    """A warning naming the joints approached from one side at almost every contact (their backlash is not
    testable on this campaign), or None."""
    lop = [f"{name} ({b['rarer_share']:.0%})" for name, b in bal.items()
           if b["positive"] + b["negative"] and b["rarer_share"] < one_sided]
    if not lop:
        return None
    return (f"joints approached from one side at almost every contact (rarer side's share): {', '.join(lop)} — a "
            f"backlash there looks like a joint offset; approach them from both sides (reverse the joint before the "
            f"search; robocal plan --backlash plans for it)")


def document_balance(doc: dict, play_rad: float = PLAY_RAD) -> dict:
    """The campaign document's `approach_balance` (and a warning when a joint is one-sided), from its
    measurements in execution order."""
    rows = doc["measurements"]
    signs, _ = last_motion_signs(np.array([r["approach_joints_rad"] for r in rows], float),
                                 np.array([r["search_joint_rate_rad_per_m"] for r in rows], float),
                                 np.array([r["predicted_travel_m"] for r in rows], float), play_rad)
    bal = balance(signs, np.array([r["face"] for r in rows]), list(doc["joint_names"]))
    doc["approach_balance"] = {"play_rad": play_rad, "joints": bal}
    if w := balance_warning(bal):
        doc.setdefault("warnings", []).append(w)
    return doc


def backlash_columns(names: list[str], dq: np.ndarray, travel: np.ndarray, play_rad: float = PLAY_RAD):
    """`select.plan`'s `extra` for planning for every joint's backlash too: per joint whose zero is a free
    parameter, the column −sign(search's turn)/2 · ∂(residual)/∂(joint zero) (a play b shifts the joint by
    −sign·b/2), 0 where the search turns the joint by no more than `play_rad` (the order decides there).  The
    candidates' search joint rates `dq` (N, nj) rad/m and predicted travels (N,) m."""
    search = np.asarray(dq, float) * np.asarray(travel, float)[:, None]
    signs = np.where(np.abs(search) > play_rad, np.sign(search), 0.0)

    def columns(J: np.ndarray, free: np.ndarray) -> np.ndarray:
        cols = [-0.5 * signs[:, j, None] * J[:, :, names.index(f"J{j + 1}.theta_offset")]
                for j in range(signs.shape[1]) if f"J{j + 1}.theta_offset" in names
                and free[names.index(f"J{j + 1}.theta_offset")]]
        return np.stack(cols, axis=2) if cols else J[:, :, :0]

    return columns
