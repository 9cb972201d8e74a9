"""What a bench is: the device, the model and the sinks, in one small TOML file.

Following labgrid's split between what a place *is* and how it is *driven*, a bench
configuration only names things; :func:`open_device` turns its device into a running
:class:`~exohil.harness.frame_source.FrameSource`. ``exohil demo``, ``exohil run`` and
``exohil conform`` all read this format (``--bench FILE``), and their command-line options
fill in or override it. Example (every key but ``model`` is optional)::

    [device]                      # the emulator replaying a recording ...
    emulator = "fixtures/paper_protocol_heldout.mcap"
    faults = "drop:rate=0.002;corrupt:rate=0.001"
    seed = 0
    loop = false                # replay cyclically
    # url = "/dev/ttyACM0"        # ... or any pyserial URL of a real device
    # reference = "trial.mcap"    # ground truth for a real device (aligned by device time)

    [sensors]
    names = ["F", "SF", "SR", "R"]  # checked against the model's
    rate_hz = 250   # a real device's frame rate, written into what a session records
                    # [default: the reference's, else 250]; the emulator streams its
                    # recording at that recording's own rate

    [model]
    checkpoint = "fixtures/models/ennet.npz"
    backend = "auto"

    [teleop]
    robots = ["simulated"]          # "simulated", "mujoco", "udp:HOST:PORT"

    [record]
    path = "session.mcap"

Relative paths are relative to the TOML file's folder. A device *target* on the command line
is ``emulator:RECORDING[?faults=SPEC&seed=N]`` or a pyserial URL (:func:`parse_target`).
"""

from __future__ import annotations

import tomllib
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs

from exohil.formats.errors import InputError
from exohil.formats.recording import Recording
from exohil.formats.recording_metadata import DEFAULT_SENSOR_RATE_HZ
from exohil.harness.acquisition import SerialFrameSource
from exohil.harness.cli_types import MAX_RATE_HZ, check_seed
from exohil.harness.pipeline import DeviceClock


class BenchError(InputError, ValueError):
    """A bench configuration or target that cannot be used; the message says why."""


@dataclass(frozen=True)
class EmulatorDevice:
    """The software Arduino on a pty, replaying ``recording`` with seeded ``faults``
    (cyclically with ``loop``: ground truth then ends with the recording's first pass)."""

    recording: Path
    faults: str | None = None
    seed: int = 0
    loop: bool = False

    def describe(self) -> str:
        faults = f" with faults {self.faults!r}" if self.faults else ""
        return f"emulator replaying {self.recording}{faults}"


@dataclass(frozen=True)
class SerialDevice:
    """A device behind a pyserial URL; ``reference`` holds its ground truth, if any."""

    url: str
    reference: Path | None = None

    def describe(self) -> str:
        return f"serial device {self.url}"

    def path_problem(self) -> str | None:
        """Why ``url``, a plain path (no ``scheme://``), cannot be a serial device: it does
        not exist, or it is a regular file or a folder; None for a URL or a device node."""
        if "://" in self.url:
            return None
        path = Path(self.url)
        if not path.exists():
            return f"{self.url} does not exist (is the device plugged in?)"
        if path.is_dir():
            return f"{self.url} is a folder, not a serial device"
        if path.is_file():
            return f"{self.url} is a regular file, not a serial device"
        return None


Device = EmulatorDevice | SerialDevice


@dataclass(frozen=True)
class BenchConfig:
    """One bench (see module doc)."""

    device: Device | None = None
    model: Path | None = None
    backend: str = "auto"
    sensor_names: tuple[str, ...] | None = None
    #: a serial device's frame rate, Hz (None: not stated; see session.device_rate_hz)
    rate_hz: float | None = None
    robots: tuple[str, ...] = ("simulated",)
    record: Path | None = None

    def with_overrides(self, **changes: Any) -> BenchConfig:
        """A copy with every non-None value of ``changes`` applied."""
        return replace(self, **{k: v for k, v in changes.items() if v is not None})


