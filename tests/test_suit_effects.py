"""Effect library: each effect's physical property, serialisation, chain seeding."""

import tomllib

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from exohil.emulators.effects import (
    EFFECT_TYPES,
    Creep,
    Drift,
    Dropout,
    EffectChain,
    Gain,
    Hysteresis,
    Lag,
    Noise,
    Quantization,
    Saturation,
    Signal,
    effect_from_dict,
    effect_to_dict,
)

RATE = 250.0


def rng() -> np.random.Generator:
    return np.random.default_rng(0)


def triangle(amplitudes, points_per_mm=20) -> np.ndarray:
    """Piecewise-linear series through 0 → a1 → 0 → a2 → ... (mm)."""
    pieces, last = [], 0.0
    for target in amplitudes:
        n = max(2, int(abs(target - last) * points_per_mm))
        pieces.append(np.linspace(last, target, n, endpoint=False))
        last = target
    pieces.append(np.array([last]))
    return np.concatenate(pieces)


def signal_of(x: np.ndarray, rate: float = RATE) -> Signal:
    return Signal.from_values(np.arange(len(x)) / rate, x)


# --- hysteresis ---------------------------------------------------------------------------

def test_hysteresis_branches_differ_by_the_loop_width():
    x = triangle([60.0, 0.0, 60.0, 0.0])
    y = Hysteresis(width_mm=3.0, span_mm=10.0).apply(signal_of(x), rng()).values[:, 0]
    peak = int(np.argmax(x))
    rising = np.interp(30.0, x[:peak], y[:peak])
    falling_x, falling_y = x[peak:2 * peak][::-1], y[peak:2 * peak][::-1]
    falling = np.interp(30.0, falling_x, falling_y)
    assert falling - rising == pytest.approx(3.0, abs=1e-9)
    assert np.all(np.abs(y - x) <= 1.5 + 1e-12)


def test_hysteresis_is_rate_independent():
    x = triangle([40.0, 10.0, 30.0, 0.0])
    slow = Hysteresis(width_mm=2.0, span_mm=8.0).apply(signal_of(x, rate=10.0), rng())
    fast = Hysteresis(width_mm=2.0, span_mm=8.0).apply(signal_of(x, rate=1000.0), rng())
    np.testing.assert_array_equal(slow.values, fast.values)


def test_hysteresis_output_depends_on_reversal_history():
    effect = Hysteresis(width_mm=4.0, span_mm=20.0, operators=5)
    direct = effect.apply(signal_of(triangle([20.0])), rng()).values[-1, 0]
    via_reversal = effect.apply(signal_of(triangle([30.0, 12.0, 20.0])), rng()).values[-1, 0]
    assert abs(direct - via_reversal) > 0.5


def test_hysteresis_minor_loops_are_narrower_than_major_loops():
    effect = Hysteresis(width_mm=4.0, span_mm=20.0, operators=8)
    x = triangle([5.0, -5.0, 5.0])  # 10 mm peak-to-peak < span
    y = effect.apply(signal_of(x), rng()).values[:, 0]
    assert np.max(np.abs(y - x)) < 2.0 - 0.1


@given(st.lists(st.floats(-50, 50), min_size=2, max_size=40),
       st.floats(0.0, 5.0), st.floats(0.5, 30.0))
def test_hysteresis_stays_within_half_the_width_of_the_input(values, width, span):
    x = np.asarray(values)
    y = Hysteresis(width_mm=width, span_mm=span).apply(signal_of(x), rng()).values[:, 0]
    assert np.all(np.abs(y - x) <= width / 2 + 1e-9)


# --- creep --------------------------------------------------------------------------------

def test_creep_builds_with_tau_build_and_recovers_with_tau_recover():
    rate, tau_b, tau_r, gain = 100.0, 5.0, 20.0, 0.1
    t = np.arange(int(120 * rate)) / rate
    x = np.where((t >= 1.0) & (t < 41.0), 10.0, 0.0)  # 10 mm of stretch for 40 s
    y = Creep(gain=gain, tau_build_s=tau_b, tau_recover_s=tau_r).apply(
        Signal.from_values(t, x), rng()).values[:, 0]
    creep = y - x
    at = lambda s: creep[int(round(s * rate))]  # noqa: E731
    assert at(1.0 + tau_b) == pytest.approx(gain * 10 * (1 - np.exp(-1)), rel=0.01)
    plateau = at(41.0 - 1 / rate)
    assert plateau == pytest.approx(gain * 10, rel=0.01)
    assert at(41.0 + tau_r) == pytest.approx(plateau * np.exp(-1), rel=0.01)
    # recovery is slower than build-up: after one tau_build, much less has recovered
    assert plateau - at(41.0 + tau_b) < 0.5 * at(1.0 + tau_b)


