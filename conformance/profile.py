"""Conformance profiles: which checks run, with which limits, in TOML.

A profile is a file in ``conformance/profiles/`` (``default``, ``bench``, ``ci``) or a user's
own ``.toml``::

    name = "default"
    description = "what this profile gates"

    [settings]
    realtime_seconds = 30        # the real-time segment over the pty, s of device time
    replay = "full"              # accuracy: replay the whole recording as fast as it goes
    faults = "drop:rate=0.002"   # emulator faults when the target names none ("" for none)
    conversion_examples = 400    # hypothesis examples per conversion property
    seed = 0                     # hypothesis and fault seed
    latency_attempts = 1         # real-time segments the latency check may take (see below)

    [checks.accuracy]            # one table per check; its keys are measurement limits
    "accuracy.rmse.elv_angle" = "< 3.0 deg"

    [checks.heldout]             # a check with no limit keys runs with its built-in limits

A limit is ``"< X unit"``, ``"<= X unit"``, ``"> X unit"``, ``">= X unit"`` or
``"LOW .. HIGH unit"``; the unit must be one of :data:`exohil.formats.measurement.UNITS` and of
the measurement's quantity. An unknown check, setting, measurement or unit is a ProfileError.
Checks not named in a profile do not run (reported as skipped, never as passed).
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from exohil.estimator.coverage import OUTSIDE_SHARE_PERCENT
from exohil.formats.errors import InputError
from exohil.formats.measurement import Limit, check_unit, convert
from exohil.harness.cli_types import MAX_DURATION_S, SEED_MAX

PROFILES_DIR = Path(__file__).parent / "profiles"


class ProfileError(InputError, ValueError):
    """A profile that cannot be used; the message names the file and the problem."""


#: check → {measurement name: unit}. Measurement names ending in ``.*`` stand for a family
#: (the model's angles, NAO's joints, the distribution statistics p50/p99/max).
CHECKS: dict[str, dict[str, str]] = {
    "compatibility": {"compatibility.sensor_mismatch": "count",
                      "compatibility.angle_mismatch": "count",
                      "compatibility.rate_mismatch": "count",
                      "compatibility.outside_training": "%"},
    "heldout": {"heldout.overlap": "count"},
    "accuracy": {"accuracy.rmse.*": "deg", "accuracy.direction_rmse": "deg",
                 "accuracy.frames_scored": "count", "accuracy.reference_coverage": "%"},
    "latency": {"latency.end_to_end.*": "ms", "latency.estimator.*": "ms",
                "latency.device_to_host.*": "ms", "latency.decode.*": "ms",
                "latency.queue_and_estimate.*": "ms", "latency.command.*": "ms",
                "latency.host.*": "ratio", "latency.attempts": "count"},
    "link": {"link.frames": "count", "link.rate": "Hz", "link.dropped": "count",
             "link.crc_errors": "count", "link.decode_errors": "count",
             "link.overflow": "count", "link.lost_on_host": "count",
             "link.bad_frames_delivered": "count", "link.dropped_unexplained": "count",
             "link.lost": "count", "link.rejected": "count", "link.sequence_resets": "count",
             "link.disconnects": "count"},
    "conversions": {"conversions.failures": "count", "conversions.examples": "count",
                    "conversions.max_error": "deg"},
    "teleop": {"teleop.rmse.*": "deg", "teleop.clamped_share": "ratio",
               "teleop.mapping_error": "deg"},
    "regression": {"regression.accuracy.rmse.*": "deg",
                   "regression.accuracy.direction_rmse": "deg",
                   "regression.latency_p99_ratio": "x"},
}
#: Tolerance of ``teleop.mapping_error``, deg: float round-off only (see BUILTIN_LIMITS).
TELEOP_MAPPING_TOLERANCE_DEG = 1e-6
#: Limits a check always applies unless the profile states its own for that measurement.
BUILTIN_LIMITS: dict[str, dict[str, Limit]] = {
    "compatibility": {"compatibility.sensor_mismatch": Limit(high=0, unit="count",
                                                             inclusive=True),
                      "compatibility.angle_mismatch": Limit(high=0, unit="count",
                                                            inclusive=True),
                      "compatibility.rate_mismatch": Limit(high=0, unit="count",
                                                           inclusive=True),
                      "compatibility.outside_training": Limit(high=OUTSIDE_SHARE_PERCENT,
                                                              unit="%")},
    "heldout": {"heldout.overlap": Limit(high=0, unit="count", inclusive=True)},
    "link": {"link.lost_on_host": Limit(high=0, unit="count", inclusive=True),
             "link.bad_frames_delivered": Limit(high=0, unit="count", inclusive=True),
             "link.dropped_unexplained": Limit(high=0, unit="count", inclusive=True),
             "link.overflow": Limit(high=0, unit="count", inclusive=True)},
    "conversions": {"conversions.failures": Limit(high=0, unit="count", inclusive=True)},
    # The sink and the reference run the same float operations on the same poses, so they
    # agree bit for bit (0 measured); the tolerance only leaves room for a reordered float
    # expression, and is the conversions check's (whose properties hold to ~1e-10 deg), far
    # below any wiring error (a swapped joint or angle is degrees off).
    "teleop": {"teleop.mapping_error": Limit(high=TELEOP_MAPPING_TOLERANCE_DEG, unit="deg",
                                             inclusive=True)},
}
SETTINGS: dict[str, type] = {"realtime_seconds": float, "replay": str, "faults": str,
                             "conversion_examples": int, "seed": int,
                             "regression_accuracy_margin_deg": float,
                             "regression_latency_factor": float, "latency_attempts": int}
_KIND_NAMES = {int: "an integer", float: "a number", str: "a string"}
DEFAULT_SETTINGS: dict[str, Any] = {
    "realtime_seconds": 30.0, "replay": "full", "faults": "", "conversion_examples": 400,
    "seed": 0, "regression_accuracy_margin_deg": 0.25, "regression_latency_factor": 1.5,
    "latency_attempts": 1,
}
_LIMIT = re.compile(r"^\s*(?:(<=|<|>=|>)\s*(\S+)|(\S+)\s*\.\.\s*(\S+))\s+(\S+)\s*$")


def parse_limit(text: str) -> Limit:
    """``"< 3 deg"`` → Limit; ProfileError on anything else."""
    match = _LIMIT.match(text)
    if not match:
        raise ProfileError(f"limit {text!r} is not '< X unit', '<= X unit', '> X unit', "
                           "'>= X unit' or 'LOW .. HIGH unit'")
    op, value, low, high, unit = match.groups()
    try:
        check_unit(unit)
        if op is None:
            if float(low) > float(high):
                raise ValueError(f"its low end {low} is above its high end {high}: no value "
                                 "can pass")
            return Limit(low=float(low), high=float(high), unit=unit, inclusive=True)
        x = float(value)
    except ValueError as err:
        raise ProfileError(f"limit {text!r}: {err}") from None
    if op in ("<", "<="):
        return Limit(high=x, unit=unit, inclusive=op == "<=")
    # "> x" is ">= x" up to the float next to x; exohil's figures are continuous
    return Limit(low=x, unit=unit)


def _family(check: str, measurement: str) -> str | None:
    """The unit of ``measurement`` in ``check``'s vocabulary, or None if it is not there."""
    for name, unit in CHECKS[check].items():
        if name == measurement or (name.endswith(".*") and
                                   measurement.startswith(name[:-1]) and
                                   measurement.count(".") == name.count(".")):
            return unit
    return None


