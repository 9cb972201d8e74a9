"""Streaming inference: one ``push(values) -> angles`` call per sensor frame.

The engine reproduces :meth:`TrainedEstimator.predict_block` frame by frame:
- offset removal: the causal initial rest value (mean of the first ``offset_frames`` frames
  seen so far), as in :func:`exohil.estimator.dataset.initial_baseline`;
- normalisation with the checkpoint's statistics;
- the window: a ring buffer written twice (positions k and k + span), so the newest ``span``
  frames are always one contiguous view; the first frame fills the whole ring, which is the
  edge padding used in training and evaluation;
- the LSTM is re-run over the window at every frame (10 steps by default). Carrying the LSTM
  state from frame to frame would NOT be equivalent: the training model restarts its LSTM at
  the oldest frame of every window.

Backends:
- ``numpy`` (default, fastest): hand-written float64 LSTM/MLP with preallocated buffers — no
  allocation per frame in steady state. The input projection x·W_ih + b of each frame is
  computed once, when the frame arrives, and kept in the ring with the frame. ENNet, LNNet
  (S independent LSTMs, batched), ANN and classical run here; CNN does not (use ``torch``).
- ``torch``: the checkpoint's module in eager mode under ``inference_mode``, one thread.
- ``torchscript``: the same module traced with ``torch.jit.trace``.

``push`` returns a view of an internal buffer that the next call overwrites; copy it to keep it.
"""

from __future__ import annotations

import warnings

import numpy as np

from exohil.estimator.trained import TrainedEstimator

BACKENDS = ("numpy", "torch", "torchscript")


class StreamingEstimator:
    """Per-frame estimator over a trained checkpoint. Angles come out in degrees."""

    def __init__(self, est: TrainedEstimator, backend: str = "numpy") -> None:
        if backend not in BACKENDS:
            raise ValueError(f"unknown backend {backend!r}; choose from {BACKENDS}")
        if backend == "numpy" and est.kind == "cnn":
            raise ValueError("the numpy backend has no CNN; use backend='torch'")
        if backend != "numpy" and est.kind == "classical":
            raise ValueError("the classical model runs on the numpy backend only")
        self.est = est
        self.backend = backend
        cfg = est.config
        self.n_sensors, self.n_angles = cfg.n_sensors, cfg.n_angles
        self.window = 1 if cfg.kind in ("ann", "classical") else cfg.window
        self.dilation = cfg.dilation
        self.span = (self.window - 1) * self.dilation + 1
        self._x_mean = est.norm.x_mean.astype(np.float64)
        self._x_std = est.norm.x_std.astype(np.float64)
        self._y_mean = est.norm.y_mean.astype(np.float64)
        self._y_std = est.norm.y_std.astype(np.float64)
        self._offset_frames = est.offset_frames
        self._z = np.zeros(self.n_sensors)
        self._base_sum = np.zeros(self.n_sensors)
        self._base = np.zeros(self.n_sensors)
        self._out = np.zeros(self.n_angles)
        self._runner = _make_runner(est, backend, self.span)
        self.reset()

    def reset(self) -> None:
        """Forget every frame: the next push starts a new stream (new donning)."""
        self._count = 0
        self._base_sum[:] = 0.0
        self._base[:] = 0.0
        self._runner.reset()

    def push(self, values: np.ndarray) -> np.ndarray:
        """One sensor frame (S,) in recording units → (A,) angle estimates, degrees."""
        z = self._z
        z[:] = values
        if self._offset_frames:
            if self._count < self._offset_frames:
                self._base_sum += z
                np.divide(self._base_sum, self._count + 1, out=self._base)
            z -= self._base
        z -= self._x_mean
        z /= self._x_std
        self._count += 1
        y = self._runner.step(z, first=self._count == 1)
        np.multiply(y, self._y_std, out=self._out)
        self._out += self._y_mean
        return self._out


class _Ring:
    """Double-written ring of the newest ``span`` rows of width ``shape``."""

    def __init__(self, span: int, shape: tuple[int, ...]) -> None:
        self.span = span
        self.buf = np.zeros((2 * span, *shape))
        self.pos = 0

    def fill(self, row: np.ndarray) -> None:
        self.buf[:] = row
        self.pos = 0

    def add(self, row: np.ndarray) -> np.ndarray:
        """Store ``row`` as the newest and return the contiguous (span, …) view, oldest first."""
        p = self.pos
        self.buf[p] = row
        self.buf[p + self.span] = row
        self.pos = (p + 1) % self.span
        return self.buf[p + 1 : p + 1 + self.span]


