"""Shared click parameter types for the ``exohil`` commands.

Every option and argument is checked here, when the command line is parsed and before any
work starts, and a bad value is refused with one line naming the value and what is allowed
(docs/reliability.md, "Bad input"). The ranges are part of the interface:

* seeds: integers ``0 <= seed <= 2**32 - 1`` (:data:`SEED_MAX`), everywhere a seed is taken
  (command line, bench files, ``emulator:`` targets, conformance profiles);
* floats: finite (NaN and ±inf are refused; click's ``FloatRange`` lets NaN through) and
  inside a stated range (:class:`Finite`): durations at most :data:`MAX_DURATION_S`, times
  within ±:data:`MAX_TIME_S`, rates positive and at most :data:`MAX_RATE_HZ`, fractions
  inside [0, 1];
* counts: integers inside a stated range, never unbounded (:class:`Count`);
* paths: never empty, never with a NUL byte; inputs exist, outputs can be created
  (:class:`InputFile`, :class:`InputDir`, :class:`OutputFile`, :class:`OutputDir`);
* names and labels: non-empty, printable, at most :data:`MAX_NAME_LENGTH` characters
  (:class:`Name`, :class:`NameList`).
"""

from __future__ import annotations

import math
import os
import tempfile
import unicodedata
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import click

from exohil.formats.atomic import same_file

#: Seeds are integers 0..SEED_MAX (numpy's legacy seed range, 32 bits).
SEED_MAX = 2**32 - 1
#: The longest duration any command takes, s (one day).
MAX_DURATION_S = 86_400.0
#: The largest magnitude of a time (a point in a recording, not a duration), s (~317 years:
#: a recording on a Unix-epoch clock, 1.7e9 s in 2024, fits).
MAX_TIME_S = 1e10
#: The highest rate any command takes, Hz.
MAX_RATE_HZ = 100_000.0
#: The longest name or label, characters.
MAX_NAME_LENGTH = 200
#: The longest file name (one path component), bytes, as on Linux and macOS.
MAX_FILE_NAME_BYTES = 255


def check_seed(value: Any, what: str = "seed") -> int:
    """``value`` as a seed (an integer 0..SEED_MAX); ValueError saying what is allowed. For
    seeds read from files (bench files, conformance profiles) rather than the command line."""
    if isinstance(value, bool) or not isinstance(value, int | str):
        raise ValueError(f"{what} must be an integer 0..{SEED_MAX}, got {value!r}")
    try:
        seed = int(value)
    except ValueError:
        raise ValueError(f"{what} must be an integer 0..{SEED_MAX}, got {value!r}") from None
    if not 0 <= seed <= SEED_MAX:
        raise ValueError(f"{what} must be an integer 0..{SEED_MAX}, got {seed}")
    return seed


class Finite(click.FloatRange):
    """A finite float inside [min, max] (open ends with ``min_open``/``max_open``). Both bounds
    are required, so every float option states its range; NaN and ±inf are refused."""

    name = "float"

    def __init__(self, min: float, max: float, *, min_open: bool = False,
                 max_open: bool = False) -> None:
        super().__init__(min=min, max=max, min_open=min_open, max_open=max_open)

    def convert(self, value, param, ctx):
        number = click.FLOAT.convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number (allowed: {self._describe_range()})",
                      param, ctx)
        return super().convert(number, param, ctx)


class Count(click.IntRange):
    """An integer inside [min, max]; both bounds are required (no count is unbounded)."""

    def __init__(self, min: int, max: int) -> None:
        super().__init__(min=min, max=max)


class Seed(click.IntRange):
    """A seed: an integer 0..:data:`SEED_MAX`."""

    name = "seed"

    def __init__(self) -> None:
        super().__init__(min=0, max=SEED_MAX)


def _is_control(char: str) -> bool:
    return unicodedata.category(char) in ("Cc", "Cf", "Cs", "Co", "Cn", "Zl", "Zp")


