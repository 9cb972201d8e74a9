"""A trained network's layers as NumPy arrays, read from its weights by torch ``state_dict``
name (:func:`exohil.estimator.architecture.state_shapes`): the one place that knows how the
parameters are laid out, for the engines that run without torch — the NumPy engine
(:mod:`exohil.estimator.inference`) and the ONNX graph (:mod:`exohil.estimator.onnx_graph`).

- LSTMs (:func:`lstm_weights`): ENNet's one LSTM and LNNet's S one-input LSTMs, both as
  :class:`LSTMWeights` (G LSTMs side by side), which each engine reorders to its gate order;
- the dense head (:func:`dense_layers`), optionally with the output de-normalisation folded
  into its last layer (:meth:`~exohil.estimator.trained.Normalisation.fold_y`);
- the CNN's convolutions (:func:`conv_layers`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from exohil.estimator.trained import Normalisation

#: PyTorch's order of the four LSTM gate blocks: input, forget, cell candidate (g), output.
GATES = "ifgo"

State = dict[str, np.ndarray]
Layer = tuple[np.ndarray, np.ndarray]


@dataclass(frozen=True)
class LSTMWeights:
    """G independent one-layer LSTMs of H units; LSTM g reads the inputs g·I … g·I + I − 1
    (ENNet: G = 1, I = S; LNNet: G = S, I = 1, one LSTM per sensor).

    Row-vector layout, the 4H gate axis last: gates = x·w_ih + h·w_hh + bias, with ``w_ih``
    (G, I, 4H), ``w_hh`` (G, H, 4H) and ``bias`` (G, 4H) = b_ih + b_hh; gate blocks in
    :data:`GATES` order until :meth:`gates` reorders them.
    """

    w_ih: np.ndarray
    w_hh: np.ndarray
    bias: np.ndarray

    @property
    def hidden(self) -> int:
        return self.w_hh.shape[1]

    def gates(self, order: str) -> LSTMWeights:
        """The same LSTMs with the gate blocks in ``order``, a permutation of :data:`GATES`
        (e.g. "iofg" for ONNX, whose c is PyTorch's g)."""
        return LSTMWeights(*(reorder_gates(a, order) for a in (self.w_ih, self.w_hh, self.bias)))

    def folded(self, norm: Normalisation) -> LSTMWeights:
        """The same LSTMs reading centred sensors x − x_mean: the input scaling folded into
        ``w_ih`` (:meth:`~exohil.estimator.trained.Normalisation.fold_x`)."""
        w_ih, bias = norm.fold_x(self.w_ih, self.bias)
        return LSTMWeights(w_ih, self.w_hh, bias)

    def merged(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The G LSTMs as one LSTM of U = G·H units: (W (G·I, 4U), R (U, 4U), b (4U,)) with
        block-diagonal weights, each gate's units in LSTM order (unit g·H + k belongs to LSTM
        g). The zero blocks add exact zeros, so the maths is unchanged and the final hidden
        state is the G LSTMs' states one after another."""
        groups, width, four_h = self.w_ih.shape
        if groups == 1:
            return self.w_ih[0], self.w_hh[0], self.bias[0]
        h = four_h // 4
        units = groups * h
        w = np.zeros((groups * width, 4, units))
        r = np.zeros((units, 4, units))
        b = np.zeros((4, units))
        for g in range(groups):
            own = slice(g * h, (g + 1) * h)
            w[g * width : (g + 1) * width, :, own] = self.w_ih[g].reshape(width, 4, h)
            r[own, :, own] = self.w_hh[g].reshape(h, 4, h)
            b[:, own] = self.bias[g].reshape(4, h)
        return w.reshape(-1, 4 * units), r.reshape(units, 4 * units), b.reshape(4 * units)


def reorder_gates(a: np.ndarray, order: str) -> np.ndarray:
    """``a`` with the four gate blocks of its last axis (in :data:`GATES` order) put in
    ``order``."""
    if sorted(order) != sorted(GATES):
        raise ValueError(f"gate order {order!r} is not a permutation of {GATES!r}")
    h = a.shape[-1] // 4
    blocks = {gate: a[..., k * h : (k + 1) * h] for k, gate in enumerate(GATES)}
    return np.concatenate([blocks[gate] for gate in order], axis=-1)


def lstm_weights(kind: str, state: State) -> LSTMWeights:
    """The LSTM(s) of an ENNet (``nn.LSTM``) or LNNet (``GroupedLSTM``) from its weights."""
    if kind == "ennet":
        return LSTMWeights(state["lstm.weight_ih_l0"].T[None], state["lstm.weight_hh_l0"].T[None],
                           (state["lstm.bias_ih_l0"] + state["lstm.bias_hh_l0"])[None])
    if kind == "lnnet":
        return LSTMWeights(state["lstm.weight_ih"][:, None, :],
                           state["lstm.weight_hh"].transpose(0, 2, 1), state["lstm.bias"])
    raise ValueError(f"a {kind} has no LSTM")


def dense_layers(state: State, norm: Normalisation | None = None) -> list[Layer]:
    """The dense head's linear layers in order, (weight (out, in), bias (out,)) each, a ReLU
    after every one but the last; with ``norm``, the last gives angles in degrees (the output
    de-normalisation folded in)."""
    layers = _numbered(state, "head")
    if norm is not None:
        layers[-1] = norm.fold_y(*layers[-1])
    return layers


def conv_layers(state: State) -> list[Layer]:
    """The CNN's temporal convolutions in order, (weight (out, in, kernel), bias (out,))
    each, a ReLU after every one."""
    return _numbered(state, "conv")


def _numbered(state: State, module: str) -> list[Layer]:
    """The (weight, bias) of every layer of the ``nn.Sequential`` ``module``, by index (its
    ReLUs have no parameters)."""
    prefix = f"{module}."
    idx = sorted({int(k.split(".")[1]) for k in state if k.startswith(prefix)})
    return [(state[f"{prefix}{i}.weight"], state[f"{prefix}{i}.bias"]) for i in idx]