class _DenseHead:
    """ReLU stack + linear output from a state dict (weights transposed for row vectors)."""

    def __init__(self, layers: list[tuple[np.ndarray, np.ndarray]]) -> None:
        self.layers = [(np.ascontiguousarray(w.T, dtype=np.float64), b.astype(np.float64))
                       for w, b in layers]
        self.bufs = [np.zeros(b.shape[0]) for _, b in self.layers]

    def __call__(self, a: np.ndarray) -> np.ndarray:
        last = len(self.layers) - 1
        for k, ((w, b), buf) in enumerate(zip(self.layers, self.bufs, strict=True)):
            np.dot(a, w, out=buf)
            buf += b
            if k != last:
                np.maximum(buf, 0.0, out=buf)
            a = buf
        return a


def _head_layers(state: dict, prefix: str) -> list[tuple[np.ndarray, np.ndarray]]:
    idx = sorted({int(k.split(".")[1]) for k in state if k.startswith(prefix)})
    return [(state[f"{prefix}{i}.weight"], state[f"{prefix}{i}.bias"]) for i in idx]


class _NumpyLSTM:
    """G independent LSTMs (hidden H) over the window, with per-frame input projections.

    Gate columns are reordered to [i, f, o, g] and the i/f/o columns halved, so one tanh over
    all gates gives σ(x) = 0.5·tanh(x/2) + 0.5 for the first 3H and tanh for the last H.
    """

    def __init__(self, w_ih: np.ndarray, w_hh: np.ndarray, bias: np.ndarray, span: int,
                 dilation: int) -> None:
        # w_ih (G, In, 4H), w_hh (G, H, 4H), bias (G, 4H), PyTorch gate order [i, f, g, o]
        hidden = w_hh.shape[1]
        order = np.r_[0 : 2 * hidden, 3 * hidden : 4 * hidden, 2 * hidden : 3 * hidden]
        scale = np.ones(4 * hidden)
        scale[: 3 * hidden] = 0.5
        self.w_ih = np.ascontiguousarray(w_ih[:, :, order] * scale, dtype=np.float64)
        self.w_hh = np.ascontiguousarray(w_hh[:, :, order] * scale, dtype=np.float64)
        self.bias = bias[:, order] * scale
        self.groups, self.hidden = w_hh.shape[0], hidden
        self.dilation = dilation
        self.ring = _Ring(span, (self.groups, 4 * hidden))
        self.xp = np.zeros((self.groups, 4 * hidden))
        self.gates = np.zeros((self.groups, 4 * hidden))
        self.h = np.zeros((self.groups, hidden))
        self.c = np.zeros((self.groups, hidden))
        self.tmp = np.zeros((self.groups, hidden))
        self.h_flat = self.h.reshape(-1)
        self.grouped = self.groups > 1
        self.h3 = self.h[:, None, :]
        self.g3 = self.gates[:, None, :]

    def reset(self) -> None:
        self.ring.fill(0.0)

    def project(self, z: np.ndarray) -> None:
        """xp = z·W_ih + b for one frame; z (S,) is split across groups when G > 1."""
        if self.grouped:
            np.multiply(z[:, None], self.w_ih[:, 0, :], out=self.xp)
        else:
            np.dot(z, self.w_ih[0], out=self.xp[0])
        self.xp += self.bias

    def run(self, z: np.ndarray, first: bool) -> np.ndarray:
        """Add frame z to the window and return the last hidden state (G·H,)."""
        self.project(z)
        if first:
            self.ring.fill(self.xp)
        window = self.ring.add(self.xp)[:: self.dilation]
        h3, hd = 3 * self.hidden, self.hidden
        g, c, h, tmp = self.gates, self.c, self.h, self.tmp
        for step in range(window.shape[0]):
            if step == 0:
                g[:] = window[0]
            elif self.grouped:
                np.matmul(self.h3, self.w_hh, out=self.g3)
                g += window[step]
            else:
                np.dot(h[0], self.w_hh[0], out=g[0])
                g += window[step]
            np.tanh(g, out=g)
            sig = g[:, :h3]
            sig *= 0.5
            sig += 0.5
            if step == 0:
                np.multiply(g[:, :hd], g[:, h3:], out=c)
            else:
                c *= g[:, hd : 2 * hd]
                np.multiply(g[:, :hd], g[:, h3:], out=tmp)
                c += tmp
            np.tanh(c, out=tmp)
            np.multiply(g[:, 2 * hd : h3], tmp, out=h)
        return self.h_flat


