"""Benchmarks refuse what they cannot do before they run, with one line: outputs that would
overwrite an input or cannot be written, meaningless values, unreadable inputs. Nothing here
asserts a timing; the runs that start are a fraction of a second long."""

import argparse
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from cli_interrupt import sigint_handled_by, started_with_sigint

ROOT = Path(__file__).resolve().parents[1]
FIXTURE = ROOT / "fixtures" / "paper_protocol.mcap"
MODEL = ROOT / "fixtures" / "models" / "ennet.npz"


def run_module(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=timeout)


def refused(result: subprocess.CompletedProcess[str], message: str, status: int = 2) -> None:
    """Exit ``status`` with ``message`` on stderr's last line and no traceback."""
    assert result.returncode == status, (result.returncode, result.stderr)
    assert "Traceback" not in result.stderr, result.stderr
    assert message in result.stderr.strip().splitlines()[-1], result.stderr


@pytest.fixture
def report_module(monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT))
    import benchmarks.report

    return benchmarks.report


def test_json_never_overwrites_a_checkpoint_it_times(tmp_path):
    checkpoint = tmp_path / "c.npz"
    shutil.copy(MODEL, checkpoint)
    before = checkpoint.read_bytes()
    out = run_module("benchmarks.bench_inference", "--checkpoint", str(checkpoint), "--json",
                     str(checkpoint))
    refused(out, "would overwrite the input")
    assert out.stdout == "" and checkpoint.read_bytes() == before


def test_json_never_overwrites_a_calibration_recording(tmp_path):
    recording = tmp_path / "test.mcap"
    shutil.copy(FIXTURE, recording)
    before = recording.read_bytes()
    out = run_module("benchmarks.bench_calibration", "--case", "a", str(MODEL), str(FIXTURE),
                     str(recording), "--json", str(recording))
    refused(out, f"--json {recording} would overwrite the input")
    assert out.stdout == "" and recording.read_bytes() == before


def test_robot_outputs_never_overwrite_its_fixture_and_the_gif_is_a_gif(tmp_path):
    # a hard link names the fixture; were it written, only the link would be replaced
    before = FIXTURE.stat().st_mtime_ns
    for option in ("--json", "--gif"):
        name = tmp_path / f"link{option}.gif"
        os.link(FIXTURE, name)
        out = run_module("benchmarks.bench_robot", "--seconds", "0.5", option, str(name))
        refused(out, "would overwrite the input")
        assert name.stat().st_ino == FIXTURE.stat().st_ino
    assert FIXTURE.stat().st_mtime_ns == before
    refused(run_module("benchmarks.bench_robot", "--gif", str(tmp_path / "a.png")),
            "name it *.gif")
    refused(run_module("benchmarks.bench_robot", "--gif", "/nonexist/a.gif"), "no such folder")
    refused(run_module("benchmarks.bench_robot", "--gif", str(tmp_path)), "is a folder")


@pytest.mark.parametrize("start", ["nan", "-100", "1e6", "240"])
def test_the_robot_replay_must_lie_within_the_fixture(start):
    refused(run_module("benchmarks.bench_robot", "--start", start), "within the fixture's")


@pytest.mark.parametrize("value, message", [("", "empty file name"), ("/tmp", "is a folder")])
def test_json_names_a_file_that_can_be_written(value, message):
    refused(run_module("benchmarks.bench_sim", "--json", value), message)


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux /proc")
def test_json_in_a_folder_that_takes_no_files_is_refused(report_module):
    # /proc exists but no new file can be created in it, even by root (the check tries one,
    # as the exohil commands' output options do: a permission check alone passes for root)
    with pytest.raises(argparse.ArgumentTypeError, match="cannot write in folder /proc"):
        report_module.json_file("/proc/x.json")