@dataclass(frozen=True)
class Profile:
    """A loaded profile: its checks and their limits, and the run settings."""

    name: str
    description: str
    checks: dict[str, dict[str, Limit]]
    settings: dict[str, Any] = field(default_factory=dict)
    path: Path | None = None

    def limits(self, check: str) -> dict[str, Limit]:
        """The built-in limits of ``check`` overlaid with the profile's."""
        return {**BUILTIN_LIMITS.get(check, {}), **self.checks.get(check, {})}

    def setting(self, name: str) -> Any:
        return self.settings.get(name, DEFAULT_SETTINGS[name])


#: numeric setting → (low, high), both inclusive; the values are finite.
_SETTING_RANGES: dict[str, tuple[float, float]] = {
    "realtime_seconds": (0.1, MAX_DURATION_S), "conversion_examples": (1, 100_000),
    "seed": (0, SEED_MAX), "regression_accuracy_margin_deg": (0.0, 360.0),
    "regression_latency_factor": (1.0, 1000.0), "latency_attempts": (1, 10),
}


def _settings_problem(settings: dict[str, Any]) -> str | None:
    """What is wrong with the settings' values (range, fault spec), or None."""
    for key, (low, high) in _SETTING_RANGES.items():
        value = settings.get(key)
        if value is not None and not (math.isfinite(value) and low <= value <= high):
            return f"setting {key} must be within {low:g}..{high:g}, got {value!r}"
    if settings.get("faults"):
        from exohil.emulators.fault_spec import fault_plan

        try:
            fault_plan(settings["faults"])
        except (ValueError, OSError) as err:
            return f"setting faults: {err}"
    return None


