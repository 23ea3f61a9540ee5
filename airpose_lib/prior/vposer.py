"""A VPoser-v2-architecture variational auto-encoder over the 21 SMPL-X body rotations.

The paper (Sec. III-C, III-D) uses VPoser (Pavlakos et al., CVPR 2019; release V02_05 of
``human_body_prior``) twice: its encoder ``E`` maps a body pose to a 32-d latent kept close to 0
during fine-tuning, and AirPose+ optimises the latent ``v`` and decodes the pose as
``theta = D(v)``. This module has the same layers, in the same order and with the same parameter
names, as that release, so the official V02_05 weights load into it unchanged
(:func:`airpose_lib.prior.checkpoint.load_prior` with ``source="vposer"``):

``encoder_net``  0 flatten, 1 BatchNorm1d(63), 2 Linear(63, 512), 3 LeakyReLU, 4 BatchNorm1d(512),
                 5 Dropout(0.1), 6 Linear(512, 512), 7 Linear(512, 512) (no nonlinearity between
                 6 and 7, as in the release), 8 Gaussian head: ``mu`` Linear(512, 32) and
                 ``logvar`` Linear(512, 32); the head's scale is ``softplus(logvar)`` (the name is
                 the release's, the value is a standard deviation, not a log-variance).
``decoder_net``  0 Linear(32, 512), 1 LeakyReLU, 2 Dropout(0.1), 3 Linear(512, 512), 4 LeakyReLU,
                 5 Linear(512, 126), 6 continuous-6D decoder: each joint's 6 numbers reshaped to
                 (3, 2) are the first two columns of its rotation, orthonormalised by Gram-Schmidt
                 (the kit's :func:`~airpose_lib.geometry.rot6d_to_matrix` convention).

The encoder reads axis-angle body poses (joints 1..21 of SMPL-X, radians); the decoder returns
rotation matrices and axis-angle.
"""
from __future__ import annotations

import torch
from torch import Tensor, nn
from torch.distributions import Normal
from torch.nn import functional as F

from airpose_lib.geometry import matrix_to_axis_angle, rot6d_to_matrix

__all__ = ["VPoser", "NUM_JOINTS", "LATENT_DIM", "NUM_NEURONS"]

NUM_JOINTS = 21  # SMPL-X body joints 1..21 (the root is not part of the prior)
LATENT_DIM = 32
NUM_NEURONS = 512


class _Flatten(nn.Module):
    """``(B, ...) -> (B, prod(...))``; parameter-free, it only holds index 0 of ``encoder_net``."""

    def forward(self, x: Tensor) -> Tensor:
        return x.reshape(x.shape[0], -1)


class _GaussianHead(nn.Module):
    """Diagonal Gaussian ``N(mu(x), softplus(logvar(x)))`` (attribute names of the release)."""

    def __init__(self, num_in: int, latent_dim: int) -> None:
        super().__init__()
        self.mu = nn.Linear(num_in, latent_dim)
        self.logvar = nn.Linear(num_in, latent_dim)

    def forward(self, x: Tensor) -> Normal:
        # validate_args=False: a saturated softplus may round to 0 in float32; that must not raise.
        return Normal(self.mu(x), F.softplus(self.logvar(x)), validate_args=False)


class _Rot6dToMatrix(nn.Module):
    """``(B, 21 * 6) -> (B, 21, 3, 3)`` by Gram-Schmidt of each joint's ``(3, 2)`` reshape."""

    def forward(self, x: Tensor) -> Tensor:
        return rot6d_to_matrix(x.reshape(x.shape[0], -1, 6))


