"""A trained estimator: network or classical model plus everything needed to apply it.

Pipeline for one block of sensor frames (recording units, e.g. mm):
1. optional per-recording offset removal (causal initial rest value, done when the blocks are
   made — :func:`exohil.estimator.dataset.recording_blocks` with ``offset_frames``);
2. per-sensor normalisation z = (x − x_mean) / x_std (training statistics);
3. the model on edge-padded causal windows, or (stateful ENNet) on the whole block from a zero
   state, or the classical operators on the block;
4. de-normalisation of the outputs: ŷ · y_std + y_mean;
5. for a ``direction`` output (a shoulder θ/φ target, see
   :data:`~exohil.estimator.architecture.OUTPUTS`), the humerus direction → θ/φ
   (:meth:`TrainedEstimator.decode`); angles in degrees.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from exohil.estimator.architecture import ModelConfig
from exohil.estimator.classical import ClassicalModel
from exohil.estimator.dataset import Block, TargetSpec
from exohil.estimator.windows import block_windows
from exohil.kinematics import humerus_angles, humerus_direction

#: The shoulder angles a direction output stands for: plane of elevation θ and elevation φ.
DIRECTION_ANGLES = ("elv_angle", "shoulder_elv")


def is_direction_target(target: TargetSpec) -> bool:
    """True when ``target`` is exactly the θ/φ pair a direction output stands for (in
    either order)."""
    return sorted(target.angles) == sorted(DIRECTION_ANGLES)


def direction_columns(target: TargetSpec) -> tuple[int, int]:
    """Columns of θ and φ in ``target``'s angles."""
    theta, phi = (target.angles.index(a) for a in DIRECTION_ANGLES)
    return theta, phi


def encode_targets(output: str, target: TargetSpec, angles: np.ndarray) -> np.ndarray:
    """Network targets (N, K) from target angles (N, A), degrees, for a network of ``output``
    (see :data:`~exohil.estimator.architecture.OUTPUTS`): the angles themselves, or for a
    direction output the unit humerus direction (thorax frame)."""
    if output != "direction":
        return angles
    th, ph = direction_columns(target)
    return humerus_direction(np.deg2rad(angles[:, th]), np.deg2rad(angles[:, ph]))

#: Frames per forward pass when predicting a long block.
PREDICT_BATCH = 4096


