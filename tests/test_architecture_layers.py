"""The layering rule (docs/architecture.md), checked on the source text (AST), including
imports inside functions:

* kinematics → formats → {emulators, estimator} → harness → conformance: each layer imports
  only from the layers before it, and the emulators and the estimator do not import each
  other (a model never depends on how its data was simulated; the simulator never on a model);
* the real-device path in harness (acquisition, decoding, buffering, the pipeline and its
  sinks) imports nothing from the emulators, so it runs the same against a real device;
* ``exohil.realtime`` (operating-system scheduling) may be used by every layer.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ALLOWED = {
    "kinematics": set(),
    "formats": {"kinematics"},
    "emulators": {"kinematics", "formats"},
    "estimator": {"kinematics", "formats"},
    "harness": {"kinematics", "formats", "emulators", "estimator"},
    "conformance": {"kinematics", "formats", "emulators", "estimator", "harness"},
}
#: harness modules on the path of a frame from a real device to the robot
DEVICE_PATH = ("acquisition", "link_decoder", "frame_buffer", "frame_source", "pipeline",
               "teleop", "recorder", "robot_mujoco", "robot_udp", "robot_coppelia",
               "robot_trace")


def _exohil_imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    found = set()
    for node in ast.walk(tree):
        names = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module]
        for name in names:
            parts = name.split(".")
            if parts[0] == "exohil" and len(parts) > 1 and parts[1] in ALLOWED:
                found.add(parts[1])
    return found


def _modules(layer: str) -> list[Path]:
    return sorted((ROOT / layer).rglob("*.py"))


@pytest.mark.parametrize("layer", list(ALLOWED))
def test_layer_imports_only_what_the_rule_allows(layer):
    allowed = ALLOWED[layer] | {layer}
    offenders = {}
    for path in _modules(layer):
        bad = _exohil_imports(path) - allowed
        if bad:
            offenders[str(path.relative_to(ROOT))] = sorted(bad)
    assert not offenders, f"{layer} imports layers the rule does not allow: {offenders}"


@pytest.mark.parametrize("module", DEVICE_PATH)
def test_the_real_device_path_does_not_depend_on_the_emulator(module):
    path = ROOT / "harness" / f"{module}.py"
    assert path.is_file(), f"{module} moved: update DEVICE_PATH"
    assert "emulators" not in _exohil_imports(path)


def test_the_rule_catches_a_wrong_way_import(tmp_path):
    bad = tmp_path / "acquisition.py"
    bad.write_text("def f():\n    from exohil.emulators.arduino import ArduinoEmulator\n")
    assert _exohil_imports(bad) == {"emulators"}


def test_exohil_package_links_every_layer():
    for layer in ALLOWED:
        link = ROOT / "exohil" / layer
        assert link.is_symlink() and link.resolve() == (ROOT / layer).resolve(), layer
