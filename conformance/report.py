"""What a conformance run leaves behind: ``conformance.json``, ``summary.md``, ``run.mcap``.

``conformance.json`` (schema ``exohil-conformance/1``, docs/conformance.md)::

    {"schema": "exohil-conformance/1", "verdict": "pass" | "fail",
     "target": str, "reference": str | null, "reference_sha256": str | null,
     "model": {"path", "sha256", "kind"}, "baseline": str | null,
     "profile": {"name", "path", "sha256"},
     "versions": {"exohil", "python", "numpy", "torch", "onnxruntime"}, "machine": str,
     "started": ISO time, "duration_s": s,
     "checks": [{"name", "verdict", "required", "message", "duration_s",
                 "measurements": [{"name", "value", "unit", "limit", "verdict", "note"}]}]}

Every file is written to a temporary name and renamed into place when complete.
"""

from __future__ import annotations

import math
import platform
import time
from importlib import metadata
from pathlib import Path
from typing import Any

from exohil.formats import strict_json
from exohil.formats.atomic import write_text
from exohil.formats.measurement import Verdict
from exohil.harness.machine import machine

SCHEMA = "exohil-conformance/1"
#: The files :func:`write_reports` writes into a run's report folder (the plugin's
#: --exohil-out; ``exohil conform`` adds :data:`JUNIT_FILE`, which pytest writes).
REPORT_FILES = ("conformance.json", "summary.md", "run.mcap")
JUNIT_FILE = "junit.xml"
#: The message of a check the session left out (``-k``, a node id).
NOT_RUN = "not run: left out of this session (-k or a node id)"
#: The message of a check an interrupted run (Ctrl-C) never reached.
INTERRUPTED = "not run: the run was interrupted before it"


def _version(package: str) -> str | None:
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return None


def overall(results: list[Any]) -> Verdict:
    """PASS only when at least one check ran, every required check passed and none failed."""
    required = [r for r in results if r.required]
    ok = bool(required) and all(r.verdict is Verdict.PASS for r in required)
    return Verdict.PASS if ok and not any(r.verdict is Verdict.FAIL for r in results) \
        else Verdict.FAIL


def report_dict(run: Any, results: list[Any]) -> dict[str, Any]:
    """The conformance.json content (module doc)."""
    model: dict[str, Any] = {"path": str(run.model_path)}
    try:
        model.update(sha256=run.model.sha256, kind=run.model.estimator.kind)
    except Exception:  # an unreadable model is reported by its failed checks
        model.update(sha256=None, kind=None)
    return {
        "schema": SCHEMA,
        "verdict": overall(results).value,
        "target": run.target,
        "reference": None if run.reference_file is None else str(run.reference_file),
        "reference_sha256": run.reference_sha256,
        "model": model,
        "baseline": None if run.baseline_path is None else str(run.baseline_path),
        "profile": {"name": run.profile.name, "path": str(run.profile.path),
                    "sha256": run.profile_sha256},
        "versions": {"exohil": _version("exohil"), "python": platform.python_version(),
                     **{p: _version(p) for p in ("numpy", "torch", "onnxruntime", "pytest",
                                                 "hypothesis")}},
        "machine": machine(),
        "started": time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime(run.started)),
        "duration_s": round(time.time() - run.started, 3),
        "checks": [{"name": r.name, "verdict": r.verdict.value, "required": r.required,
                    "message": r.message, "duration_s": round(r.duration_s, 3),
                    "measurements": [m.to_dict() for m in r.measurements]} for r in results],
    }


def _fmt(value: float) -> str:
    if math.isnan(value):
        return "—"
    return str(int(value)) if value.is_integer() and abs(value) < 1e15 else f"{value:.4g}"