@pytest.mark.parametrize("args, message", [
    (("--read-timeout-ms", "0"), "must be a positive number"),
    (("--read-timeout-ms", "-5"), "must be a positive number"),
    (("--read-timeout-ms", "nan"), "must be a positive number"),
    (("--spin-ms", "-1"), "finite number ≥ 0"),
    (("--spin-ms", "nan"), "finite number ≥ 0"),
    (("--spin-ms", "1e9"), "longer than the 4 ms period"),
])
def test_emulator_timings_are_checked_before_the_child_starts(args, message):
    out = run_module("benchmarks.bench_emulator", "--seconds", "0.5", *args, timeout=60)
    refused(out, message)
    assert out.stdout == ""


def test_emulator_run_too_short_for_a_rate_is_one_line():
    out = run_module("benchmarks.bench_emulator", "--seconds", "0.001", timeout=90)
    refused(out, "too few frames to measure a rate")


@pytest.mark.parametrize("args, message", [
    (("--pace-hz", "-5"), "finite number ≥ 0"),
    (("--pace-hz", "nan"), "finite number ≥ 0"),
    (("--pace-hz", "inf"), "finite number ≥ 0"),
    (("--frames", "1"), "at least 100 for a p99"),
    (("--checkpoint", "README.md"), "error: README.md: not an exohil estimator checkpoint"),
])
def test_inference_refuses_meaningless_values_and_bad_checkpoints(args, message):
    refused(run_module("benchmarks.bench_inference", *args), message)


@pytest.mark.parametrize("args, message", [
    (("--robot", "bogus"), "error: unknown robot 'bogus'"),
    (("--faults", "bogus"), "error: unknown effect kind 'bogus'"),
    # every frame dropped: "--seconds 0.001" was relied on to end before the first frame,
    # and under load one arrived (the tox probe saw it)
    (("--faults", "drop:rate=1"), "error: no frame arrived"),
])
def test_pipeline_session_errors_are_one_line(args, message):
    refused(run_module("benchmarks.bench_pipeline", "--seconds", "1", *args), message)


def test_soak_output_folder_is_checked_and_json_may_go_into_it(tmp_path):
    refused(run_module("benchmarks.soak", "--out", "README.md"), "exists and is not a folder")
    refused(run_module("benchmarks.soak", "--out", str(tmp_path / "d"), "--json",
                       str(tmp_path / "e" / "x.json")), "no such folder")
    assert not (tmp_path / "d").exists()  # refused before anything was created


def test_soak_accepts_json_inside_the_folder_it_creates(report_module, monkeypatch, tmp_path):
    from benchmarks import soak

    seen = {}
    monkeypatch.setattr(soak, "run_session", lambda config, seconds, progress: seen.setdefault(
        "out", config.record.parent) and (_ for _ in ()).throw(KeyboardInterrupt))
    monkeypatch.setattr(sys, "argv", ["soak", "--out", str(tmp_path / "d"), "--json",
                                      str(tmp_path / "d" / "x.json")])
    with pytest.raises(KeyboardInterrupt):
        soak.main()
    assert seen["out"] == tmp_path / "d" and (tmp_path / "d").is_dir()


def test_recording_sizes_are_in_bytes(report_module):
    from exohil.formats.measurement import Measurement

    line = report_module.table([Measurement.judge("lz4.size", 1234567, "B")])[1]
    assert "1234567  B" in line


@pytest.fixture
def sigint_restored() -> Iterator[None]:
    """SIGINT's handler in this process restored after the test (``run_main`` sets its own,
    and a test that runs later in this process must find the one it inherited)."""
    with sigint_handled_by(signal.getsignal(signal.SIGINT)):
        yield


def test_run_main_turns_input_errors_into_one_line_and_ctrl_c_into_130(report_module, capsys,
                                                                         sigint_restored):
    from exohil.estimator.checkpoint import CheckpointError

    def raising(exc):
        def main():
            raise exc
        return main

    for exc, status, line in [(CheckpointError("c.npz: bad"), 2, "error: c.npz: bad"),
                              (FileNotFoundError(2, "No such file", "x"), 2,
                               "error: x: No such file"),
                              (KeyboardInterrupt(), 130, "interrupted; nothing written")]:
        with pytest.raises(SystemExit) as exit_:
            report_module.run_main(raising(exc))
        assert exit_.value.code == status
        assert capsys.readouterr().err == line + "\n"
    with pytest.raises(RuntimeError):  # a bug keeps its traceback
        report_module.run_main(raising(RuntimeError("bug")))
    for returned, status in [(None, 0), (1, 1)]:  # `python -m benchmarks`: 1 when one broke
        with pytest.raises(SystemExit) as exit_:
            report_module.run_main(lambda returned=returned: returned)
        assert exit_.value.code == status


