"""tox.ini read as tox reads it, without running tox: each environment says what it does and
runs what the Makefile target it names runs."""

import configparser
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# tox reads a value's line that opens with "factors: " as a condition on the environment's
# name ("py311,lint: ..."), kept only for an environment with those factors
FACTOR_CONDITION = re.compile(r"^[\w{}.!,-]+:\s")


def tox_ini() -> configparser.ConfigParser:
    config = configparser.ConfigParser(interpolation=None)
    config.read(ROOT / "tox.ini", encoding="utf-8")
    return config


def test_no_setting_of_tox_ini_is_read_as_a_factor_condition():
    """`description = benchmarks: report ...` made bench's description the base "unit tests"
    and listed a phantom environment "benchmarks" in `tox -av`."""
    config = tox_ini()
    for section in config.sections():
        for key, value in config[section].items():
            for line in value.splitlines():
                assert not FACTOR_CONDITION.match(line.strip()), (section, key, line)
