"""Where the exchange's gain could come from: probes of the features and the views' depth errors.

The paper's Fullcam -> AirPose gain needs per-view estimates whose errors the exchange can average.
Three measurements say whether the kit's networks have such errors, all on arrays (numpy, torch
for the small MLP), one row per two-view sample and one column per view:

* **probes**: how much of a quantity (stature, gender, log depth) a readout finds in one view's
  backbone features (:func:`fit_ridge`, :func:`fit_mlp`), scored on held-out subjects by R^2
  (:func:`r2_score`) or accuracy, and how correlated the two views' probe errors are
  (:func:`view_error_correlation`): a quantity both views misread alike cannot be averaged away;
* **relative depth errors** ``(tau_z_pred - tau_z_true) / tau_z_true`` (:func:`relative_depth_error`);
* **the bound of a shared body scalar** (:func:`depth_scaled`): a body scalar (the person's
  size) moves each view's estimate along its ray, so the most an exchanged scalar can do is give
  both views the mean of their relative depth errors; the MPE of that estimate, against the
  measured one, is what exchanging it could buy. With each view's relative error set to zero it
  gives what a perfect depth scale leaves (the error across the ray).

Intervals resample two-view samples (:func:`probe_interval`, through
:func:`airpose_lib.eval.significance.bootstrap_interval`).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from .significance import bootstrap_interval

__all__ = ["RIDGE_PENALTIES", "Probe", "fit_ridge", "fit_mlp", "r2_score", "accuracy", "view_error_correlation",
           "relative_depth_error", "depth_scaled", "probe_interval"]

#: Ridge penalties tried, per standardised column and fitted row (chosen on a part of the fitting rows).
RIDGE_PENALTIES = (1e-4, 1e-3, 1e-2, 1e-1, 1.0, 10.0)


@dataclass(frozen=True)
class Probe:
    """A fitted readout ``X (n, d) -> (n,)``: inputs standardised by the fitting rows' mean and SD,
    the target restored to its units."""

    mean: np.ndarray
    scale: np.ndarray
    predict_standardised: Callable[[np.ndarray], np.ndarray]
    y_mean: float
    y_scale: float
    note: str = ""

    def __call__(self, X: np.ndarray) -> np.ndarray:
        Z = (np.asarray(X, dtype=np.float64) - self.mean) / self.scale
        return self.y_mean + self.y_scale * self.predict_standardised(Z)


def _standardise(X: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float, float]:
    X, y = np.asarray(X, dtype=np.float64), np.asarray(y, dtype=np.float64)
    mean, scale = X.mean(0), X.std(0)
    scale[scale == 0] = 1.0  # a constant column carries nothing; keep it finite
    y_scale = float(y.std()) or 1.0
    return (X - mean) / scale, (y - y.mean()) / y_scale, mean, scale, float(y.mean()), y_scale


def _ridge_weights(Z: np.ndarray, t: np.ndarray, penalty: float) -> np.ndarray:
    n, d = Z.shape
    return np.linalg.solve(Z.T @ Z + penalty * n * np.eye(d), Z.T @ t)


def fit_ridge(X: np.ndarray, y: np.ndarray, penalties=RIDGE_PENALTIES, holdout: float = 0.2, seed: int = 0) -> Probe:
    """Ridge regression in closed form on standardised inputs, its penalty chosen on a held-out
    part of the fitting rows, then refitted on all of them.

    Args:
        X: ``(n, d)`` inputs; y: ``(n,)`` target. Rows of one subject must be held out together:
            pass the rows in (sample, view) order and they are split by pairs of rows when n is
            even (the two views of a sample stay on one side).
        penalties: per-row penalties tried (:data:`RIDGE_PENALTIES`).
        holdout: share of the fitting rows that chooses the penalty.
    """
    Z, t, mean, scale, y_mean, y_scale = _standardise(X, y)
    n = len(Z)
    groups = np.arange(n) // 2 if n % 2 == 0 else np.arange(n)
    held = np.random.default_rng(seed).random(groups.max() + 1)[groups] < holdout
    errors = [np.mean((Z[held] @ _ridge_weights(Z[~held], t[~held], lam) - t[held]) ** 2) for lam in penalties]
    best = penalties[int(np.argmin(errors))]
    w = _ridge_weights(Z, t, best)
    return Probe(mean, scale, lambda Zn: Zn @ w, y_mean, y_scale, note=f"penalty {best:g}")


def fit_mlp(X: np.ndarray, y: np.ndarray, hidden: int = 128, steps: int = 400, batch_size: int = 256,
            lr: float = 1e-3, weight_decay: float = 1e-3, seed: int = 0) -> Probe:
    """A one-hidden-layer MLP (ReLU) on standardised inputs, Adam on the squared error, mini-batches.

    Args:
        X: ``(n, d)``; y: ``(n,)``.
        hidden, steps, batch_size, lr, weight_decay: its size and training (a few hundred steps:
            a probe of what a small nonlinear readout finds, not a tuned model).
    """
    Z, t, mean, scale, y_mean, y_scale = _standardise(X, y)
    g = torch.Generator().manual_seed(seed)
    torch.manual_seed(seed)
    net = torch.nn.Sequential(torch.nn.Linear(Z.shape[1], hidden), torch.nn.ReLU(), torch.nn.Linear(hidden, 1))
    opt = torch.optim.Adam(net.parameters(), lr=lr, weight_decay=weight_decay)
    Zt, tt = torch.as_tensor(Z, dtype=torch.float32), torch.as_tensor(t, dtype=torch.float32)
    for _ in range(steps):
        idx = torch.randint(0, len(Zt), (min(batch_size, len(Zt)),), generator=g)
        loss = torch.nn.functional.mse_loss(net(Zt[idx])[:, 0], tt[idx])
        opt.zero_grad()
        loss.backward()
        opt.step()
    net.eval()

    def predict(Zn: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return net(torch.as_tensor(Zn, dtype=torch.float32))[:, 0].double().numpy()

    return Probe(mean, scale, predict, y_mean, y_scale, note=f"{hidden} hidden, {steps} steps")


def r2_score(y: np.ndarray, y_pred: np.ndarray) -> float:
    """``1 - sum (y - y_pred)^2 / sum (y - mean y)^2`` over every entry (NaN when y is constant)."""
    y, y_pred = np.asarray(y, dtype=np.float64).ravel(), np.asarray(y_pred, dtype=np.float64).ravel()
    spread = np.sum((y - y.mean()) ** 2)
    return float(1.0 - np.sum((y - y_pred) ** 2) / spread) if spread > 0 else float("nan")


def accuracy(label: np.ndarray, score: np.ndarray, threshold: float = 0.5) -> float:
    """Share of entries whose ``score > threshold`` agrees with the 0/1 ``label``."""
    label, score = np.asarray(label).ravel(), np.asarray(score, dtype=np.float64).ravel()
    return float(np.mean((score > threshold) == (label > 0.5)))


def view_error_correlation(errors: np.ndarray) -> float:
    """Pearson correlation of the first two views' errors, ``errors (N, V >= 2) -> float``: near 1,
    both views misread a sample alike (nothing for an exchange to average); near 0, independently."""
    e = np.asarray(errors, dtype=np.float64)
    return float(np.corrcoef(e[:, 0], e[:, 1])[0, 1])


def relative_depth_error(tau_pred: np.ndarray, tau_true: np.ndarray) -> np.ndarray:
    """``(tau_z_pred - tau_z_true) / tau_z_true``: ``(..., 3)`` x2 -> ``(...)``."""
    tau_pred, tau_true = np.asarray(tau_pred, dtype=np.float64), np.asarray(tau_true, dtype=np.float64)
    return (tau_pred[..., 2] - tau_true[..., 2]) / tau_true[..., 2]


def depth_scaled(tau_pred: np.ndarray, tau_true: np.ndarray, shared: bool = True) -> np.ndarray:
    """Each view's estimate moved along its own ray so that its relative depth error becomes the mean
    of the views' (``shared``: the best an exchanged body scalar can do) or zero (a perfect depth scale).

    Args:
        tau_pred, tau_true: ``(N, V, 3)`` estimated and true translations, camera frames.
    Returns:
        ``(N, V, 3)``: ``tau_pred (1 + r_target) / (1 + r_v)``, r from :func:`relative_depth_error`.
    """
    tau_pred = np.asarray(tau_pred, dtype=np.float64)
    r = relative_depth_error(tau_pred, tau_true)
    target = np.broadcast_to(r.mean(axis=1, keepdims=True), r.shape) if shared else np.zeros_like(r)
    return tau_pred * ((1.0 + target) / (1.0 + r))[..., None]


def probe_interval(score: Callable[[np.ndarray, np.ndarray], float], y: np.ndarray, y_pred: np.ndarray,
                   n_resamples: int = 2000, seed: int = 0) -> tuple[float, float, float]:
    """``score`` (e.g. :func:`r2_score`) of per-view values with its 95 % interval over two-view samples.

    Args:
        score: ``(y, y_pred) -> float`` over the entries given.
        y, y_pred: ``(N, V)`` or ``(N, ...)``: row i is sample i, resampled whole.
    Returns:
        ``(value, low, high)``.
    """
    y, y_pred = np.asarray(y), np.asarray(y_pred)
    return bootstrap_interval(lambda idx: score(y[idx], y_pred[idx]), len(y), n_resamples, seed=seed)
