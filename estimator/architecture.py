"""The networks' architecture without torch: the configuration stored in checkpoints and the
parameter names and shapes each kind has (its torch ``state_dict``), so a checkpoint's weights
are checked, and run by the NumPy and ONNX Runtime engines, with NumPy alone.

The torch modules themselves are in :mod:`exohil.estimator.models`; a test builds each kind
there and compares its ``state_dict`` with :func:`state_shapes`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

MODEL_KINDS = ("ennet", "lnnet", "ann", "cnn")
#: What a network outputs: the target angles themselves, or the humerus direction (a 3-vector
#: in the thorax frame, converted back to θ/φ after the network) for a shoulder θ/φ target,
#: which has no singularity where the arm hangs (docs/estimator.md, "Target").
OUTPUTS = ("angles", "direction")
DENSE_STACK = (512, 256, 128, 64, 32)
#: The CNN's temporal kernel (frames); 'same' padding.
CONV_KERNEL = 3


@dataclass
class ModelConfig:
    """Architecture of one network; stored verbatim in checkpoints.

    Attributes:
        kind: one of MODEL_KINDS.
        n_sensors / n_angles: input and output widths.
        window: frames per window (n); dilation: frame step inside the window.
        hidden: LSTM hidden size (ENNet; per sensor for LNNet); CNN channels.
        dense: widths of the ReLU layers after the temporal encoder.
        output: one of OUTPUTS; "direction" makes the network's output 3 wide.
        stateful: ENNet only: the LSTM state is carried from frame to frame over the whole
            stream (one LSTM step per frame; ``window`` and ``dilation`` are 1) instead of
            re-run over a window from a zero state.
    """

    kind: str
    n_sensors: int
    n_angles: int
    window: int = 10
    dilation: int = 1
    hidden: int = 64
    dense: tuple[int, ...] = field(default=DENSE_STACK)
    output: str = "angles"
    stateful: bool = False

    @property
    def n_outputs(self) -> int:
        """Width of the network's output layer."""
        return 3 if self.output == "direction" else self.n_angles

    def to_dict(self) -> dict:
        d = asdict(self)
        d["dense"] = list(self.dense)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> ModelConfig:
        d = dict(d)
        d["dense"] = tuple(d.get("dense", DENSE_STACK))
        return cls(**d)


def state_shapes(cfg: ModelConfig) -> dict[str, tuple[int, ...]]:
    """Every parameter of ``cfg``'s network by its torch ``state_dict`` name, in that order,
    with its shape. Raises ValueError for an unknown kind or a size that is not positive."""
    if cfg.kind not in MODEL_KINDS:
        raise ValueError(f"unknown model kind {cfg.kind!r}; choose from {MODEL_KINDS}")
    if cfg.output not in OUTPUTS:
        raise ValueError(f"unknown model output {cfg.output!r}; choose from {OUTPUTS}")
    if cfg.output == "direction" and cfg.n_angles != 2:
        raise ValueError(f"a direction output estimates 2 angles, not {cfg.n_angles}")
    if not isinstance(cfg.stateful, bool):
        raise ValueError(f"model config stateful = {cfg.stateful!r} is not true or false")
    if cfg.stateful and (cfg.kind != "ennet" or cfg.window != 1 or cfg.dilation != 1):
        raise ValueError("stateful is true only for an ENNet of window 1, dilation 1")
    sizes = {"n_sensors": cfg.n_sensors, "n_angles": cfg.n_angles, "window": cfg.window,
             "dilation": cfg.dilation, "hidden": cfg.hidden}
    sizes.update({f"dense[{k}]": w for k, w in enumerate(cfg.dense)})
    for name, size in sizes.items():
        if not isinstance(size, int) or isinstance(size, bool) or size < 1:
            raise ValueError(f"model config {name} = {size!r} is not a positive whole number")
    s, h = cfg.n_sensors, cfg.hidden
    shapes: dict[str, tuple[int, ...]] = {}
    if cfg.kind == "ennet":  # nn.LSTM(S, H)
        shapes = {"lstm.weight_ih_l0": (4 * h, s), "lstm.weight_hh_l0": (4 * h, h),
                  "lstm.bias_ih_l0": (4 * h,), "lstm.bias_hh_l0": (4 * h,)}
        features = h
    elif cfg.kind == "lnnet":  # GroupedLSTM(S, H)
        shapes = {"lstm.weight_ih": (s, 4 * h), "lstm.weight_hh": (s, 4 * h, h),
                  "lstm.bias": (s, 4 * h)}
        features = s * h
    elif cfg.kind == "cnn":  # Sequential(Conv1d, ReLU, Conv1d, ReLU)
        shapes = {"conv.0.weight": (h, s, CONV_KERNEL), "conv.0.bias": (h,),
                  "conv.2.weight": (h, h, CONV_KERNEL), "conv.2.bias": (h,)}
        features = h * cfg.window
    else:  # ann: the newest frame
        features = s
    # dense head: Sequential(Linear, ReLU, …, Linear), so the Linear layers are 0, 2, 4, …
    for k, width in enumerate((*cfg.dense, cfg.n_outputs)):
        shapes[f"head.{2 * k}.weight"] = (width, features)
        shapes[f"head.{2 * k}.bias"] = (width,)
        features = width
    return shapes


def check_state(cfg: ModelConfig, shapes: dict[str, tuple[int, ...]]) -> None:
    """Raise ValueError (one line) unless ``shapes`` (parameter name → shape) are exactly
    those of ``cfg``'s network: no name missing, none unexpected, every shape right."""
    expected = state_shapes(cfg)
    missing = [k for k in expected if k not in shapes]
    unexpected = [k for k in shapes if k not in expected]
    wrong = [f"{k} {tuple(shapes[k])} (expected {expected[k]})"
             for k in expected if k in shapes and tuple(shapes[k]) != expected[k]]
    problems = []
    if missing:
        problems.append(f"missing {', '.join(missing)}")
    if unexpected:
        problems.append(f"unexpected {', '.join(unexpected)}")
    if wrong:
        problems.append(f"wrong shape: {', '.join(wrong)}")
    if problems:
        raise ValueError("; ".join(problems))
