"""The conformance checks, one pytest test each (docs/conformance.md explains every check).

Run through ``exohil conform`` or ``pytest --pyargs exohil.conformance --exohil-target ...
--exohil-model ...``; the ``check`` fixture (plugin.py) measures, records and judges, with
``ConformanceRun.<check>_measurements`` (context.py) doing the measuring.
"""

import pytest

from exohil.conformance.profile import CHECKS


@pytest.mark.parametrize("name", list(CHECKS))
def test_check(check, name):
    """compatibility, heldout, accuracy, latency, link, conversions, teleop, regression."""
    check(name, lambda run: getattr(run, f"{name}_measurements")())