class Name(click.ParamType):
    """A name or label: non-empty, no control characters, at most :data:`MAX_NAME_LENGTH`
    characters."""

    name = "text"

    def convert(self, value, param, ctx):
        text = str(value)
        if not text.strip():
            self.fail("an empty value is not allowed (give a name, or leave the option out)",
                      param, ctx)
        if any(_is_control(c) for c in text):
            self.fail(f"{text!r} contains control characters (allowed: printable text)",
                      param, ctx)
        if len(text) > MAX_NAME_LENGTH:
            self.fail(f"{text[:20]!r}... is {len(text)} characters long (at most "
                      f"{MAX_NAME_LENGTH})", param, ctx)
        return text


class NameList(Name):
    """Comma-separated names, each a :class:`Name` (and one of ``choices`` when given), none
    twice; the text is returned unchanged."""

    name = "names"

    def __init__(self, choices: Sequence[str] | None = None) -> None:
        self.choices = tuple(choices) if choices is not None else None

    def convert(self, value, param, ctx):
        text = super().convert(value, param, ctx)
        names = [part.strip() for part in text.split(",")]
        if not all(names):
            self.fail(f"{text!r} has an empty name (allowed: NAME[,NAME...])", param, ctx)
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            self.fail(f"{text!r} names {', '.join(map(repr, twice))} twice", param, ctx)
        if self.choices is not None:
            unknown = [n for n in names if n not in self.choices]
            if unknown:
                self.fail(f"unknown {', '.join(map(repr, unknown))} (choose from "
                          f"{', '.join(self.choices)})", param, ctx)
        return text


class Widths(click.ParamType):
    """Comma-separated layer widths, e.g. ``512,256,128``: 1 to ``max_layers`` whole numbers,
    each in [1, ``max_width``]; returned as a tuple of ints."""

    name = "widths"

    def __init__(self, max_width: int, max_layers: int) -> None:
        self.max_width, self.max_layers = max_width, max_layers

    def convert(self, value, param, ctx):
        if isinstance(value, tuple):  # already converted
            return value
        text = str(value)
        parts = [part.strip() for part in text.split(",")]
        if not 1 <= len(parts) <= self.max_layers:
            self.fail(f"{text!r}: give 1 to {self.max_layers} comma-separated widths", param,
                      ctx)
        count = Count(1, self.max_width)
        return tuple(count.convert(part, param, ctx) for part in parts)


def _fail_unusable_path(kind: click.ParamType, value, param, ctx) -> None:
    """Refuse what no file system accepts: an empty path, a NUL byte, an over-long name."""
    text = os.fspath(value)
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    if not text.strip():
        kind.fail("an empty path is not allowed", param, ctx)
    if "\x00" in text:
        kind.fail(f"{text!r} contains a NUL byte", param, ctx)
    for part in Path(text).parts:
        if len(os.fsencode(part)) > MAX_FILE_NAME_BYTES:
            kind.fail(f"{part[:20]!r}... is longer than {MAX_FILE_NAME_BYTES} bytes, the "
                      "longest file name allowed", param, ctx)


def _existing_ancestor(path: Path) -> Path:
    for folder in (path, *path.parents):
        if folder.exists():
            return folder
    return Path.cwd()


class _UsablePath(click.Path):
    """A ``click.Path`` that first refuses what no file system accepts
    (:func:`_fail_unusable_path`)."""

    def convert(self, value, param, ctx):
        _fail_unusable_path(self, value, param, ctx)
        return super().convert(value, param, ctx)


class InputFile(_UsablePath):
    """A file the command reads: it must exist and be a file."""

    def __init__(self) -> None:
        super().__init__(exists=True, dir_okay=False, path_type=Path)


class InputDir(_UsablePath):
    """A folder the command reads: it must exist and be a folder."""

    def __init__(self) -> None:
        super().__init__(exists=True, file_okay=False, path_type=Path)


