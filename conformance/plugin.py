"""The pytest plugin behind ``exohil conform`` (registered under the ``pytest11`` entry point).

    pytest --pyargs exohil.conformance \\
        --exohil-target emulator:fixtures/paper_protocol_heldout.mcap \\
        --exohil-model fixtures/models/ennet.npz [--exohil-profile ci] [--exohil-out DIR]

Each check of ``test_checks.py`` records its measurements (name, value, unit, limit, verdict)
as JUnit properties and into the run's report. A check whose limits are all met passes; one
that cannot be measured (no reference, not in the profile, no baseline) is skipped, and a
skipped *required* check (one the profile names, other than ``regression`` without a
baseline) makes the run fail: skipped is never passed. A required check left out of the
session (``-k``, a node id) is reported as skipped, "not run", so a subset never passes the
profile; the checks that did run keep their own verdicts. With ``--exohil-out DIR`` the run
writes ``conformance.json``, ``summary.md`` and ``run.mcap`` there (``exohil conform`` adds
``junit.xml``).
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from exohil.formats.measurement import Measurement, Verdict

CHECKS_MODULE = "exohil.conformance.test_checks"
_RESULTS = pytest.StashKey[list["CheckResult"]]()
_RUN = pytest.StashKey[object]()
_SELECTED = pytest.StashKey[set[str]]()


@dataclass
class CheckResult:
    """The outcome of one check."""

    name: str
    verdict: Verdict
    required: bool
    message: str
    duration_s: float
    measurements: list[Measurement] = field(default_factory=list)


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("exohil", "exohil conformance suite (docs/conformance.md)")
    group.addoption("--exohil-target", default=None,
                    help="emulator:RECORDING[?faults=SPEC&seed=N] or a pyserial URL.")
    group.addoption("--exohil-model", default=None, help="Checkpoint under test (.npz).")
    group.addoption("--exohil-bench", default=None,
                    help="Bench file (TOML) naming the device and model; the options above "
                         "override it (a target alone keeps the bench's reference).")
    group.addoption("--exohil-profile", default="default",
                    help="Profile name (default, bench, ci) or a .toml file.")
    group.addoption("--exohil-baseline", default=None,
                    help="Baseline for the regression check: a checkpoint or an earlier "
                         "run's conformance.json.")
    group.addoption("--exohil-reference", default=None,
                    help="Ground truth recording for a serial device (aligned by device time).")
    group.addoption("--exohil-backend", default=None,
                    help="Streaming inference backend [the bench's, else auto].")
    group.addoption("--exohil-out", default=None,
                    help="Folder for conformance.json, summary.md and run.mcap (an earlier "
                         "run's are removed first; one that is an input is refused).")
    group.addoption("--exohil-verdict-after", action="store_true",
                    help="The caller prints the verdict line after pytest's own lines "
                         "(exohil conform): the summary table leaves it out.")


def _is_check(item: pytest.Item) -> bool:
    module = getattr(item, "module", None)
    return module is not None and module.__name__ == CHECKS_MODULE


def pytest_collection_modifyitems(session: pytest.Session, config: pytest.Config,
                                  items: list[pytest.Item]) -> None:
    if not any(_is_check(item) for item in items):
        return
    from exohil.conformance.context import ConformanceRun
    from exohil.conformance.profile import ProfileError, load_profile
    from exohil.harness.bench import BenchConfig, BenchError, SerialDevice, load_bench

    try:
        bench_file = config.getoption("exohil_bench")
        bench = load_bench(Path(bench_file)) if bench_file else BenchConfig()
        target = config.getoption("exohil_target") or bench.device
        model = config.getoption("exohil_model") or bench.model
        if not target or not model:
            raise pytest.UsageError("the conformance suite needs --exohil-target and "
                                    "--exohil-model, or a --exohil-bench file naming them")
        profile = load_profile(config.getoption("exohil_profile"))
        reference = config.getoption("exohil_reference")
        if (reference is None and isinstance(target, str) and isinstance(bench.device,
                                                                        SerialDevice)
                and not target.startswith("emulator:")):
            # another port for the bench's device (it re-enumerated): the same ground truth
            reference = bench.device.reference
        baseline = config.getoption("exohil_baseline")
        if baseline is not None and "regression" not in profile.checks:
            raise pytest.UsageError(
                f"baseline {baseline}: profile {profile.name} has no "
                "[checks.regression], so nothing would compare with the baseline and the run "
                "could pass without it; add [checks.regression] to the profile or leave out "
                "the baseline")
        run = ConformanceRun(target, Path(model), profile,
                             reference=None if reference is None else Path(reference),
                             baseline=None if baseline is None else Path(baseline),
                             backend=config.getoption("exohil_backend") or bench.backend,
                             say=_progress_writer(config), sensor_names=bench.sensor_names,
                             rate_hz=bench.rate_hz)
    except (ProfileError, BenchError) as err:
        raise pytest.UsageError(str(err)) from None
    out = config.getoption("exohil_out")
    if out:
        _clear_earlier_reports(Path(out), run, bench_file)
    config.stash[_RUN] = run
    config.stash[_RESULTS] = []


def _clear_earlier_reports(out: Path, run, bench_file: str | None) -> None:
    """Refuse an --exohil-out whose reports would replace one of the run's inputs (a
    baseline ``conformance.json`` in the same folder, the target recording, the model, the
    bench file or the profile), then remove an earlier run's reports there: a run killed
    before it writes leaves no report of another run looking like its own, and a run whose
    real-time segment did not run leaves no earlier ``run.mcap`` beside its reports."""
    from exohil.conformance.report import REPORT_FILES
    from exohil.formats.atomic import same_file
    from exohil.harness.bench import EmulatorDevice

    inputs = [run.model_path, run.baseline_path, run.reference_file, run.profile.path,
              bench_file and Path(bench_file),
              run.device.recording if isinstance(run.device, EmulatorDevice) else None]
    for name in REPORT_FILES:
        clash = same_file(out / name, [p for p in inputs if p is not None])
        if clash is not None:
            raise pytest.UsageError(f"--exohil-out {out}: its {name} is the input {clash}; "
                                    "refusing to overwrite it (choose another folder)")
    for name in REPORT_FILES:
        (out / name).unlink(missing_ok=True)


def _progress_writer(config: pytest.Config) -> Callable[[str], None]:
    """Progress lines to the terminal, past pytest's output capture, every 5 s at most for
    repeated lines."""
    reporter = config.pluginmanager.get_plugin("terminalreporter")
    capture = config.pluginmanager.get_plugin("capturemanager")
    last = [0.0]

    def say(line: str) -> None:
        now = time.monotonic()
        if reporter is None or (line.startswith("  ") and now - last[0] < 5.0):
            return
        last[0] = now
        with capture.global_and_fixture_disabled() if capture else contextlib.nullcontext():
            reporter.ensure_newline()
            reporter.write_line(f"[exohil] {line}")

    return say


def _required(name: str, run) -> bool:
    """Whether the run passes only with ``name`` passed: every check the profile names,
    except ``regression`` without a baseline."""
    return name in run.profile.checks and not (name == "regression" and
                                               run.baseline_path is None)


def pytest_collection_finish(session: pytest.Session) -> None:
    """Which checks the session selected (``-k`` and node ids applied)."""
    if _RUN in session.config.stash:
        selected: set[str] = {str(item.callspec.params["name"]) for item in session.items
                              if isinstance(item, pytest.Function) and _is_check(item)}
        session.config.stash[_SELECTED] = selected


def _with_checks_not_run(run, results: list[CheckResult],
                         interrupted: set[str] | None = None) -> list[CheckResult]:
    """``results`` with a skipped entry for each check the session left out (``-k``, a node
    id) or, among ``interrupted`` (those selected in a run that was interrupted), never
    reached, in the suite's order."""
    from exohil.conformance.profile import CHECKS
    from exohil.conformance.report import INTERRUPTED, NOT_RUN

    ran = {r.name: r for r in results}
    out = []
    for name in CHECKS:
        if name in ran:
            out.append(ran.pop(name))
        else:
            message = (f"not in profile {run.profile.name}" if name not in run.profile.checks
                       else INTERRUPTED if name in (interrupted or ()) else NOT_RUN)
            out.append(CheckResult(name, Verdict.SKIP, _required(name, run), message, 0.0))
    return out + list(ran.values())


