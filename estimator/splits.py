"""Train/validation/test splits made of whole blocks or contiguous time blocks.

Windows are built inside one block only (:mod:`exohil.estimator.windows`), so cutting a block
into contiguous pieces guarantees that no window straddles two parts of a split. Shuffling
happens only among training windows, never across parts.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from exohil.estimator.dataset import Block


@dataclass
class Split:
    """Blocks of each part, plus a one-line description for checkpoints and tables."""

    train: list[Block] = field(default_factory=list)
    val: list[Block] = field(default_factory=list)
    test: list[Block] = field(default_factory=list)
    description: str = ""


def cut_at_segments(blocks: list[Block]) -> list[Block]:
    """Blocks cut wherever the movement label changes, so each piece is one movement."""
    pieces: list[Block] = []
    for block in blocks:
        if not len(block):
            continue
        change = np.flatnonzero(block.segment[1:] != block.segment[:-1]) + 1
        edges = [0, *change.tolist(), len(block)]
        pieces += [block.slice(a, b) for a, b in zip(edges[:-1], edges[1:], strict=True)]
    return pieces


def tail_cut(block: Block, fraction: float) -> tuple[Block, Block]:
    """(head, tail): the last ``fraction`` of the block's frames become the tail."""
    if not 0.0 <= fraction < 1.0:
        raise ValueError(f"fraction must be in [0, 1), got {fraction}")
    cut = len(block) - int(round(len(block) * fraction))
    return block.slice(0, cut), block.slice(cut, len(block))


def validation_split(blocks: list[Block], val_fraction: float = 0.15) -> Split:
    """All data for training except the last ``val_fraction`` of every block (validation)."""
    split = Split(description=f"train = first {1 - val_fraction:.0%} of each block, "
                  f"validation = last {val_fraction:.0%} (contiguous time blocks)")
    for block in blocks:
        head, tail = tail_cut(block, val_fraction)
        _append_nonempty(split.train, head)
        _append_nonempty(split.val, tail)
    return split


def time_block_split(
    blocks: list[Block], test_fraction: float = 0.3, val_fraction: float = 0.15
) -> Split:
    """Within-recording split: per block, first part train, then validation, last part test.

    ``val_fraction`` is a fraction of the training part (carved from its end).
    """
    split = Split(
        description=(
            f"per recording block: first {1 - test_fraction:.0%} train (its last "
            f"{val_fraction:.0%} = validation), last {test_fraction:.0%} test; contiguous"
        )
    )
    for block in blocks:
        head, test = tail_cut(block, test_fraction)
        train, val = tail_cut(head, val_fraction)
        _append_nonempty(split.train, train)
        _append_nonempty(split.val, val)
        _append_nonempty(split.test, test)
    return split


def trial_split(
    train_blocks: list[Block], test_blocks: list[Block], val_fraction: float = 0.15
) -> Split:
    """Across-trial split: whole recordings for test; validation = end of each training block."""
    split = validation_split(train_blocks, val_fraction)
    split.test = [b for b in test_blocks if len(b)]
    split.description = (
        f"whole recordings: train/validation from the training recordings (validation = last "
        f"{val_fraction:.0%} of each), test = the held-out recordings"
    )
    return split


def _append_nonempty(parts: list[Block], block: Block) -> None:
    if len(block):
        parts.append(block)