def summary_markdown(run: Any, results: list[Any]) -> str:
    """A table a person reads in CI logs."""
    verdict = overall(results)
    lines = [f"# exohil conformance: {verdict.value.upper()}", "",
             f"- target: `{run.target}`", f"- model: `{run.model_path}`",
             f"- profile: `{run.profile.name}`"
             + ("" if run.profile_sha256 is None else f" (sha256 {run.profile_sha256[:12]})"),
             *([] if run.baseline_path is None else [f"- baseline: `{run.baseline_path}`"]),
             f"- machine: {machine()}", "",
             "| check | verdict | measurement | value | unit | limit |",
             "|---|---|---|---:|---|---|"]
    for r in results:
        # a check failed on no measurement's figure (a profile limit it did not measure)
        # says why, or its rows would all read pass under a FAIL heading
        if not r.measurements or (r.verdict is Verdict.FAIL and
                                  not any(m.failed for m in r.measurements)):
            lines.append(f"| {r.name} | {r.verdict.value} | — | — | — | {r.message} |")
        for m in r.measurements:
            limit = m.limit.describe() if m.limit else ""
            lines.append(f"| {r.name} | {m.verdict.value} | {m.name} | {_fmt(m.value)} | "
                         f"{m.unit} | {limit} |")
    retried = [m for r in results for m in r.measurements
               if m.name == "latency.attempts" and m.value > 1]
    for m in retried:
        lines += ["", f"Latency took {_fmt(m.value)} real-time segments (a failing one is "
                  "measured again: a busy host only adds time); the table gives the last. "
                  f"Each: {m.note}."]
    return "\n".join(lines) + "\n"


def summary_lines(run: Any, results: list[Any], verdict: bool = True) -> list[str]:
    """The terminal summary; its last line names the verdict and, on failure, the first
    failing check and its figure (without ``verdict``, left to the caller to print last)."""
    lines = [f"{'check':14s} {'verdict':8s} message"]
    for r in results:
        req = "" if r.required else " (optional)"
        lines.append(f"{r.name:14s} {r.verdict.value.upper():8s} {r.message}{req}")
    if verdict:
        lines.append(final_line(report_dict(run, results)))
    return lines


def final_line(report: dict[str, Any]) -> str:
    """From a conformance.json dict: ``PASS: 8 checks passed`` (naming those among them that
    judged nothing: no measurement with a limit, so their figures are reported only) or
    ``FAIL: <check>: <figure>`` naming the first failing (or skipped required) check."""
    checks = report["checks"]
    if report["verdict"] == Verdict.PASS.value:
        passed = [c for c in checks if c["verdict"] == "pass"]
        unjudged = [c["name"] for c in passed
                    if all(m["limit"] is None for m in c["measurements"])]
        return (f"PASS: {len(passed)} checks passed"
                + (f"; {', '.join(unjudged)} with no limit (figures reported only)"
                   if unjudged else ""))
    unmet = [c for c in checks if c["required"] and c["verdict"] != "pass"]
    bad = next((c for c in checks if c["verdict"] == "fail"), None) or next(
        (c for c in unmet if c["message"] != NOT_RUN), None)
    if bad is None and unmet:
        ran = [c for c in checks if c["verdict"] == "pass"]
        return (f"FAIL: {len(unmet)} required check(s) not run (-k or a node id): "
                f"{', '.join(c['name'] for c in unmet)}; the {len(ran)} that ran passed")
    if bad is None:
        return "FAIL: no required check ran"
    state = "" if bad["verdict"] == "fail" else "skipped, not passed: "
    return f"FAIL: {bad['name']}: {state}{bad['message']}"


def write_reports(out: Path, run: Any, results: list[Any]) -> None:
    """conformance.json, summary.md and (when the real-time segment ran) run.mcap in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    write_text(out / "conformance.json",
               strict_json.dumps(report_dict(run, results), indent=2) + "\n")
    write_text(out / "summary.md", summary_markdown(run, results))
    session = run.segment_result()  # the real-time segment, if a check ran it
    if session is not None:
        from exohil.harness.run_recording import write_run_recording

        est = session.model.estimator
        write_run_recording(out / "run.mcap", session.run, est.sensor_names, est.target.joint,
                            est.target.angles, {"generator": "exohil conform",
                                                "source": run.target,
                                                "model_sha256": session.model.sha256,
                                                "profile": run.profile.name},
                            session.sensor_rate_hz)
