"""Whether sensors at one frame rate suit a model trained at another (no torch here: the
demo's and run's report read it)."""

from __future__ import annotations

#: Relative difference of sensor rates beyond which a model's window would span another time.
RATE_TOLERANCE = 0.01
#: What to do about it: calibration keeps the base model's rate and refuses another.
RATE_REMEDY = "train a model at this rate (calibration cannot change a model's rate)"


def same_rate(rate_hz: float, model_rate_hz: float) -> bool:
    """Whether sensors at ``rate_hz`` suit a model of ``model_rate_hz`` (within
    :data:`RATE_TOLERANCE`): otherwise its window and time constants span another time."""
    return abs(rate_hz - model_rate_hz) <= RATE_TOLERANCE * model_rate_hz


def rate_mismatch(rate_hz: float, model_rate_hz: float,
                  what: str = "the recordings' sensor rate") -> str | None:
    """Why sensors at ``rate_hz`` (``what`` names them) do not suit a model of
    ``model_rate_hz`` (:func:`same_rate`), or None."""
    if same_rate(rate_hz, model_rate_hz):
        return None
    return (f"{what} is {rate_hz:g} Hz, the model's {model_rate_hz:g} Hz: its window "
            "would span another time")
