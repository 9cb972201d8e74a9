"""Classical baseline without deep learning: Prandtl–Ishlinskii hysteresis + creep terms +
a static quadratic map, all fitted by one ridge least-squares solve (NumPy only).

Per normalised sensor channel z_s(t) the feature map holds
- the static quadratic terms 1, z_s, z_s·z_r (every pair, squares included);
- play (backlash) operators p_{s,k} with thresholds r_k (Prandtl–Ishlinskii model):
  p(t) = min(z(t) + r, max(z(t) − r, p(t−1))), p(0) = z(0);
  a weighted sum of plays is the PI hysteresis operator, and its inverse is again a PI operator,
  so the weights fitted here are the inverse-PI compensation;
- first-order creep terms z − EMA_τ(z) for a few time constants τ (rate-dependent drift).
The weights on all terms come from a ridge solve; the ridge strength is picked on validation
data. Operator states start at each block's first frame, like a freshly started stream.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: Play thresholds in units of the channel's training standard deviation.
DEFAULT_THRESHOLDS = (0.05, 0.15, 0.3, 0.5, 0.8, 1.2)
#: Creep time constants, seconds.
DEFAULT_CREEP_TAUS_S = (0.5, 2.0, 8.0)
RIDGE_GRID = (1e-6, 1e-4, 1e-2, 1.0, 100.0)


@dataclass
class ClassicalState:
    """Streaming state: last play outputs (S, K) and creep averages (S, M)."""

    play: np.ndarray
    ema: np.ndarray


@dataclass
class ClassicalModel:
    """Fitted PI + creep + quadratic map from normalised sensors to normalised angles.

    Attributes:
        thresholds: (K,) play thresholds (normalised units).
        alphas: (M,) per-frame EMA update factors 1 − exp(−dt/τ).
        weights: (F, A) ridge weights over :meth:`features`.
    """

    thresholds: np.ndarray
    alphas: np.ndarray
    weights: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))

    @classmethod
    def create(
        cls,
        rate_hz: float,
        thresholds: tuple[float, ...] = DEFAULT_THRESHOLDS,
        creep_taus_s: tuple[float, ...] = DEFAULT_CREEP_TAUS_S,
    ) -> ClassicalModel:
        alphas = 1.0 - np.exp(-1.0 / (rate_hz * np.asarray(creep_taus_s, dtype=np.float64)))
        return cls(np.asarray(thresholds, dtype=np.float64), alphas)

    def start(self, z0: np.ndarray) -> ClassicalState:
        """Fresh operator state at the first frame ``z0`` (S,)."""
        return ClassicalState(
            np.repeat(z0[:, None], self.thresholds.shape[0], axis=1).astype(np.float64),
            np.repeat(z0[:, None], self.alphas.shape[0], axis=1).astype(np.float64),
        )

    def step_features(self, z: np.ndarray, state: ClassicalState) -> np.ndarray:
        """Advance the state by one frame z (S,) and return its (F,) feature vector."""
        r = self.thresholds[None, :]
        zc = z[:, None]
        np.minimum(zc + r, np.maximum(zc - r, state.play), out=state.play)
        state.ema += self.alphas[None, :] * (zc - state.ema)
        return np.concatenate([_static_terms(z[None, :])[0], state.play.ravel(),
                               (zc - state.ema).ravel()])

    def features(self, z: np.ndarray) -> np.ndarray:
        """(N, F) features of one block's normalised sensors z (N, S), state from frame 0."""
        n, s = z.shape
        k = self.thresholds.shape[0]
        play = np.empty((n, s, k))
        p = np.repeat(z[0][:, None], k, axis=1).astype(np.float64)
        lo = z[:, :, None] - self.thresholds[None, None, :]
        hi = z[:, :, None] + self.thresholds[None, None, :]
        for i in range(n):
            np.minimum(hi[i], np.maximum(lo[i], p), out=p)
            play[i] = p
        creep = np.empty((n, s, self.alphas.shape[0]))
        for m, a in enumerate(self.alphas):
            creep[:, :, m] = z - _ema(z, float(a))
        return np.concatenate([_static_terms(z), play.reshape(n, -1), creep.reshape(n, -1)],
                              axis=1)

    def fit(self, train: list[np.ndarray], train_y: list[np.ndarray],
            val: list[np.ndarray], val_y: list[np.ndarray]) -> dict[str, float]:
        """Ridge-fit on train blocks, choosing the ridge strength on validation blocks.

        Returns {"ridge": chosen λ, "val_mse": its validation MSE (normalised units)}.
        """
        f_tr = np.concatenate([self.features(z) for z in train])
        y_tr = np.concatenate(train_y)
        f_va = np.concatenate([self.features(z) for z in val]) if val else f_tr
        y_va = np.concatenate(val_y) if val else y_tr
        scale = np.sqrt(np.mean(f_tr**2, axis=0)) + 1e-12
        gram = (f_tr / scale).T @ (f_tr / scale)
        rhs = (f_tr / scale).T @ y_tr
        best: tuple[float, float, np.ndarray] | None = None
        for lam in RIDGE_GRID:
            ridge = lam * len(f_tr) * np.eye(gram.shape[0])
            w = np.linalg.solve(gram + ridge, rhs) / scale[:, None]
            mse = float(np.mean((f_va @ w - y_va) ** 2))
            if best is None or mse < best[1]:
                best = (lam, mse, w)
        assert best is not None
        self.weights = best[2]
        return {"ridge": best[0], "val_mse": best[1]}

    def predict(self, z: np.ndarray) -> np.ndarray:
        """(N, A) normalised predictions for one block's normalised sensors (N, S)."""
        return self.features(z) @ self.weights


def static_polynomial_fit(z: np.ndarray, y: np.ndarray, lam: float = 1e-6) -> np.ndarray:
    """Weights of the static quadratic map alone (for comparison): (F_static, A)."""
    f = _static_terms(z)
    return np.linalg.solve(f.T @ f + lam * len(f) * np.eye(f.shape[1]), f.T @ y)


def static_polynomial_predict(z: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Predictions of :func:`static_polynomial_fit` weights, (N, A)."""
    return _static_terms(z) @ w


def _static_terms(z: np.ndarray) -> np.ndarray:
    """1, z_s and z_s·z_r (s ≤ r) for (N, S) inputs → (N, 1 + S + S(S+1)/2)."""
    n, s = z.shape
    iu, ju = np.triu_indices(s)
    return np.concatenate([np.ones((n, 1)), z, z[:, iu] * z[:, ju]], axis=1)


def _ema(z: np.ndarray, alpha: float) -> np.ndarray:
    """Exponential moving average along axis 0, started at z[0]."""
    from scipy.signal import lfilter

    zi = (1.0 - alpha) * z[0]
    return lfilter([alpha], [1.0, -(1.0 - alpha)], z, axis=0, zi=zi[None, :])[0]
