"""Hand-built ONNX graphs of the trained networks, for the ONNX Runtime streaming backend.

The graph is written node by node with ``onnx.helper`` from the checkpoint's weights (no
``torch.onnx.export``). It maps one *normalised* float32 window — z = (x − x_mean)/x_std,
computed outside the graph in float64 — to the angles in degrees: the output de-normalisation
(ŷ·y_std + y_mean) is folded into the last Gemm.

Graph input ``window``, per kind (batch of one, frames oldest first):
- ``ennet`` / ``lnnet``: (n, 1, S), ONNX LSTM layout (sequence, batch, input);
- ``cnn``: (1, S, n), channels first (the torch model's ``x.transpose(1, 2)``);
- ``ann``: (1, S), the newest frame only.
Graph output ``angles``: (1, K) float32: the angles in degrees, or the de-normalised humerus
direction (K = 3) for a direction output.

A stateful ENNet (window of one frame) also takes the LSTM state in, ``h_in`` and ``c_in``
(1, 1, H), and gives the state after the frame out, ``h_out`` and ``c_out``: the runner feeds
each frame's state out to the next frame.

The weights come as layers from :mod:`exohil.estimator.weights` (shared with the NumPy engine).
Gate order: PyTorch stores LSTM gates [i, f, g, o]; ONNX wants [i, o, f, c] (c = the cell
candidate g) and two biases Wb, Rb (here Wb = b_ih + b_hh, Rb = 0). LNNet's S independent
one-input LSTMs become one ONNX LSTM of hidden size S·H with block-diagonal weights
(:meth:`~exohil.estimator.weights.LSTMWeights.merged`): unit s·H + k belongs to sensor s only,
and the zero blocks add exact zeros, so the maths is unchanged and the final hidden state is
already sensor-major, as ``GroupedLSTM`` returns it.
"""

from __future__ import annotations

import numpy as np

from exohil.estimator.trained import TrainedEstimator
from exohil.estimator.weights import conv_layers, dense_layers, lstm_weights

#: ONNX opset the graphs are written for (LSTM, Gemm, Relu, Conv, Flatten, Squeeze).
OPSET = 17
#: IR version 8 is the one that goes with opset 17; onnx's own default may be newer than what
#: the installed onnxruntime reads.
IR_VERSION = 8
INPUT_NAME = "window"
OUTPUT_NAME = "angles"
#: The LSTM state of a stateful ENNet: graph inputs (before the frame) and outputs (after).
STATE_INPUTS = ("h_in", "c_in")
STATE_OUTPUTS = ("h_out", "c_out")


def input_shape(est: TrainedEstimator) -> tuple[int, ...]:
    """Shape of the graph input ``window`` for this checkpoint (see module docstring)."""
    cfg = est.config
    if est.kind in ("ennet", "lnnet"):
        return (cfg.window, 1, cfg.n_sensors)
    if est.kind == "cnn":
        return (1, cfg.n_sensors, cfg.window)
    if est.kind == "ann":
        return (1, cfg.n_sensors)
    raise ValueError(f"no ONNX graph for model kind {est.kind!r}")


class _Graph:
    """Nodes and initialisers of the graph being built."""

    def __init__(self) -> None:
        self.nodes: list = []
        self.inits: list = []

    def const(self, name: str, value: np.ndarray, dtype: type = np.float32) -> str:
        """Register an initialiser and return its name."""
        from onnx import numpy_helper

        self.inits.append(numpy_helper.from_array(np.ascontiguousarray(value, dtype), name))
        return name

    def node(self, op: str, inputs: list[str], outputs: list[str], **attrs) -> str:
        """Append one node; returns its first output's name."""
        from onnx import helper

        self.nodes.append(helper.make_node(op, inputs, outputs, **attrs))
        return outputs[0]


def build_onnx_model(est: TrainedEstimator):
    """The ONNX ``ModelProto`` of ``est``'s network; raises ValueError for the classical model."""
    import onnx
    from onnx import TensorProto, helper

    if est.kind == "classical" or not est.has_network:
        raise ValueError("the classical model has no ONNX graph; use backend='numpy'")
    shape = input_shape(est)
    state = est.weights()
    g = _Graph()
    if est.kind in ("ennet", "lnnet"):
        features = _lstm_nodes(est, state, g)
    elif est.kind == "cnn":
        features = _conv_nodes(state, g)
    else:
        features = INPUT_NAME
    _head_nodes(est, state, features, g)
    inputs = [helper.make_tensor_value_info(INPUT_NAME, TensorProto.FLOAT, list(shape))]
    outputs = [helper.make_tensor_value_info(OUTPUT_NAME, TensorProto.FLOAT,
                                             [1, est.config.n_outputs])]
    if est.config.stateful:
        state_shape = [1, 1, est.config.hidden]
        inputs += [helper.make_tensor_value_info(n, TensorProto.FLOAT, state_shape)
                   for n in STATE_INPUTS]
        outputs += [helper.make_tensor_value_info(n, TensorProto.FLOAT, state_shape)
                    for n in STATE_OUTPUTS]
    graph = helper.make_graph(g.nodes, f"exohil_{est.kind}", inputs, outputs,
                              initializer=g.inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)],
                              producer_name="exohil", ir_version=IR_VERSION)
    onnx.checker.check_model(model)
    return model


def _lstm_nodes(est: TrainedEstimator, state: dict, g: _Graph) -> str:
    # ONNX wants [i, o, f, c] with c = PyTorch's g; W (4U, S), R (4U, U) and the two biases
    w, r, b = lstm_weights(est.kind, state).gates("iofg").merged()
    bias = np.concatenate([b, np.zeros_like(b)])  # Wb = b_ih + b_hh, Rb = 0
    units = r.shape[0]
    inputs = [INPUT_NAME, g.const("lstm_W", w.T[None]), g.const("lstm_R", r.T[None]),
              g.const("lstm_B", bias[None])]
    # outputs: Y (all steps) unused; Y_h (1 direction, 1 batch, U) → (1, U); a stateful ENNet
    # starts from the state given (no sequence_lens) and gives Y_c out too
    outputs = ["", "lstm_h"]
    if est.config.stateful:
        inputs += ["", *STATE_INPUTS]
        outputs = ["", *STATE_OUTPUTS]
    g.node("LSTM", inputs, outputs, hidden_size=units)
    return g.node("Squeeze", [outputs[1], g.const("axis0", np.array([0]), np.int64)],
                  ["features"])


def _conv_nodes(state: dict, g: _Graph) -> str:
    a = INPUT_NAME
    for k, (w, b) in enumerate(conv_layers(state)):  # 'same' padding
        a = g.node("Conv", [a, g.const(f"conv{k}_W", w), g.const(f"conv{k}_B", b)],
                   [f"conv{k}"], kernel_shape=[w.shape[2]], pads=[w.shape[2] // 2] * 2)
        a = g.node("Relu", [a], [f"conv{k}_relu"])
    return g.node("Flatten", [a], ["features"], axis=1)  # channel-major, as torch flatten(1)


def _head_nodes(est: TrainedEstimator, state: dict, a: str, g: _Graph) -> None:
    layers = dense_layers(state, est.norm)  # the last gives degrees
    last = len(layers) - 1
    for k, (w, b) in enumerate(layers):
        out = OUTPUT_NAME if k == last else f"dense{k}"
        a = g.node("Gemm", [a, g.const(f"dense{k}_W", w), g.const(f"dense{k}_B", b)], [out],
                   transB=1)
        if k != last:
            a = g.node("Relu", [a], [f"{out}_relu"])
