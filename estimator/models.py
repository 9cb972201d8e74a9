"""The neural estimators (PyTorch): ENNet, LNNet, ANN and CNN.

All map a normalised sensor window (B, n, S) — oldest frame first, newest last — to normalised
angles (B, A). Normalisation (per-sensor and per-angle mean/std) lives outside the network, in
the checkpoint (:mod:`exohil.estimator.checkpoint`). The configuration and the parameter shapes
of each kind are in :mod:`exohil.estimator.architecture`, which needs no torch.

- ENNet (early fusion, Varghese et al.): one LSTM over all S sensors per time step, its last
  hidden state → dense 512-256-128-64-32 (ReLU) → linear A outputs. Stateful ENNet
  (``cfg.stateful``): the same network, its LSTM state carried over the whole stream, so every
  frame's hidden state goes through the head (:meth:`ENNet.sequence`).
- LNNet (late fusion): one LSTM per sensor (input size 1), last hidden states concatenated →
  the same dense stack (the S LSTMs run batched, see :class:`GroupedLSTM`).
- ANN: memoryless MLP on the newest frame only (the paper's baseline) → the same dense stack.
- CNN: two 1-D temporal convolutions over the window (after Ogata et al. 2019), flattened →
  the same dense stack.
"""

from __future__ import annotations

import torch
from torch import nn

from exohil.estimator.architecture import CONV_KERNEL, MODEL_KINDS, ModelConfig

__all__ = ["ANN", "CNN", "ENNet", "GroupedLSTM", "LNNet", "MODEL_KINDS", "ModelConfig",
           "build_model", "dense_head"]


def dense_head(n_in: int, widths: tuple[int, ...], n_out: int) -> nn.Sequential:
    """ReLU layers of the given widths, then a linear output layer."""
    layers: list[nn.Module] = []
    for w in widths:
        layers += [nn.Linear(n_in, w), nn.ReLU()]
        n_in = w
    layers.append(nn.Linear(n_in, n_out))
    return nn.Sequential(*layers)


class ENNet(nn.Module):
    """Early fusion: one LSTM sees every sensor at every step."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        self.lstm = nn.LSTM(cfg.n_sensors, cfg.hidden, batch_first=True)
        self.head = dense_head(cfg.hidden, cfg.dense, cfg.n_outputs)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        _, (h, _) = self.lstm(x)
        return self.head(h[-1])

    def sequence(self, x: torch.Tensor, state: tuple[torch.Tensor, torch.Tensor] | None = None,
                 ) -> tuple[torch.Tensor, tuple[torch.Tensor, torch.Tensor]]:
        """Stateful use: outputs of every frame (B, T, A) of streams x (B, T, S) that go on
        from ``state`` (None: the streams start here), and the state after their last frame."""
        hs, state = self.lstm(x, state)
        return self.head(hs), state


class GroupedLSTM(nn.Module):
    """S independent LSTMs of hidden size H, one per sensor (input size 1), run as one batched
    computation. Identical in maths to S separate ``nn.LSTM(1, H)`` but much faster on CPU.

    Parameters (gate order [i, f, g, o] as in PyTorch): ``weight_ih`` (S, 4H) — the input
    weights of each sensor's LSTM; ``weight_hh`` (S, 4H, H); ``bias`` (S, 4H) = b_ih + b_hh.
    """

    def __init__(self, n_sensors: int, hidden: int) -> None:
        super().__init__()
        self.hidden = hidden
        bound = 1.0 / hidden**0.5
        self.weight_ih = nn.Parameter(torch.empty(n_sensors, 4 * hidden))
        self.weight_hh = nn.Parameter(torch.empty(n_sensors, 4 * hidden, hidden))
        self.bias = nn.Parameter(torch.empty(n_sensors, 4 * hidden))
        for p in (self.weight_ih, self.weight_hh):
            nn.init.uniform_(p, -bound, bound)
        nn.init.uniform_(self.bias, -2 * bound, 2 * bound)  # sum of two uniform biases' range

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Concatenated last hidden states (B, S·H), sensor-major, for x (B, n, S)."""
        xp = x[..., None] * self.weight_ih + self.bias  # (B, n, S, 4H)
        h = x.new_zeros(x.shape[0], x.shape[2], self.hidden)
        c = torch.zeros_like(h)
        for t in range(x.shape[1]):
            gates = xp[:, t] + torch.einsum("bsh,sgh->bsg", h, self.weight_hh)
            i, f, g, o = gates.chunk(4, dim=2)
            c = torch.sigmoid(f) * c + torch.sigmoid(i) * torch.tanh(g)
            h = torch.sigmoid(o) * torch.tanh(c)
        return h.flatten(1)


class LNNet(nn.Module):
    """Late fusion: one LSTM per sensor, concatenated last hidden states."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        self.lstm = GroupedLSTM(cfg.n_sensors, cfg.hidden)
        self.head = dense_head(cfg.hidden * cfg.n_sensors, cfg.dense, cfg.n_outputs)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.lstm(x))


class ANN(nn.Module):
    """Memoryless baseline: the newest frame only."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        self.head = dense_head(cfg.n_sensors, cfg.dense, cfg.n_outputs)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(x[:, -1, :])


class CNN(nn.Module):
    """Two 'same' 1-D convolutions (kernel 3, ReLU) over time, flattened into the dense stack."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        self.conv = nn.Sequential(
            nn.Conv1d(cfg.n_sensors, cfg.hidden, CONV_KERNEL, padding=CONV_KERNEL // 2), nn.ReLU(),
            nn.Conv1d(cfg.hidden, cfg.hidden, CONV_KERNEL, padding=CONV_KERNEL // 2), nn.ReLU(),
        )
        self.head = dense_head(cfg.hidden * cfg.window, cfg.dense, cfg.n_outputs)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        z = self.conv(x.transpose(1, 2))
        return self.head(z.flatten(1))


_CLASSES: dict[str, type[nn.Module]] = {"ennet": ENNet, "lnnet": LNNet, "ann": ANN, "cnn": CNN}


def build_model(cfg: ModelConfig) -> nn.Module:
    """A freshly initialised network for ``cfg`` (uses torch's global RNG)."""
    if cfg.kind not in _CLASSES:
        raise ValueError(f"unknown model kind {cfg.kind!r}; choose from {MODEL_KINDS}")
    return _CLASSES[cfg.kind](cfg)