class VPoser(nn.Module):
    """VPoser v2 (V02_05 layout): encoder to a 32-d Gaussian, decoder to 21 rotations.

    Args:
        num_neurons: hidden width (512 in the release).
        latent_dim: latent size (32 in the release).
    """

    def __init__(self, num_neurons: int = NUM_NEURONS, latent_dim: int = LATENT_DIM) -> None:
        super().__init__()
        self.num_neurons = int(num_neurons)
        self.latent_dim = int(latent_dim)
        n_in = NUM_JOINTS * 3
        self.encoder_net = nn.Sequential(
            _Flatten(),
            nn.BatchNorm1d(n_in),
            nn.Linear(n_in, num_neurons),
            nn.LeakyReLU(),
            nn.BatchNorm1d(num_neurons),
            nn.Dropout(0.1),
            nn.Linear(num_neurons, num_neurons),
            nn.Linear(num_neurons, num_neurons),
            _GaussianHead(num_neurons, latent_dim),
        )
        self.decoder_net = nn.Sequential(
            nn.Linear(latent_dim, num_neurons),
            nn.LeakyReLU(),
            nn.Dropout(0.1),
            nn.Linear(num_neurons, num_neurons),
            nn.LeakyReLU(),
            nn.Linear(num_neurons, NUM_JOINTS * 6),
            _Rot6dToMatrix(),
        )

    # -- encoder / decoder ------------------------------------------------------------------------
    def encode(self, pose_body: Tensor) -> Normal:
        """Posterior ``q(z | theta)``.

        Args:
            pose_body: ``(B, 21, 3)`` or ``(B, 63)`` axis-angle body pose, radians. In training
                mode the batch norms need B > 1.

        Returns:
            ``Normal`` with ``loc``/``scale`` of shape ``(B, latent_dim)``.
        """
        if pose_body.shape[-1] != NUM_JOINTS * 3 and tuple(pose_body.shape[-2:]) != (NUM_JOINTS, 3):
            raise ValueError(f"encode expects (B, 21, 3) or (B, 63) axis-angle, got {tuple(pose_body.shape)}")
        return self.encoder_net(pose_body)

    def decode_matrot(self, z: Tensor) -> Tensor:
        """Decoded rotations only (what fitting needs): ``z (B, latent_dim) -> (B, 21, 3, 3)``."""
        if z.ndim != 2 or z.shape[-1] != self.latent_dim:
            raise ValueError(f"decode expects (B, {self.latent_dim}) latents, got {tuple(z.shape)}")
        return self.decoder_net(z)

    def decode(self, z: Tensor) -> dict[str, Tensor]:
        """Decode latents into a body pose.

        Args:
            z: ``(B, latent_dim)``.

        Returns:
            ``pose_body`` ``(B, 21, 3)`` axis-angle and ``pose_body_matrot`` ``(B, 21, 3, 3)``.
        """
        R = self.decode_matrot(z)
        return {"pose_body": matrix_to_axis_angle(R), "pose_body_matrot": R}

    def forward(self, pose_body: Tensor) -> dict[str, Tensor | Normal]:
        """Encode, draw ``z ~ q(z | theta)`` with the reparameterisation trick, decode.

        Args:
            pose_body: ``(B, 21, 3)`` or ``(B, 63)`` axis-angle.

        Returns:
            :meth:`decode`'s dict plus ``q_z`` (the posterior), ``z_mean`` and ``z_std``
            ``(B, latent_dim)``.
        """
        q_z = self.encode(pose_body)
        out: dict[str, Tensor | Normal] = dict(self.decode(q_z.rsample()))
        out.update(q_z=q_z, z_mean=q_z.loc, z_std=q_z.scale)
        return out

    @torch.no_grad()
    def sample(self, n: int, seed: int | None = None) -> dict[str, Tensor]:
        """Decode ``n`` latents drawn from the prior ``N(0, I)``.

        Args:
            n: number of poses.
            seed: seed of a private generator (same seed, same poses); None draws from torch's
                global generator.

        Returns:
            :meth:`decode`'s dict, ``(n, 21, 3)`` and ``(n, 21, 3, 3)``.
        """
        ref = next(self.parameters())
        gen = torch.Generator(device=ref.device).manual_seed(int(seed)) if seed is not None else None
        z = torch.randn(n, self.latent_dim, generator=gen, device=ref.device, dtype=ref.dtype)
        was_training = self.training
        self.eval()  # dropout off
        try:
            return self.decode(z)
        finally:
            self.train(was_training)
