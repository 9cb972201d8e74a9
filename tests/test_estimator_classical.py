"""The classical baseline (PI play operators + creep + quadratic, ridge) compensates a
hysteretic sensor that a static polynomial cannot."""

import numpy as np
from estimator_synth import play

from exohil.estimator.classical import (
    ClassicalModel,
    static_polynomial_fit,
    static_polynomial_predict,
)


def _hysteretic_sensor(seed: int):
    rng = np.random.default_rng(seed)
    t = np.arange(6_000) / 100.0
    amplitude = 30 + 20 * np.sin(2 * np.pi * 0.03 * t)
    angle = amplitude * np.sin(2 * np.pi * 0.25 * t + rng.uniform(0, 6)) + 40  # degrees
    sensor = 0.6 * angle + 0.4 * play(angle, 10.0)  # PI-type: strictly increasing
    sensor = 0.02 * sensor + 1e-4 * sensor**2 + rng.normal(0, 0.002, t.size)
    return sensor[:, None], angle[:, None]


def _z(x, ref):
    return (x - ref.mean(0)) / ref.std(0)


def test_classical_beats_static_polynomial_on_hysteresis():
    x, y = _hysteretic_sensor(0)
    cut, val_cut = 4200, 3500
    x_tr, y_tr = x[:val_cut], y[:val_cut]
    x_va, y_va = x[val_cut:cut], y[val_cut:cut]
    x_te, y_te = x[cut:], y[cut:]
    model = ClassicalModel.create(rate_hz=100.0)
    model.fit([_z(x_tr, x_tr)], [y_tr], [_z(x_va, x_tr)], [y_va])
    rmse_classical = np.sqrt(np.mean((model.predict(_z(x_te, x_tr)) - y_te) ** 2))
    w = static_polynomial_fit(_z(x_tr, x_tr), y_tr)
    rmse_static = np.sqrt(np.mean((static_polynomial_predict(_z(x_te, x_tr), w) - y_te) ** 2))
    assert rmse_static > 2.0  # the hysteresis is real
    assert rmse_classical < 0.5 * rmse_static


def test_streaming_features_equal_batch_features():
    x, _ = _hysteretic_sensor(1)
    z = _z(x[:500], x[:500])
    model = ClassicalModel.create(rate_hz=100.0)
    batch = model.features(z)
    state = model.start(z[0])
    streamed = np.array([model.step_features(row, state) for row in z])
    np.testing.assert_allclose(streamed, batch, atol=1e-12)
