"""HMR-style iterative regressor: the trunk shared by all four AirPose variants.

One iteration maps the concatenated input (image feature, current parameters and, for the
multi-view variants, the other view's message) to residual updates of the parameters:

    h = drop2(fc2(drop1(fc1(x))))        (no nonlinearity between, as HMR/SPIN)
    delta_pose = decpose(h), delta_beta = decshape(h), delta_cam = deccam(h)

``activation="relu"`` (not the paper's) puts a ReLU after fc1 and after fc2, each before its
dropout. HMR, SPIN and AirPose train their backbone with the regressor, so its last blocks shape
the feature for this linear trunk; a frozen backbone cannot, and a ReLU gives the trunk the
nonlinearity those blocks would have supplied (a nonlinear readout of the cpu profile's frozen
features finds the root orientation that a linear one misses: ``docs/findings.md``, the root probes).

The decoder heads start Xavier-uniform with gain 0.01, so the first updates are small and the
iteration starts close to the mean parameters. The layer names (``fc1``, ``fc2``, ``decpose``,
``decshape``, ``deccam``) are those of HMR/SPIN and the official AirPose code, so their checkpoints
map onto this module by key prefix only (:func:`airpose_lib.model.variants.convert_official_state_dict`).
"""
from __future__ import annotations

from torch import Tensor, nn

from airpose_lib.errors import ConfigError

__all__ = ["IterativeRegressor", "HIDDEN_WIDTH", "DECODER_GAIN", "ACTIVATIONS"]

HIDDEN_WIDTH = 1024
DECODER_GAIN = 0.01
#: The trunk's nonlinearity after fc1 and fc2: ``"none"`` (HMR/SPIN/AirPose) or ``"relu"``.
ACTIVATIONS = ("none", "relu")


class IterativeRegressor(nn.Module):
    """fc1(in -> 1024), Dropout, fc2(1024 -> 1024), Dropout, then residual decoder heads.

    Args:
        in_features: width of the fc1 input (variant-specific, see ``variants.fc1_input_width``).
        pose_dim: output width of ``decpose`` (132 = root 6D + 21 x 6D, or 135 with tau first).
        shape_dim: output width of ``decshape`` (10 betas).
        cam_dim: output width of ``deccam`` (3 for the weak-perspective camera, 0 = no such head).
        hidden: hidden width (1024).
        dropout: dropout probability after fc1 and fc2 (0.5).
        activation: ``"none"`` (the paper's linear trunk) or ``"relu"`` (module docstring).

    Raises:
        ConfigError: an activation not in :data:`ACTIVATIONS` (a ``ValueError``).
    """

    def __init__(self, in_features: int, pose_dim: int, shape_dim: int = 10, cam_dim: int = 0,
                 hidden: int = HIDDEN_WIDTH, dropout: float = 0.5, activation: str = "none"):
        super().__init__()
        if activation not in ACTIVATIONS:
            raise ConfigError(f"model.activation must be one of {', '.join(ACTIVATIONS)}, got {activation!r}")
        self.in_features = in_features
        # parameter-free: the state dict (and the official checkpoints' keys) stay the same
        self.act = nn.ReLU() if activation == "relu" else nn.Identity()
        self.fc1 = nn.Linear(in_features, hidden)
        self.drop1 = nn.Dropout(dropout)
        self.fc2 = nn.Linear(hidden, hidden)
        self.drop2 = nn.Dropout(dropout)
        self.decpose = nn.Linear(hidden, pose_dim)
        self.decshape = nn.Linear(hidden, shape_dim)
        self.deccam = nn.Linear(hidden, cam_dim) if cam_dim else None
        for head in (self.decpose, self.decshape, self.deccam):
            if head is not None:
                # Only the weights, as HMR/SPIN: the biases keep PyTorch's default init.
                nn.init.xavier_uniform_(head.weight, gain=DECODER_GAIN)

    def forward(self, x: Tensor) -> tuple[Tensor, Tensor, Tensor | None]:
        """One iteration.

        Args:
            x: ``(..., in_features)``.

        Returns:
            ``delta_pose (..., pose_dim)``, ``delta_shape (..., shape_dim)`` and
            ``delta_cam (..., cam_dim)`` (None without a camera head).
        """
        h = self.drop2(self.act(self.fc2(self.drop1(self.act(self.fc1(x))))))
        dcam = self.deccam(h) if self.deccam is not None else None
        return self.decpose(h), self.decshape(h), dcam
