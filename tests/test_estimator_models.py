"""Estimator networks: shapes for any sensor/angle count, and LNNet's batched LSTMs equal
separate per-sensor nn.LSTM modules."""

import pytest
import torch

from exohil.estimator.architecture import check_state, state_shapes
from exohil.estimator.models import GroupedLSTM, ModelConfig, build_model


@pytest.mark.parametrize("kind", ["ennet", "lnnet", "ann", "cnn"])
@pytest.mark.parametrize(("sensors", "angles", "window"), [(4, 2, 10), (5, 1, 7), (1, 3, 3)])
def test_output_shape_for_any_sensor_and_angle_count(kind, sensors, angles, window):
    torch.manual_seed(0)
    net = build_model(ModelConfig(kind, sensors, angles, window=window, hidden=8))
    out = net(torch.randn(6, window, sensors))
    assert out.shape == (6, angles)
    assert torch.isfinite(out).all()


@pytest.mark.parametrize("kind", ["ennet", "lnnet", "ann", "cnn"])
@pytest.mark.parametrize(("sensors", "angles", "window", "dense"),
                         [(4, 2, 10, (512, 256, 128, 64, 32)), (5, 1, 7, (6,)), (1, 3, 3, ())])
def test_torch_free_shapes_are_the_modules_state_dict(kind, sensors, angles, window, dense):
    cfg = ModelConfig(kind, sensors, angles, window=window, hidden=8, dense=dense)
    state = {k: tuple(v.shape) for k, v in build_model(cfg).state_dict().items()}
    assert list(state_shapes(cfg).items()) == list(state.items())  # names, order and shapes
    check_state(cfg, state)


def test_check_state_names_every_problem():
    cfg = ModelConfig("ennet", 4, 2, hidden=8, dense=(6,))
    shapes = dict(state_shapes(cfg))
    del shapes["lstm.bias_hh_l0"]
    shapes["head.0.weight"] = (6, 7)
    shapes["head.9.bias"] = (2,)
    problems = (r"missing lstm.bias_hh_l0; unexpected head.9.bias; "
                r"wrong shape: head.0.weight \(6, 7\) \(expected \(6, 8\)\)")
    with pytest.raises(ValueError, match=problems):
        check_state(cfg, shapes)


def test_unknown_kind_is_rejected():
    with pytest.raises(ValueError, match="unknown model kind"):
        build_model(ModelConfig("rnn", 4, 2))
    with pytest.raises(ValueError, match="unknown model kind"):
        state_shapes(ModelConfig("rnn", 4, 2))


@pytest.mark.parametrize("change", [{"hidden": 0}, {"window": -1}, {"dense": (8, 0)},
                                    {"n_sensors": 2.5}])
def test_sizes_that_are_not_positive_whole_numbers_are_rejected(change):
    cfg = ModelConfig.from_dict({**ModelConfig("ennet", 4, 2).to_dict(), **change})
    with pytest.raises(ValueError, match="not a positive whole number"):
        state_shapes(cfg)


def test_grouped_lstm_equals_separate_per_sensor_lstms():
    torch.manual_seed(1)
    sensors, hidden = 3, 5
    grouped = GroupedLSTM(sensors, hidden)
    x = torch.randn(4, 9, sensors)
    separate = []
    for s in range(sensors):
        lstm = torch.nn.LSTM(1, hidden, batch_first=True)
        with torch.no_grad():
            lstm.weight_ih_l0.copy_(grouped.weight_ih[s][:, None])
            lstm.weight_hh_l0.copy_(grouped.weight_hh[s])
            lstm.bias_ih_l0.copy_(grouped.bias[s])
            lstm.bias_hh_l0.zero_()
        separate.append(lstm(x[:, :, s : s + 1])[1][0][-1])
    torch.testing.assert_close(grouped(x), torch.cat(separate, dim=1), rtol=1e-5, atol=1e-6)


def test_ann_ignores_all_but_the_newest_frame():
    torch.manual_seed(2)
    net = build_model(ModelConfig("ann", 4, 2, window=10))
    x = torch.randn(3, 10, 4)
    y = x.clone()
    y[:, :-1] = torch.randn(3, 9, 4)
    torch.testing.assert_close(net(x), net(y))
