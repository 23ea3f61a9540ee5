"""Joints-only forward pass of an ``smplx.SMPLX`` model, for fitting over long sequences.

A full forward skins every vertex (13.7k for the open model, 10.5k for SMPL-X) although fitting
only needs the skeleton joints and the ~21 vertices keypoints are read from. This module
precomputes the joint regressor applied to the template and shape space, and keeps the
template, shape directions, pose correctives and skinning weights of just the keypoint
vertices. The result equals ``model(...).joints[:, :76]`` (skeleton + keypoint vertices).
"""
from __future__ import annotations

import torch
from smplx.lbs import batch_rigid_transform, batch_rodrigues

from .joint_sets import NUM_OUTPUT_JOINTS


class JointsOnly(torch.nn.Module):
    """Skeleton joints and keypoint vertices of an smplx SMPL-X model, without the mesh.

    Args:
        model: a loaded ``smplx.SMPLX`` (open or licensed); its buffers are copied, so later
            changes to ``model`` do not reach this module.
    """

    def __init__(self, model) -> None:
        super().__init__()
        dirs = torch.cat([model.shapedirs, model.expr_dirs], dim=-1)  # (V, 3, S)
        ids = model.vertex_joint_selector.extra_joints_idxs.clone()
        reg = model.J_regressor  # (55, V)
        self.register_buffer("J_template", reg @ model.v_template)  # (55, 3)
        self.register_buffer("J_dirs", torch.einsum("jv,vcs->jcs", reg, dirs))  # (55, 3, S)
        self.register_buffer("kp_template", model.v_template[ids])  # (K, 3)
        self.register_buffer("kp_dirs", dirs[ids])  # (K, 3, S)
        posedirs = model.posedirs.view(model.posedirs.shape[0], -1, 3)  # (P, V, 3)
        self.register_buffer("kp_posedirs", posedirs[:, ids].reshape(posedirs.shape[0], -1))
        self.register_buffer("kp_weights", model.lbs_weights[ids])  # (K, 55)
        self.register_buffer("parents", model.parents.clone())
        self.register_buffer("pose_mean", model.pose_mean.clone())  # (165,)
        self.num_betas = model.num_betas
        self.num_expression_coeffs = model.num_expression_coeffs
        self.use_pca = model.use_pca
        if self.use_pca:
            self.register_buffer("left_hand_components", model.left_hand_components.clone())
            self.register_buffer("right_hand_components", model.right_hand_components.clone())

    @property
    def num_keypoint_vertices(self) -> int:
        return self.kp_template.shape[0]

    def forward(
        self,
        betas: torch.Tensor | None = None,
        global_orient: torch.Tensor | None = None,
        body_pose: torch.Tensor | None = None,
        transl: torch.Tensor | None = None,
        left_hand_pose: torch.Tensor | None = None,
        right_hand_pose: torch.Tensor | None = None,
        jaw_pose: torch.Tensor | None = None,
        leye_pose: torch.Tensor | None = None,
        reye_pose: torch.Tensor | None = None,
        expression: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Axis-angle interface, same arguments and defaults (zeros) as ``smplx.SMPLX.forward``.

        Args:
            betas: (B, num_betas); global_orient: (B, 3); body_pose: (B, 63);
            transl: (B, 3); hand poses: (B, 45) (or (B, n_pca) with PCA); jaw/eye poses: (B, 3);
            expression: (B, num_expression_coeffs). Missing ones are zero.
        Returns:
            (B, 55 + K, 3) joints: skeleton then keypoint vertices (K = 21), as ``smplx`` orders them.
        """
        given = [t for t in (betas, global_orient, body_pose, transl) if t is not None]
        batch = given[0].shape[0] if given else 1
        dtype, device = self.J_template.dtype, self.J_template.device
        zeros = lambda n: torch.zeros(batch, n, dtype=dtype, device=device)  # noqa: E731
        hand_dim = self.left_hand_components.shape[0] if self.use_pca else 45
        left = left_hand_pose if left_hand_pose is not None else zeros(hand_dim)
        right = right_hand_pose if right_hand_pose is not None else zeros(hand_dim)
        if self.use_pca:
            left = left @ self.left_hand_components
            right = right @ self.right_hand_components
        full_pose = torch.cat(
            [
                (global_orient if global_orient is not None else zeros(3)).reshape(batch, 3),
                (body_pose if body_pose is not None else zeros(63)).reshape(batch, 63),
                (jaw_pose if jaw_pose is not None else zeros(3)).reshape(batch, 3),
                (leye_pose if leye_pose is not None else zeros(3)).reshape(batch, 3),
                (reye_pose if reye_pose is not None else zeros(3)).reshape(batch, 3),
                left.reshape(batch, 45),
                right.reshape(batch, 45),
            ],
            dim=1,
        ) + self.pose_mean
        rotmats = batch_rodrigues(full_pose.reshape(-1, 3)).reshape(batch, -1, 3, 3)
        return self.forward_rotmat(
            rotmats,
            betas if betas is not None else zeros(self.num_betas),
            transl,
            expression if expression is not None else zeros(self.num_expression_coeffs),
        )

    def forward_rotmat(
        self,
        rotmats: torch.Tensor,
        betas: torch.Tensor,
        transl: torch.Tensor | None = None,
        expression: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Rotation-matrix interface (what 6D-rotation fitting produces).

        Args:
            rotmats: (B, 55, 3, 3) local joint rotations, root first (hand mean already applied).
            betas: (B, num_betas) or (1, num_betas), broadcast over the batch.
            transl: (B, 3) or None.
            expression: (B, num_expression_coeffs) or None (zeros).
        Returns:
            (B, 55 + K, 3) joints.
        """
        batch = rotmats.shape[0]
        betas = betas.expand(batch, -1)
        if expression is None:
            expression = betas.new_zeros(batch, self.J_dirs.shape[-1] - betas.shape[1])
        shape = torch.cat([betas, expression.expand(batch, -1)], dim=-1)  # (B, S)
        joints_rest = self.J_template + torch.einsum("jcs,bs->bjc", self.J_dirs, shape)
        joints, A = batch_rigid_transform(rotmats, joints_rest, self.parents, dtype=rotmats.dtype)

        ident = torch.eye(3, dtype=rotmats.dtype, device=rotmats.device)
        pose_feature = (rotmats[:, 1:] - ident).reshape(batch, -1)  # (B, 486)
        kp = self.kp_template + torch.einsum("kcs,bs->bkc", self.kp_dirs, shape)
        kp = kp + (pose_feature @ self.kp_posedirs).view(batch, -1, 3)
        T = torch.einsum("kj,bjxy->bkxy", self.kp_weights, A)  # (B, K, 4, 4)
        kp = torch.einsum("bkxy,bky->bkx", T[..., :3, :3], kp) + T[..., :3, 3]

        out = torch.cat([joints, kp], dim=1)
        if transl is not None:
            out = out + transl[:, None, :]
        assert out.shape[1] == NUM_OUTPUT_JOINTS or self.num_keypoint_vertices != 21
        return out