CTRL_C = """
import os, signal, sys, time
from concurrent.futures import ProcessPoolExecutor
import multiprocessing
sys.path.insert(0, {root!r})
from benchmarks.report import run_main

def nap(_):
    time.sleep(30)

def main():
    with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("fork")) as pool:
        print("ready", flush=True)
        list(pool.map(nap, range(4)))

run_main(main)
"""


def test_ctrl_c_stops_the_workers_at_once_without_tracebacks(tmp_path):
    script = tmp_path / "ctrl_c.py"
    script.write_text(CTRL_C.format(root=str(ROOT)))
    proc = subprocess.Popen(started_with_sigint(signal.SIG_DFL, [sys.executable, str(script)]),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)  # SIGINT as at a terminal
    assert proc.stdout is not None and proc.stdout.readline() == "ready\n"
    time.sleep(1.0)  # the workers have started their naps
    os.killpg(proc.pid, signal.SIGINT)  # what the terminal sends on Ctrl-C
    _, err = proc.communicate(timeout=20)  # far less than the workers' 30 s naps
    assert proc.returncode == 130 and err == "interrupted; nothing written\n", err


def test_run_main_leaves_an_ignored_sigint_ignored(report_module):
    seen = []
    with sigint_handled_by(signal.SIG_IGN), pytest.raises(SystemExit) as exit_:
        report_module.run_main(lambda: seen.append(signal.getsignal(signal.SIGINT)))
    assert exit_.value.code == 0 and seen == [signal.SIG_IGN]


SIGINT_IGNORED = """
import os, sys, time
from concurrent.futures import ProcessPoolExecutor
import multiprocessing
sys.path.insert(0, {root!r})
from benchmarks.report import run_main

def nap(k):
    os.write(1, b"napping\\n")  # one write: two workers' prints came out interleaved
    time.sleep(2)
    return k

def main():
    with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as pool:
        print(list(pool.map(nap, range(2))), flush=True)

if __name__ == "__main__":
    run_main(main)
"""


def test_a_benchmark_started_with_sigint_ignored_and_its_workers_run_on(tmp_path):
    """Until 2026-12-07 its spawned workers ended at the group's SIGINT (and the benchmark
    with 130)."""
    script = tmp_path / "ignored.py"
    script.write_text(SIGINT_IGNORED.format(root=str(ROOT)))
    proc = subprocess.Popen(started_with_sigint(signal.SIG_IGN, [sys.executable, str(script)]),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)  # SIGINT as a script's `cmd &` has it
    try:
        assert proc.stdout is not None
        assert [proc.stdout.readline(), proc.stdout.readline()] == ["napping\n"] * 2
        os.killpg(proc.pid, signal.SIGINT)  # what the terminal sends on Ctrl-C
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 0 and out == "[0, 1]\n" and err == "", (out, err)


def test_the_pools_cancelled_future_race_is_quiet_and_other_thread_errors_are_not():
    """The InvalidStateError Python 3.11's process pool raises in its manager thread's
    ``terminate_broken`` on Ctrl-C (CPython gh-107219) is dropped; the same error raised
    elsewhere, and any other error of that thread, still reach the hook before."""
    import threading
    from concurrent.futures import InvalidStateError

    from benchmarks.report import _quiet_cancelled_future_race

    seen = []
    hook = _quiet_cancelled_future_race(lambda args: seen.append(args.exc_type))
    namespace: dict = {"InvalidStateError": InvalidStateError}
    source = "def terminate_broken(error):\n    raise error\n"
    for where in (os.path.join("lib", "concurrent", "futures", "process.py"), "elsewhere.py"):
        exec(compile(source, where, "exec"), namespace)
        for error in (InvalidStateError("CANCELLED"), RuntimeError("a bug")):
            try:
                namespace["terminate_broken"](error)
            except Exception as exc:  # noqa: BLE001 - handed to the hook as a thread's
                hook(threading.ExceptHookArgs([type(exc), exc, exc.__traceback__, None]))
    assert seen == [RuntimeError, InvalidStateError, RuntimeError]


