"""Fault plans from a spec string or a TOML file (docs/emulator.md).

Spec string: faults separated by ``;``, each ``kind`` or ``kind:param=value,param=value``::

    noise:sigma_mm=0.5;drop:rate=0.01,burst=3;corrupt:rate=0.001;stall:every_s=5,duration_ms=40

TOML: an array of tables named ``fault``, each with a ``kind`` key::

    [[fault]]
    kind = "drop"
    rate = 0.01
    burst = 3

Frame/byte-level kinds are those of :data:`exohil.emulators.faults.FRAME_FAULT_TYPES`; any
other kind is a value-level effect of :mod:`exohil.emulators.effects` (``noise``, ``creep``,
``drift``, ``dropout``, ...). Per-sensor effect parameters take a list in TOML, or values
separated by ``/`` in a spec string (``noise:sigma_mm=0.5/0.5/1/1``).
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from exohil.emulators.effects import (
    Effect,
    EffectChain,
    check_parameter,
    effect_from_dict,
)
from exohil.emulators.faults import (
    FRAME_FAULT_TYPES,
    Corrupt,
    Disconnect,
    Drop,
    FrameFault,
    Stall,
    Truncate,
)


@dataclass
class FaultPlan:
    """The faults of one emulator run.

    Attributes:
        frame_faults: frame/byte-level faults, applied while sending.
        value_effects: value-level effects, applied in order to the whole series (mm).
    """

    frame_faults: list[FrameFault] = field(default_factory=list)
    value_effects: list[Effect] = field(default_factory=list)

    @property
    def effect_chain(self) -> EffectChain:
        return EffectChain(list(self.value_effects))


def _scalar(text: str) -> Any:
    lowered = text.strip().lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    for convert in (int, float):
        try:
            return convert(text)
        except ValueError:
            continue
    return text.strip()


def _value(text: str) -> Any:
    return [_scalar(part) for part in text.split("/")] if "/" in text else _scalar(text)


def fault_from_dict(entry: dict[str, Any]) -> FrameFault | Effect:
    """One fault from ``{"kind": ..., <param>: <value>}``; ValueError names what is wrong
    (parameters must be finite numbers within
    ±:data:`~exohil.emulators.effects.MAX_PARAMETER`)."""
    if "kind" not in entry:
        raise ValueError(f"fault without a 'kind': {entry!r}")
    params = dict(entry)
    kind = params.pop("kind")
    if not isinstance(kind, str):
        raise ValueError(f"a fault's kind is a name, got {kind!r}")
    for name, value in params.items():
        check_parameter(kind, name, value)
    cls = FRAME_FAULT_TYPES.get(kind)
    if cls is None:
        try:
            return effect_from_dict(entry)
        except (ValueError, TypeError) as exc:
            known = ", ".join(FRAME_FAULT_TYPES)
            raise ValueError(f"{exc} (frame-level fault kinds: {known})") from None
    allowed = {f.name for f in fields(cls)}
    unknown = sorted(set(params) - allowed)
    if unknown:
        raise ValueError(f"{kind}: unknown parameter(s) {', '.join(unknown)}; "
                         f"allowed: {', '.join(sorted(allowed))}")
    listed = sorted(name for name, value in params.items() if isinstance(value, list))
    if listed:  # a frame-level fault acts on whole frames: one value, not one per sensor
        raise ValueError(f"{kind}: {listed[0]} takes one number, got {params[listed[0]]!r} "
                         "(per-sensor lists are for value-level effects)")
    try:
        return cls(**params)
    except (TypeError, OverflowError) as exc:
        raise ValueError(f"{kind}: {exc}") from None


def check_sensor_count(plan: FaultPlan, sensors: int) -> None:
    """ValueError unless every per-sensor list in ``plan`` has one value per sensor (the
    effects would otherwise fail once streaming has begun)."""
    for effect in plan.value_effects:
        for f in fields(effect):  # type: ignore[arg-type]  # every Effect is a dataclass
            value = getattr(effect, f.name)
            if isinstance(value, list | tuple) and len(value) != sensors:
                raise ValueError(f"{effect.name}: {f.name} lists {len(value)} values for "
                                 f"{sensors} sensors; give one number or {sensors} values "
                                 "separated by '/'")


def plan_from_dicts(entries: list[dict[str, Any]]) -> FaultPlan:
    """A plan from fault dicts, in order."""
    plan = FaultPlan()
    for entry in entries:
        fault = fault_from_dict(entry)
        if isinstance(fault, Drop | Corrupt | Truncate | Stall | Disconnect):
            plan.frame_faults.append(fault)
        else:
            plan.value_effects.append(fault)
    return plan


def parse_fault_spec(spec: str) -> FaultPlan:
    """Parse a spec string (see the module docstring); ValueError on malformed input."""
    entries: list[dict[str, Any]] = []
    for item in filter(None, (part.strip() for part in spec.split(";"))):
        kind, _, rest = item.partition(":")
        entry: dict[str, Any] = {"kind": kind.strip()}
        for assignment in filter(None, (a.strip() for a in rest.split(","))):
            name, sep, text = assignment.partition("=")
            if not sep or not name.strip() or not text.strip():
                raise ValueError(f"{kind}: expected param=value, got {assignment!r}")
            value = _value(text)
            if any(isinstance(v, str) for v in (value if isinstance(value, list) else [value])):
                raise ValueError(f"{kind.strip()}: {name.strip()} must be a number "
                                 f"(or numbers separated by '/'), got {text.strip()!r}")
            entry[name.strip()] = value
        entries.append(entry)
    return plan_from_dicts(entries)


def load_fault_file(path: Path) -> FaultPlan:
    """Read a TOML fault file (``[[fault]]`` tables and nothing else); ValueError on
    malformed input, another top-level key included."""
    try:
        data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: invalid TOML: {exc}") from None
    unknown = sorted(set(data) - {"fault"})
    if unknown:  # e.g. [[faults]]: would run with no fault at all
        raise ValueError(f"{path}: unknown top-level key(s) {', '.join(map(repr, unknown))}; "
                         "a fault file holds only [[fault]] tables")
    entries = data.get("fault", [])
    if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
        raise ValueError(f"{path}: expected [[fault]] tables")
    return plan_from_dicts(entries)


def fault_plan(spec_or_path: str | None) -> FaultPlan:
    """A plan from a spec string, or from a TOML file when the argument names one."""
    if not spec_or_path:
        return FaultPlan()
    if spec_or_path.endswith(".toml") or Path(spec_or_path).is_file():
        return load_fault_file(Path(spec_or_path))
    return parse_fault_spec(spec_or_path)
