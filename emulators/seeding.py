"""Seeded random streams for the emulators: one generator per ``(seed, kind, occurrence)``.

Effects (:class:`~exohil.emulators.effects.EffectChain`) and frame faults
(:mod:`exohil.emulators.faults`) each draw from their own child of the run's seed, keyed by
their kind and their occurrence among items of that kind, so adding, removing or reordering
one never reseeds another's random stream.
"""

from __future__ import annotations

import zlib

import numpy as np


def keyed_rng(seed: int, kind: str, occurrence: int) -> np.random.Generator:
    """The generator of the ``occurrence``-th stream of ``kind`` under ``seed`` (0 for the
    first): ``default_rng(SeedSequence(seed, spawn_key=(crc32(kind), occurrence)))``."""
    key = zlib.crc32(kind.encode("utf-8"))
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(key, occurrence)))
