"""``exohil convert`` as a user meets it: hints, ranges of the printed angles, option errors."""

import json

import pytest
from click.testing import CliRunner

from exohil.harness.cli import main


def convert(*args: str) -> dict:
    result = CliRunner().invoke(main, ["convert", *args])
    assert result.exit_code == 0, result.output
    return json.loads(result.output)


def test_a_hint_beyond_180_means_the_same_angle_as_its_wrapped_value():
    """`--hint 300` printed α = 300 (documented [−180, 180)), and for NAO commanded pitch
    −119.5 where `--hint -60`, the same angle, commands −60."""
    isb = convert("--from", "ms", "--to", "isb", "--hint", "300", "90", "0", "10")
    assert isb["values"]["plane_of_elevation"] == pytest.approx(-60.0)
    far = convert("--from", "ms", "--to", "nao", "--hint", "300", "0", "90", "0")
    near = convert("--from", "ms", "--to", "nao", "--hint", "-60", "0", "90", "0")
    assert far["values"] == near["values"] and far["unclamped"] == near["unclamped"]
    assert far["values"]["RShoulderPitch"] == pytest.approx(-60.0)
