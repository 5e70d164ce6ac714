"""The diagnosis table of an independent generator's campaign (`independent_touch` / `independent_search`), built
as robocal builds it from a recording: the product's recording-side code
(`pipeline.diagnose.adapters.touch_table.add_context`) over what the controller logged — the contacts, the encoder
stream, the payload changes as they happened, the faces' normals.  The generators themselves import no robocal
code; this is the one step where their campaign enters the product (as `from_recording` does for an MCAP file:
`tests/test_independent_generators.py` checks the two agree)."""

from __future__ import annotations

from pipeline.diagnose.adapters.touch_table import add_context


def diagnosis_table(campaign) -> dict:
    """The diagnosis table of `campaign` (`independent_touch.Campaign`); no payload logged before the first change
    reads as 0 kg, as on the arc welder."""
    schedule = [{"t_ns": int(t), "payload_kg": float(kg)} for t, kg in campaign.payload_changes]
    return add_context(campaign.contacts, campaign.stream_t_ns, campaign.stream_q,
                       normal_sign_of=campaign.normal_sign_of, payload_schedule=schedule, default_payload_kg=0.0)
