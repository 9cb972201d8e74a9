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


def test_printed_angles_keep_to_their_documented_half_open_ranges():
    """`--from ms --to isb 180 60 0` printed α = 180 (documented [−180, 180)), as did an angle
    a hair below 180 once rounded to 9 decimals; NAO's exact pitch printed −180 for an arm
    pointing straight back (documented (−180, 180])."""
    for theta in ("180", "179.9999999999"):
        isb = convert("--from", "ms", "--to", "isb", theta, "60", "0")["values"]
        assert isb["plane_of_elevation"] == -180.0 and isb["axial_rotation"] == -180.0
        ms = convert("--from", "ms", "--to", "ms", theta, "60", "180")["values"]
        assert ms["elv_angle"] == -180.0 and ms["shoulder_rot"] == -180.0
    nao = convert("--from", "ms", "--to", "nao", "-170", "90", "0")
    assert nao["unclamped"]["RShoulderPitch"] == 180.0


def test_axes_mobl_where_it_cannot_apply_is_refused_naming_the_option():
    """`--axes mobl --convention paper` failed as 'Invalid value for VALUES' (the values were
    fine), and `--axes mobl` with --from isb or quat was ignored while the JSON reported
    "axes": "mobl"."""
    for args, option in ((["--from", "ms", "--axes", "mobl", "--convention", "paper",
                           "1", "2", "3"], "'--convention'"),
                         (["--from", "quat", "--axes", "mobl", "0", "0", "0", "1"], "'--axes'"),
                         (["--from", "isb", "--axes", "mobl", "1", "2", "3"], "'--axes'")):
        result = CliRunner().invoke(main, ["convert", "--to", "isb", *args])
        assert result.exit_code == 2, result.output
        assert result.exception is None or isinstance(result.exception, SystemExit)
        errors = [line for line in result.output.splitlines() if line.startswith("Error")]
        assert len(errors) == 1 and option in errors[0] and "VALUES" not in errors[0]
    used = convert("--from", "ms", "--to", "ms", "--axes", "mobl", "45", "60", "-30")
    assert used["axes"] == "mobl" and used["values"]["elv_angle"] != pytest.approx(45.0)


def test_a_mistyped_option_is_named_as_an_option_not_as_a_bad_number():
    """Negative numbers pass as VALUES, and so did `--hnit 5`: the error was "'--hnit' is not
    a valid float", as if the user had typed a bad number."""
    result = CliRunner().invoke(main, ["convert", "--from", "ms", "--to", "isb",
                                       "--hnit", "5", "1", "2", "3"])
    assert result.exit_code == 2
    assert "No such option '--hnit'" in result.output and "--hint" in result.output
    assert "valid float" not in result.output
    assert convert("--from", "ms", "--to", "isb", "-1e1", "-0", "-5")["input"] == {
        "elv_angle": -10.0, "shoulder_elv": -0.0, "shoulder_rot": -5.0}


def test_a_too_short_quaternion_is_refused_with_the_length_it_needs():
    """(1e-13, 0, 0, 0) was refused as 'must be finite and non-zero', though it is not zero;
    1e-11 was accepted. The limit is a length of 1e-12, and the error says so."""
    result = CliRunner().invoke(main, ["convert", "--from", "quat", "--to", "isb",
                                       "1e-13", "0", "0", "0"])
    assert result.exit_code == 2 and "length of at least 1e-12" in result.output
    assert convert("--from", "quat", "--to", "quat", "1e-11", "0", "0", "0")["values"] == {
        "x": 1.0, "y": 0.0, "z": 0.0, "w": 0.0}
