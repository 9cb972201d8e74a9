"""JSON schemas of recording format v1 messages (MCAP schema encoding ``jsonschema``).

``/suit/sensors`` carries :func:`sensor_frame_schema` messages
``{"seq": int, "t": s, "values": [mm, ...]}``; ``/mocap/<joint>`` carries
:func:`joint_angles_schema` messages ``{"t": s, "<angle>": deg, ...}``. The schemas are
serialised with sorted keys and fixed separators (:func:`schema_bytes`) so files are
reproducible byte for byte.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any

SENSOR_SCHEMA_NAME = "exohil.SensorFrame"
SCHEMA_ENCODING = "jsonschema"
MESSAGE_ENCODING = "json"


def sensor_frame_schema(sensor_count: int) -> dict[str, Any]:
    """Schema of one ``/suit/sensors`` frame carrying ``sensor_count`` values."""
    return {
        "title": SENSOR_SCHEMA_NAME,
        "type": "object",
        "properties": {
            "seq": {"type": "integer", "description": "device frame counter, unwrapped"},
            "t": {"type": "number", "description": "device clock, seconds"},
            "values": {
                "type": "array",
                "items": {"type": "number"},
                "minItems": sensor_count,
                "maxItems": sensor_count,
                "description": "sensor values in metadata 'sensors' order and 'units' unit",
            },
        },
        "required": ["seq", "t", "values"],
    }


def joint_angles_schema_name(joint: str) -> str:
    """Schema name of a joint's angle messages, e.g. ``exohil.ShoulderAngles``."""
    return f"exohil.{joint[:1].upper()}{joint[1:]}Angles"


def joint_angles_schema(joint: str, angle_names: Sequence[str]) -> dict[str, Any]:
    """Schema of one ``/mocap/<joint>`` sample: ``t`` in seconds plus each angle in degrees."""
    properties: dict[str, Any] = {"t": {"type": "number", "description": "seconds"}}
    for name in angle_names:
        properties[name] = {"type": "number", "description": "degrees"}
    return {
        "title": joint_angles_schema_name(joint),
        "type": "object",
        "properties": properties,
        "required": ["t", *angle_names],
    }


def schema_bytes(schema: dict[str, Any]) -> bytes:
    """Canonical UTF-8 JSON of a schema (sorted keys, compact separators)."""
    return json.dumps(schema, sort_keys=True, separators=(",", ":")).encode("utf-8")
