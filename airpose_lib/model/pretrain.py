r"""A backbone pretrained once per profile on a variant-neutral objective (the CPU protocol).

The paper starts every variant from ImageNet weights, which cannot be downloaded here. The kit
gives all four variants the same substitute starting point instead: one ResNet trained on the
kit's own crops to read what every variant needs from the image and nothing that tells the
variants apart -- no crop vector P, no translation, no exchange between views. Its heads are
linear in the pooled feature, like the variants' regressor (fc1 and fc2 have no nonlinearity
between them), so what the heads read, the variants can read too.

Heads on the feature ``f (N, C)``:

==============  ==============  =================================================================
``heading``     (N, n_bins)     the body's heading in the camera (azimuth of the body's forward
                                axis in the camera's x-z plane) as classes
                                (:func:`airpose_lib.losses.pretrain.heading_bin`): a classification does
                                not average the front and back modes of a small, ambiguous
                                person the way a mean-squared rotation regression does
``phi6d``       (N, 6)          root rotation in the camera (6D, first two columns of R)
``theta6d``     (N, 21, 6)      body pose
``beta``        (N, 10)         shape
``j3d``         (N, 22, 3)      model-frame body joints (identity root, zero translation), metres
``j2d``         (N, 22, 2)      body joints in the crop, normalised to [-1, 1]
``stature``     (N, 1)          with ``body_scalars``: the T-posed stature, standardised
                                (:class:`~airpose_lib.losses.pretrain.PretrainLossConfig`)
``female``      (N, 1)          with ``body_scalars``: logit of the subject being female
==============  ==============  =================================================================
"""
from __future__ import annotations

import math

from torch import Tensor, nn

from airpose_lib.config_fields import Range

from .backbone import ResNet, build_backbone

__all__ = ["PretrainNet", "PRETRAIN_HEADS", "BODY_SCALAR_HEADS"]

#: Output widths of the linear heads (besides ``heading``, whose width is the number of bins).
PRETRAIN_HEADS: dict[str, tuple[int, ...]] = {
    "phi6d": (6,), "theta6d": (21, 6), "beta": (10,), "j3d": (22, 3), "j2d": (22, 2),
}
#: The heads that ``body_scalars=True`` adds (after the others, so that without them the network,
#: its random initialisation included, is the one of the earlier backbones).
BODY_SCALAR_HEADS: dict[str, tuple[int, ...]] = {"stature": (1,), "female": (1,)}


class PretrainNet(nn.Module):
    """ResNet + linear heads of the variant-neutral objective.

    Args:
        backbone: ``"resnet18"`` / ``"resnet34"`` / ``"resnet50"`` or a :class:`ResNet`.
        n_heading_bins: classes of the heading head.
        channels_last: NHWC backbone (faster on CPU).
        body_scalars: add the ``stature`` and ``female`` heads (:data:`BODY_SCALAR_HEADS`).
    """

    #: The numbers the keyword arguments accept (a training config checks them before it runs).
    OPTION_RANGES = {"n_heading_bins": Range(ge=1)}

    def __init__(self, backbone: str | ResNet = "resnet18", n_heading_bins: int = 12,
                 channels_last: bool = False, body_scalars: bool = False) -> None:
        super().__init__()
        self.backbone = backbone if isinstance(backbone, ResNet) else build_backbone(backbone, channels_last)
        C = self.backbone.feature_dim
        self.n_heading_bins = int(n_heading_bins)
        self.heads = nn.ModuleDict({"heading": nn.Linear(C, self.n_heading_bins)})
        self.head_shapes = {**PRETRAIN_HEADS, **(BODY_SCALAR_HEADS if body_scalars else {})}
        for name, shape in self.head_shapes.items():
            self.heads[name] = nn.Linear(C, math.prod(shape))

    def forward(self, images: Tensor) -> dict[str, Tensor]:
        """Args: images ``(N, 3, S, S)`` normalised crops. Returns the heads' outputs (module doc)
        and ``feature (N, C)``."""
        f = self.backbone(images)
        out = {"feature": f, "heading": self.heads["heading"](f)}
        for name, shape in self.head_shapes.items():
            out[name] = self.heads[name](f).unflatten(-1, shape)
        return out