def parse_target(text: str) -> Device:
    """``emulator:RECORDING[?faults=SPEC&seed=N&loop=1]`` → :class:`EmulatorDevice`; anything
    else is a pyserial URL or device path → :class:`SerialDevice`."""
    if not text:
        raise BenchError("empty target")
    if not text.startswith("emulator:"):
        return SerialDevice(text)
    path, _, query = text[len("emulator:"):].partition("?")
    if not path:
        raise BenchError("emulator target without a recording: emulator:RECORDING[?faults=...]")
    params = {k: v[-1] for k, v in parse_qs(query, keep_blank_values=True).items()}
    unknown = sorted(set(params) - {"faults", "seed", "loop"})
    if unknown:
        raise BenchError(f"unknown emulator option(s) {', '.join(unknown)}; "
                         "allowed: faults, seed, loop")
    if params.get("loop", "0") not in ("0", "1"):
        raise BenchError(f"loop must be 0 or 1, got {params['loop']!r}")
    try:
        seed = check_seed(params.get("seed", "0"))
    except ValueError as err:
        raise BenchError(str(err)) from None
    return EmulatorDevice(Path(path), params.get("faults") or None, seed,
                          params.get("loop") == "1")


_SECTIONS = {"device": {"emulator", "faults", "seed", "loop", "url", "reference"},
             "sensors": {"names", "rate_hz"}, "model": {"checkpoint", "backend"},
             "teleop": {"robots"}, "record": {"path"}}


def load_bench(path: Path) -> BenchConfig:
    """Read a bench TOML file (see module doc); BenchError names any problem."""
    try:
        data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as err:
        raise BenchError(f"{path}: {err}") from None
    where = Path(path).resolve().parent
    for name, value in data.items():
        if name not in _SECTIONS or not isinstance(value, dict):
            raise BenchError(f"{path}: unknown section [{name}]; allowed: {', '.join(_SECTIONS)}")
        unknown = sorted(set(value) - _SECTIONS[name])
        if unknown:
            raise BenchError(f"{path}: unknown key(s) {', '.join(unknown)} in [{name}]")

    def rel(table: dict[str, Any], key: str) -> Path | None:
        return None if key not in table else where / _text(path, table, key)

    dev = data.get("device", {})
    device: Device | None = None
    if "emulator" in dev and "url" in dev:
        raise BenchError(f"{path}: [device] names both an emulator and a url; pick one")
    if "emulator" in dev:
        device = EmulatorDevice(where / _text(path, dev, "emulator"),
                                _faults(path, dev),
                                _seed(path, dev), _flag(path, dev, "loop"))
    elif "url" in dev:
        device = SerialDevice(_text(path, dev, "url"), rel(dev, "reference"))
    sensors = data.get("sensors", {})
    model = data.get("model", {})
    backend = _text(path, model, "backend") if "backend" in model else "auto"
    from exohil.estimator.inference import BACKENDS

    if backend != "auto" and backend not in BACKENDS:
        raise BenchError(f"{path}: [model] backend {backend!r}; choose from auto, "
                         f"{', '.join(BACKENDS)}")
    names = _names(path, sensors, "names", "sensors")
    robots = _names(path, data.get("teleop", {}), "robots", "teleop")
    return BenchConfig(
        device=device,
        model=rel(model, "checkpoint"),
        backend=backend,
        sensor_names=names,
        rate_hz=_rate(path, sensors),
        robots=("simulated",) if robots is None else robots,
        record=rel(data.get("record", {}), "path"),
    )


def _names(path: Path, table: dict[str, Any], key: str, section: str) -> tuple[str, ...] | None:
    """A list of names (``names = ["F", "SF"]``), not one string (which reads letter by
    letter), or None when the key is absent."""
    value = table.get(key)
    if value is None:
        return None
    if not isinstance(value, list) or not all(isinstance(v, str) and v.strip() for v in value):
        raise BenchError(f"{path}: [{section}] {key} must be a list of names, e.g. "
                         f"{key} = [\"...\", \"...\"], got {value!r}")
    return tuple(value)