@pytest.mark.parametrize("args, message", [
    (("--seeds", "0"), "--seeds: must be at least 1"),
    (("--seeds", "-3"), "--seeds: must be at least 1"),
    (("--duration", "0"), "--duration: must be a positive number"),
    (("--duration", "-5"), "--duration: must be a positive number"),
    (("--duration", "nan"), "--duration: must be a positive number"),
    (("--workers", "0"), "--workers: must be at least 1"),
    (("--time-workers", "0"), "--time-workers: must be at least 1"),
    (("--repeats", "-1"), "--repeats: must be at least 0"),
    (("--no-sweep", "--repeats", "0"), "does nothing"),
    (("--time-on", "README.md"), "--time-on: README.md: not an MCAP file"),
    (("--mocap-late", "nan"), "--mocap-late: must be a finite number"),
    (("--mocap-late", "0.5", "--repeats", "0"), "--mocap-late with --repeats 0 times nothing"),
])
def test_the_discrepancy_sweep_refuses_meaningless_values_before_it_starts(args, message):
    out = run_module("benchmarks.bench_discrepancy", *args)
    refused(out, message)
    assert out.stdout == ""


@pytest.mark.parametrize("args, message", [
    (("--seeds", "0"), "--seeds: must be at least 1"),
    (("--duration", "0"), "--duration: must be a positive number"),
    (("--workers", "0"), "--workers: must be at least 1"),
    (("--out", "README.md"), "README.md exists and is not a folder"),
])
def test_the_sphere_refuses_meaningless_values_before_it_starts(args, message):
    refused(run_module("benchmarks.bench_discrepancy_sphere", *args), message)


@pytest.mark.parametrize("args, message", [
    (("--seeds", "0"), "--seeds: must be at least 1"),
    (("--noise", "half"), "--noise: not a list of numbers: 'half'"),
    (("--noise", "0.5,-1"), "--noise: each SD must be a finite number ≥ 0: '0.5,-1'"),
    (("--noise", "nan"), "--noise: each SD must be a finite number ≥ 0: 'nan'"),
    (("--duration", "0"), "--duration: must be a positive number"),
    (("--workers", "0"), "--workers: must be at least 1"),
])
def test_the_angle_noise_benchmark_refuses_meaningless_values_before_it_starts(args, message):
    out = run_module("benchmarks.bench_discrepancy_angle_noise", *args)
    refused(out, message)
    assert out.stdout == ""


def test_the_sphere_answer_key_is_the_list_the_blind_scorer_reads(monkeypatch, tmp_path):
    monkeypatch.syspath_prepend(str(ROOT))
    from benchmarks.bench_discrepancy_blind import load_truth
    from benchmarks.bench_discrepancy_sphere import SphereCase, write_cases

    write_cases(tmp_path, [SphereCase("lag", 2, 1, 3.0), SphereCase("clean", 1, 0, 3.0)])
    truth = load_truth(tmp_path)  # exits on a key it cannot score
    assert [(e["file"], e["effect"]) for e in truth] == [("lag_m2_s1.mcap", "lag"),
                                                         ("clean_m1_s0.mcap", "clean")]
    assert truth[0]["rms_mm"] == pytest.approx(0.6) and truth[1]["rms_mm"] == 0.0


def _blind_folder(tmp_path: Path, entries: list[dict]) -> Path:
    import json

    folder = tmp_path / "blind"
    folder.mkdir()
    for entry in entries:
        (folder / entry["file"]).write_bytes(b"not a recording")
    (folder / "truth.json").write_text(json.dumps(entries))
    return folder


