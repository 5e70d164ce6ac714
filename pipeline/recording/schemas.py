"""Message schemas, loaded from the JSON Schema files in `schemas/` (the files the writer registers)."""

from __future__ import annotations

import json
from functools import cache
from pathlib import Path

import jsonschema

# channel -> schema file stem (the public contract; see README)
CHANNELS: dict[str, str] = {
    "/robot/joint_state": "joint_state",
    "/touch/contact": "touch_contact",
    "/touch/miss": "touch_miss",
    "/scanner/stripe": "scanner_stripe",
    "/tracker/point": "tracker_point",
    "/arm/temperature": "temperature",
    "/arm/payload": "payload",
    "/measure/point": "measure_point",
    "/measure/pose": "measure_pose",
    "/measure/plane": "measure_plane",
    "/measure/coincidence": "measure_coincidence",
    "/measure/camera": "measure_camera",
}

STREAM = "/robot/joint_state"  # the encoder stream: protobuf `robocal.JointStateBatch` (JSON when archived)

# metadata record names
META_ROBOT = "robocal.robot_model"
META_FIXTURE = "robocal.fixture"
META_CAMPAIGN = "robocal.campaign"
META_URDF = "robocal.urdf"


def schema_dir() -> Path:
    """Installed copy (wheel) or the repository's `schemas/` (editable install)."""
    here = Path(__file__).resolve().parent.parent
    for cand in (here / "_schemas", here.parent / "schemas"):
        if cand.is_dir():
            return cand
    raise FileNotFoundError("robocal schemas/ directory not found")


@cache
def schema_bytes(stem: str) -> bytes:
    return (schema_dir() / f"{stem}.schema.json").read_bytes()


@cache
def schema(stem: str) -> dict:
    return json.loads(schema_bytes(stem))


@cache
def validator(stem: str) -> jsonschema.protocols.Validator:
    s = schema(stem)
    cls = jsonschema.validators.validator_for(s)
    return cls(s)


def schema_title(stem: str) -> str:
    return schema(stem)["title"]
