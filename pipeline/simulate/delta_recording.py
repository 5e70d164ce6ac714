"""Writing a simulated laser-tracker campaign of the Delta robot (`pipeline.simulate.delta_tracker`):
the recording (nominal robot, tracker fixture and campaign metadata, the encoder stream,
`/tracker/point` messages) and TRUTH.json (true parameters and realised errors, never in the recording)."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np

from pipeline.models.delta import Delta
from pipeline.simulate.delta_tracker import (Campaign, Noise, SimResult, Truth, Variations, simulate,
                                             simulate_effects)
from pipeline.systems.delta_tracker import H_NOMINAL


def tracker_messages(sim: SimResult) -> list[tuple[str, dict]]:
    """`/tracker/point` message bodies of a simulated campaign."""
    idx = range(sim.t_ns.size) if sim.point_index is None else [int(i) for i in sim.point_index]
    return [("/tracker/point", {"timestamp_ns": int(t), "joint_positions": q, "point": p, "point_index": i})
            for i, t, q, p in zip(idx, sim.t_ns, np.round(sim.q, 12).tolist(), sim.point_t.tolist())]


def truth_document(delta: Delta, truth: Truth, noise: Noise, campaign: Campaign, sim: SimResult) -> dict:
    """TRUTH.json: true parameters and realised errors (never written to the recording)."""
    return {
        "system": "delta-tracker",
        "truth_model": truth.model,
        "nominal": delta.to_dict(),
        "parameters": truth.parameters(),
        "noise": asdict(noise),
        "campaign": {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(campaign).items()},
        "tracker_noise_rms_m": sim.tracker_noise_rms_m,
        "measurement_error_rms_m": sim.measurement_error_rms_m,
        "note": "tracker_noise_rms_m: injected tracker noise per axis; measurement_error_rms_m: the whole error "
                "a perfect model would leave (tracker noise plus encoder quantisation), per axis",
    }


def recording_metadata(delta: Delta, campaign: Campaign, noise: Noise) -> dict[str, dict]:
    """Metadata records of a campaign: nominal robot, tracker/reflector fixture, campaign plan."""
    from pipeline.recording.schemas import META_CAMPAIGN, META_FIXTURE, META_ROBOT

    return {
        META_ROBOT: delta.to_dict(),
        META_FIXTURE: {"kind": "laser_tracker", "reflector_offset_m": H_NOMINAL,
                       "note": "reflector (SMR centre) sits reflector_offset_m below the platform point P "
                               "along the platform's w axis (seed 003 eq. 13)"},
        META_CAMPAIGN: {"system": "delta-tracker", "simulated": True, "robot_id": "sim-delta-tracker",
                        "grid": list(campaign.grid), "spacing_m": list(campaign.spacing_m),
                        "center_m": list(campaign.center_m), "random_points": campaign.points,
                        "controller_rate_hz": campaign.rate_hz, "settle_s": campaign.settle_s,
                        "tracker_sigma_m": noise.tracker_sigma_m * noise.scale},
    }


def write(path, delta: Delta, truth: Truth, campaign: Campaign = Campaign(), noise: Noise = Noise(),
          truth_path=None, effects: tuple = (), variations: "Variations | None" = None,
          error_model: str | None = None) -> SimResult:
    """Simulate and write REC.mcap (and TRUTH.json if `truth_path`).  With `effects` or
    `variations`, the campaign with concealed effects (`simulate_effects`); the effects go to
    TRUTH.json only, the variations (what the integrator programmed) to the campaign metadata.
    `error_model` ("simplified"/"extended"): the error model the robot's metadata asks
    identification for (`pipeline.systems.delta_tracker.load`); None leaves it out."""
    from pipeline.recording.output import generated
    from pipeline.recording.writer import write_campaign

    varied = bool(effects) or (variations is not None and variations != Variations())
    var = variations or Variations()
    sim = simulate_effects(delta, truth, campaign, noise, effects, var) if varied else simulate(delta, truth, campaign, noise)
    meta = recording_metadata(delta, campaign, noise)
    if error_model is not None:
        from pipeline.recording.schemas import META_ROBOT
        meta[META_ROBOT]["error_model"] = error_model
    if varied:
        from pipeline.recording.schemas import META_CAMPAIGN
        meta[META_CAMPAIGN].update({"both_sides": var.both_sides, "passes": var.passes, "warmup_s": var.warmup_s,
                                    "approach_overshoot_rad": var.overshoot_rad if var.both_sides else None})
    temp_msgs = sim.temperature.messages() if sim.temperature is not None else []
    write_campaign(path, meta, (sim.stream_t_ns, sim.stream_q, ["A1", "A2", "A3"]), tracker_messages(sim) + temp_msgs)
    if truth_path is not None:
        doc = truth_document(delta, truth, noise, campaign, sim)
        if varied:
            doc["effects"] = [{"effect": e.name, "location": e.location, "values": list(e.values)} for e in effects]
            doc["variations"] = asdict(var)
        Path(truth_path).write_text(json.dumps(generated(doc), indent=2) + "\n")
    return sim