def test_blind_out_never_overwrites_the_twin_summaries_it_reads(tmp_path):
    folder = _blind_folder(tmp_path, [{"file": "rec_00.mcap", "effect": "lag"}])
    twins = tmp_path / "runs"
    twins.mkdir()
    summary = twins / "rec_00.json"
    summary.write_text('{"gap_before": 1.0}')
    for out in (twins, tmp_path / "runs" / "."):
        result = run_module("benchmarks.bench_discrepancy_blind", str(folder), "--twins",
                            str(twins), "--out", str(out))
        refused(result, "would overwrite the input")
    assert summary.read_text() == '{"gap_before": 1.0}'


def test_blind_reports_an_unreadable_recording_and_refuses_an_empty_key(tmp_path):
    folder = _blind_folder(tmp_path, [{"file": "rec_00.mcap", "effect": "lag"}])
    out = run_module("benchmarks.bench_discrepancy_blind", str(folder), "--workers", "1")
    refused(out, "none of the 1 recordings could be run")
    assert "rec_00   lag         not scored: " in out.stdout and "MCAP" in out.stdout
    (folder / "truth.json").write_text("[]")
    refused(run_module("benchmarks.bench_discrepancy_blind", str(folder)), "lists no recording")


@pytest.mark.parametrize("module, words", [
    ("benchmarks.blind4.generate", ["independent test-data generator", "clean twin"]),
    ("benchmarks.blind5.generate", ["pulley-routed tendons and flex goniometers",
                                    "never the workflow", "clean twin", "--only"]),
    ("benchmarks.blind6.generate", ["blind6 recordings and their answer key", "clean twins",
                                    "--only"]),
    ("benchmarks.blind3.antipodal", ["anchors pass", "opposite sides of the cap."]),
    ("benchmarks.blind4.verify", ["by the magnitude its truth gives."]),
])
def test_help_gives_the_whole_first_paragraph_and_every_option(module, words):
    out = run_module(module, "--help")
    assert out.returncode == 0, out.stderr
    text = " ".join(out.stdout.split())
    assert all(word in text for word in words), text


def test_blind4_verify_without_an_answer_key_is_one_line(tmp_path):
    refused(run_module("benchmarks.blind4.verify", str(tmp_path), str(tmp_path)),
            "truth.json not found")


def test_unseen_suits_checks_model_names_and_shows_a_failed_commands_stderr(monkeypatch):
    out = run_module("benchmarks.bench_unseen_suits", "--model", "bogus")
    refused(out, "unknown model 'bogus'; choose from ennet")
    monkeypatch.syspath_prepend(str(ROOT))
    from benchmarks.bench_unseen_suits import _exohil
    from benchmarks.report import BenchmarkError

    with pytest.raises(BenchmarkError, match=r"-c 'import sys; sys.exit\(\"boom\"\)' exited 1: "
                                             r"boom"):
        _exohil([sys.executable, "-c", 'import sys; sys.exit("boom")'])


def test_the_runner_refuses_an_unknown_benchmark_before_any_runs():
    """`python -m benchmarks NAME...` (`tox -e bench -- NAME...`) runs only those; a misspelt
    name is refused before the first one starts."""
    result = run_module("benchmarks", "bench_simm", "bench_sim")
    refused(result, "unknown benchmark bench_simm: choose from bench_sim, bench_recording_io")
    assert "=== benchmarks." not in result.stdout


def test_the_runner_runs_the_benchmarks_named_in_their_order(report_module, monkeypatch,
                                                             capsys):
    import json

    import benchmarks.__main__ as runner

    ran: list[str] = []

    def call(command: list[str]) -> int:  # each benchmark's process, not started here
        ran.append(command[2])
        Path(command[-1]).write_text(json.dumps({"benchmark": command[2], "measurements": []}))
        return 0

    monkeypatch.setattr(runner.subprocess, "call", call)
    monkeypatch.setattr(sys, "argv", ["benchmarks", "bench_robot", "bench_sim"])
    assert runner.main() == 0
    assert ran == ["benchmarks.bench_robot", "benchmarks.bench_sim"]
    monkeypatch.setattr(sys, "argv", ["benchmarks"])
    ran.clear()
    assert runner.main() == 0
    assert ran == [f"benchmarks.{name}" for name in runner.BENCHMARKS]