class OutputFile(_UsablePath):
    """A file the command will write: its folder must exist, checked when the command line is
    parsed, so a long run (training, streaming) cannot fail only at the end."""

    def __init__(self) -> None:
        super().__init__(dir_okay=False, path_type=Path)

    def convert(self, value, param, ctx):
        path = super().convert(value, param, ctx)
        if Path(path).name in ("", ".", ".."):
            self.fail(f"{os.fspath(path)!r} is not a file name", param, ctx)
        folder = Path(path).parent
        if not folder.is_dir():
            self.fail(f"folder {folder.absolute()} does not exist (create it first)", param, ctx)
        problem = cannot_write_in(folder)
        if problem:
            self.fail(f"cannot write in folder {folder.absolute()}: {problem}", param, ctx)
        return path


class OutputDir(_UsablePath):
    """A folder the command will create (with its parents) or fill: it must not be a file,
    nor lie inside one, and it (or the nearest folder above it that exists) must take new
    files."""

    def __init__(self) -> None:
        super().__init__(file_okay=False, path_type=Path)

    def convert(self, value, param, ctx):
        path = super().convert(value, param, ctx)
        ancestor = _existing_ancestor(Path(path).absolute())
        if not ancestor.is_dir():
            self.fail(f"{os.fspath(path)!r} lies inside {os.fspath(ancestor)!r}, which is "
                      "not a folder", param, ctx)
        problem = cannot_write_in(ancestor)
        if problem:
            self.fail(f"cannot write in folder {ancestor}: {problem}", param, ctx)
        return path


def cannot_write_in(folder: Path) -> str | None:
    """Why a new file cannot be created in ``folder`` (tried with a temporary file, removed at
    once; a permission check alone would pass for root), or None."""
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as err:
        return f"no new file can be created there ({err.strerror or err})"
    return None


def refuse_overwriting_inputs(outputs: Iterable[tuple[str, Path | None]],
                              inputs: Iterable[Path | None]) -> None:
    """Refuse (a usage error naming both) when an output file is one of the input files, by
    any path to it: a command never replaces what it reads. ``outputs`` holds (option that
    names it, path) of each output; None paths are ignored. Two options that name the same
    output file are refused too: one would replace what the other wrote."""
    sources = [path for path in inputs if path is not None]
    written: dict[str, tuple[str, Path]] = {}
    for option, path in outputs:
        if path is None:
            continue
        clash = same_file(path, sources)
        if clash is not None:
            raise click.UsageError(f"{option} {path} is the input {clash}; refusing to overwrite "
                                   "it (choose another output)")
        key = os.path.realpath(path)
        other = written.get(key)
        if other is not None and other[0] != option:
            raise click.UsageError(f"{other[0]} {other[1]} and {option} {path} name the same "
                                   "file; one would replace the other (choose another output)")
        written.setdefault(key, (option, path))


def refuse_repeated_inputs(inputs: Iterable[tuple[str, Path]]) -> None:
    """Refuse (a usage error naming both) an input file given twice, by any path to it:
    ``inputs`` holds (how it was given: an option or an argument's name, path). A recording
    read twice counts its frames twice; one given to ``--train`` and to ``--test`` would score
    a model on what it was trained on."""
    seen: list[tuple[str, Path]] = []
    for given, path in inputs:
        clash = same_file(path, [p for _, p in seen])
        if clash is not None:
            first = next(g for g, p in seen if p == clash)
            why = ("a model would be scored on a recording it was trained on"
                   if {first, given} == {"--train", "--test"}
                   else "its frames would count twice")
            raise click.UsageError(f"{first} {clash} and {given} {path} are the same file: "
                                   f"{why}")
        seen.append((given, path))


class FaultSpec(click.ParamType):
    """An emulator fault spec string or TOML file (docs/emulator.md), parsed here so a bad one
    is refused before the emulator starts; the text is returned unchanged."""

    name = "faults"

    def convert(self, value, param, ctx):
        from exohil.emulators.fault_spec import fault_plan

        text = str(value)
        if not text.strip():
            self.fail("an empty fault spec is not allowed (for none: --no-faults where the "
                      "command injects faults by default, as the demo does; elsewhere leave "
                      "--faults out)", param, ctx)
        if "\x00" in text:
            self.fail(f"{text!r} contains a NUL byte", param, ctx)
        try:
            fault_plan(text)
        except (ValueError, OSError) as exc:
            self.fail(str(exc), param, ctx)
        return text


