"""Robust penalties."""

from __future__ import annotations

from torch import Tensor

__all__ = ["geman_mcclure"]


def geman_mcclure(residual: Tensor, sigma: float, *, scaled: bool = False) -> Tensor:
    """Geman-McClure penalty ``rho(r) = r^2 / (r^2 + sigma^2)``, elementwise.

    The unscaled form (default) is the one of the official AirPose+ code (sigma = 30 px, applied per
    keypoint coordinate): bounded in ``[0, 1)`` and ``~ r^2 / sigma^2`` for ``|r| << sigma``.
    ``scaled=True`` multiplies by ``sigma^2`` (the SMPLify form), which behaves like ``r^2`` for
    small residuals and saturates at ``sigma^2``.

    Args:
        residual: ``(...)`` residuals (e.g. pixels).
        sigma: scale, > 0, in the units of the residual.
        scaled: multiply by ``sigma^2``.

    Returns:
        ``(...)`` penalties, same shape as ``residual``.
    """
    if not sigma > 0:
        raise ValueError(f"sigma must be positive, got {sigma}")
    r2 = residual.square()
    sigma2 = float(sigma) ** 2
    rho = r2 / (r2 + sigma2)
    return rho * sigma2 if scaled else rho
