"""Suit profiles: tendon geometry plus the default effect chain, stored as TOML.

The schema is documented in docs/suit-model.md; ``emulators/profiles/default.toml`` is the
packaged default. :func:`load_profile` reports the first problem in one clear line
(:class:`ProfileError`), naming the file and the offending table or key.
"""

from __future__ import annotations

import hashlib
import json
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from exohil.emulators.effects import EffectChain, Signal, effect_from_dict
from exohil.emulators.suit_geometry import SuitGeometry, Tendon
from exohil.formats.errors import InputError

PROFILE_SCHEMA = "exohil-suit-profile"
PROFILE_VERSION = 1
#: The packaged suit profiles (``default.toml``, ``donning-b.toml``: another wearer/donning).
PROFILES_DIR = Path(__file__).parent / "profiles"
DEFAULT_PROFILE_PATH = PROFILES_DIR / "default.toml"


class ProfileError(InputError, ValueError):
    """A suit profile that cannot be used; the message says which file and what is wrong."""


@dataclass(frozen=True)
class SuitProfile:
    """A simulated suit.

    Attributes:
        name: short profile name (stored in recordings' provenance).
        description: free text.
        geometry: shoulder cap and tendons (mm, thorax/humerus frames).
        effects: the default effect chain, in order.
    """

    name: str
    description: str
    geometry: SuitGeometry
    effects: EffectChain

    @property
    def sensor_names(self) -> tuple[str, ...]:
        return self.geometry.sensor_names

    def to_dict(self) -> dict[str, Any]:
        """The profile as plain data in the TOML schema's layout."""
        return {
            "schema": PROFILE_SCHEMA,
            "version": PROFILE_VERSION,
            "name": self.name,
            "description": self.description,
            "cap": {"centre_mm": self.geometry.cap_centre_mm.tolist(),
                    "radius_mm": self.geometry.cap_radius_mm},
            "tendon": [{"name": t.name, "thorax_points_mm": t.thorax_points_mm.tolist(),
                        "humerus_points_mm": t.humerus_points_mm.tolist()}
                       for t in self.geometry.tendons],
            "effect": self.effects.to_dicts(),
        }

    def sha256(self) -> str:
        """Hash of the profile's content (canonical JSON), independent of TOML formatting."""
        canonical = json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(canonical.encode("utf-8")).hexdigest()


def read_toml(path: Path, what: str) -> dict:
    """The TOML table in ``path``; ProfileError naming the file when it is missing (``what``
    says what was expected there) or unreadable."""
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise ProfileError(f"{path}: no such {what}") from exc
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ProfileError(f"{path}: not a readable TOML file ({exc})") from exc


def load_profile(path: str | Path) -> SuitProfile:
    """Read and validate a suit profile TOML file."""
    path = Path(path)
    data = read_toml(path, "suit profile")
    try:
        return profile_from_dict(data)
    except ProfileError as exc:
        raise ProfileError(f"{path}: {exc}") from exc


def load_default_profile() -> SuitProfile:
    """The packaged default profile (``emulators/profiles/default.toml``)."""
    return load_profile(DEFAULT_PROFILE_PATH)