def test_creep_ignores_brief_excursions():
    rate = 250.0
    t = np.arange(int(10 * rate)) / rate
    x = np.where((t >= 1.0) & (t < 1.2), 20.0, 0.0)  # 0.2 s blip
    y = Creep(gain=0.1, tau_build_s=10.0, tau_recover_s=30.0).apply(
        Signal.from_values(t, x), rng()).values[:, 0]
    assert np.max(np.abs(y - x)) < 0.1 * 20 * 0.03


# --- saturation, lag ----------------------------------------------------------------------

def test_saturation_clips_per_sensor():
    x = np.column_stack([np.linspace(0, 100, 101), np.linspace(0, 100, 101)])
    y = Saturation(lower_mm=[10.0, 20.0], upper_mm=90.0).apply(signal_of(x), rng()).values
    assert y[:, 0].min() == 10.0 and y[:, 1].min() == 20.0 and y.max() == 90.0
    np.testing.assert_array_equal(y[30:80], x[30:80])


def test_saturation_with_one_side_only():
    x = np.linspace(-5, 5, 11)
    y = Saturation(upper_mm=1.0).apply(signal_of(x), rng()).values[:, 0]
    assert y.min() == -5.0 and y.max() == 1.0


@pytest.mark.parametrize("delay", [0.004, 0.02, 0.1])
def test_lag_transport_delay_shifts_a_ramp(delay):
    x = np.linspace(0, 50, 2000)
    out = Lag(delay_s=delay).apply(signal_of(x), rng())
    slope = 50 / (1999 / RATE)  # mm/s
    np.testing.assert_allclose(out.values[200:, 0], x[200:] - slope * delay, atol=1e-9)


def test_lag_first_order_step_reaches_63_percent_at_tau():
    t = np.arange(5000) / RATE
    x = np.where(t >= 1.0, 10.0, 0.0)
    y = Lag(tau_s=0.2).apply(Signal.from_values(t, x), rng()).values[:, 0]
    assert y[int(round(1.2 * RATE))] == pytest.approx(10 * (1 - np.exp(-1)), rel=0.01)
    assert y[0] == 0.0 and y[-1] == pytest.approx(10.0)


def test_lag_clock_offset_shifts_timestamps_only():
    sig = signal_of(np.linspace(0, 1, 10))
    out = Lag(clock_offset_s=0.015).apply(sig, rng())
    np.testing.assert_allclose(out.t, sig.t + 0.015)
    np.testing.assert_array_equal(out.values, sig.values)


# --- drift, noise, quantization, dropout --------------------------------------------------

def test_drift_linear_rate_and_random_walk_growth():
    t = np.arange(2501) / RATE  # 10 s
    x = np.zeros((t.size, 2000))
    out = Drift(rate_mm_per_s=0.01, walk_mm_per_sqrt_s=0.2).apply(Signal.from_values(t, x), rng())
    final = out.values[-1] - 0.01 * 10.0
    assert final.mean() == pytest.approx(0.0, abs=0.05)
    assert final.std() == pytest.approx(0.2 * np.sqrt(10.0), rel=0.06)
    assert np.all(out.values[0] == 0.0)


def test_noise_standard_deviation_matches_sigma():
    x = np.zeros((100_000, 2))
    y = Noise(sigma_mm=[0.5, 2.0]).apply(signal_of(x), rng()).values
    np.testing.assert_allclose(y.std(axis=0), [0.5, 2.0], rtol=0.02)
    assert np.abs(y.mean(axis=0)).max() < 0.03


def test_quantization_step_is_travel_over_4096():
    x = np.linspace(100.0, 101.0, 10_001)
    y = Quantization(bits=12, travel_mm=1000.0).apply(signal_of(x), rng()).values[:, 0]
    step = 1000.0 / 4096
    levels = np.unique(y)
    np.testing.assert_allclose(np.diff(levels), step, rtol=1e-9)
    assert np.max(np.abs(y - x)) <= step / 2 + 1e-12
    np.testing.assert_allclose(levels / step, np.round(levels / step), atol=1e-9)


def test_quantization_clips_to_the_adc_range():
    y = Quantization(bits=4, travel_mm=16.0, zero_mm=0.0).apply(
        signal_of(np.array([-3.0, 7.2, 40.0])), rng()).values[:, 0]
    np.testing.assert_allclose(y, [0.0, 7.0, 15.0])


