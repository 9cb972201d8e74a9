"""The conformance checks, one pytest test each (docs/conformance.md explains every check).

Run through ``exohil conform`` or ``pytest --pyargs exohil.conformance --exohil-target ...
--exohil-model ...``; the ``check`` fixture (plugin.py) measures, records and judges.
"""


def test_compatibility(check):
    """The model's sensors and angles match the device's and the reference's."""
    check("compatibility", lambda run: run.compatibility_measurements())


def test_heldout(check):
    """The accuracy recording is not one the model was trained on (SHA-256)."""
    check("heldout", lambda run: run.heldout_measurements())


def test_accuracy(check):
    """RMSE per angle where elevation ≥ 20°, and the arm-direction RMSE over all frames."""
    check("accuracy", lambda run: run.accuracy_measurements())


def test_latency(check):
    """Per-stage latency of every frame of the real-time segment."""
    check("latency", lambda run: run.latency_measurements())


def test_link(check):
    """Injected faults counted exactly; no bad frame delivered; nothing lost on the host."""
    check("link", lambda run: run.link_measurements())


def test_conversions(check):
    """Kinematics round trips and oracles under hypothesis, fixed seed and example count."""
    check("conversions", lambda run: run.conversion_measurements())


def test_teleop(check):
    """NAO commands from the estimates against those from the true angles."""
    check("teleop", lambda run: run.teleop_measurements())


def test_regression(check):
    """Against --baseline: accuracy within the profile's margin, latency p99 within its factor."""
    check("regression", lambda run: run.regression_measurements())
