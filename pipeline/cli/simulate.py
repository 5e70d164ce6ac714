"""`robocal simulate arc-welder`."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
from typing import Literal

import typer

from pipeline.cli import err, force_option, simulate_app


@simulate_app.command("arc-welder")
def arc_welder_cmd(
    out: Path = typer.Option(..., "--out", help="Recording to write (MCAP)."),
    truth: Path = typer.Option(None, "--truth", help="Where to write TRUTH.json (true model, noise, realised errors)."),
    contacts: int = typer.Option(100, "--contacts", min=10, help="Number of contacts."),
    seed: int = typer.Option(0, "--seed", help="Random seed (targets, noise, random truth)."),
    noise_scale: float = typer.Option(1.0, "--noise-scale", min=0.0, help="Multiplies every error source; 0 turns all off."),
    random_errors: bool = typer.Option(False, "--random-errors", help="Draw a random truth of the paper's error size instead of Table 2's."),
    effect: list[str] = typer.Option([], "--effect", help="Inject a library effect into the TRUE robot: NAME=VALUE[,VALUE][@LOCATION] "
                                     "(repeatable), e.g. joint_compliance=5e-6@J2, backlash=1e-3@J3, trigger_latency=0.02."),
    payloads: str = typer.Option("", "--payloads", help="Campaign variation: payloads (kg) cycled in blocks of 10 contacts, e.g. 0,6."),
    search_speeds: str = typer.Option("", "--search-speeds", help="Campaign variation: search speeds (m/s) drawn per contact, e.g. 0.005,0.01,0.02."),
    face_order: Literal["shuffled", "blocked"] = typer.Option("shuffled", "--face-order", help="Campaign variation: shuffled (interleaved) or blocked faces."),
    payload_pairs: bool = typer.Option(False, "--payload-pairs", help="With --payloads: touch each point once per payload, the "
                                       "points planned for the compliance information left after the geometry."),
    repeatability: float = typer.Option(None, "--repeatability", min=0.0, help="Robot repeatability 3σ (m); default 1e-4."),
    warm_up: str = typer.Option("", "--warm-up", help="Thermal: the arm warms as ΔT∞·(1 − exp(−t/τ)), given as TAU_S,DT_K "
                                "(e.g. 900,6); an injected thermal_drift=GX,GY,GZ is then in m/K of that rise."),
    temperature_sensor: bool = typer.Option(False, "--temperature-sensor", help="Thermal: log a temperature sensor "
                                            "(1 Hz, 0.05 K noise) on /arm/temperature."),
    dwell_s: float = typer.Option(None, "--dwell-s", min=0.0, help="Campaign: dwell (s) at the approach pose and at "
                                  "each contact (default 0.2); longer dwells make a longer campaign (warm-up)."),
    robot_id: str = typer.Option("sim-arc-welder", "--robot-id", help="Robot identity written to the campaign metadata."),
    start: str = typer.Option("", "--start", help="Campaign start, ISO 8601 UTC (e.g. 2026-07-01T08:00:00Z); "
                              "default 2026-01-01T00:00:00Z."),
    campaign_file: list[Path] = typer.Option([], "--campaign", help="Execute this planned campaign (robocal plan --out) "
                                             "on the true robot instead of drawing targets; misses go to /touch/miss. "
                                             "Repeat for the stages of a staged campaign: run back to back, one recording."),
    force: bool = force_option(),
) -> None:
    """Touch-sensing campaign of seed 000's arc-welding arm on the stepped jig."""
    from pipeline.errors import MAX_CONTACTS, MAX_COUNT, at_most

    for option, value in (("--contacts", contacts),):
        at_most(option, value, MAX_CONTACTS if option == "--contacts" else MAX_COUNT)
    from pipeline.models.jig import stepped_block
    from pipeline.recording.output import check_outputs, claim_outputs
    from pipeline.simulate.arc_welder import Campaign, Noise, simulate, truth_document
    from pipeline.systems import arc_welder as aw

    check_outputs(force, out=out, truth=truth)  # before any work: an existing recording only with --force
    nominal = aw.nominal_arm()
    true = aw.random_truth(nominal, np.random.default_rng(seed + 1_000_003)) if random_errors else aw.reference_truth()
    campaign, noise = Campaign(contacts=contacts, seed=seed), Noise(scale=noise_scale)
    if repeatability is not None:
        noise = Noise(repeatability_3sigma_m=repeatability, scale=noise_scale)
    if dwell_s is not None:
        campaign = replace(campaign, dwell_s=dwell_s)
    if start:
        campaign = replace(campaign, start_ns=_start_ns(start))
    from pipeline.errors import RobocalError
    from pipeline.plan.campaign import MAX_SAMPLES, expected_samples

    if not campaign_file and not expected_samples(campaign) <= MAX_SAMPLES:
        raise RobocalError(f"--contacts {contacts} --dwell-s {campaign.dwell_s}: ~{expected_samples(campaign):.3g} "
                           f"encoder samples, more than robocal simulates in one campaign ({MAX_SAMPLES:.0e})")
    jig = stepped_block()
    thermal = (warm_up, temperature_sensor)
    effects = (effect or payloads or search_speeds or face_order != "shuffled" or warm_up or temperature_sensor
               or payload_pairs)
    claim_outputs(force, out=out, truth=truth)  # with --force the old files kept as NAME.bak
    if campaign_file:  # a planned campaign on the true robot, with the effects when any are asked for
        _run_campaign(out, truth, nominal, true, jig, campaign_file, noise, seed, robot_id,
                      _effect_options(effect, payloads, search_speeds, face_order, thermal, payload_pairs) if effects
                      else None)
        return
    if effects:
        _with_effects(out, truth, nominal, true, jig, campaign, noise, effect, payloads, search_speeds, face_order,
                      thermal, payload_pairs, robot_id)  # the effects simulator (concealed physics)
        return
    with err.status(f"simulating {contacts} contacts…"):
        sim = simulate(nominal, true, jig, campaign, noise)
    _write(out, truth, nominal, jig, campaign, sim, truth_document(true, noise, campaign, sim), {"robot_id": robot_id})
    err.print(f"wrote {out} ({sim.stream_t_ns.size} encoder samples, {sim.contact_t_ns.size} contacts; "
              f"injected noise RMS {sim.injected_noise_rms_m * 1e3:.4f} mm)")