#: Robot sinks (``--sink``): the fixed names and ``udp:HOST:PORT``.
ROBOT_NAMES = ("simulated", "mujoco", "none")


class Robot(click.ParamType):
    """A robot sink: ``simulated``, ``mujoco``, ``none`` or ``udp:HOST:PORT`` (port 1..65535)."""

    name = "robot"

    def convert(self, value, param, ctx):
        text = str(value)
        if text in ROBOT_NAMES:
            return text
        if text.startswith("udp:"):
            from exohil.harness.robot_udp import parse_udp_address

            try:
                parse_udp_address(text)
            except ValueError as err:
                self.fail(str(err), param, ctx)
            return text
        self.fail(f"unknown robot {text!r}; available: {', '.join(ROBOT_NAMES)}, "
                  "udp:HOST:PORT", param, ctx)


def _url_problem(url: str) -> str | None:
    """Why ``url`` cannot be a pyserial URL or device path, or None."""
    if not url.strip():
        return "the device URL is empty"
    if any(_is_control(c) for c in url):
        return f"{url!r} contains control characters"
    if "://" in url:
        import importlib.util

        scheme, _, rest = url.partition("://")
        scheme = scheme.lower()
        known = ("alt", "cp2110", "hwgrep", "loop", "rfc2217", "socket", "spy")
        try:
            found = scheme.isidentifier() and importlib.util.find_spec(
                f"serial.urlhandler.protocol_{scheme}") is not None
        except (ImportError, ValueError):
            found = False
        if not found:
            return f"{url!r}: unknown URL scheme {scheme!r} (pyserial knows {', '.join(known)})"
        if scheme in ("socket", "rfc2217"):
            host, _, port = rest.partition("?")[0].rpartition(":")
            if not host or not (port.isascii() and port.isdigit()
                                and 1 <= int(port) <= 65535):
                return f"{url!r} is not {scheme}://HOST:PORT with a port 1..65535"
    return None


class DeviceUrl(click.ParamType):
    """A serial device: a path (``/dev/ttyACM0``, a pty printed by ``exohil emulate``) or a
    pyserial URL whose scheme pyserial knows (``socket://HOST:PORT``, ``loop://``, ...). A
    path that does not exist yet is allowed: the device may be plugged in (the run waits for
    frames, docs/architecture.md)."""

    name = "url"

    def convert(self, value, param, ctx):
        text = str(value)
        problem = _url_problem(text)
        if problem:
            self.fail(problem, param, ctx)
        return text


class Target(click.ParamType):
    """A conformance target: ``emulator:RECORDING[?faults=SPEC&seed=N&loop=1]`` (the
    recording must exist, the faults parse, the seed be 0..SEED_MAX) or a :class:`DeviceUrl`;
    the text is returned unchanged."""

    name = "target"

    def convert(self, value, param, ctx):
        from exohil.harness.bench import BenchError, EmulatorDevice, parse_target

        text = str(value)
        if not text.startswith("emulator:"):
            problem = _url_problem(text)
            if problem:
                self.fail(f"{problem} (or use emulator:RECORDING[?faults=SPEC&seed=N])",
                          param, ctx)
            return text
        try:
            device = parse_target(text)
        except BenchError as exc:
            self.fail(str(exc), param, ctx)
        assert isinstance(device, EmulatorDevice)
        _fail_unusable_path(self, device.recording, param, ctx)
        if device.recording.is_dir():
            self.fail(f"{os.fspath(device.recording)!r} is a folder, not a recording", param,
                      ctx)
        if not device.recording.is_file():
            self.fail(f"no recording {os.fspath(device.recording)!r}", param, ctx)
        if device.faults is not None:
            FaultSpec().convert(device.faults, param, ctx)
        return text
