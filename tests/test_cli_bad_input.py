"""Every bad input gets one clear error (issue 13): for every command of the ``exohil`` CLI
and every option or argument that takes a value, values that are unambiguously invalid for
the parameter's type give exactly one line on stderr, exit code 2 (click's usage error), no
traceback, and no work: the command's body never starts.

The commands and their parameters are discovered from the click group, so a new command or
option is covered (or fails here until it has base arguments and a type with a bad-value
strategy). The bad values are derived from each parameter's type: below/above the range of a
:class:`~exohil.harness.cli_types.Finite` or :class:`~exohil.harness.cli_types.Count`, NaN,
±inf, integers ≥ 2**64, garbage and unicode text, empty strings, paths that do not exist or
are of the wrong kind, and so on. To make sure nothing runs, the command's callback is replaced
by one that fails the test; a few known cases also run the real command (and one the real
executable) to see the same line there.
"""

from __future__ import annotations

import math
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import fields
from pathlib import Path
from unittest import mock

import click
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from exohil.conformance.cmd_conform import ConformanceProfile, KeywordExpression
from exohil.emulators.effects import EFFECT_TYPES
from exohil.emulators.faults import FRAME_FAULT_TYPES
from exohil.harness import cli_types as ct
from exohil.harness.cli import TRACEBACK_ENV, _Group, main
from exohil.harness.cmd_import import Columns, Delimiter
from exohil.harness.cmd_simulate import Protocol
from exohil.harness.cmd_train import AngleLimit

ROOT = Path(__file__).resolve().parents[1]
RECORDING = ROOT / "fixtures" / "paper_protocol.mcap"
MODEL = ROOT / "fixtures" / "models" / "ann.npz"

#: Otherwise valid arguments of every command, per parameter name (``{tmp}`` is a temporary
#: folder). With them alone each command passes validation and reaches its body.
BASE: dict[str, dict[str, list[str]]] = {
    "calibrate": {"checkpoint": [str(MODEL)], "recordings": [str(RECORDING)],
                  "out": ["--out", "{tmp}/calibrated.npz"]},
    "conform": {"target": ["--target", f"emulator:{RECORDING}"], "model": ["--model", str(MODEL)],
                "out_dir": ["--out", "{tmp}/conform"]},
    "convert": {"source": ["--from", "ms"], "target": ["--to", "nao"],
                "values": ["90", "90", "0"]},
    "demo": {"out_dir": ["--out", "{tmp}/demo"]},
    "discrepancy": {"measured": [str(RECORDING)], "out_dir": ["--out", "{tmp}/discrepancy"]},
    "emulate": {"recording": [str(RECORDING)]},
    "evaluate": {"checkpoint": [str(MODEL)], "recordings": [str(RECORDING)]},
    "fixtures build": {"fixtures_dir": ["--dir", "{tmp}/fixtures"],
                       "shoulder_ik_dir": ["--shoulder-ik", "{tmp}"]},
    "fixtures list": {},
    "import csv": {"input_file": [str(RECORDING)], "out": ["--out", "{tmp}/csv.mcap"],
                   "rate": ["--rate", "100"], "sensor_cols": ["--sensor-cols", "1-4"]},
    "import mot": {"input_file": [str(RECORDING)], "out": ["--out", "{tmp}/mot.mcap"]},
    "plot": {"file": [str(RECORDING)], "kind": ["--kind", "timeseries"],
             "out": ["--out", "{tmp}/plot.png"]},
    "record info": {"file": [str(RECORDING)]},
    "record cut": {"file": [str(RECORDING)], "out": ["--out", "{tmp}/cut.mcap"]},
    "record recover": {"file": [str(RECORDING)], "out": ["--out", "{tmp}/recovered.mcap"]},
    "run": {"url": ["loop://"]},
    "simulate": {"out_path": ["--out", "{tmp}/simulated.mcap"]},
    "table": {"train_paths": ["--train", str(RECORDING)]},
    "train": {"recordings": [str(RECORDING)], "out": ["--out", "{tmp}/model.npz"]},
}
#: Parameters not tested here, with the reason: every string is a valid value.
SKIPPED: dict[tuple[str, str], str] = {}


def _commands(group: click.Group = main, path: tuple[str, ...] = ()
              ) -> Iterator[tuple[str, click.Command]]:
    for name, command in sorted(group.commands.items()):
        if isinstance(command, click.Group):
            yield from _commands(command, (*path, name))
        else:
            yield " ".join((*path, name)), command