def _points(value: Any, where: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ProfileError(f"{where}: expected a list of [x, y, z] points in mm") from exc
    if arr.ndim != 2 or arr.shape[1] != 3 or arr.shape[0] < 1 or not np.isfinite(arr).all():
        raise ProfileError(f"{where}: expected a non-empty list of finite [x, y, z] points in mm")
    return arr


def _require(table: dict, key: str, where: str) -> Any:
    if key not in table:
        raise ProfileError(f"{where}: missing key '{key}'")
    return table[key]


def _table(value: Any, where: str) -> dict[str, Any]:
    """``value`` when it is a TOML table (``cap = 3`` or ``tendon = [1]`` are not)."""
    if not isinstance(value, dict):
        raise ProfileError(f"{where}: expected a table, got {value!r}")
    return value


def _reject_unknown(table: dict[str, Any], allowed: set[str], where: str) -> None:
    """A misspelt key (e.g. ``[[efect]]``) must not silently drop part of the suit."""
    unknown = set(table) - allowed
    if unknown:
        raise ProfileError(f"{where}: unknown key(s) {', '.join(sorted(unknown))}")


def profile_from_dict(data: dict[str, Any]) -> SuitProfile:
    """Validate parsed TOML (or :meth:`SuitProfile.to_dict` output) into a profile."""
    _reject_unknown(data, {"schema", "version", "name", "description", "cap", "tendon",
                           "effect"}, "profile")
    if data.get("schema") != PROFILE_SCHEMA:
        raise ProfileError(f"'schema' must be \"{PROFILE_SCHEMA}\", got {data.get('schema')!r}")
    version = data.get("version")
    # TOML's true equals 1 and 1.0 does too; only the integer names a schema version
    if type(version) is not int or version != PROFILE_VERSION:
        raise ProfileError(f"unsupported profile version {data.get('version')!r} "
                           f"(this exohil reads version {PROFILE_VERSION})")
    name = _require(data, "name", "profile")
    if not isinstance(name, str) or not name.strip():
        raise ProfileError("'name' must be a non-empty string")
    cap = _table(_require(data, "cap", "profile"), "[cap]")
    _reject_unknown(cap, {"centre_mm", "radius_mm"}, "[cap]")
    try:
        centre = np.asarray(_require(cap, "centre_mm", "[cap]"), dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ProfileError("[cap] centre_mm must be [x, y, z] in mm") from exc
    if centre.shape != (3,) or not np.isfinite(centre).all():
        raise ProfileError("[cap] centre_mm must be [x, y, z] in mm")
    radius = _require(cap, "radius_mm", "[cap]")
    if (isinstance(radius, bool) or not isinstance(radius, int | float)
            or not 0 < radius < math.inf):
        raise ProfileError("[cap] radius_mm must be a positive finite number (mm)")
    tendon_tables = data.get("tendon")
    if not isinstance(tendon_tables, list) or not tendon_tables:
        raise ProfileError("at least one [[tendon]] table is required")
    tendons = []
    for i, table in enumerate(tendon_tables):
        where = f"[[tendon]] #{i + 1}"
        tname = _require(_table(table, where), "name", where)
        if not isinstance(tname, str) or not tname.strip():
            # the name labels the sensor's channel in every recording the profile makes
            raise ProfileError(f"{where}: name must be a non-empty string, got {tname!r}")
        where = f"[[tendon]] {tname!r}"
        _reject_unknown(table, {"name", "thorax_points_mm", "humerus_points_mm"}, where)
        tendons.append(Tendon(
            name=tname,
            thorax_points_mm=_points(_require(table, "thorax_points_mm", where),
                                     f"{where} thorax_points_mm"),
            humerus_points_mm=_points(_require(table, "humerus_points_mm", where),
                                      f"{where} humerus_points_mm"),
        ))
    names = [t.name for t in tendons]
    if len(set(names)) != len(names):
        raise ProfileError(f"tendon names must be unique, got {names}")
    geometry = SuitGeometry(cap_centre_mm=centre, cap_radius_mm=float(radius),
                            tendons=tuple(tendons))
    effect_tables = data.get("effect", [])
    if not isinstance(effect_tables, list):
        raise ProfileError("'effect' must be a list of [[effect]] tables, got "
                           f"{type(effect_tables).__name__}")
    effects = []
    for i, table in enumerate(effect_tables):
        try:
            effect = effect_from_dict(table)
        except (TypeError, ValueError) as exc:
            raise ProfileError(f"[[effect]] #{i + 1}: {exc}") from exc
        effects.append(effect)
    try:
        geometry.validate()
        chain = EffectChain(effects)
        _check_per_sensor_lengths(chain, len(tendons))
    except ValueError as exc:
        raise ProfileError(str(exc)) from exc
    return SuitProfile(name=name, description=str(data.get("description", "")),
                       geometry=geometry, effects=chain)


def _check_per_sensor_lengths(chain: EffectChain, n_sensors: int) -> None:
    """Apply the chain to a tiny flat signal so per-sensor list lengths are checked at load."""
    probe = Signal.from_values(np.arange(3) / 250.0, np.full((3, n_sensors), 500.0))
    chain.apply(probe, seed=0)