class _NumpyRecurrentRunner:
    """ENNet (G = 1) or LNNet (G = S) on the numpy LSTM + dense head."""

    def __init__(self, est: TrainedEstimator, span: int) -> None:
        state = {k: v.detach().cpu().numpy().astype(np.float64)
                 for k, v in est.network.state_dict().items()}  # type: ignore[union-attr]
        if est.kind == "ennet":
            w_ih = state["lstm.weight_ih_l0"].T[None]
            w_hh = state["lstm.weight_hh_l0"].T[None]
            bias = (state["lstm.bias_ih_l0"] + state["lstm.bias_hh_l0"])[None]
        else:  # lnnet: GroupedLSTM parameters
            w_ih = state["lstm.weight_ih"][:, None, :]
            w_hh = state["lstm.weight_hh"].transpose(0, 2, 1)
            bias = state["lstm.bias"]
        self.lstm = _NumpyLSTM(w_ih, w_hh, bias, span, est.config.dilation)
        self.head = _DenseHead(_head_layers(state, "head."))

    def reset(self) -> None:
        self.lstm.reset()

    def step(self, z: np.ndarray, first: bool) -> np.ndarray:
        return self.head(self.lstm.run(z, first))


class _NumpyANNRunner:
    """ANN: dense head on the newest frame."""

    def __init__(self, est: TrainedEstimator) -> None:
        state = {k: v.detach().cpu().numpy() for k, v in est.network.state_dict().items()}  # type: ignore[union-attr]
        self.head = _DenseHead(_head_layers(state, "head."))

    def reset(self) -> None:
        """Memoryless: nothing to forget."""

    def step(self, z: np.ndarray, first: bool) -> np.ndarray:
        return self.head(z)


class _ClassicalRunner:
    """Classical model: play/creep operator states advance one frame per push."""

    def __init__(self, est: TrainedEstimator) -> None:
        assert est.classical is not None
        self.model = est.classical
        self.state = self.model.start(np.zeros(est.config.n_sensors))

    def reset(self) -> None:
        self.state = self.model.start(np.zeros(self.state.play.shape[0]))

    def step(self, z: np.ndarray, first: bool) -> np.ndarray:
        if first:
            self.state = self.model.start(z)
        return self.model.step_features(z, self.state) @ self.model.weights


class _TorchRunner:
    """The torch module (eager or traced) on the window, one thread, inference mode."""

    def __init__(self, est: TrainedEstimator, span: int, script: bool) -> None:
        import torch

        torch.set_num_threads(1)
        self.torch = torch
        self.dilation = est.config.dilation
        self.ring = _Ring(span, (est.config.n_sensors,))
        net = est.network
        assert isinstance(net, torch.nn.Module)
        net.eval()
        example = torch.zeros(1, est.config.window, est.config.n_sensors)
        if script:
            with torch.inference_mode(), warnings.catch_warnings():
                # the LSTM's own input-shape checks become constants: the shape is fixed here
                warnings.simplefilter("ignore", torch.jit.TracerWarning)
                net = torch.jit.trace(net, example)
        self.net = net
        self.xbuf = torch.zeros(1, est.config.window, est.config.n_sensors)
        self.xview = self.xbuf.numpy()
        self.out = np.zeros(est.config.n_angles)

    def reset(self) -> None:
        self.ring.fill(0.0)

    def step(self, z: np.ndarray, first: bool) -> np.ndarray:
        if first:
            self.ring.fill(z)
        win = self.ring.add(z)[:: self.dilation]
        self.xview[0, -win.shape[0] :] = win
        with self.torch.inference_mode():
            y = self.net(self.xbuf)
        self.out[:] = y.numpy()[0]
        return self.out


def _make_runner(est: TrainedEstimator, backend: str, span: int):
    if backend == "numpy":
        if est.kind == "classical":
            return _ClassicalRunner(est)
        if est.kind == "ann":
            return _NumpyANNRunner(est)
        return _NumpyRecurrentRunner(est, span)
    return _TorchRunner(est, span, script=backend == "torchscript")