def _start_ns(text: str) -> int:
    """ISO 8601 (naive = UTC) → ns since the Unix epoch."""
    from datetime import datetime, timezone

    from pipeline.errors import RobocalError

    try:
        t = datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        raise RobocalError(f"--start {text!r}: not an ISO 8601 time (e.g. 2026-07-01T08:00:00Z)") from None
    t = t if t.tzinfo else t.replace(tzinfo=timezone.utc)
    return int(t.timestamp()) * 1_000_000_000 + t.microsecond * 1000


def _write(out: Path, truth: Path | None, nominal, jig, campaign, sim, truth_doc: dict, campaign_meta: dict,
           extra_events: list | tuple = ()) -> None:
    """Write the recording (nominal model, jig, campaign metadata, stream, contacts) and TRUTH.json."""
    from pipeline.recording.output import generated
    from pipeline.recording.schemas import META_CAMPAIGN, META_FIXTURE, META_ROBOT
    from pipeline.recording.writer import write_campaign
    from pipeline.systems import arc_welder as aw

    meta = {META_ROBOT: nominal.to_dict(), META_FIXTURE: jig.to_dict(),
            META_CAMPAIGN: {"system": aw.SYSTEM, "simulated": True, "contacts": campaign.contacts,
                            "controller_rate_hz": campaign.rate_hz, "search_speed_m_s": campaign.search_speed_m_s,
                            "approach_offset_m": campaign.approach_offset_m, **campaign_meta}}
    out.parent.mkdir(parents=True, exist_ok=True)
    with err.status("writing recording…"):
        write_campaign(out, meta, (sim.stream_t_ns, sim.stream_q, [j.name for j in nominal.joints]),
                       list(aw.contact_messages(sim)) + list(extra_events))
    if truth is not None:
        truth.parent.mkdir(parents=True, exist_ok=True)
        truth.write_text(json.dumps(generated(truth_doc), indent=2, default=float) + "\n")