def unmatched_limits(profile, check: str, measurements: list[Measurement]) -> list[str]:
    """The profile's limits on members of ``check``'s families (``accuracy.rmse.*``: the
    model's angles; ``latency.end_to_end.*``: p50, p99, max) that name none of
    ``measurements``. A profile is loaded before the model is, so ``accuracy.rmse.elv_anlge``
    or ``latency.end_to_end.p95`` pass the profile's vocabulary and would judge nothing,
    leaving the measurement they meant without its limit."""
    from exohil.conformance.profile import CHECKS

    measured = {m.name for m in measurements}
    return [limit for limit in profile.checks.get(check, {})
            if limit not in CHECKS[check] and limit not in measured]


@pytest.fixture(scope="session")
def conformance_run(request: pytest.FixtureRequest):
    """The run under test (:class:`exohil.conformance.context.ConformanceRun`)."""
    return request.config.stash[_RUN]


@pytest.fixture
def check(request: pytest.FixtureRequest, conformance_run, record_property):
    """``check(name, produce)``: measure one check with ``produce(run)`` and judge it."""
    from exohil.conformance.context import CheckBlocked
    from exohil.harness.session import SessionError

    results = request.config.stash[_RESULTS]
    profile = conformance_run.profile

    def run_check(name: str, produce: Callable[[object], list[Measurement]]) -> None:
        start = time.perf_counter()
        required = _required(name, conformance_run)

        def done(verdict: Verdict, message: str, measurements: list[Measurement]) -> None:
            results.append(CheckResult(name, verdict, required, message,
                                       time.perf_counter() - start, measurements))

        if name not in profile.checks:
            done(Verdict.SKIP, f"not in profile {profile.name}", [])
            pytest.skip(f"{name}: not in profile {profile.name}")
        try:
            measurements = produce(conformance_run)
        except CheckBlocked as err:
            blocked, failure = str(err), None
        except SessionError as err:
            blocked, failure = None, str(err)
        else:
            blocked = failure = None
        # outside the except clauses, so pytest shows the one message, not the chain
        if blocked is not None:
            done(Verdict.SKIP, blocked, [])
            pytest.skip(f"{name}: {blocked}")
        if failure is not None:
            done(Verdict.FAIL, failure, [])
            pytest.fail(f"{name}: {failure}", pytrace=False)
        for m in measurements:
            for key, value in m.junit_properties():
                record_property(key, value)
        unmatched = unmatched_limits(profile, name, measurements)
        if unmatched:
            message = (f"profile {profile.name} limits {', '.join(unmatched)}, which this check "
                       f"did not measure (it measured {', '.join(m.name for m in measurements)}"
                       "): a misspelt limit judges nothing")
            done(Verdict.FAIL, message, measurements)
            pytest.fail(f"{name}: {message}", pytrace=False)
        failed = [m for m in measurements if m.failed]
        judged = [m for m in measurements if m.limit is not None]
        if failed:  # a note the measurement before gave (the frames scored) is not repeated
            message = "; ".join(m.describe(with_note=m.note not in [f.note for f in failed[:i]])
                                for i, m in enumerate(failed))
            done(Verdict.FAIL, message, measurements)
            pytest.fail(f"{name}: {message}", pytrace=False)
        if judged and all(m.verdict is Verdict.SKIP for m in judged):
            message = "; ".join(f"{m.name}: {m.note}" for m in judged)
            done(Verdict.SKIP, message, measurements)
            pytest.skip(f"{name}: {message}")
        passed = sum(m.verdict is Verdict.PASS for m in measurements)
        # a limit that could not be measured here is said on the verdict's line, not only in
        # the report's notes: the check passed on what it could judge
        unjudged = [m.name for m in judged if m.verdict is Verdict.SKIP]
        message = (f"{passed} measurement(s) within limits" if judged else
                   f"{len(measurements)} measurement(s) reported, none with a limit")
        if unjudged:
            message += f"; {len(unjudged)} not measurable here: {', '.join(unjudged)}"
        done(Verdict.PASS, message, measurements)

    return run_check


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    config = session.config
    if _RESULTS not in config.stash:
        return
    interrupted = (config.stash.get(_SELECTED, set())
                   if exitstatus == pytest.ExitCode.INTERRUPTED else None)
    results = _with_checks_not_run(config.stash[_RUN], config.stash[_RESULTS], interrupted)
    config.stash[_RESULTS] = results
    from exohil.conformance.report import overall

    # the exit status follows the same verdict as conformance.json (skipped is not passed)
    if overall(results) is Verdict.FAIL and session.exitstatus == pytest.ExitCode.OK:
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
    out = config.getoption("exohil_out")
    if out:
        from exohil.conformance.report import write_reports

        write_reports(Path(out), config.stash[_RUN], results)


def pytest_terminal_summary(terminalreporter, exitstatus: int, config: pytest.Config) -> None:
    if _RESULTS not in config.stash:
        return
    from exohil.conformance.report import summary_lines

    terminalreporter.section("exohil conformance")
    for line in summary_lines(config.stash[_RUN], config.stash[_RESULTS],
                              verdict=not config.getoption("exohil_verdict_after")):
        terminalreporter.write_line(line)