@pytest.mark.parametrize(("rate", "burst"), [(0.01, 1.0), (0.05, 4.0)])
def test_dropout_rate_and_burst_length(rate, burst):
    out = Dropout(rate=rate, mean_burst_frames=burst).apply(signal_of(np.zeros(400_000)), rng())
    dropped = ~out.keep
    assert dropped.mean() == pytest.approx(rate, rel=0.1)
    starts = np.flatnonzero(dropped[1:] & ~dropped[:-1]).size
    assert dropped.sum() / starts == pytest.approx(burst, rel=0.1)
    np.testing.assert_array_equal(out.values, np.zeros((400_000, 1)))


# --- gain ---------------------------------------------------------------------------------

def test_gain_scales_then_offsets_each_sensor():
    x = np.column_stack([np.linspace(450.0, 600.0, 50), np.linspace(500.0, 520.0, 50)])
    out = Gain(gain=[0.9, 1.1], offset_mm=[-3.0, 4.5]).apply(signal_of(x), rng())
    np.testing.assert_allclose(out.values, x * [0.9, 1.1] + [-3.0, 4.5], rtol=0, atol=1e-12)
    scalar = Gain(gain=1.05, offset_mm=-2.0).apply(signal_of(x), rng())
    np.testing.assert_allclose(scalar.values, 1.05 * x - 2.0, rtol=0, atol=1e-12)
    assert out.keep.all()


def test_default_gain_is_the_identity_and_draws_nothing():
    sig = wave_signal()
    generator = rng()
    before = generator.bit_generator.state
    out = Gain().apply(sig, generator)
    np.testing.assert_array_equal(out.values, sig.values)
    assert generator.bit_generator.state == before


def test_gain_round_trips_through_a_toml_effect_table():
    table = tomllib.loads("""
        [[effect]]
        kind = "gain"
        gain = [0.88, 1.12, 0.95, 1.06]
        offset_mm = [-6.5, 4.0, 9.0, -3.0]
    """)["effect"][0]
    effect = effect_from_dict(table)
    assert isinstance(effect, Gain)
    assert effect_to_dict(effect) == table
    assert effect_to_dict(effect_from_dict(effect_to_dict(effect))) == table
    scalar = {"kind": "gain", "gain": 1.1, "offset_mm": -2.0}
    assert effect_to_dict(effect_from_dict(scalar)) == scalar


@pytest.mark.parametrize(("params", "message"), [
    ({"gain": 0.0}, "gain must be > 0 and finite"),
    ({"gain": -1.2}, "gain must be > 0 and finite"),
    ({"gain": float("nan")}, "gain must be a finite number"),
    ({"gain": float("inf")}, "gain must be a finite number"),
    ({"gain": [1.0, 0.0, 1.1, 0.9]}, "gain must be > 0 and finite"),
    ({"gain": [1.0, float("nan")]}, "gain must be a finite number"),
    ({"offset_mm": float("nan")}, "offset_mm must be a finite number"),
    ({"offset_mm": [0.0, -float("inf")]}, "offset_mm must be a finite number"),
    ({"gian": 1.0}, "unknown parameter"),
])
def test_bad_gain_parameters_are_rejected(params, message):
    with pytest.raises(ValueError, match=message):
        effect_from_dict({"kind": "gain", **params})


@pytest.mark.parametrize("params", [{"gain": [1.0, 1.1, 0.9]}, {"offset_mm": [1.0, 2.0, 3.0]}])
def test_gain_per_sensor_list_of_the_wrong_length_is_rejected(params):
    with pytest.raises(ValueError, match="list of 2 values"):
        Gain(**params).apply(wave_signal(), rng())


# --- chain, registry ----------------------------------------------------------------------

FULL_CHAIN = [
    {"kind": "lag", "tau_s": 0.03, "delay_s": 0.01, "clock_offset_s": 0.01},
    {"kind": "hysteresis", "width_mm": [2.0, 3.0], "span_mm": 10.0, "operators": 3},
    {"kind": "creep", "gain": 0.05, "tau_build_s": 10.0, "tau_recover_s": 40.0},
    {"kind": "saturation", "lower_mm": 10.0, "upper_mm": [90.0, 95.0]},
    {"kind": "drift", "rate_mm_per_s": 0.01, "walk_mm_per_sqrt_s": 0.05},
    {"kind": "noise", "sigma_mm": 0.2},
    {"kind": "quantization", "bits": 12, "travel_mm": 500.0, "zero_mm": 0.0},
    {"kind": "dropout", "rate": 0.01, "mean_burst_frames": 2.0},
]


def wave_signal() -> Signal:
    t = np.arange(3000) / RATE
    return Signal.from_values(t, 50 + 30 * np.column_stack([np.sin(t), np.cos(0.7 * t)]))


