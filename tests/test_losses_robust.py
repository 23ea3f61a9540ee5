"""Geman-McClure penalty: hand values, bounds, small-residual behaviour."""

import pytest
import torch

from airpose_lib.losses import geman_mcclure

DTYPES = [torch.float32, torch.float64]


@pytest.mark.parametrize("dtype", DTYPES)
def test_hand_computed_values(dtype):
    r = torch.tensor([0.0, 30.0, -30.0, 60.0, 10.0], dtype=dtype)
    expected = torch.tensor([0.0, 0.5, 0.5, 3600 / 4500, 100 / 1000], dtype=dtype)
    got = geman_mcclure(r, 30.0)
    assert got.dtype == dtype and got.shape == r.shape
    torch.testing.assert_close(got, expected)
    torch.testing.assert_close(geman_mcclure(r, 30.0, scaled=True), expected * 900)
    torch.testing.assert_close(geman_mcclure(torch.tensor([2.0], dtype=dtype), 1.0), torch.tensor([0.8], dtype=dtype))


def test_bounded_and_monotone():
    g = torch.Generator().manual_seed(0)
    r = torch.randn(10_000, generator=g, dtype=torch.float64) * 1e3
    rho = geman_mcclure(r, 30.0)
    assert (rho >= 0).all() and (rho < 1).all()
    mags = torch.linspace(0, 1e4, 1000, dtype=torch.float64)
    assert (geman_mcclure(mags, 30.0).diff() > 0).all()
    assert geman_mcclure(torch.tensor(1e6, dtype=torch.float64), 30.0) < 1
    # saturates (within rounding) rather than growing
    assert geman_mcclure(torch.tensor(1e12, dtype=torch.float64), 30.0) <= 1
    rho_s = geman_mcclure(r, 30.0, scaled=True)
    assert (rho_s < 900).all()


def test_small_residuals_quadratic():
    sigma = 30.0
    r = torch.tensor([1e-3, 1e-2, 0.1], dtype=torch.float64)
    rho = geman_mcclure(r, sigma)
    # rho = r^2/sigma^2 (1 - r^2/sigma^2 + ...): relative deviation is O(r^2 / sigma^2)
    rel = (rho - r**2 / sigma**2).abs() / (r**2 / sigma**2)
    assert (rel <= 1.01 * (r / sigma) ** 2).all()
    torch.testing.assert_close(geman_mcclure(r, sigma, scaled=True), r**2, rtol=2e-5, atol=0)


def test_gradient_and_broadcast_shape():
    r = torch.randn(2, 3, 22, 2, requires_grad=True)
    rho = geman_mcclure(r, 30.0)
    assert rho.shape == r.shape
    rho.sum().backward()
    # d/dr r^2/(r^2+s^2) = 2 r s^2 / (r^2 + s^2)^2
    expected = 2 * r.detach() * 900 / (r.detach() ** 2 + 900) ** 2
    torch.testing.assert_close(r.grad, expected)


@pytest.mark.parametrize("sigma", [0.0, -1.0, float("nan")])
def test_invalid_sigma(sigma):
    with pytest.raises(ValueError, match="sigma"):
        geman_mcclure(torch.ones(3), sigma)
