"""Causal sensor windows over blocks, edge-padded at each block start.

The window of frame i holds frames ``i - (n-1)·d, …, i - d, i`` (d = dilation), oldest first;
indices before the block's first frame are clamped to that first frame. Every frame therefore
has a prediction, all models are scored on exactly the same frames whatever their window, and a
streaming engine that starts by filling its ring buffer with the first frame reproduces it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from exohil.estimator.dataset import Block


@dataclass
class FrameTable:
    """Blocks concatenated: x (N, S), y (N, A), and each frame's block start index (N,)."""

    x: np.ndarray
    y: np.ndarray
    block_start: np.ndarray

    @classmethod
    def from_blocks(cls, blocks: list[Block], dtype: type = np.float32) -> FrameTable:
        if not blocks:
            raise ValueError("no frames")
        x: np.ndarray = np.concatenate([b.x for b in blocks]).astype(dtype)
        y: np.ndarray = np.concatenate([b.y for b in blocks]).astype(dtype)
        starts = np.cumsum([0] + [len(b) for b in blocks[:-1]])
        block_start = np.repeat(starts, [len(b) for b in blocks]).astype(np.int64)
        return cls(x, y, block_start)

    def __len__(self) -> int:
        return int(self.x.shape[0])

    def window_indices(self, frames: np.ndarray, window: int, dilation: int = 1) -> np.ndarray:
        """(len(frames), window) frame indices of each frame's window, oldest first."""
        offsets = np.arange(window - 1, -1, -1, dtype=np.int64) * dilation
        idx = frames[:, None] - offsets[None, :]
        return np.maximum(idx, self.block_start[frames][:, None])

    def windows(self, frames: np.ndarray, window: int, dilation: int = 1) -> np.ndarray:
        """(len(frames), window, S) sensor windows."""
        return self.x[self.window_indices(frames, window, dilation)]


def block_windows(x: np.ndarray, window: int, dilation: int = 1) -> np.ndarray:
    """(N, window, S) windows of every frame of one block's (N, S) sensor array."""
    table = FrameTable(x, np.zeros((x.shape[0], 0), x.dtype), np.zeros(x.shape[0], np.int64))
    return table.windows(np.arange(x.shape[0]), window, dilation)