COMMANDS = dict(_commands())


def _takes_a_value(param: click.Parameter) -> bool:
    return not (isinstance(param, click.Option) and (param.is_flag or param.count))


PARAMS = [(name, param.name) for name, command in COMMANDS.items() for param in command.params
          if _takes_a_value(param) and (name, param.name) not in SKIPPED]


def _param(command: str, name: str) -> click.Parameter:
    return next(p for p in COMMANDS[command].params if p.name == name)


@pytest.fixture(scope="module")
def tmp(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("bad-input")
    (folder / "bad-profile.toml").write_text("[settings]\nseed = -1\n", encoding="utf-8")
    (folder / "misspelled-faults.toml").write_text('[[faults]]\nkind = "drop"\nrate = 0.5\n',
                                                   encoding="utf-8")
    return folder


def _runner() -> CliRunner:
    try:  # click < 8.2 mixes stderr into stdout unless told not to
        return CliRunner(mix_stderr=False)  # type: ignore[call-arg]
    except TypeError:
        return CliRunner()


# --- bad values, from the parameter's type -------------------------------------------------

NON_FINITE = ["nan", "NaN", "-nan", "inf", "-inf", "+Infinity", "1e400", "-1e999"]
HUGE_INTEGERS = [str(2**64), str(2**64 + 1), str(-(2**64)), "1" + "0" * 40]
CONTROL = ["\x00", "\n", "\x1b[31m", "\u202e", "a\tb\x07"]
KINDS = {**FRAME_FAULT_TYPES, **EFFECT_TYPES}


def _not_a_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return True
    return False


def _not_an_int(text: str) -> bool:
    try:
        int(text)
    except ValueError:
        return True
    return False


def _too_long() -> str:
    return "x" * (ct.MAX_NAME_LENGTH + 1)


def fixed_bad_values(param: click.Parameter, tmp: Path) -> list[str]:
    """Values every parameter of this type must refuse (deterministic)."""
    kind = param.type
    missing = str(tmp / "no-such-file.mcap")
    if isinstance(kind, ct.Finite):
        low = f"{kind.min}" if kind.min_open else repr(math.nextafter(kind.min, -math.inf))
        high = f"{kind.max}" if kind.max_open else repr(math.nextafter(kind.max, math.inf))
        return [*NON_FINITE, low, high, *HUGE_INTEGERS, "-1e308", "abc", "", "1,5", "٣x"]
    if isinstance(kind, click.IntRange):
        return [str(kind.min - 1), str(kind.max + 1), *HUGE_INTEGERS, "nan", "inf", "1.5",
                "1e3", "", "abc", "-"]
    if isinstance(kind, click.Choice):
        return ["", "NONE", "abc", *(c.upper() + "x" for c in kind.choices)]
    if isinstance(kind, ct.InputFile):
        return ["", "\x00", missing, str(tmp), "x" * 300, f"{RECORDING}/inside"]
    if isinstance(kind, ct.InputDir):
        return ["", "\x00", str(tmp / "no-such-folder"), str(RECORDING)]
    if isinstance(kind, ct.OutputFile):
        return ["", " ", "\x00", str(tmp), str(tmp / "no" / "such" / "out.x"),
                f"{RECORDING}/out.x", str(tmp / ("x" * 300))]
    if isinstance(kind, ct.OutputDir):
        return ["", "\x00", str(RECORDING), f"{RECORDING}/sub", str(tmp / ("x" * 300))]
    if isinstance(kind, KeywordExpression):
        return ["", "(", ")", "and", "not", "a b", "a and", *CONTROL]
    if isinstance(kind, ct.NameList):
        bad = ["", " ", ",", "a,,b", "a,", *CONTROL, _too_long()]
        return bad + (["gpt", "ennet,gpt", "ENNET"] if kind.choices else [])
    if isinstance(kind, ct.Name | AngleLimit):
        bad = ["", " ", *CONTROL, _too_long()]
        if isinstance(kind, AngleLimit):
            bad += ["phi", "=3", "phi=", "phi>3", *(f"phi={v}" for v in NON_FINITE),
                    "phi=361", "phi=-1e308", "phi=abc", "\x00=3"]
        return bad
    if isinstance(kind, ct.FaultSpec):
        return ["", " ", "\x00", "warp", "drop:rate", "drop:rate=", "drop:rate=abc",
                "drop:rate=true", "drop:rat=0.1", *(f"drop:rate={v}" for v in NON_FINITE),
                "drop:burst=1e400", "stall:every_s=nan", "disconnect:at_s=1e10",
                "noise:sigma_mm=inf", "noise:sigma_mm=1/nan", "hysteresis:operators=1e9",
                "drop:rate=0.1/0.2", "stall:every_s=1/2", "disconnect:at_s=1/2",
                "drop:rate=2", str(tmp / "no-such-faults.toml"),
                str(tmp / "misspelled-faults.toml")]
    if isinstance(kind, ct.Robot):
        return ["", "abc", "udp:", "udp:host", "udp:host:0", "udp::9000", "udp:host:65536",
                "udp:host:x", "udp:host:1e3", "MUJOCO", "\x00"]
    if isinstance(kind, ct.Target):
        return ["", " ", "\x00", "nosuch://x", "socket://", "socket://host:0", "emulator:",
                f"emulator:{missing}", f"emulator:{RECORDING}?seed=-1",
                f"emulator:{RECORDING}?seed={2**64}", f"emulator:{RECORDING}?seed=x",
                f"emulator:{RECORDING}?faults=drop:rate=nan", f"emulator:{RECORDING}?speed=2",
                f"emulator:{RECORDING}?loop=2"]
    if isinstance(kind, ct.DeviceUrl):
        return ["", " ", "\x00", "\n", "nosuch://x", "socket://", "socket://host:0",
                "socket://:7000", "rfc2217://host:99999"]
    if isinstance(kind, ConformanceProfile):
        return ["", " ", "\x00", "nosuch", "default.toml", missing, str(tmp / "no-such.toml"),
                str(tmp / "bad-profile.toml")]
    if isinstance(kind, Protocol):
        return ["", "walk", "PAPER", "CALIBRATION", "calibration:60", "mot:", "mot:,",
                f"mot:{missing}", f"mot:{RECORDING},", "mot:\x00"]
    if isinstance(kind, Columns):
        return ["", "a", "-1", "3-1", "1,1", "1-", "0-100000", str(2**64), "1;2", "nan"]
    if isinstance(kind, Delimiter):
        return ["", ";;", "\n", "\r", '"', "\x00", "\x1b"]
    if isinstance(kind, ct.Widths):
        return ["", ",", "0", "-1", "1,,2", "64,", "1.5", "nan", "abc", str(kind.max_width + 1),
                ",".join(["8"] * (kind.max_layers + 1)), *HUGE_INTEGERS]
    pytest.fail(f"{param.name}: no bad values for type {type(kind).__name__}; add them here")


def random_bad_values(param: click.Parameter, tmp: Path) -> st.SearchStrategy[str]:
    """Generated values every parameter of this type must refuse."""
    kind = param.type
    text = st.text(max_size=30)
    if isinstance(kind, ct.Finite):
        below = st.floats(max_value=kind.min, exclude_max=not kind.min_open,
                          allow_nan=False, allow_infinity=False)
        above = st.floats(min_value=kind.max, exclude_min=not kind.max_open,
                          allow_nan=False, allow_infinity=False)
        return st.one_of(below.map(repr), above.map(repr), st.sampled_from(NON_FINITE),
                         st.integers(min_value=2**64).map(str), text.filter(_not_a_float))
    if isinstance(kind, click.IntRange):
        return st.one_of(st.integers(max_value=kind.min - 1).map(str),
                         st.integers(min_value=kind.max + 1).map(str),
                         text.filter(_not_an_int))
    if isinstance(kind, click.Choice):
        choices = {str(c).casefold() for c in kind.choices}
        return text.filter(lambda s: s.casefold() not in choices)
    if isinstance(kind, ct.InputFile | ct.InputDir):
        names = st.from_regex(r"[a-zA-Z0-9_.\-]{1,40}", fullmatch=True)
        return names.filter(lambda s: s not in (".", "..")).map(
            lambda s: str(tmp / "missing" / s))
    if isinstance(kind, ct.OutputFile):
        # "." would name the missing folder itself (pathlib drops it): a valid output file
        return text.map(lambda s: str(tmp / "no-such-folder" / (
            s.replace("/", "_").replace("\x00", "").strip(".") or "x")))
    if isinstance(kind, ct.OutputDir):
        return text.map(lambda s: f"{RECORDING}/{s}")
    if isinstance(kind, ct.Name | ct.NameList | AngleLimit):
        control = st.characters(categories=["Cc", "Cf", "Zl", "Zp", "Co"])
        return st.one_of(
            st.tuples(text, control, text).map("".join),
            st.text(min_size=ct.MAX_NAME_LENGTH + 1, max_size=ct.MAX_NAME_LENGTH + 20)
            .filter(lambda s: len(s) > ct.MAX_NAME_LENGTH),
            st.sampled_from(["", " ", "\t"]))
    if isinstance(kind, ct.FaultSpec):
        names = st.sampled_from(sorted(KINDS))
        unknown_kind = st.from_regex(r"[a-z_]{1,12}", fullmatch=True).filter(
            lambda s: s not in KINDS)
        number = st.one_of(st.sampled_from([*NON_FINITE, "abc", "true", "1/nan"]),
                           st.floats(min_value=1.0000001e9, allow_infinity=False).map(repr))
        with_bad_number = names.flatmap(lambda k: st.tuples(
            st.just(k), st.sampled_from([f.name for f in fields(KINDS[k])]), number)).map(
            lambda t: f"{t[0]}:{t[1]}={t[2]}")
        return st.one_of(with_bad_number, unknown_kind)
    if isinstance(kind, ct.Robot):
        return text.filter(lambda s: s not in ct.ROBOT_NAMES and not s.startswith("udp:"))
    if isinstance(kind, ct.DeviceUrl | ct.Target):
        schemes = st.from_regex(r"[a-z][a-z0-9]{0,10}", fullmatch=True).filter(
            lambda s: s not in ("alt", "cp2110", "hwgrep", "loop", "rfc2217", "socket", "spy"))
        return st.tuples(schemes, text).map(lambda t: f"{t[0]}://{t[1]}")
    if isinstance(kind, ConformanceProfile):
        return st.from_regex(r"[a-z_]{1,20}", fullmatch=True).filter(
            lambda s: s not in ("default", "bench", "ci"))
    if isinstance(kind, Protocol):
        return text.filter(lambda s: s not in ("paper", "calibration")
                           and not s.startswith("mot:"))
    if isinstance(kind, Columns):
        return st.one_of(st.integers(min_value=10_000).map(str),
                         st.integers(max_value=-1).map(str), text.filter(
                             lambda s: any(c.isalpha() for c in s)))
    if isinstance(kind, Delimiter):
        return st.text(min_size=2, max_size=5)
    if isinstance(kind, KeywordExpression):
        return st.sampled_from(["(", ")", "and", "or", "not", "a b", "a or", "(a"])
    if isinstance(kind, ct.Widths):
        width = st.one_of(st.integers(max_value=0), st.integers(min_value=kind.max_width + 1))
        return st.lists(width, min_size=1, max_size=3).map(lambda ws: ",".join(map(str, ws)))
    pytest.fail(f"{param.name}: no bad values for type {type(kind).__name__}; add them here")


# --- running a command with one bad value --------------------------------------------------

class _Reached(BaseException):
    """The command's body started: the bad value passed validation. A BaseException, so
    neither the CLI's catch-all nor click's test runner turns it into an exit code."""


def _argv(command: str, tmp: Path, bad: tuple[str, str] | None = None) -> list[str]:
    """The command line: the base arguments, with parameter ``bad[0]`` set to ``bad[1]``."""
    options: list[str] = []
    arguments: list[str] = []
    base = {k: [t.replace("{tmp}", str(tmp)) for t in v] for k, v in BASE[command].items()}
    for param in COMMANDS[command].params:
        tokens = base.get(param.name or "", [])
        if bad is not None and param.name == bad[0]:
            value = bad[1]
            if isinstance(param, click.Argument):
                tokens = [value, *tokens[1:]]
            else:
                flag = max(param.opts, key=len)
                tokens = [f"{flag}={value}"] if flag.startswith("--") else [flag, value]
        (arguments if isinstance(param, click.Argument) else options).extend(tokens)
    return [*command.split(), *options, *(["--", *arguments] if arguments else [])]


def _invoke(command: str, argv: list[str]):
    """The result of running ``argv`` with the command's body replaced by a tripwire
    (:class:`_Reached` propagates out of here when the body starts)."""
    def body(*args, **kwargs):
        raise _Reached(argv)

    with mock.patch.object(COMMANDS[command], "callback", body):
        return _runner().invoke(main, argv)


def _assert_refused_before_any_work(command: str, argv: list[str]) -> None:
    try:
        result = _invoke(command, argv)
    except _Reached:
        pytest.fail(f"{argv!r} passed validation: the command's body started")
    _assert_one_line_refusal(result, argv)


def _assert_one_line_refusal(result, argv: list[str]) -> None:
    shown = f"{argv!r}\nstdout: {result.stdout!r}\nstderr: {result.stderr!r}"
    assert "Traceback" not in result.stdout + result.stderr, shown
    assert result.exit_code == 2, shown
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error: "), shown
    assert result.stdout == "", shown


def test_every_command_has_base_arguments_that_pass_validation(tmp):
    assert set(BASE) == set(COMMANDS), "add the new command's base arguments to BASE"
    for command in COMMANDS:
        argv = _argv(command, tmp)
        with pytest.raises(_Reached):
            result = _invoke(command, argv)
            pytest.fail(f"{argv!r} was refused: {result.output}")


@pytest.mark.parametrize(("command", "name"), PARAMS, ids=[f"{c}:{n}" for c, n in PARAMS])
def test_known_bad_values_are_one_line_before_any_work(tmp, command, name):
    for value in fixed_bad_values(_param(command, name), tmp):
        _assert_refused_before_any_work(command, _argv(command, tmp, (name, value)))


@pytest.mark.parametrize(("command", "name"), PARAMS, ids=[f"{c}:{n}" for c, n in PARAMS])
@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(data=st.data())
def test_generated_bad_values_are_one_line_before_any_work(tmp, command, name, data):
    value = data.draw(random_bad_values(_param(command, name), tmp), label="value")
    _assert_refused_before_any_work(command, _argv(command, tmp, (name, value)))


# --- the types themselves: no option can let NaN or an unbounded number through -------------

def _all_params() -> Iterator[tuple[str, click.Parameter]]:
    for command_name, command in COMMANDS.items():
        for param in command.params:
            if _takes_a_value(param):
                yield f"{command_name} {param.name}", param


def test_every_float_option_refuses_nan_and_states_its_range():
    for where, param in _all_params():
        if isinstance(param.type, click.types.FloatParamType):
            assert isinstance(param.type, ct.Finite), f"{where}: use cli_types.Finite"
            assert math.isfinite(param.type.min) and math.isfinite(param.type.max), where
            for text in ("nan", "inf", "-inf"):
                with pytest.raises(click.BadParameter):
                    param.type.convert(text, param, None)


def test_every_integer_option_is_bounded():
    for where, param in _all_params():
        if isinstance(param.type, click.types.IntParamType):
            assert isinstance(param.type, click.IntRange), f"{where}: use cli_types.Count/Seed"
            assert param.type.min is not None and param.type.max is not None, where
            if param.name == "seed":
                assert isinstance(param.type, ct.Seed), where


def test_no_option_takes_a_plain_string_or_path():
    for where, param in _all_params():
        kind = param.type
        assert kind is not click.STRING, f"{where}: give it a type that refuses bad text"
        if isinstance(kind, click.Path):
            assert isinstance(kind, ct.InputFile | ct.InputDir | ct.OutputFile | ct.OutputDir),\
                f"{where}: use a cli_types path type"


# --- the real commands and the real executable -----------------------------------------------

REAL_CASES = [
    ["simulate", "--seed", "-1", "--out", "{tmp}/s.mcap"],
    ["simulate", "--seed", str(2**64), "--out", "{tmp}/s.mcap"],
    ["demo", "--seconds", "nan", "--out", "{tmp}/demo"],
    ["demo", "--faults", "drop:rate=nan", "--out", "{tmp}/demo"],
    ["emulate", str(RECORDING), "--faults", "noise:sigma_mm=inf"],
    ["emulate", str(RECORDING), "--faults", "drop:burst=1e400"],
    ["convert", "--from", "ms", "--to", "nao", "1e308", "1e308", "0"],
    ["convert", "--from", "quat", "--to", "nao", "1e308", "1e308", "0", "1"],
    ["train", str(RECORDING), "--out", "{tmp}/m.npz", "--time-budget", "nan"],
    ["import", "csv", str(RECORDING), "--rate", "inf", "--sensor-cols", "1", "--out",
     "{tmp}/c.mcap"],
    ["table", "--train", str(RECORDING), "--models", "ennet,gpt"],
    ["run", "nosuch://device"],
    ["--no-such-option"],
    ["no-such-command"],
]


@pytest.mark.parametrize("args", REAL_CASES, ids=[" ".join(a[:3]) for a in REAL_CASES])
def test_known_failures_are_one_line_and_write_nothing(tmp_path, args):
    argv = [a.replace("{tmp}", str(tmp_path)) for a in args]
    result = _runner().invoke(main, argv)
    _assert_one_line_refusal(result, argv)
    assert list(tmp_path.iterdir()) == []


def test_the_executable_prints_one_line_and_exits_2(tmp_path):
    exe = Path(sys.executable).with_name("exohil")
    command = [str(exe)] if exe.is_file() else [sys.executable, "-m", "exohil"]
    done = subprocess.run([*command, "simulate", "--seed", "-1", "--out",
                           str(tmp_path / "s.mcap")], capture_output=True, text=True,
                          timeout=120, check=False)
    assert done.returncode == 2
    assert done.stdout == ""
    assert done.stderr == ("Error: Invalid value for '--seed': -1 is not in the range "
                           "0<=x<=4294967295.\n")


def _group_with(exc: BaseException) -> click.Group:
    @click.group(cls=_Group)
    def group() -> None:
        pass

    @group.command()
    def boom() -> None:
        raise exc

    return group


def test_an_unexpected_error_deep_in_a_command_is_one_line(monkeypatch):
    monkeypatch.delenv(TRACEBACK_ENV, raising=False)
    result = _runner().invoke(_group_with(ValueError("expected non-negative integer")),
                              ["boom"])
    assert result.exit_code == 1
    assert result.stderr == ("Error: unexpected ValueError: expected non-negative integer (set "
                             f"{TRACEBACK_ENV}=1 for the traceback)\n")


def test_the_traceback_is_there_when_asked_for(monkeypatch):
    monkeypatch.setenv(TRACEBACK_ENV, "1")
    result = _runner().invoke(_group_with(ValueError("x")), ["boom"])
    assert isinstance(result.exception, ValueError)


def test_a_multi_line_message_becomes_one_line():
    result = _runner().invoke(_group_with(click.ClickException("first\n  second\n")), ["boom"])
    assert result.exit_code == 1 and result.stderr == "Error: first second\n"


def test_help_is_still_help():
    result = _runner().invoke(main, ["simulate", "--help"])
    assert result.exit_code == 0 and "--seed" in result.stdout


@pytest.mark.parametrize("args, message", [
    (["evaluate", "{model}", "{rec}", "{link}"], "its frames would count twice"),
    (["calibrate", "{model}", "{rec}", "{rec}", "--out", "{tmp}/c.npz"],
     "its frames would count twice"),
    (["train", "{rec}", "{link}", "--out", "{tmp}/m.npz"], "its frames would count twice"),
    (["table", "--train", "{rec}", "--test", "{link}", "--out", "{tmp}/t.md"],
     "a model would be scored on a recording it was trained on"),
])
def test_a_recording_given_twice_is_refused(tmp_path, args, message):
    """`evaluate M X X` scored every frame twice; `table --train X --test X` scored a model on
    its own training recording."""
    from exohil.harness.paths import FIXTURES_DIR

    rec = FIXTURES_DIR / "paper_protocol_heldout.mcap"
    link = tmp_path / "link.mcap"
    link.symlink_to(rec)
    values = {"model": str(FIXTURES_DIR / "models" / "ennet.npz"), "rec": str(rec),
              "link": str(link), "tmp": str(tmp_path)}
    result = CliRunner().invoke(main, [a.format(**values) for a in args])
    assert result.exit_code == 2, result.output
    assert "are the same file: " + message in result.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.mcap"]


@pytest.mark.parametrize("args", [
    ["train", "--angles", "elv_angle,elv_angle", "x.mcap", "--out", "m.npz"],
    ["table", "--models", "ann,classical,ann", "--train", "x.mcap"],
    ["import", "csv", "x.csv", "--rate", "100", "--sensor-names", "a, a", "--out", "y.mcap"],
])
def test_a_name_given_twice_in_a_list_is_refused(args):
    """`train --angles elv_angle,elv_angle` trained a model of two equal outputs whose metrics
    showed one."""
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 2, result.output
    assert "twice" in result.output and "Traceback" not in result.output
