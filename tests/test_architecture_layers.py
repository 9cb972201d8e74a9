"""Each layer imports only from the layers before it (README, "Layout").

kinematics → formats → emulators → estimator → harness → conformance. Checked on the source
text (AST), including imports inside functions.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYERS = ["kinematics", "formats", "emulators", "estimator", "harness", "conformance"]


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
            if parts[0] == "exohil" and len(parts) > 1 and parts[1] in LAYERS:
                found.add(parts[1])
    return found


@pytest.mark.parametrize("layer", LAYERS)
def test_layer_imports_only_from_earlier_layers(layer):
    allowed = set(LAYERS[: LAYERS.index(layer) + 1])
    offenders = {}
    for path in sorted((ROOT / layer).glob("*.py")):
        bad = _exohil_imports(path) - allowed
        if bad:
            offenders[path.name] = sorted(bad)
    assert not offenders, f"{layer} imports later layers: {offenders}"
