"""Keypoints of the body model for fitting: only the joints a detector sees, fast to differentiate.

:class:`KeypointBody` is built from :class:`airpose_lib.body.fast.JointsOnly` (whose buffers it
slices) and returns exactly ``JointsOnly.forward_rotmat(...)[:, output_index]`` for a body with
identity root rotation and zero translation, but

* only the skeleton joints the requested outputs need (the requested joints, the joints that
  skin the requested keypoint vertices, and their ancestors: 24 of 55 for BODY_25 + COCO-18);
  the other joints keep the model's rest rotation (``pose_mean``: flat hands, eyes straight);
* the kinematic chain is kept as a list of per-joint tensors. ``smplx``'s ``batch_rigid_transform``
  reads each parent out of one stacked tensor, and the backward pass of every such read writes a
  full-size zero gradient: for a 1,000-frame sequence that made the backward pass ~4x slower
  than the forward pass;
* the shape-dependent rest joints are computed once per call for a shared ``beta`` (one per
  sequence in AirPose+) and broadcast over the frames.
"""
from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor, nn

from airpose_lib.body.fast import JointsOnly
from airpose_lib.geometry import axis_angle_to_matrix

__all__ = ["KeypointBody"]

_NUM_SKELETON = 55


def _mm3(a: Tensor, b: Tensor) -> Tensor:
    """``a @ b`` for ``(..., 3, 3)`` stacks. (Broadcast products instead of batched GEMM were
    measured slower, forward + backward, for 1,000 frames.)"""
    return a @ b


def _mv3(a: Tensor, x: Tensor) -> Tensor:
    """``a @ x`` for ``a (..., 3, 3)`` and vectors ``x (..., 3)`` (broadcast)."""
    return (a @ x.unsqueeze(-1)).squeeze(-1)
_BODY = range(1, 22)  # the 21 joints of theta


