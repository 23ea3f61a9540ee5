"""Joints-only fast path against the full smplx forward (the reference)."""
from __future__ import annotations

import pytest
import torch

from airpose_lib.body import load_body_model
from airpose_lib.body.fast import JointsOnly


def _random_inputs(batch: int, dtype, seed: int = 0, hands: bool = False):
    g = torch.Generator().manual_seed(seed)
    r = lambda *s, scale=1.0: (scale * torch.randn(*s, generator=g, dtype=torch.float64)).to(dtype)  # noqa: E731
    kw = dict(
        betas=r(batch, 10, scale=1.5),
        global_orient=r(batch, 3),
        body_pose=r(batch, 63, scale=0.5),
        transl=r(batch, 3, scale=3.0),
        jaw_pose=r(batch, 3, scale=0.2),
        leye_pose=torch.zeros(batch, 3, dtype=dtype),
        reye_pose=torch.zeros(batch, 3, dtype=dtype),
        expression=torch.zeros(batch, 10, dtype=dtype),
        left_hand_pose=r(batch, 45, scale=0.3 if hands else 0.0),
        right_hand_pose=r(batch, 45, scale=0.3 if hands else 0.0),
    )
    return kw


@pytest.mark.parametrize("dtype,atol", [(torch.float64, 1e-10), (torch.float32, 1e-5)])
def test_equals_full_forward(open_model_files, dtype, atol):
    batch = 16
    model = load_body_model("open", dtype=dtype, batch_size=batch)
    fast = JointsOnly(model)
    kw = _random_inputs(batch, dtype, hands=True)
    with torch.no_grad():
        ref = model(**kw).joints[:, :76]
        got = fast(**kw)
    assert got.shape == (batch, 76, 3)
    torch.testing.assert_close(got, ref, atol=atol, rtol=0)


def test_pose_correctives_and_hand_mean_are_honoured(open_model_files):
    """The licensed model has non-zero posedirs and a hand mean; exercise both paths."""
    batch = 4
    model = load_body_model("open", dtype=torch.float64, batch_size=batch, flat_hand_mean=False)
    g = torch.Generator().manual_seed(1)
    model.posedirs = 1e-3 * torch.randn(model.posedirs.shape, generator=g, dtype=torch.float64)
    model.pose_mean[66:] = 0.1 * torch.randn(99, generator=g, dtype=torch.float64)
    fast = JointsOnly(model)
    kw = _random_inputs(batch, torch.float64, seed=2)
    with torch.no_grad():
        torch.testing.assert_close(fast(**kw), model(**kw).joints[:, :76], atol=1e-10, rtol=0)


def test_rotmat_interface_matches_and_has_gradients(open_model_files):
    from smplx.lbs import batch_rodrigues

    model = load_body_model("open", dtype=torch.float64, batch_size=3)
    fast = JointsOnly(model)
    kw = _random_inputs(3, torch.float64, seed=3)
    pose = torch.cat([kw["global_orient"], kw["body_pose"], torch.zeros(3, 99, dtype=torch.float64)], 1)
    rotmats = batch_rodrigues(pose.reshape(-1, 3)).reshape(3, 55, 3, 3).requires_grad_()
    out = fast.forward_rotmat(rotmats, kw["betas"], kw["transl"])
    out.sum().backward()
    assert rotmats.grad is not None and torch.isfinite(rotmats.grad).all()
    with torch.no_grad():
        ref = model(betas=kw["betas"], global_orient=kw["global_orient"], body_pose=kw["body_pose"],
                    transl=kw["transl"]).joints[:, :76]
    torch.testing.assert_close(out.detach(), ref, atol=1e-10, rtol=0)
