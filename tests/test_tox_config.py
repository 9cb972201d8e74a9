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


def test_every_environment_installs_the_pins_on_python_3_11():
    """tox run from a 3.12 install (pipx) made lint, conformance and bench on 3.12, where
    torch==2.13.0 is no local CPU wheel but a download with several GB of CUDA packages; a
    missing python3.11 skipped py311 and let the rest pass."""
    config = tox_ini()
    assert config["tox"]["minversion"] == "4.0"  # tox 3 ignores base_python
    assert config["tox"]["skip_missing_interpreters"] == "false"
    assert config["testenv"]["base_python"] == "python3.11"
    assert "-c {toxinidir}/constraints.txt" in config["testenv"]["install_command"]
    for section in config.sections():
        if section.startswith("testenv:"):
            assert "base_python" not in config[section], section
            assert "install_command" not in config[section], section


def make_recipe(target: str) -> list[str]:
    """The commands of a Makefile target, continuation lines joined and $(GATE) expanded."""
    text = (ROOT / "Makefile").read_text(encoding="utf-8").replace("\\\n", " ")
    gate = re.search(r"^GATE = (.*)$", text, re.M)
    recipe = re.search(rf"^{target}:.*\n((?:\t.*\n)+)", text, re.M)
    assert gate and recipe, target
    return [" ".join(line.replace("$(GATE)", gate.group(1)).split())
            for line in recipe.group(1).splitlines()]


def tox_commands(env: str) -> list[str]:
    config = tox_ini()
    section = config[f"testenv:{env}"] if f"testenv:{env}" in config else config["testenv"]
    commands = section.get("commands", config["testenv"]["commands"])
    return [" ".join(line.split()) for line in commands.replace("\\\n", " ").splitlines()
            if line.strip()]


def test_the_conformance_environment_runs_the_gate_of_make_conform():
    """The same target, model, profile and baseline, and the report where the docs and make
    conform put it (it was in .tox/conformance/tmp/, emptied by the next run)."""
    [make] = make_recipe("conform")
    [tox] = tox_commands("conformance")
    assert make.replace("$(BIN)/", "") + " {posargs}" == tox.replace("{toxinidir}/", "")


def test_the_other_environments_run_what_their_make_targets_run():
    """py311's pytest is the environment's own (the installed package, not the checkout that
    `python -m pytest` puts first), with make test's arguments."""
    assert [make.replace("$(BIN)/python -m pytest", "pytest") + " {posargs}"
            for make in make_recipe("test")] == tox_commands("py311")
    assert [make.replace("$(BIN)/", "").replace(" .", " {toxinidir}")
            for make in make_recipe("lint")] == tox_commands("lint")
    assert [make.replace("$(BIN)/", "") + " {posargs}"
            for make in make_recipe("bench")] == tox_commands("bench")
    # .ci/run's profile (the sdist, which carries these tests, has no .ci/)
    assert tox_ini()["testenv"]["setenv"].split() == ["HYPOTHESIS_PROFILE", "=", "ci"]
