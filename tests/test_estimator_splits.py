"""Splits are contiguous time blocks and no window ever reaches into another part."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from exohil.estimator.dataset import Block
from exohil.estimator.splits import cut_at_segments, time_block_split, trial_split
from exohil.estimator.windows import FrameTable


def _block(n: int, t0: float, source: str, labels=None) -> Block:
    t = t0 + np.arange(n, dtype=float)
    seg = np.array(labels if labels is not None else [""] * n, dtype=object)
    return Block(t[:, None].copy(), t[:, None].copy(), t, seg, source)


@settings(max_examples=300)
@given(
    lengths=st.lists(st.integers(1, 400), min_size=1, max_size=5),
    test_fraction=st.floats(0.05, 0.8),
    val_fraction=st.floats(0.0, 0.5),
    window=st.integers(1, 30),
    dilation=st.integers(1, 5),
)
def test_time_block_split_never_lets_a_window_straddle(lengths, test_fraction, val_fraction,
                                                       window, dilation):
    blocks = [_block(n, 10_000.0 * i, f"r{i}") for i, n in enumerate(lengths)]
    split = time_block_split(blocks, test_fraction, val_fraction)
    parts = {"train": split.train, "val": split.val, "test": split.test}
    # every frame lands in exactly one part
    times = np.concatenate([b.t for p in parts.values() for b in p])
    assert sorted(times.tolist()) == sorted(np.concatenate([b.t for b in blocks]).tolist())
    # within a source: all train times < all val times < all test times
    for i in range(len(lengths)):
        spans = [np.concatenate([b.t for b in p if b.source == f"r{i}"] or [np.empty(0)])
                 for p in parts.values()]
        nonempty = [s for s in spans if s.size]
        for a, b in zip(nonempty, nonempty[1:], strict=False):
            assert a.max() < b.min()
    # windows built per part only contain frames of the same block
    for blocks_of_part in parts.values():
        if not blocks_of_part:
            continue
        table = FrameTable.from_blocks(blocks_of_part)
        frames = np.arange(len(table))
        win_t = table.windows(frames, window, dilation)[:, :, 0]
        newest = table.x[frames, 0]
        assert np.all(win_t <= newest[:, None])
        assert np.all(newest[:, None] - win_t <= (window - 1) * dilation)
        owner = np.searchsorted(np.cumsum([len(b) for b in blocks_of_part]), frames, "right")
        for k, b in enumerate(blocks_of_part):
            rows = win_t[owner == k]
            assert np.all((rows >= b.t[0]) & (rows <= b.t[-1]))


def test_trial_split_keeps_test_recordings_whole():
    train_blocks = [_block(100, 0.0, "a"), _block(50, 1000.0, "b")]
    test_blocks = [_block(70, 5000.0, "c")]
    split = trial_split(train_blocks, test_blocks, 0.2)
    assert [len(b) for b in split.test] == [70]
    assert sum(len(b) for b in split.train) == 80 + 40
    assert sum(len(b) for b in split.val) == 20 + 10
    assert all(b.source != "c" for b in split.train + split.val)


def test_cut_at_segments_gives_one_movement_per_piece():
    labels = ["a"] * 5 + ["b"] * 3 + ["a"] * 2
    pieces = cut_at_segments([_block(10, 0.0, "r", labels)])
    assert [len(p) for p in pieces] == [5, 3, 2]
    assert [set(p.segment) for p in pieces] == [{"a"}, {"b"}, {"a"}]
