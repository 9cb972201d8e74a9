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
#: Widths of the dense ReLU layers after the temporal encoder, every network (the paper's is
#: 512-256-128-64-32, ``architecture.DENSE_STACK``).
DEFAULT_DENSE = (128, 64, 32)
#: (frames per window, seconds the window spans) per windowed model name; the dilation follows
#: from the sensor rate (:func:`default_window`), so a default means the same time at 250 Hz
#: (the suit) and at 100 Hz (the graphene knee sleeve).
DEFAULT_WINDOW = {"ennet": (10, 0.44), "lnnet": (10, 0.44), "cnn": (10, 0.036)}


def default_window(name: str, rate_hz: float) -> tuple[int, int]:
    """(frames per window, dilation) of model ``name`` at ``rate_hz`` frames per second:
    the dilation that spans :data:`DEFAULT_WINDOW`'s seconds best, at least 1. Models
    without a window get (1, 1)."""
    if name not in DEFAULT_WINDOW:
        return 1, 1
    frames, span_s = DEFAULT_WINDOW[name]
    return frames, max(1, round(span_s * rate_hz / (frames - 1)))

#: Calibration (:mod:`exohil.estimator.calibration`): the input jitter levels tried when none
#: is given, σ of the per-sensor offset in training standard deviations (docs/calibration.md).
CALIBRATION_JITTERS = (0.03, 0.1, 0.3)
