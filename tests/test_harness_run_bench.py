"""``exohil run --bench FILE``: the bench's device and reference, with the command line's URL
and options overriding only what they name."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from exohil.harness import cmd_run
from exohil.harness.bench import SerialDevice
from exohil.harness.cli import main
from exohil.harness.paths import FIXTURES_DIR, MODELS_DIR

REFERENCE = FIXTURES_DIR / "paper_protocol_heldout.mcap"


@pytest.fixture
def ran(monkeypatch) -> list:
    """The bench configurations ``exohil run`` would run (nothing is opened)."""
    configs: list = []
    monkeypatch.setattr(cmd_run, "run_and_report",
                        lambda config, *args, **kwargs: configs.append(config))
    return configs


def bench(tmp_path: Path) -> Path:
    path = tmp_path / "bench.toml"
    path.write_text(f'[device]\nurl = "{tmp_path / "ttyACM0"}"\nreference = "{REFERENCE}"\n'
                    f'[model]\ncheckpoint = "{MODELS_DIR / "ennet.npz"}"\n', encoding="utf-8")
    return path


def test_run_with_a_bench_and_no_url_runs_the_benchs_device(tmp_path, ran) -> None:
    result = CliRunner().invoke(main, ["run", "--bench", str(bench(tmp_path))])
    assert result.exit_code == 0, result.output
    assert ran[0].device == SerialDevice(str(tmp_path / "ttyACM0"), REFERENCE)


def test_run_with_a_url_keeps_the_benchs_reference(tmp_path, ran) -> None:
    result = CliRunner().invoke(main, ["run", "loop://", "--bench", str(bench(tmp_path))])
    assert result.exit_code == 0, result.output
    assert ran[0].device == SerialDevice("loop://", REFERENCE)


def test_run_without_url_or_bench_device_is_a_usage_error(tmp_path, ran) -> None:
    result = CliRunner().invoke(main, ["run"])
    assert result.exit_code == 2 and "give the device's URL" in result.output
    assert not ran