@dataclass
class Normalisation:
    """Per-sensor and per-angle mean/std from the training data (recording units / degrees)."""

    x_mean: np.ndarray
    x_std: np.ndarray
    y_mean: np.ndarray
    y_std: np.ndarray

    @classmethod
    def fit(cls, x: np.ndarray, y: np.ndarray, scale_y: bool = True) -> Normalisation:
        """Statistics of training sensors ``x`` (N, S) and network targets ``y`` (N, K);
        ``scale_y`` False leaves the targets as they are (mean 0, std 1: a unit direction
        vector, whose squared error is then the squared chord between directions)."""
        if scale_y:
            return cls(x.mean(0), _safe_std(x), y.mean(0), _safe_std(y))
        return cls(x.mean(0), _safe_std(x), np.zeros(y.shape[1]), np.ones(y.shape[1]))

    def x(self, x: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Normalised sensors z = (x − x_mean) / x_std (into ``out`` when given: no allocation,
        for per-frame streaming)."""
        z = np.subtract(x, self.x_mean, out=out)
        z /= self.x_std
        return z

    def y(self, y: np.ndarray) -> np.ndarray:
        """Normalised angles (y − y_mean) / y_std, the training targets."""
        return (y - self.y_mean) / self.y_std

    def y_inverse(self, y: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Angles (degrees) from normalised outputs: y · y_std + y_mean (into ``out`` when
        given)."""
        angles = np.multiply(y, self.y_std, out=out)
        angles += self.y_mean
        return angles

    def fold_x(self, w: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The input scaling folded into linear maps that read the normalised sensors:
        (w', b) with (x − x_mean)·w' + b = z·w + b for z = (x − x_mean) / x_std.

        The mean is left to the caller, to subtract in float64 before float32 maths: folding
        it too (x·w' + b − x_mean·w') cancels large terms in float32 (raw sensors ~550 mm
        with a spread of ~30 mm lose ~3e-3° of output that way).

        ``w`` (G, I, K) and ``b`` (G, K): G maps that each read I of the S = G·I sensors, in
        sensor order (G = 1: one map over every sensor; I = 1: one map per sensor).
        """
        groups, width = w.shape[:2]
        return w / self.x_std.reshape(groups, width, 1), b.copy()

    def fold_y(self, w: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The output de-normalisation folded into the layer that gives the normalised angles:
        (w', b') with w'·a + b' = (w·a + b) · y_std + y_mean, for ``w`` (A, n) and ``b`` (A,)
        (torch ``Linear`` layout)."""
        return w * self.y_std[:, None], b * self.y_std + self.y_mean


class TrainedEstimator:
    """Everything a checkpoint holds.

    Attributes:
        config: architecture (``kind`` "classical" for the classical model).
        sensor_names: expected sensor columns, in order.
        target: joint and angle fields estimated.
        norm: normalisation statistics.
        offset_frames: 0 = raw sensors; k > 0 = subtract the causal mean of the first k frames.
        sensor_rate_hz: nominal rate of the training data (frames per second).
        network: the torch module (neural kinds) — None for classical; see below.
        classical: the fitted classical model — None for neural kinds.
        info: training provenance and metrics (JSON-serialisable).

    A network's weights are held one of two ways: as NumPy arrays by torch ``state_dict`` name
    (``state``, what :func:`~exohil.estimator.checkpoint.load_checkpoint` gives: no torch
    needed to read, check or run them on the NumPy and ONNX Runtime engines), or as the torch
    module (``network``, what training gives). Reading ``network`` when only the arrays are
    held builds the module from them then (importing torch); from then on the module is the
    weights, so what is done to it (training on, perturbing) is what :meth:`weights` returns.
    """

    def __init__(
        self,
        config: ModelConfig,
        sensor_names: tuple[str, ...],
        target: TargetSpec,
        norm: Normalisation,
        offset_frames: int = 0,
        sensor_rate_hz: float = 250.0,
        network: object | None = None,
        classical: ClassicalModel | None = None,
        info: dict | None = None,
        *,
        state: dict[str, np.ndarray] | None = None,
    ) -> None:
        self.config = config
        self.sensor_names = sensor_names
        self.target = target
        self.norm = norm
        self.offset_frames = offset_frames
        self.sensor_rate_hz = sensor_rate_hz
        self.classical = classical
        self.info: dict = {} if info is None else info
        self._network = network
        self._state = None if network is not None else state

    def __repr__(self) -> str:
        held = ("classical" if self.classical is not None else
                "torch module" if self._network is not None else
                "numpy weights" if self._state is not None else "no model")
        return (f"TrainedEstimator({self.kind}, sensors={list(self.sensor_names)}, "
                f"target={self.target}, {held})")

    @property
    def kind(self) -> str:
        return self.config.kind

    def encode(self, angles: np.ndarray) -> np.ndarray:
        """Network targets (N, K) from target angles (N, A), degrees (:func:`encode_targets`
        for this network's output)."""
        return encode_targets(self.config.output, self.target, angles)

    def decode(self, outputs: np.ndarray) -> np.ndarray:
        """Angles (N, A), degrees, from de-normalised network outputs (N, K): the inverse of
        :meth:`encode` (θ is 0 where the direction is vertical, its singular pose)."""
        if self.config.output != "direction":
            return outputs
        angles = np.empty((outputs.shape[0], 2))
        theta, phi = humerus_angles(outputs)
        th, ph = direction_columns(self.target)
        angles[:, th], angles[:, ph] = np.rad2deg(theta), np.rad2deg(phi)
        return angles

    @property
    def network(self) -> object | None:
        """The torch module, built from the NumPy weights at the first read (imports torch);
        None for the classical model."""
        if self._network is None and self._state is not None:
            self._network = _torch_module(self.config, self._state)
            self._state = None  # the module holds the weights from now on
        return self._network

    @network.setter
    def network(self, module: object | None) -> None:
        self._network = module
        self._state = None

    def set_weights(self, state: dict[str, np.ndarray]) -> None:
        """Hold the network's weights as these arrays (by torch ``state_dict`` name, already
        checked against the architecture), in place of any module."""
        self._network = None
        self._state = state

    @property
    def has_network(self) -> bool:
        """True when a network's weights are held (as arrays or as the module), without
        building the module."""
        return self._network is not None or self._state is not None

    def predict_block(self, block: Block) -> np.ndarray:
        """(N, A) angle estimates in degrees for every frame of one block (the network runs in
        torch; a stateful ENNet starts from a zero state at the block's first frame)."""
        z = self.norm.x(block.x)
        if self.classical is not None:
            return self.decode(self.norm.y_inverse(self.classical.predict(z)))
        return self.decode(self.norm.y_inverse(self.network_outputs(z.astype(np.float32))))

    def network_outputs(self, z: np.ndarray) -> np.ndarray:
        """Normalised network outputs (N, K) for one block's normalised sensors z (N, S),
        float32, in torch (inference mode, the module in eval mode)."""
        import torch

        net = self.network
        assert isinstance(net, torch.nn.Module)
        net.eval()
        out = np.empty((z.shape[0], self.config.n_outputs), dtype=np.float64)
        with torch.inference_mode():
            if self.config.stateful:
                from exohil.estimator.models import ENNet

                assert isinstance(net, ENNet)
                state = None
                for s in range(0, z.shape[0], PREDICT_BATCH):
                    y, state = net.sequence(torch.from_numpy(z[None, s : s + PREDICT_BATCH]),
                                            state)
                    out[s : s + PREDICT_BATCH] = y[0]
                return out
            wins = block_windows(z, self.config.window, self.config.dilation)
            for s in range(0, z.shape[0], PREDICT_BATCH):
                out[s : s + PREDICT_BATCH] = net(torch.from_numpy(wins[s : s + PREDICT_BATCH]))
        return out

    def predict(self, blocks: list[Block]) -> list[np.ndarray]:
        """Estimates (degrees) for each block."""
        return [self.predict_block(b) for b in blocks]

    def weights(self, dtype: type = np.float64) -> dict[str, np.ndarray]:
        """The network's parameters as NumPy arrays (new copies), by torch ``state_dict`` name
        (neural kinds only; raises ValueError for the classical model). Needs torch only when
        the module is what holds them."""
        if self._network is not None:
            state = self._network.state_dict()  # type: ignore[attr-defined]
            return {name: t.detach().cpu().numpy().astype(dtype) for name, t in state.items()}
        if self._state is None:
            raise ValueError(f"{self.kind} has no network weights")
        return {name: array.astype(dtype) for name, array in self._state.items()}


def _torch_module(config: ModelConfig, state: dict[str, np.ndarray]) -> object:
    """The torch module of ``config`` holding ``state`` (checked against the architecture
    when it was loaded), in eval mode."""
    import torch

    from exohil.estimator.models import build_model

    net = build_model(config)
    net.load_state_dict({k: torch.from_numpy(np.array(v, dtype=np.float32))
                         for k, v in state.items()}, strict=True)
    return net.eval()


def _safe_std(a: np.ndarray) -> np.ndarray:
    std = a.std(0)
    return np.where(std > 1e-9, std, 1.0)
