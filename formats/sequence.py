"""Dropped-frame statistics from device sequence numbers."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SequenceGaps:
    """Gaps in a strictly increasing sequence-number series.

    Attributes:
        gaps: number of places where consecutive frames skip at least one number.
        missing: total frames missing (sum over gaps of the numbers skipped).
        largest: frames missing in the largest single gap (0 when there are no gaps).
    """

    gaps: int
    missing: int
    largest: int


def sequence_gaps(seq: np.ndarray) -> SequenceGaps:
    """Count the gaps in ``seq`` ((N,) integers, strictly increasing)."""
    steps = np.diff(np.asarray(seq, dtype=np.int64)) - 1
    skipped = steps[steps > 0]
    return SequenceGaps(
        gaps=int(skipped.size),
        missing=int(skipped.sum()),
        largest=int(skipped.max()) if skipped.size else 0,
    )
