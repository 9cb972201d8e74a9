"""Estimator networks: shapes for any sensor/angle count, and LNNet's batched LSTMs equal
separate per-sensor nn.LSTM modules."""

import pytest
import torch

from exohil.estimator.models import GroupedLSTM, ModelConfig, build_model


@pytest.mark.parametrize("kind", ["ennet", "lnnet", "ann", "cnn"])
@pytest.mark.parametrize(("sensors", "angles", "window"), [(4, 2, 10), (5, 1, 7), (1, 3, 3)])
def test_output_shape_for_any_sensor_and_angle_count(kind, sensors, angles, window):
    torch.manual_seed(0)
    net = build_model(ModelConfig(kind, sensors, angles, window=window, hidden=8))
    out = net(torch.randn(6, window, sensors))
    assert out.shape == (6, angles)
    assert torch.isfinite(out).all()


def test_unknown_kind_is_rejected():
    with pytest.raises(ValueError, match="unknown model kind"):
        build_model(ModelConfig("rnn", 4, 2))


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