def profile_path(name_or_path: str) -> Path:
    """A bundled profile by name, or a ``.toml`` path."""
    if name_or_path.endswith(".toml"):
        return Path(name_or_path)
    path = PROFILES_DIR / f"{name_or_path}.toml"
    if not path.is_file():
        bundled = ", ".join(sorted(p.stem for p in PROFILES_DIR.glob("*.toml")))
        if Path(name_or_path).is_file():  # a file, but not a profile's .toml
            raise ProfileError(f"{name_or_path}: a profile file must end in .toml; bundled "
                               f"profiles: {bundled}")
        raise ProfileError(f"no profile {name_or_path!r}; bundled: {bundled} "
                           "(or give a path to a .toml file)")
    return path


def load_profile(name_or_path: str) -> Profile:
    """Load and validate a profile (module doc); ProfileError names any problem."""
    path = profile_path(name_or_path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as err:
        raise ProfileError(f"{path}: {err}") from None
    unknown = sorted(set(data) - {"name", "description", "settings", "checks"})
    if unknown:
        raise ProfileError(f"{path}: unknown key(s) {', '.join(unknown)}")
    for key in ("settings", "checks"):
        if not isinstance(data.get(key, {}), dict):
            raise ProfileError(f"{path}: {key} must be a table ([{key}]), got "
                               f"{type(data[key]).__name__} {data[key]!r}")
    settings = dict(data.get("settings", {}))
    for key, value in settings.items():
        if key not in SETTINGS:
            raise ProfileError(f"{path}: unknown setting {key!r}; allowed: "
                               f"{', '.join(SETTINGS)}")
        kind = SETTINGS[key]
        if kind is float and isinstance(value, int) and not isinstance(value, bool):
            settings[key] = value = float(value)
        if not isinstance(value, kind) or isinstance(value, bool):
            raise ProfileError(f"{path}: setting {key} must be {_KIND_NAMES[kind]}")
    if settings.get("replay", "full") not in ("full", "none"):
        raise ProfileError(f"{path}: replay must be 'full' or 'none'")
    problem = _settings_problem(settings)
    if problem:
        raise ProfileError(f"{path}: {problem}")
    checks: dict[str, dict[str, Limit]] = {}
    for check, limits in data.get("checks", {}).items():
        if check not in CHECKS:
            raise ProfileError(f"{path}: unknown check {check!r}; known: {', '.join(CHECKS)}")
        if not isinstance(limits, dict):
            raise ProfileError(f"{path}: [checks.{check}] must be a table of limits")
        parsed = {}
        for measurement, text in limits.items():
            if isinstance(text, dict):  # TOML reads an unquoted dotted key as nested tables
                raise ProfileError(f"{path}: [checks.{check}]: {measurement}.… is a table, "
                                   "not a limit: put the measurement's dotted name in quotes "
                                   f'("{check}.….…" = "< X unit")')
            unit = _family(check, measurement)
            if unit is None:
                raise ProfileError(f"{path}: check {check!r} has no measurement "
                                   f"{measurement!r}; it measures {', '.join(CHECKS[check])}")
            try:
                limit = parse_limit(str(text))
                convert(1.0, limit.unit, unit)
            except (ProfileError, ValueError) as err:
                raise ProfileError(f"{path}: {measurement}: {err}") from None
            parsed[measurement] = limit
        checks[check] = parsed
    return Profile(str(data.get("name", path.stem)), str(data.get("description", "")), checks,
                   settings, path)

