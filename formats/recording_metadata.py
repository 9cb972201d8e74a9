"""The ``exohil.recording`` metadata record of recording format v1: its defaults, the record a
writer builds, and the checked, defaulted reading of it (see docs/recording-format.md).

Metadata is str → str. The reserved keys (format, version, sensors, units, rates, segments)
are computed by the writer; on reading, a missing ``sensors``, ``units`` or rate falls back to
a default with a note, and a wrong format or version raises
:class:`~exohil.formats.errors.RecordingError` naming the file.
"""

from __future__ import annotations

import json
import math
import numbers
from collections.abc import Mapping, Sequence
from pathlib import Path

from mcap.records import Metadata

from exohil.formats import strict_json
from exohil.formats.digest import sha256_file
from exohil.formats.errors import RecordingError
from exohil.formats.recording import (
    FORMAT_NAME,
    FORMAT_VERSION,
    SENSOR_TOPIC,
    Recording,
    Segment,
)

METADATA_NAME = "exohil.recording"
ANGLE_UNIT = "deg"
DEFAULT_SUIT_SENSORS = ("F", "SF", "SR", "R")
DEFAULT_SENSOR_RATE_HZ = 250.0
DEFAULT_MOCAP_RATE_HZ = 120.0
RESERVED_KEYS = frozenset(
    {"format", "version", "sensors", "units", "sensor_rate_hz", "mocap_rate_hz", "segments"}
)


def format_number(value: float) -> str:
    """Metadata text of a rate or other number: integers without '.0', at most 12 digits."""
    return format(float(value), ".12g")


# ----------------------------------------------------------------------------- writing


def plain_field(text: str) -> bool:
    """Whether ``text`` can stand in a comma-separated metadata field (``sensors``,
    ``units``): not empty, no comma, no outer spaces."""
    return bool(text) and "," not in text and text == text.strip()


def metadata_record(
    path: Path,
    sensor_names: tuple[str, ...],
    sensor_units: str,
    sensor_rate_hz: float,
    mocap_rate_hz: float,
    extra: Mapping[str, str] | None,
) -> dict[str, str]:
    """The record a writer stores: ``extra`` (str → str, reserved keys dropped) plus the
    reserved keys computed from the arguments (segments are added at close); without
    sensors the default ``sensor_rate_hz`` is left out, as no sensor was sampled at it."""
    for what, rate in (("sensor_rate_hz", sensor_rate_hz), ("mocap_rate_hz", mocap_rate_hz)):
        if isinstance(rate, bool) or not isinstance(rate, numbers.Real) \
                or not math.isfinite(rate) or not rate > 0:
            raise RecordingError(f"{path}: {what} must be a positive number of Hz, got {rate!r}")
    if not plain_field(sensor_units):
        raise RecordingError(f"{path}: invalid sensor unit {sensor_units!r} (empty, comma, "
                             "spaces): `units` is '<sensor unit>,deg'")
    record: dict[str, str] = {}
    for key, value in (extra or {}).items():
        if not isinstance(key, str) or not isinstance(value, str):
            raise RecordingError(f"{path}: metadata must be str → str, got {key!r}: {value!r}")
        if key not in RESERVED_KEYS:
            record[key] = value
    record.update(
        {
            "format": FORMAT_NAME,
            "version": str(FORMAT_VERSION),
            "sensors": ",".join(sensor_names),
            "units": f"{sensor_units},{ANGLE_UNIT}",
            "sensor_rate_hz": format_number(sensor_rate_hz),
            "mocap_rate_hz": format_number(mocap_rate_hz),
        }
    )
    if not sensor_names and sensor_rate_hz == DEFAULT_SENSOR_RATE_HZ:
        # no sensors (imported motion), no sensor rate to claim; a reader falls back to this
        # same default, so leaving it out loses nothing (a rate given otherwise is kept)
        del record["sensor_rate_hz"]
    return record


def segments_text(segments: Sequence[Segment]) -> str:
    """The ``segments`` metadata value: compact JSON list of {name, t0, t1}."""
    return json.dumps(
        [{"name": s.name, "t0": s.t0, "t1": s.t1} for s in segments],
        separators=(",", ":"),
    )


# ----------------------------------------------------------------------------- reading


