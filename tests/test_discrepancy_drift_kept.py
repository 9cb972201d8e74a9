"""How much of a slow drift the static map leaves in the held-out gap: where the poses follow
time, the map takes a drift in as the pose's doing, and the workflow says so."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from exohil.emulators.discrepancy import run
from exohil.emulators.discrepancy.data import prepare_trial
from exohil.emulators.discrepancy.model import (
    Spec,
    drift_kept_heldout,
    make_inputs,
    restrict_to_coverage,
)
from exohil.emulators.discrepancy.report import markdown
from exohil.formats.recording import AngleStream, Recording, SensorStream

RATE_HZ = 100.0


def _knee(flexion_of: Callable[[np.ndarray], np.ndarray], seconds: float = 80.0,
          drift: float = 0.0) -> Recording:
    """Two bands over a knee whose flexion is ``flexion_of(t)``, noise 0.01, plus a linear
    drift of ``drift`` from start to end on the first."""
    t = np.arange(int(seconds * RATE_HZ)) / RATE_HZ
    flexion = flexion_of(t)
    x = np.deg2rad(flexion)
    values = np.column_stack([1.0 + 0.4 * x + 0.15 * x**2, 2.0 - 0.3 * np.sin(x)])
    values[:, 0] += drift * t / seconds
    values += np.random.default_rng(3).normal(0.0, 0.01, values.shape)
    return Recording(sensor_names=("s1", "s2"),
                     sensors=SensorStream(seq=np.arange(t.size), t=t, values=values),
                     mocap={"knee": AngleStream(t=t, names=("flexion",), angles=flexion[:, None])},
                     sensor_units="V", sensor_rate_hz=RATE_HZ, mocap_rate_hz=RATE_HZ)


def _cycles(t: np.ndarray) -> np.ndarray:
    return 50.0 - 40.0 * np.cos(2 * np.pi * 0.2 * t)


def _one_sweep(t: np.ndarray) -> np.ndarray:
    return 10.0 + 90.0 * t / t[-1] + 3.0 * np.sin(2 * np.pi * 0.5 * t)


def _kept(rec: Recording, degree: int = 5) -> float:
    trial = prepare_trial(rec, "knee")
    scaled = make_inputs(trial)
    restrict_to_coverage(trial, scaled.u)
    spec = Spec(degree=degree)
    return drift_kept_heldout(trial, make_inputs(trial, spec), spec)


def test_a_map_of_poses_that_follow_time_keeps_little_of_a_drift():
    """Flexion cycled over the whole session: the map cannot follow time, and a linear drift
    is kept held out almost whole. One slow sweep through the range, each pose once: the
    map follows time through the poses, and keeps little of it."""
    assert _kept(_knee(_cycles)) > 0.9
    assert _kept(_knee(_one_sweep)) < 0.1


def test_the_workflow_says_when_the_poses_follow_time():
    """On one slow sweep with a drift the workflow reports the map's hold on time, in the
    JSON, in a progress line under [2] and in the report; on cycles, the JSON only."""
    lines: list[str] = []
    swept = run(_knee(_one_sweep, drift=0.2), "sweep", progress=lines.append, workers=1)
    kept = swept.summary["drift_kept_heldout"]
    assert 0.0 <= kept < 0.1
    at = next(i for i, line in enumerate(lines) if line.startswith("[2]"))
    assert lines[at + 1].startswith("    the poses follow time: held out, the static map keeps")
    assert f"The poses follow time: held out, the static map keeps {kept:.1%}" in markdown(
        swept.summary)
    lines.clear()
    cycled = run(_knee(_cycles, drift=0.2), "cycles", progress=lines.append, workers=1)
    assert cycled.summary["drift_kept_heldout"] > 0.9
    assert not any("the poses follow time" in line for line in lines)
    assert "poses follow time" not in markdown(cycled.summary)
    assert cycled.summary["effects"][:1] == ["drift"]  # seen where the poses repeat
