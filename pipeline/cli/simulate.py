"""`robocal simulate arc-welder`."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import typer

from pipeline.cli import err, simulate_app


@simulate_app.command("arc-welder")
def arc_welder_cmd(
    out: Path = typer.Option(..., "--out", help="Recording to write (MCAP)."),
    truth: Path = typer.Option(None, "--truth", help="Where to write TRUTH.json (true model, noise, realised errors)."),
    contacts: int = typer.Option(100, "--contacts", min=10, help="Number of contacts."),
    seed: int = typer.Option(0, "--seed", help="Random seed (targets, noise, random truth)."),
    noise_scale: float = typer.Option(1.0, "--noise-scale", min=0.0, help="Multiplies every error source; 0 turns all off."),
    random_errors: bool = typer.Option(False, "--random-errors", help="Draw a random truth of the paper's error size instead of Table 2's."),
) -> None:
    """Touch-sensing campaign of seed 000's arc-welding arm on the stepped jig."""
    from pipeline.models.jig import stepped_block
    from pipeline.recording.schemas import META_CAMPAIGN, META_FIXTURE, META_ROBOT
    from pipeline.recording.writer import write_campaign
    from pipeline.simulate.arc_welder import Campaign, Noise, simulate, truth_document
    from pipeline.systems import arc_welder as aw

    nominal = aw.nominal_arm()
    true = aw.random_truth(nominal, np.random.default_rng(seed + 1_000_003)) if random_errors else aw.reference_truth()
    campaign, noise = Campaign(contacts=contacts, seed=seed), Noise(scale=noise_scale)
    jig = stepped_block()
    with err.status(f"simulating {contacts} contacts…"):
        sim = simulate(nominal, true, jig, campaign, noise)
    meta = {META_ROBOT: nominal.to_dict(), META_FIXTURE: jig.to_dict(),
            META_CAMPAIGN: {"system": aw.SYSTEM, "simulated": True, "contacts": contacts,
                            "controller_rate_hz": campaign.rate_hz, "search_speed_m_s": campaign.search_speed_m_s,
                            "approach_offset_m": campaign.approach_offset_m}}
    out.parent.mkdir(parents=True, exist_ok=True)
    with err.status("writing recording…"):
        write_campaign(out, meta, (sim.stream_t_ns, sim.stream_q, [j.name for j in nominal.joints]),
                       aw.contact_messages(sim))
    if truth is not None:
        truth.parent.mkdir(parents=True, exist_ok=True)
        truth.write_text(json.dumps(truth_document(true, noise, campaign, sim), indent=2) + "\n")
    err.print(f"wrote {out} ({sim.stream_t_ns.size} encoder samples, {sim.contact_t_ns.size} contacts; "
              f"injected noise RMS {sim.injected_noise_rms_m * 1e3:.4f} mm)")