def merged_metadata(path: Path, records: list[Metadata], notes: list[str]) -> dict[str, str]:
    """The ``exohil.recording`` records merged in file order, format and version checked;
    other metadata records are ignored with a note."""
    ours = [record for record in records if record.name == METADATA_NAME]
    for record in records:
        if record.name != METADATA_NAME:
            notes.append(f"ignored metadata record {record.name!r}")
    if not ours:
        raise RecordingError(
            f"{path}: no '{METADATA_NAME}' metadata record; not an exohil recording"
        )
    if len(ours) > 1:
        notes.append(f"{len(ours)} '{METADATA_NAME}' records; merged in file order")
    metadata: dict[str, str] = {}
    for record in ours:
        metadata.update(record.metadata)
    found_format = metadata.get("format")
    if found_format != FORMAT_NAME:
        raise RecordingError(
            f"{path}: metadata format is {found_format!r}, expected {FORMAT_NAME!r}"
        )
    found_version = metadata.get("version")
    if found_version != str(FORMAT_VERSION):
        raise RecordingError(
            f"{path}: unsupported recording format version {found_version!r} "
            f"(this reader supports {FORMAT_VERSION})"
        )
    return metadata


def sensor_names(
    path: Path, metadata: dict[str, str], messages: list[tuple[int, bytes]], notes: list[str]
) -> tuple[str, ...]:
    """Sensor names from ``sensors``; without it, the suit's four names for four values per
    frame, else ``ch0, ch1, ...`` (counted in the first message)."""
    text = metadata.get("sensors")
    if text is not None:
        names = tuple(name.strip() for name in text.split(",") if name.strip())
        twice = sorted({name for name in names if names.count(name) > 1})
        if twice:  # the writer refuses them: a part cut from it could not be written
            raise RecordingError(f"{path}: metadata sensors {text!r} names "
                                 f"{', '.join(twice)} twice; each sensor needs its own name")
        return names
    if not messages:
        return ()
    try:
        count = len(strict_json.loads(messages[0][1])["values"])
    except (ValueError, KeyError, TypeError) as exc:
        raise RecordingError(f"{path}: {SENSOR_TOPIC} message 0 is not a sensor frame") from exc
    names = DEFAULT_SUIT_SENSORS if count == 4 else tuple(f"ch{k}" for k in range(count))
    notes.append(f"metadata has no 'sensors'; using {','.join(names)}")
    return names


def sensor_units(path: Path, metadata: dict[str, str]) -> str:
    """The sensor unit from ``units`` ("<sensor unit>,deg"; default mm)."""
    text = metadata.get("units", f"mm,{ANGLE_UNIT}")
    sensor_unit, _, angle_unit = text.rpartition(",")
    if not sensor_unit:
        return text or "mm"
    if angle_unit.strip().lower() not in ("deg", "degree", "degrees"):
        raise RecordingError(f"{path}: angle unit {angle_unit!r} unsupported (v1 uses deg)")
    return sensor_unit.strip()


#: A nominal rate more than this factor from what the timestamps give (either way) is noted:
#: times written in another unit than seconds, most likely.
RATE_DISAGREEMENT = 2.0


def rates_disagree(nominal_hz: float, measured_hz: float) -> bool:
    """Whether a nominal rate and the rate the timestamps give differ by more than
    :data:`RATE_DISAGREEMENT` times either way."""
    return not 1 / RATE_DISAGREEMENT < nominal_hz / measured_hz < RATE_DISAGREEMENT


def rate_the_times_give(rec: Recording) -> float | None:
    """The sensor rate ``rec``'s timestamps give (Hz) where it disagrees with its nominal
    ``sensor_rate_hz`` (:func:`rates_disagree`: times in another unit than seconds, most
    likely), else None."""
    measured = rec.sensors.rate_from_times()
    if math.isfinite(measured) and measured > 0 and rates_disagree(rec.sensor_rate_hz,
                                                                   measured):
        return measured
    return None


def cut_lineage(metadata: dict[str, str]) -> list[str]:
    """The sha256 of every recording a recording was cut from (``exohil record cut``
    writes ``cut.source_sha256``, and ``cut.origins_sha256`` for a part of a part),
    nearest first; empty for one that was not cut."""
    return [d for d in (metadata.get("cut.source_sha256", ""),
                        *metadata.get("cut.origins_sha256", "").split(",")) if d]


