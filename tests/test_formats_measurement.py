"""Measurements: limits in any unit of the right quantity, verdicts, JSON and JUnit forms."""

import json
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from exohil.formats.measurement import (
    Limit,
    Measurement,
    Verdict,
    convert,
    distribution,
)


def test_a_limit_in_ms_judges_a_value_in_us():
    limit = Limit(high=12.0, unit="ms")
    assert limit.holds(11_999.0, "us") and not limit.holds(12_000.0, "us")
    assert Limit(high=12.0, unit="ms", inclusive=True).holds(12_000.0, "us")
    assert Limit(low=0.99, unit="ratio").holds(99.5, "%")


@pytest.mark.parametrize("unit", ["furlong", "", "DEG"])
def test_unknown_units_are_refused(unit):
    with pytest.raises(ValueError, match="unknown unit"):
        Measurement.judge("x", 1.0, unit)
    with pytest.raises(ValueError, match="unknown unit"):
        Limit(high=1.0, unit=unit)


def test_a_limit_of_another_quantity_is_refused():
    with pytest.raises(ValueError, match="cannot compare"):
        Limit(high=3.0, unit="deg").holds(1.0, "ms")


@given(st.floats(-1e6, 1e6, allow_nan=False), st.sampled_from(["s", "ms", "us", "ns"]),
       st.sampled_from(["s", "ms", "us", "ns"]))
def test_unit_conversion_round_trips(value, a, b):
    assert convert(convert(value, a, b), b, a) == pytest.approx(value, rel=1e-12, abs=1e-12)


def test_verdicts_follow_the_limit_and_nan_never_passes():
    assert Measurement.judge("a", 2.0, "deg", Limit(high=3.0, unit="deg")).verdict is Verdict.PASS
    assert Measurement.judge("a", 3.0, "deg", Limit(high=3.0, unit="deg")).failed
    assert Measurement.judge("a", math.nan, "deg", Limit(high=3.0, unit="deg")).failed
    assert Measurement.judge("a", 2.0, "deg").verdict is Verdict.INFO
    skipped = Measurement.skipped("a", "deg", "no reference")
    assert skipped.verdict is Verdict.SKIP and not skipped.failed


def test_json_and_junit_forms():
    m = Measurement.judge("accuracy.rmse.elv_angle", 2.5, "deg", Limit(high=3.0, unit="deg"))
    d = json.loads(json.dumps(m.to_dict()))
    assert d == {"name": "accuracy.rmse.elv_angle", "value": 2.5, "unit": "deg",
                 "limit": {"low": None, "high": 3.0, "unit": "deg", "inclusive": False},
                 "verdict": "pass", "note": ""}
    props = dict(m.junit_properties())
    assert props["accuracy.rmse.elv_angle[deg]"] == "2.5"
    assert props["accuracy.rmse.elv_angle.verdict"] == "pass"
    assert props["accuracy.rmse.elv_angle.limit"] == "< 3 deg"
    assert Measurement.skipped("x", "ms", "why").to_dict()["value"] is None  # no NaN in JSON


def test_distribution_reports_p50_p99_max_with_limits():
    ms = distribution("latency.end_to_end", np.arange(1, 101, dtype=float), "ms",
                      {"max": Limit(high=12.0, unit="ms")})
    by_name = {m.name: m for m in ms}
    assert by_name["latency.end_to_end.p50"].value == 50.5
    assert by_name["latency.end_to_end.max"].value == 100.0
    assert by_name["latency.end_to_end.max"].failed
    assert by_name["latency.end_to_end.p99"].verdict is Verdict.INFO
    empty = distribution("x", np.array([]), "ms")
    assert all(m.verdict is Verdict.SKIP for m in empty)



def test_an_infinite_sample_fails_a_limit_on_the_maximum():
    """distribution() left out inf samples, so a frame that never finished passed `max < 4 ms`
    on the others' maximum."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no NaN from interpolating with inf
        p50, p99, top = distribution("lat", [1.0, 2.0, math.inf, math.nan], "ms",
                                     {"max": Limit(high=4, unit="ms")})
    assert top.value == math.inf and top.verdict is Verdict.FAIL
    assert p50.value == 2.0 and p99.value == math.inf and "3 samples" in top.note
    finite = distribution("lat", [1.0, 2.0, 3.0], "ms")  # figures of finite samples unchanged
    assert [m.value for m in finite] == [2.0, pytest.approx(2.98), 3.0]


@pytest.mark.parametrize(("low", "high", "said"), [
    (math.nan, None, "not NaN"), (None, math.nan, "not NaN"), (5.0, 1.0, "no value could pass"),
])
def test_a_limit_no_value_can_meet_or_every_value_meets_is_refused(low, high, said):
    with pytest.raises(ValueError, match=said):
        Limit(low, high, "ms")


def test_a_limit_on_a_statistic_a_distribution_lacks_is_refused():
    with pytest.raises(ValueError, match="limits on p95: a distribution has p50, p99, max"):
        distribution("lat", [1.0], "ms", {"p95": Limit(high=1, unit="ms")})


@pytest.mark.parametrize(("value", "written"), [
    (10580.3, "10580"), (4.0821, "4.082"), (0.00012344, "0.0001234"), (-3.21, "-3.21"),
    (0.0, "0"), (5.5e-13, "5.5e-13"), (2.5e6, "2.5e+06"), (float("nan"), "—")])
def test_a_measurement_is_written_out_where_a_person_reads_it_so(value, written):
    """A failed latency read '1.058e+04 ms (limit < 12 ms)' on the gate's last line."""
    m = Measurement.judge("latency.end_to_end.p99", value, "ms", Limit(high=12.0, unit="ms"))
    assert m.describe().startswith(f"latency.end_to_end.p99 = {written} ms (limit < 12 ms) ")