def _run_campaign(out: Path, truth: Path | None, nominal, true, jig, campaign_files: list[Path], noise,
                  seed: int, robot_id: str = "sim-arc-welder", effects: tuple | None = None) -> None:
    """Execute planned campaign files, back to back, on the true robot (`pipeline.simulate.campaign_run`);
    `effects` (injected, variations) puts library effects into the true robot as `_with_effects` does."""
    from pipeline.errors import RobocalError
    from pipeline.plan.campaign import concat, read
    from pipeline.simulate import effects as se
    from pipeline.simulate.arc_welder import truth_document
    from pipeline.simulate.campaign_run import execute, execute_with_effects
    from pipeline.systems import arc_welder as aw

    plan = concat([read(f, aw.SYSTEM, nominal.n_joints, jig) for f in campaign_files])
    campaign_file = ", ".join(str(f) for f in campaign_files)
    with err.status(f"executing {plan.n} planned contacts…"):
        if effects is None:
            ex, es, extra = execute(nominal, true, jig, plan, noise, seed), None, []
        else:
            try:
                es, ex = execute_with_effects(nominal, true, jig, plan, noise, seed, *effects)
            except (ValueError, RuntimeError) as e:
                raise RobocalError(f"{campaign_file}: {e}") from None
            extra = es.temperature.messages() if es.temperature is not None else []
    sim = ex.sim
    camp = replace(plan.campaign, contacts=int(sim.contact_t_ns.size), seed=seed)
    meta = {"campaign_file": str(campaign_file), "planned": plan.n, "landed": int(ex.landed.sum()),
            "missed": int((~ex.landed).sum()), "stage": plan.doc["stage"], "stages": plan.doc["stages"]}
    doc = truth_document(true, noise, camp, sim) | {
        "campaign_execution": {**meta, "land_rate": ex.land_rate,
                               "misses": [{"index": int(i), "face": plan.face_id[i], "reason": r}
                                          for i, r in zip(ex.miss_index, ex.miss_reason)]}}
    if es is not None:
        doc |= se.truth_effects(es)
        meta = se.campaign_metadata(es, camp) | meta | {"robot_id": robot_id}
    _write(out, truth, nominal, jig, camp, sim, doc, meta, ex.miss_messages() + list(extra))
    err.print(f"wrote {out}: {plan.n} planned contacts, {meta['landed']} landed, {meta['missed']} missed "
              f"(logged on /touch/miss); {sim.stream_t_ns.size} encoder samples"
              + (f"; {len(effects[0])} concealed effect(s)" if effects else ""))


def _effect_options(effect, payloads, search_speeds, face_order, thermal_opts, payload_pairs,
                    planned: bool = True) -> tuple:
    """(injected effects, Variations) from the command's options (one-line errors); `planned`: for a
    campaign file (which fixes the targets: no --payload-pairs)."""
    from pipeline.errors import RobocalError
    from pipeline.simulate import effects as se
    from pipeline.simulate.thermal import parse_warm_up

    def floats(text: str, what: str) -> tuple[float, ...]:
        try:
            return tuple(float(v) for v in text.split(",") if v.strip())
        except ValueError:
            raise RobocalError(f"{what} {text!r}: expected comma-separated numbers") from None

    try:
        injected = [se.parse_effect(e) for e in effect]
        warm = parse_warm_up(thermal_opts[0])
    except ValueError as e:
        raise RobocalError(str(e)) from None
    if payload_pairs and planned:
        raise RobocalError("--payload-pairs chooses its own targets; it does not combine with --campaign")
    return injected, se.Variations(payloads_kg=floats(payloads, "--payloads"),
                                   search_speeds_m_s=floats(search_speeds, "--search-speeds"), face_order=face_order,
                                   warm_up=(warm.tau_s, warm.rise_k) if warm else (),
                                   temperature_sensor=thermal_opts[1], payload_pairs=payload_pairs)


def _with_effects(out, truth, nominal, true, jig, campaign, noise, effect, payloads, search_speeds, face_order,
                  thermal_opts: tuple[str, bool] = ("", False), payload_pairs: bool = False,
                  robot_id: str = "sim-arc-welder") -> None:
    """Campaign with concealed effects and campaign variations (`pipeline.simulate.effects`)."""
    from pipeline.errors import RobocalError
    from pipeline.simulate import effects as se
    from pipeline.simulate.arc_welder import truth_document

    injected, var = _effect_options(effect, payloads, search_speeds, face_order, thermal_opts, payload_pairs, False)
    try:
        if payload_pairs and len(var.payloads_kg) < 2:
            raise ValueError("--payload-pairs needs two or more --payloads (e.g. --payloads 0,6)")
        with err.status(f"planning {campaign.contacts} contacts…"):
            targets = se.plan_targets(nominal, jig, campaign, truth=true,
                                      payloads_kg=var.payloads_kg if payload_pairs else ())
        es = se.run(nominal, true, jig, targets, campaign, noise, injected, var)
    except (ValueError, RuntimeError) as e:
        raise RobocalError(str(e)) from None
    sim = es.sim
    _write(out, truth, nominal, jig, campaign, sim, truth_document(true, noise, campaign, sim) | se.truth_effects(es),
           se.campaign_metadata(es, campaign) | {"robot_id": robot_id}, es.temperature.messages() if es.temperature is not None else ())
    err.print(f"wrote {out} ({sim.stream_t_ns.size} encoder samples, {sim.contact_t_ns.size} contacts, "
              f"{len(injected)} concealed effect(s))")