def source_entry(path: Path, rec: Recording, sha256: str | None = None) -> dict:
    """What a checkpoint's ``info.sources`` records of one recording read from ``path``, so
    that the heldout check sees a part cut from the recording it scores (the check describes
    that recording the same way): ``file``, ``sha256`` (given when already known) and, where
    it has sensor frames, ``cut_from`` (:func:`cut_lineage`; empty for a recording that was
    not cut, and absent only in checkpoints written before) and ``span_s``, its first and
    last sensor frame times. ``exohil record cut`` keeps times as they were, so these lie on
    the clock of every recording it was cut from."""
    entry: dict = {"file": path.name, "sha256": sha256 or sha256_file(path)}
    if len(rec.sensors):
        entry.update(cut_from=cut_lineage(rec.metadata),
                     span_s=[float(rec.sensors.t[0]), float(rec.sensors.t[-1])])
    return entry


def shared_frames(scored: dict, trained: dict) -> tuple[bool, str]:
    """Whether recording ``scored`` may hold frames of training recording ``trained``, and
    why (empty when unrelated). Both are ``info.sources``-style entries: ``file``,
    ``sha256`` and, for a cut, :func:`source_entry`'s other keys (an entry without them, as older
    checkpoints write, is taken as not cut). Two parts of one recording share no frame
    only where both spans are known and do not meet; any other relation is an overlap."""
    name, other = scored.get("file", "?"), trained.get("file", "?")
    digest, trained_digest = scored.get("sha256"), trained.get("sha256")
    if digest == trained_digest:
        return True, f"{name} was used to train the model (as {other})"
    if trained_digest in scored.get("cut_from", []):
        return True, f"{name} was cut from the training recording {other}"
    if digest in trained.get("cut_from", []):
        return True, f"the training recording {other} was cut from {name}"
    common = [d for d in scored.get("cut_from", []) if d in trained.get("cut_from", [])]
    if not common:
        return False, ""
    shared = f"{name} and the training recording {other} were cut from one recording " \
             f"(sha256 {common[0][:12]}…)"
    span, trained_span = scored.get("span_s"), trained.get("span_s")
    if not (span and trained_span):
        return True, f"{shared}, and their times are not known"
    if span[1] < trained_span[0] or trained_span[1] < span[0]:
        return False, (f"{shared} but from other times ({span[0]:.3f}–{span[1]:.3f} s and "
                       f"{trained_span[0]:.3f}–{trained_span[1]:.3f} s): no frame in common")
    return True, (f"{shared} in overlapping times ({span[0]:.3f}–{span[1]:.3f} s and "
                  f"{trained_span[0]:.3f}–{trained_span[1]:.3f} s)")


def rate(
    path: Path, metadata: dict[str, str], key: str, estimate: float, notes: list[str]
) -> float:
    """The metadata rate ``key``; when absent, ``estimate`` (or the v1 default if NaN)."""
    text = metadata.get(key)
    if text is not None:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and value > 0):
            raise RecordingError(f"{path}: metadata {key}={text!r} is not a positive number")
        if math.isfinite(estimate) and estimate > 0 and rates_disagree(value, estimate):
            notes.append(f"metadata {key}={text} but the timestamps give "
                         f"{estimate:.4g} Hz: are the times in seconds?")
        return value
    default = DEFAULT_SENSOR_RATE_HZ if key == "sensor_rate_hz" else DEFAULT_MOCAP_RATE_HZ
    value = estimate if math.isfinite(estimate) and estimate > 0 else default
    notes.append(f"metadata has no {key}; using {value:.6g} Hz (from the timestamps)"
                 if value == estimate else f"metadata has no {key}; using {value:g} Hz")
    return value


def segments(path: Path, metadata: dict[str, str]) -> list[Segment]:
    """The labelled spans in ``segments`` (none when absent)."""
    text = metadata.get("segments")
    if not text:
        return []
    try:
        items = strict_json.loads(text)
        found = [Segment(str(s["name"]), float(s["t0"]), float(s["t1"])) for s in items]
    except (ValueError, KeyError, TypeError) as exc:
        raise RecordingError(
            f"{path}: metadata 'segments' is not a JSON list of {{name, t0, t1}}: {exc}"
        ) from exc
    for segment in found:
        if not (math.isfinite(segment.t0) and math.isfinite(segment.t1)):
            raise RecordingError(f"{path}: segment {segment.name!r} has a non-finite time")
    return found