def test_chain_is_deterministic_per_seed():
    chain = EffectChain.from_dicts(FULL_CHAIN)
    a, b = chain.apply(wave_signal(), seed=5), chain.apply(wave_signal(), seed=5)
    np.testing.assert_array_equal(a.values, b.values)
    np.testing.assert_array_equal(a.keep, b.keep)
    c = chain.apply(wave_signal(), seed=6)
    assert not np.array_equal(a.values, c.values)


def test_adding_an_effect_does_not_change_other_random_streams():
    base = wave_signal()
    noise_only = EffectChain([Noise(sigma_mm=0.3)]).apply(base, seed=11)
    with_dropout = EffectChain([Dropout(rate=0.05), Noise(sigma_mm=0.3)]).apply(base, seed=11)
    np.testing.assert_array_equal(noise_only.values, with_dropout.values)
    drop_only = EffectChain([Dropout(rate=0.05)]).apply(base, seed=11)
    drop_after = EffectChain([Drift(walk_mm_per_sqrt_s=0.1), Noise(), Dropout(rate=0.05)]).apply(
        base, seed=11)
    np.testing.assert_array_equal(drop_only.keep, drop_after.keep)


def test_two_effects_of_one_kind_get_different_streams():
    base = wave_signal()
    twice = EffectChain([Noise(sigma_mm=1.0), Noise(sigma_mm=1.0)]).apply(base, seed=1)
    once = EffectChain([Noise(sigma_mm=1.0)]).apply(base, seed=1)
    second = twice.values - once.values
    assert np.corrcoef(second[:, 0], (once.values - base.values)[:, 0])[0, 1] < 0.1


def test_effects_do_not_modify_their_input():
    base = wave_signal()
    before = base.values.copy()
    EffectChain.from_dicts(FULL_CHAIN).apply(base, seed=3)
    np.testing.assert_array_equal(base.values, before)
    assert base.keep.all()


@pytest.mark.parametrize("d", FULL_CHAIN, ids=lambda d: d["kind"])
def test_dict_round_trip(d):
    effect = effect_from_dict(d)
    assert effect.name == d["kind"]
    again = effect_from_dict(effect_to_dict(effect))
    assert effect_to_dict(again) == effect_to_dict(effect)
    assert {k: v for k, v in effect_to_dict(effect).items() if k in d} == d


def test_every_registered_kind_has_defaults_and_round_trips():
    for kind, cls in EFFECT_TYPES.items():
        effect = cls()
        assert effect_to_dict(effect)["kind"] == kind
        out = effect.apply(wave_signal(), rng())
        assert out.values.shape == (3000, 2) and np.isfinite(out.values).all()


@pytest.mark.parametrize(("d", "message"), [
    ({"kind": "glue"}, "unknown effect kind 'glue'"),
    ({"tau_s": 1.0}, "needs a 'kind'"),
    ({"kind": "creep", "tau": 3.0}, "unknown parameter"),
    ({"kind": "creep", "tau_build_s": -1.0}, "tau_build_s must be > 0"),
    ({"kind": "quantization", "bits": 0}, "bits"),
    ({"kind": "dropout", "rate": 1.5}, "rate"),
    ({"kind": "creep", "gain": float("nan")}, "creep: gain must be a finite number"),
    ({"kind": "drift", "rate_mm_per_s": float("inf")}, "rate_mm_per_s must be a finite number"),
    ({"kind": "lag", "clock_offset_s": True}, "clock_offset_s must be a number"),
    # a list where one number is taken was Python's own text ("'<=' not supported ...")
    ({"kind": "dropout", "rate": [0.1, 0.1]}, "dropout: rate takes one number"),
    ({"kind": "hysteresis", "operators": [4, 4]}, "hysteresis: operators takes one number"),
    # crossed stops were refused only when applied, after the emulator had been set up
    ({"kind": "saturation", "lower_mm": 500.0, "upper_mm": 400.0}, "must not exceed"),
    ({"kind": "saturation", "lower_mm": [1.0, 500.0], "upper_mm": 400.0}, "must not exceed"),
])
def test_bad_effect_dicts_are_rejected_clearly(d, message):
    with pytest.raises(ValueError, match=message):
        effect_from_dict(d)


def test_per_sensor_list_of_the_wrong_length_is_rejected():
    with pytest.raises(ValueError, match="list of 2 values"):
        Noise(sigma_mm=[0.1, 0.2, 0.3]).apply(wave_signal(), rng())


def test_dropout_with_a_vanishing_rate_neither_crashes_nor_drops():
    t = np.arange(5000) / 250.0
    signal = Signal.from_values(t, np.zeros((5000, 4)))
    for rate in (1e-38, 1e-12):
        kept = Dropout(rate=rate).apply(signal, np.random.default_rng(3)).keep
        assert kept.all()
