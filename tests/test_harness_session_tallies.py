"""The streaming statistics a session folds frame block by frame block (bounded memory) give
the figures the whole run's per-frame arrays give."""

import numpy as np
import pytest

from exohil.estimator.evaluation import AccuracyTally, accuracy_measurements
from exohil.harness.pipeline import STAGES, FrameRows
from exohil.harness.robot_stats import LogHistogram
from exohil.harness.session import LinkTally

ANGLES = ("elv_angle", "shoulder_elv", "shoulder_rot")


def rows(seq, values):
    n = len(seq)
    return FrameRows(seq=np.asarray(seq, dtype=np.int64), device_time_s=np.zeros(n),
                     values=values, estimates=np.zeros((n, 3)),
                     stamps=np.zeros((n, len(STAGES)), dtype=np.int64),
                     compute_ns=np.zeros(n, dtype=np.int64), commands=np.zeros((n, 3)),
                     clamped=np.zeros(n, dtype=bool))


def test_accuracy_folded_in_blocks_is_the_whole_runs_accuracy():
    rng = np.random.default_rng(1)
    n = 10_000
    truth = np.column_stack([rng.uniform(-90, 180, n), rng.uniform(0, 150, n),
                             rng.uniform(-50, 50, n)])
    truth[rng.random(n) < 0.05] = np.nan  # outside the motion capture
    estimates = truth + rng.normal(0.0, 3.0, truth.shape)
    whole = accuracy_measurements(estimates, truth, ANGLES)
    tally = AccuracyTally(ANGLES)
    for i in range(0, n, 1024):
        tally.add(estimates[i:i + 1024], truth[i:i + 1024])
    folded = tally.measurements()
    assert [m.name for m in folded] == [m.name for m in whole]
    assert [m.note for m in folded] == [m.note for m in whole]
    for a, b in zip(whole, folded, strict=True):
        assert b.value == pytest.approx(a.value, rel=1e-12)
    assert folded[0].value == int(np.all(np.isfinite(truth), axis=1).sum())
    empty = AccuracyTally(ANGLES).measurements()
    assert [m.verdict.value for m in empty] == ["info"] + ["skip"] * 4


def test_link_tally_reconciles_gaps_with_the_device_log_like_the_sets_did():
    rng = np.random.default_rng(2)
    wire = rng.uniform(0, 600, (500, 4)).round(2)
    seq0, first = 1000, 1003
    sent = np.arange(first, first + 3000)
    missing = rng.random(sent.size) < 0.03
    received = sent[~missing]
    logged = set(sent[missing][rng.random(missing.sum()) < 0.8].tolist())  # some unlogged
    values = wire[(received - seq0) % wire.shape[0]].copy()
    values[[5, 77, 2001]] += 0.01  # corrupted values that got through
    tally = LinkTally(wire, seq0)
    for i in range(0, received.size, 700):
        tally(rows(received[i:i + 700], values[i:i + 700]))
    expected = set(range(int(received[0]), int(received[-1]) + 1)) - logged
    lost = np.array(sorted(logged), dtype=np.int64)
    assert tally.lost_on_host(lost) == len(expected - set(received.tolist())) > 0
    assert tally.bad == 3 and tally.late == 0
    tally(rows([int(received[10])], values[10:11]))  # an old frame again
    assert tally.late == 1


def test_histogram_added_at_once_bins_like_one_by_one_and_merges():
    rng = np.random.default_rng(3)
    values = np.concatenate([rng.lognormal(0.0, 2.0, 5000), [0.0, 1e-9, 1e9]])
    one, many = LogHistogram(1e-3, 1e6), LogHistogram(1e-3, 1e6)
    for v in values:
        one.add(float(v))
    many.add_many(values[:2000])
    rest = LogHistogram(1e-3, 1e6)
    rest.add_many(values[2000:])
    many.merge(rest)
    assert np.array_equal(one._counts, many._counts)
    assert (many.count, many.max) == (one.count, one.max) == (values.size, 1e9)
    assert many.total == pytest.approx(one.total)
    assert many.copy().quantile(0.99) == one.quantile(0.99) and many.nbytes == one.nbytes
    with pytest.raises(ValueError):
        many.add_many(np.array([1.0, -1.0]))
    with pytest.raises(ValueError):
        many.merge(LogHistogram(1e-3, 1e5))
    assert many.count == values.size  # nothing added by the refused calls
