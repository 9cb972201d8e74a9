"""Each model's default settings: what ``exohil train --model NAME`` uses when no option says
otherwise (chosen by the sweep in docs/estimator.md, "Defaults"). No torch here: the CLI reads
these to describe its options."""

from __future__ import annotations

#: ``--model`` names: every kind, and ``ennet-stateful``, the ENNet that carries its LSTM state
#: from frame to frame (the kind ``ennet`` with ``stateful`` set).
MODEL_NAMES = ("ennet", "ennet-stateful", "lnnet", "ann", "cnn", "classical")
#: Temporal-encoder width per model name (LSTM hidden size; per sensor for LNNet; CNN channels).
DEFAULT_HIDDEN = {"ennet": 64, "ennet-stateful": 64, "lnnet": 32, "cnn": 32, "ann": 64,
                  "classical": 0}
#: (frames per window, dilation) per windowed model name.
DEFAULT_WINDOW = {"ennet": (10, 12), "lnnet": (10, 12), "cnn": (10, 1)}
