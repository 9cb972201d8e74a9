"""Offset jumps while the joint holds still (emulators/discrepancy/jumps.py): a step is
found at its instant; what noise, a relaxation or a movement makes is not."""

from __future__ import annotations

import numpy as np
import pytest

from exohil.emulators.discrepancy.data import prepare_trial, true_runs
from exohil.emulators.discrepancy.hidden import Case, make_recording
from exohil.emulators.discrepancy.jumps import JUMP_WINDOW_S, jumps_in_holds
from exohil.emulators.discrepancy.model import trial_motion


@pytest.fixture(scope="module")
def held_trial():
    """A clean recording's trial (three sensors, 60 s, holds 5–47 % of the time), its
    still frames and its longest hold (start, stop) in frames."""
    trial = prepare_trial(make_recording(Case("clean", "lib", 1, seed=101)))
    still = trial_motion(trial)[1]
    hold = max(true_runs(still), key=lambda run: run[1] - run[0])
    return trial, still, hold


def _noise(trial, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).normal(0.0, 0.15, (trial.n, trial.n_sensors))


def test_a_step_in_a_hold_is_found_at_its_instant_on_its_sensor(held_trial):
    trial, still, (start, stop) = held_trial
    at = (start + stop) // 2
    residual = _noise(trial, 1)
    residual[at:, 2] += 0.3  # two noise deviations
    jumps = jumps_in_holds(trial, residual, still)
    assert [j.sensor for j in jumps] == [2], jumps
    assert abs(jumps[0].at_s - trial.t[at]) <= 0.05 + 1e-9, jumps
    assert jumps[0].height == pytest.approx(0.3, abs=0.05), jumps


def test_noise_a_relaxation_and_a_step_while_moving_are_not_jumps(held_trial):
    trial, still, (start, stop) = held_trial
    residual = _noise(trial, 2)
    # a creep relaxing over 2 s from the hold's start, 30 noise deviations at first
    since = (trial.t - trial.t[start]).clip(0.0)
    residual[:, 0] += np.where((trial.t >= trial.t[start]) & (trial.t < trial.t[stop - 1]),
                               4.5 * np.exp(-since / 2.0), 0.0)
    # coloured noise: a random walk over the whole recording, 0.1 mm per √s
    residual[:, 1] += np.cumsum(np.random.default_rng(3).normal(0.0, 0.1 / np.sqrt(
        trial.rate_hz), trial.n))
    # a step where the joint moves (more than one window from any still frame)
    moving = np.flatnonzero(~still)
    far = [k for k in moving if not still[max(0, k - int(trial.rate_hz * 2 * JUMP_WINDOW_S)):
                                          k + int(trial.rate_hz * 2 * JUMP_WINDOW_S)].any()]
    assert far, "the movement has no stretch without a hold"
    residual[far[len(far) // 2]:, 2] += 1.0
    assert jumps_in_holds(trial, residual, still) == []


def test_without_enough_holds_nothing_is_searched(held_trial):
    trial, still, _ = held_trial
    residual = _noise(trial, 4)
    residual[trial.n // 2:, 0] += 5.0
    assert jumps_in_holds(trial, residual, np.zeros(trial.n, dtype=bool)) == []
