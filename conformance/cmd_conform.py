"""``exohil conform``: the conformance suite, a thin wrapper around pytest and its plugin.

It runs ``pytest --pyargs exohil.conformance`` with the same options, so ``exohil conform``
and plain pytest can never disagree, and writes ``junit.xml`` (measurements as properties),
``conformance.json``, ``summary.md`` and ``run.mcap`` into ``--out``.
"""

from __future__ import annotations

from pathlib import Path

import click

from exohil.harness.cli_types import InputFile, Name, OutputDir, Target, refuse_overwriting_inputs


class ConformanceProfile(click.ParamType):
    """A bundled profile's name or a ``.toml`` file, loaded and checked here (unknown checks,
    settings out of range); the text is returned unchanged."""

    name = "profile"

    def convert(self, value, param, ctx):
        from exohil.conformance.profile import ProfileError, load_profile

        text = str(value)
        if not text.strip() or "\x00" in text:
            self.fail(f"{text!r} is not a profile name or a .toml file", param, ctx)
        try:
            load_profile(text)
        except (ProfileError, OSError) as exc:
            self.fail(str(exc), param, ctx)
        return text


class KeywordExpression(Name):
    """A pytest ``-k`` expression (``accuracy and not latency``), parsed here so a malformed
    one is refused before the suite starts."""

    name = "expression"

    def convert(self, value, param, ctx):
        text = super().convert(value, param, ctx)
        try:
            from _pytest.mark import expression
        except ImportError:  # pytest moved it: pytest itself will refuse a bad expression
            return text
        # pytest >= 8.4 raises SyntaxError; older versions their own ParseError
        errors = (SyntaxError, getattr(expression, "ParseError", SyntaxError))
        try:
            expression.Expression.compile(text)
        except errors as exc:
            self.fail(f"{text!r} is not a pytest -k expression: {exc}", param, ctx)
        return text


@click.command("conform")
@click.option("--target", type=Target(), default=None,
              help="emulator:RECORDING[?faults=SPEC&seed=N] (the emulator on a pty, in "
                   "process) or a pyserial URL / device path (/dev/ttyACM0, a pty printed by "
                   "`exohil emulate`, socket://host:port).")
@click.option("--model", default=None, type=InputFile(),
              help="Checkpoint under test (.npz).")
@click.option("--bench", "bench_file", default=None, type=InputFile(),
              help="Bench file (TOML, docs/architecture.md) naming the device and the model; "
                   "--target and --model override it.")
@click.option("--profile", type=ConformanceProfile(), default="default", show_default=True,
              help="Profile: default, bench, ci, or a .toml file (docs/conformance.md).")
@click.option("--baseline", type=InputFile(), default=None,
              help="Baseline: a checkpoint (accuracy and latency must not regress beyond "
                   "the profile's margin and factor) or an earlier run's conformance.json on "
                   "the same reference (accuracy only; not that of a run in which a check "
                   "failed).")
@click.option("--reference", type=InputFile(), default=None,
              help="Ground truth recording for a serial device (aligned by device time); "
                   "without it the accuracy checks are skipped, never passed.")
@click.option("--backend", default=None,
              type=click.Choice(["auto", "numpy", "torch", "torchscript", "onnxruntime"]),
              help="Streaming inference backend [the bench's, else auto].")
@click.option("--out", "out_dir", type=OutputDir(), default=Path("conformance-report"),
              show_default=True,
              help="Folder for junit.xml, conformance.json, summary.md, run.mcap (an "
                   "earlier run's are removed first; one that is an input is refused).")
@click.option("-k", "select", type=KeywordExpression(), default=None,
              help="Run only the checks matching this pytest -k expression (to debug "
                   "one); the required checks left out are reported as not run, so such a "
                   "run never passes the profile.")
def conform(target: str | None, model: Path | None, bench_file: Path | None, profile: str,
            baseline: Path | None, reference: Path | None, backend: str | None, out_dir: Path,
            select: str | None) -> None:
    """Run the conformance suite on MODEL against TARGET; exit 0 only when every required
    check passed. The last line names the verdict (and the first failing check)."""
    import json

    import pytest

    from exohil.conformance.report import JUNIT_FILE, REPORT_FILES

    if bench_file is None and (target is None or model is None):
        raise click.UsageError("give --target and --model, or a --bench file naming them")
    target_file = Path(target[len("emulator:"):].partition("?")[0]) if target and \
        target.startswith("emulator:") else None
    # what a run writes into --out: the plugin's reports and pytest's junit.xml
    refuse_overwriting_inputs([("--out", out_dir / name) for name in (JUNIT_FILE, *REPORT_FILES)],
                              [target_file, model, bench_file, baseline, reference])
    out_dir.mkdir(parents=True, exist_ok=True)
    # an earlier run's junit.xml must not pass for this run's if this one is killed (the
    # plugin clears the other reports the same way)
    (out_dir / JUNIT_FILE).unlink(missing_ok=True)
    args = ["--pyargs", "exohil.conformance", "-p", "no:cacheprovider", "-q",
            "-o", "junit_family=xunit1", "-W", "ignore::pytest.PytestAssertRewriteWarning",
            f"--junitxml={out_dir / JUNIT_FILE}", "--exohil-profile", profile,
            "--exohil-out", str(out_dir), "--exohil-verdict-after"]
    for option, value in (("--exohil-target", target), ("--exohil-model", model),
                          ("--exohil-bench", bench_file), ("--exohil-backend", backend),
                          ("--exohil-baseline", baseline), ("--exohil-reference", reference)):
        if value is not None:
            args += [option, str(value)]
    if select:
        args += ["-k", select]
    code = pytest.main(args)
    report = out_dir / "conformance.json"
    if code == pytest.ExitCode.USAGE_ERROR or not report.is_file():
        raise click.ClickException(f"the conformance suite did not run (pytest exit {int(code)})")
    from exohil.conformance.report import final_line

    data = json.loads(report.read_text(encoding="utf-8"))
    click.echo(f"reports in {out_dir}/: junit.xml conformance.json summary.md"
               + (" run.mcap" if (out_dir / "run.mcap").is_file() else ""))
    click.echo(final_line(data))
    raise SystemExit(0 if data["verdict"] == "pass" else 1)

