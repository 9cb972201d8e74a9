"""How the workflow writes its figures: to significant digits, never to a fixed number of
decimals, so that a recording in any unit (mm, m, V, pF, a strain of 10⁻⁵) keeps them, and
a decision taken on a written figure (the candidates' ranking) does not depend on the unit.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

#: Significant digits of a figure in sensor units (gaps, noise floors, sizes).
DIGITS = 7
#: Of a level of the reading (a stop, the predicted range), which carries the sensor's
#: offset: a tendon's 500 mm keeps its hundredths of a micrometre.
LEVEL_DIGITS = 9
#: Of a mean squared error in sensor units squared: the candidates are ranked on it.
MSE_DIGITS = 9


def significant(x: float, digits: int = DIGITS) -> float:
    """``x`` rounded to ``digits`` significant digits; 0, ±inf and NaN as they are."""
    x = float(x)
    if x == 0.0 or not math.isfinite(x):
        return x
    return round(x, digits - 1 - math.floor(math.log10(abs(x))))


def significant_list(values: Iterable[float] | np.ndarray, digits: int = DIGITS) -> list:
    """Each number of ``values`` (one or more dimensions) to ``digits`` significant digits,
    as (nested) lists."""
    return [_each(v, digits) for v in np.asarray(values, dtype=np.float64).tolist()]


def _each(value: list | float, digits: int) -> list | float:
    if isinstance(value, list):
        return [_each(v, digits) for v in value]
    return significant(value, digits)