def _text(path: Path, table: dict[str, Any], key: str) -> str:
    value = table[key]
    if not isinstance(value, str) or not value.strip():
        raise BenchError(f"{path}: {key} must be a non-empty string, got {value!r}")
    return value


def _faults(path: Path, dev: dict[str, Any]) -> str | None:
    """The [device] faults spec, parsed here so a bad one is named before the run starts."""
    if "faults" not in dev:
        return None
    from exohil.emulators.fault_spec import fault_plan

    spec = _text(path, dev, "faults")
    try:
        fault_plan(spec)
    except (ValueError, OSError) as err:
        raise BenchError(f"{path}: [device] faults: {err}") from None
    return spec


def _seed(path: Path, dev: dict[str, Any]) -> int:
    try:
        return check_seed(dev.get("seed", 0))
    except ValueError as err:
        raise BenchError(f"{path}: [device] {err}") from None


def _flag(path: Path, dev: dict[str, Any], key: str) -> bool:
    value = dev.get(key, False)
    if not isinstance(value, bool):
        raise BenchError(f"{path}: [device] {key} must be true or false, got {value!r}")
    return value


def _rate(path: Path, sensors: dict[str, Any]) -> float | None:
    value = sensors.get("rate_hz")
    if value is None:
        return None
    if (isinstance(value, bool) or not isinstance(value, int | float)
            or not 0 < value <= MAX_RATE_HZ):
        raise BenchError(f"{path}: [sensors] rate_hz must be a number in (0, {MAX_RATE_HZ:g}], "
                         f"got {value!r}")
    return float(value)


#: A serial device that sends no frame for this long (absent, or gone and not back) ends the
#: run, s; the acquisition thread keeps reconnecting until then.
DEVICE_TIMEOUT_S = 10.0


@dataclass
class OpenDevice:
    """A started device: its frames, its write clock (emulator only) and the emulator."""

    source: SerialFrameSource
    device_clock: DeviceClock | None
    emulator: Any = None  # exohil.emulators.arduino.ArduinoEmulator, for its fault log


def device_rate_hz(config: BenchConfig, reference: Recording | None) -> float:
    """The device's nominal frame rate, Hz: the emulator streams its recording at that
    recording's rate (:func:`open_device`); a serial device at the bench's ``[sensors]
    rate_hz`` (``run --rate``), else at its reference recording's rate, else at the Due's
    250 Hz."""
    if isinstance(config.device, EmulatorDevice) and reference is not None:
        return float(reference.sensor_rate_hz)
    if config.rate_hz is not None:
        return config.rate_hz
    return float(reference.sensor_rate_hz) if reference is not None else DEFAULT_SENSOR_RATE_HZ


@contextmanager
def open_device(device: Device, expected_sensors: int | None, *, realtime: bool = False,
                duration_s: float | None = None,
                recording: Recording | None = None) -> Iterator[OpenDevice]:
    """Start ``device`` and an acquisition thread on it; stops both on exit.

    The emulator runs in this process (its recording is read here) and streams ``duration_s``
    of device time (default: the whole recording); a serial device is opened by URL and
    reconnected on loss by the acquisition thread. ``recording`` is the emulator's recording
    when the caller has already read it.
    """
    if isinstance(device, SerialDevice):
        with SerialFrameSource(device.url, expected_sensors=expected_sensors,
                               realtime=realtime, device_timeout_s=DEVICE_TIMEOUT_S) as source:
            yield OpenDevice(source, None)
        return
    from exohil.emulators.arduino import ArduinoEmulator
    from exohil.formats.recording_reader import read_recording

    if recording is None:
        recording = read_recording(device.recording)
    # at the recording's own rate, so that device time is the recording's time (and
    # device_rate_hz reports it)
    with ArduinoEmulator.from_recording(recording, rate_hz=recording.sensor_rate_hz,
                                        faults=device.faults, seed=device.seed,
                                        loop=device.loop, realtime=realtime,
                                        duration_s=duration_s) as emulator:
        with SerialFrameSource(emulator.port, expected_sensors=expected_sensors,
                               realtime=realtime) as source:
            yield OpenDevice(source, emulator.write_time_ns, emulator)