class KeypointBody(nn.Module):
    """Selected SMPL-X output joints (skeleton joints and keypoint vertices) in the model frame.

    Args:
        joints_only: the body model's joints-only module (its buffers are copied).
        output_index: indices into the 76 outputs of ``JointsOnly`` (55 skeleton joints, then 21
            keypoint vertices); negative entries are not allowed (filter unmapped keypoints first).
    """

    def __init__(self, joints_only: JointsOnly, output_index: Sequence[int]) -> None:
        super().__init__()
        out_idx = [int(i) for i in output_index]
        n_out = _NUM_SKELETON + joints_only.num_keypoint_vertices
        if not out_idx or min(out_idx) < 0 or max(out_idx) >= n_out:
            raise ValueError(f"output_index must be non-empty indices in [0, {n_out}), got {out_idx}")
        parents = joints_only.parents.tolist()
        kp_sel = sorted({i - _NUM_SKELETON for i in out_idx if i >= _NUM_SKELETON})
        weights = joints_only.kp_weights[kp_sel]  # (k, 55)
        need = {i for i in out_idx if i < _NUM_SKELETON} | set(_BODY) | {0}
        need |= set((weights.abs() > 0).any(0).nonzero().flatten().tolist())
        for j in list(need):  # ancestors
            while parents[j] >= 0:
                j = parents[j]
                need.add(j)
        sub = sorted(need)  # SMPL-X parents precede their children, so sorted order is a valid chain
        local = {g: i for i, g in enumerate(sub)}
        self.joints = tuple(sub)
        self.local_parent = tuple(local[parents[g]] if parents[g] >= 0 else -1 for g in sub)
        # Where each requested output comes from: ("j", local joint) or ("k", row of kp_sel).
        self._gather = tuple(("j", local[i]) if i < _NUM_SKELETON else ("k", kp_sel.index(i - _NUM_SKELETON))
                             for i in out_idx)
        self.num_betas = joints_only.num_betas
        self.num_shape = joints_only.J_dirs.shape[-1]

        dtype = joints_only.J_template.dtype
        sub_t = torch.tensor(sub)
        self.register_buffer("J_template", joints_only.J_template[sub_t].clone())  # (n, 3)
        self.register_buffer("J_dirs", joints_only.J_dirs[sub_t].clone())  # (n, 3, S)
        self.register_buffer("kp_template", joints_only.kp_template[kp_sel].clone())  # (k, 3)
        self.register_buffer("kp_dirs", joints_only.kp_dirs[kp_sel].clone())  # (k, 3, S)
        self.register_buffer("kp_weights", weights[:, sub_t].clone())  # (k, n)
        # Rest rotations of every skeleton joint (root and theta's joints are overwritten).
        rest = axis_angle_to_matrix(joints_only.pose_mean.reshape(_NUM_SKELETON, 3))
        self.register_buffer("rest_rot", rest[sub_t].clone())  # (n, 3, 3)
        # Pose correctives of the keypoint vertices: rows of theta's joints, constant for the rest.
        posedirs = joints_only.kp_posedirs.reshape(_NUM_SKELETON - 1, 9, -1, 3)[:, :, kp_sel]  # (54, 9, k, 3)
        eye = torch.eye(3, dtype=dtype)
        feat = (rest[1:] - eye).reshape(_NUM_SKELETON - 1, 9)
        feat[: len(_BODY)] = 0.0  # theta's joints enter through the variable part
        self.register_buffer("kp_pose_const", torch.einsum("jf,jfkc->kc", feat, posedirs))  # (k, 3)
        self.register_buffer("kp_posedirs", posedirs[: len(_BODY)].reshape(len(_BODY) * 9, -1))  # (189, 3k)
        self._has_posedirs = bool(posedirs.numel() and posedirs.abs().max() > 0)
        self._num_kp = len(kp_sel)
        self._body_local = tuple(local[g] for g in _BODY)

    @property
    def num_outputs(self) -> int:
        return len(self._gather)

    def forward(self, theta: Tensor, betas: Tensor) -> Tensor:
        """Requested joints of the body with identity root and zero translation (``V0``'s frame).

        Args:
            theta: ``(B, 21, 3, 3)`` body joint rotations (relative to the parents).
            betas: ``(num_betas,)``, ``(1, num_betas)`` (shared) or ``(B, num_betas)``.
        Returns:
            ``(B, len(output_index), 3)`` metres.
        """
        B = theta.shape[0]
        betas = betas.reshape(-1, betas.shape[-1])
        shape = torch.cat([betas, betas.new_zeros(betas.shape[0], self.num_shape - betas.shape[-1])], -1)
        J_rest = self.J_template + torch.einsum("ncs,bs->bnc", self.J_dirs, shape)  # (b, n, 3), b in {1, B}

        rot = list(self.rest_rot.unbind(0))
        for k, li in enumerate(self._body_local):
            rot[li] = theta[:, k]
        J_list = J_rest.unbind(1)
        G_R: list[Tensor | None] = []
        G_t: list[Tensor] = []
        for i, p in enumerate(self.local_parent):
            if p < 0:  # root: identity rotation, at its rest position
                G_R.append(None)
                G_t.append(J_list[0])
                continue
            offset = J_list[i] - J_list[p]  # (b, 3)
            Rp = G_R[p]
            if Rp is None:
                G_R.append(rot[i])
                G_t.append(offset + G_t[p])
            else:
                G_R.append(_mm3(Rp, rot[i]))
                G_t.append(_mv3(Rp, offset) + G_t[p])
        ident = torch.eye(3, dtype=theta.dtype, device=theta.device).expand(B, 3, 3)
        R_all = torch.stack([ident if r is None else r.expand(B, 3, 3) for r in G_R], 1)  # (B, n, 3, 3)
        t_all = torch.stack([t.expand(B, 3) for t in G_t], 1)  # (B, n, 3)
        kp_posed = t_all[:, :0]
        if self._num_kp:
            # Rest keypoint vertices (shape and pose correctives), then LBS:
            # sum_j w_kj (G_R_j (v_k - J_j) + G_t_j).
            kp = self.kp_template + torch.einsum("kcs,bs->bkc", self.kp_dirs, shape) + self.kp_pose_const
            if self._has_posedirs:
                ident = torch.eye(3, dtype=theta.dtype, device=theta.device)
                kp = kp + ((theta - ident).reshape(B, -1) @ self.kp_posedirs).reshape(B, -1, 3)
            t_lbs = t_all - _mv3(R_all, J_rest)
            A_R = torch.einsum("kn,bnxy->bkxy", self.kp_weights, R_all)
            A_t = torch.einsum("kn,bnx->bkx", self.kp_weights, t_lbs)
            kp_posed = _mv3(A_R, kp) + A_t  # (B, k, 3)
        cols = [t_all[:, i] if kind == "j" else kp_posed[:, i] for kind, i in self._gather]
        return torch.stack(cols, 1)
