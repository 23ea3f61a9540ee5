r"""The four networks of the paper's ablation (Table I) on one shared trunk.

=====================  ==========  ==========  ==============================================
variant                multi-view  full cam    fc1 input (ResNet-50 feature, 2048)
=====================  ==========  ==========  ==============================================
``baseline``           no          no          2048 + 132 pose + 10 beta + 3 cam        = 2193
``multiview``          yes         no          2048 + 3 cam + 132 + 10 + 136 other      = 2329
``fullcam``            no          yes         2048 + 3 P + 3 tau + 132 + 10            = 2196
``airpose``            yes         yes         2048 + 3 P + 3 tau + 132 + 10 + 136 other = 2332
=====================  ==========  ==========  ==============================================

The order of the fc1 input is the order of this table (feature first); it is also the order of
the official code, so its regressor weights load unchanged (:func:`convert_official_state_dict`).

Parameters per view (the regressor's *state*): root rotation ``phi6d (6)``, body pose
``theta6d (126)`` = 21 joints x 6D, ``beta (10)`` and either the weak-perspective crop camera
``cam = [s, tx, ty]`` (Baseline, Multi-view) or the normalised translation ``tau / 20``
(Fullcam, AirPose; the paper's depth normalisation, initial ``tau = [0, 0, 10] m`` is fed as
``[0, 0, 0.5]`` and the regressed value is multiplied by 20).

Translation. Fullcam and AirPose regress the root translation ``tau`` directly in the drone's
camera frame (normalised by 20 m), as the official networks do (``copenet_singleview.py`` /
``copenet_twoview.py``: the regressed ``pred_smpltrans`` is compared with the camera-frame ground
truth); they do not regress the crop-camera translation of the paper's eq. (1)-(2) and map it back.
The crop vector P in the input is what lets them do so. The mapping of eq. (1)-(2) is in
:func:`airpose_lib.geometry.crop_to_full_translation` for whoever wants the paper's form; because
the regressed value is metric and camera-frame, a camera with another focal length than the
training one needs a rule that maps it to the training camera (see the real-data section).

Exchange (Multi-view, AirPose): after each iteration a view sends its *message*: its 126 body
pose values and 10 betas (136 float32, 544 bytes). Iteration 1 takes the mean parameters as the
"other view"; iterations 2 and 3 take the other view's previous message. With more than two views
each view takes the mean of the other views' messages (two views = the paper). Root rotation,
translation, camera and P never leave the view. Baseline and Fullcam run each view on its own.

Initial (mean) parameters: root rotation 180 degrees about x (in the OpenCV camera, y down and z
forward, that turns the SMPL-X body, Y up and facing +Z, upright and facing the camera), body
pose identity (zeros in axis-angle), betas 0, weak camera ``[0.9, 0, 0]`` as SPIN. HMR/SPIN start
from a *mean pose* file (``smpl_mean_params.npz``); that file is distributed with SPIN's data
download behind its licence and is not fetched by the kit. Pass ``mean_params=<path>`` to use it
(keys ``pose`` = at least 22 x 6D, root first, column convention; ``shape``; optional ``cam``).
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import Tensor, nn

from airpose_lib.config_fields import Range

from ..geometry import axis_angle_to_rot6d, weak_perspective_to_translation
from .backbone import ResNet, build_backbone
from .message import BETA_DIM, MESSAGE_DIM, NUM_BODY_JOINTS, THETA_DIM
from .regressor import IterativeRegressor

__all__ = [
    "VariantSpec",
    "VARIANTS",
    "NUM_BODY_JOINTS",
    "THETA_DIM",
    "BETA_DIM",
    "MESSAGE_DIM",
    "TAU_SCALE",
    "TAU_INIT",
    "WEAK_CAM_INIT",
    "MeanParams",
    "default_mean_params",
    "load_mean_params",
    "fc1_input_width",
    "fuse_messages",
    "STATE_DIM",
    "state_keys",
    "unpack_state",
    "decode_state",
    "AirPoseNet",
    "build_model",
    "convert_official_state_dict",
]

TAU_SCALE = 20.0  # metres; "maximum depth" the paper normalises by
TAU_INIT = (0.0, 0.0, 10.0)  # metres
WEAK_CAM_INIT = (0.9, 0.0, 0.0)


@dataclass(frozen=True)
class VariantSpec:
    """Which of the two AirPose ingredients a variant uses."""

    name: str
    multiview: bool  # exchanges theta and beta with the other views
    fullcam: bool  # P as input, full-perspective translation tau instead of a weak camera


VARIANTS: dict[str, VariantSpec] = {
    "baseline": VariantSpec("baseline", multiview=False, fullcam=False),
    "multiview": VariantSpec("multiview", multiview=True, fullcam=False),
    "fullcam": VariantSpec("fullcam", multiview=False, fullcam=True),
    "airpose": VariantSpec("airpose", multiview=True, fullcam=True),
}


def _spec(variant: str | VariantSpec) -> VariantSpec:
    if isinstance(variant, VariantSpec):
        return variant
    try:
        return VARIANTS[variant]
    except KeyError:
        raise ValueError(f"unknown variant {variant!r}; choose one of {sorted(VARIANTS)}") from None


def fc1_input_width(variant: str | VariantSpec, feature_dim: int = 2048) -> int:
    """Width of the regressor's fc1 input: feature + own parameters (+ P) (+ other's message).

    Args:
        variant: ``"baseline"``, ``"multiview"``, ``"fullcam"`` or ``"airpose"``.
        feature_dim: backbone feature width (2048 for ResNet-50, 512 for ResNet-18/34).
    """
    spec = _spec(variant)
    width = feature_dim + 6 + THETA_DIM + BETA_DIM + 3  # feature, phi, theta, beta, cam or tau
    if spec.fullcam:
        width += 3  # P
    if spec.multiview:
        width += MESSAGE_DIM
    return width


STATE_DIM = 6 + THETA_DIM + BETA_DIM + 3  # 145: phi6d, theta6d, beta, tau_n or cam


def state_keys(variant: str | VariantSpec) -> tuple[str, ...]:
    """Order of a view's packed state: phi6d (6), theta6d (126), beta (10), then tau_n (3, =
    tau / 20) for the full-camera variants or cam (3) for the weak-camera ones."""
    return ("phi6d", "theta6d", "beta", "tau_n" if _spec(variant).fullcam else "cam")


def unpack_state(packed: Tensor, variant: str | VariantSpec) -> dict[str, Tensor]:
    """Packed state ``(..., 145)`` -> dict of ``(..., 6)``, ``(..., 126)``, ``(..., 10)``, ``(..., 3)``."""
    return dict(zip(state_keys(variant), torch.split(packed, (6, THETA_DIM, BETA_DIM, 3), dim=-1)))


def decode_state(state: Mapping[str, Tensor], variant: str | VariantSpec) -> dict[str, Tensor]:
    """State -> network outputs: phi6d (..., 6), theta6d (..., 21, 6), beta (..., 10), and
    tau (..., 3) metres (full camera: 20 x the regressed tau_n) or cam (..., 3)."""
    out = {
        "phi6d": state["phi6d"],
        "theta6d": state["theta6d"].reshape(*state["theta6d"].shape[:-1], NUM_BODY_JOINTS, 6),
        "beta": state["beta"],
    }
    if _spec(variant).fullcam:
        out["tau"] = state["tau_n"] * TAU_SCALE
    else:
        out["cam"] = state["cam"]
    return out


@dataclass(frozen=True)
class MeanParams:
    """Initial parameters of the iteration (numpy float32)."""

    phi6d: np.ndarray  # (6,)
    theta6d: np.ndarray  # (126,)
    beta: np.ndarray  # (10,)
    cam: np.ndarray  # (3,) weak camera [s, tx, ty]
    tau: np.ndarray  # (3,) metres


def default_mean_params() -> MeanParams:
    """Root 180 degrees about x, identity body pose, zero betas, cam [0.9, 0, 0], tau [0, 0, 10] m."""
    phi = axis_angle_to_rot6d(torch.tensor([np.pi, 0.0, 0.0], dtype=torch.float64))
    theta = axis_angle_to_rot6d(torch.zeros(NUM_BODY_JOINTS, 3, dtype=torch.float64))
    return MeanParams(
        phi6d=phi.numpy().astype(np.float32),
        theta6d=theta.reshape(-1).numpy().astype(np.float32),
        beta=np.zeros(BETA_DIM, np.float32),
        cam=np.asarray(WEAK_CAM_INIT, np.float32),
        tau=np.asarray(TAU_INIT, np.float32),
    )


def load_mean_params(path: str | Path) -> MeanParams:
    """Mean parameters from an HMR/SPIN-style ``.npz``.

    Keys: ``pose`` (at least 132 = 22 x 6D, root first, then the body joints in SMPL order,
    which are the 21 SMPL-X body joints; SPIN's file has 24 x 6D, the last two are ignored),
    ``shape`` (at least 10) and optionally ``cam`` (3; default ``[0.9, 0, 0]``) and ``tau``
    (metres; default ``[0, 0, 10]``).
    """
    default = default_mean_params()
    with np.load(path) as data:
        pose = np.asarray(data["pose"], np.float32).reshape(-1)
        if pose.size < 6 + THETA_DIM:
            raise ValueError(f"{path}: 'pose' has {pose.size} values, need at least {6 + THETA_DIM}")
        shape = np.asarray(data["shape"], np.float32).reshape(-1)[:BETA_DIM]
        cam = np.asarray(data["cam"], np.float32).reshape(3) if "cam" in data.files else default.cam
        tau = np.asarray(data["tau"], np.float32).reshape(3) if "tau" in data.files else default.tau
    return MeanParams(phi6d=pose[:6].copy(), theta6d=pose[6:6 + THETA_DIM].copy(), beta=shape,
                      cam=cam, tau=tau)


def fuse_messages(messages: Tensor) -> Tensor:
    """For every view, the mean of the *other* views' messages.

    Args:
        messages: ``(..., V, 136)`` with ``V >= 2``.

    Returns:
        ``(..., V, 136)``; with two views this is the other view's message exactly (a swap).
    """
    V = messages.shape[-2]
    if V < 2:
        raise ValueError("fuse_messages needs at least two views")
    others = torch.tensor([[u for u in range(V) if u != v] for v in range(V)], device=messages.device)
    # (..., V, V-1, 136): gathered, then averaged in the same order as the staged API does.
    return messages[..., others, :].mean(dim=-2)


class AirPoseNet(nn.Module):
    """Backbone + iterative regressor for one of the four variants; all views share all weights.

    Args:
        variant: ``"baseline"``, ``"multiview"``, ``"fullcam"`` or ``"airpose"``.
        backbone: ``"resnet50"`` (paper), ``"resnet34"``, ``"resnet18"``, or a :class:`ResNet`.
        mean_params: None (defaults of :func:`default_mean_params`), a path to a mean-parameter
            ``.npz`` (:func:`load_mean_params`) or a :class:`MeanParams`.
        num_iterations: regressor iterations (3 in the paper; stage k of a drone is iteration k).
        dropout: dropout after fc1 and fc2.
        channels_last: NHWC backbone (faster CPU training).
        activation: the regressor trunk's nonlinearity, ``"none"`` (the paper's) or ``"relu"``
            (:class:`~airpose_lib.model.regressor.IterativeRegressor`).
    """

    #: The numbers the keyword arguments accept (a training config checks them before it runs).
    OPTION_RANGES = {"num_iterations": Range(ge=1), "dropout": Range(ge=0, le=1)}

    def __init__(self, variant: str = "airpose", backbone: str | ResNet = "resnet50",
                 mean_params: str | Path | MeanParams | None = None, num_iterations: int = 3,
                 dropout: float = 0.5, channels_last: bool = False, activation: str = "none"):
        super().__init__()
        self.spec = _spec(variant)
        if num_iterations < 1:
            raise ValueError("num_iterations must be >= 1")
        self.num_iterations = int(num_iterations)
        self.backbone = backbone if isinstance(backbone, ResNet) else build_backbone(backbone, channels_last)
        self.regressor = IterativeRegressor(
            fc1_input_width(self.spec, self.backbone.feature_dim),
            pose_dim=(3 if self.spec.fullcam else 0) + 6 + THETA_DIM,  # tau first, as the official code
            shape_dim=BETA_DIM,
            cam_dim=0 if self.spec.fullcam else 3,
            dropout=dropout,
            activation=activation,
        )
        if mean_params is None:
            mean = default_mean_params()
        elif isinstance(mean_params, MeanParams):
            mean = mean_params
        else:
            mean = load_mean_params(mean_params)
        as_t = lambda a: torch.as_tensor(np.asarray(a, np.float32))  # noqa: E731
        self.register_buffer("init_phi6d", as_t(mean.phi6d))
        self.register_buffer("init_theta6d", as_t(mean.theta6d))
        self.register_buffer("init_beta", as_t(mean.beta))
        if self.spec.fullcam:
            self.register_buffer("init_tau_n", as_t(mean.tau) / TAU_SCALE)
        else:
            self.register_buffer("init_cam", as_t(mean.cam))

    # -- small pieces, shared by the batched forward, the staged API and the ONNX export --------

    @property
    def variant(self) -> str:
        return self.spec.name

    @property
    def state_keys(self) -> tuple[str, ...]:
        """Order of the packed per-view state (see :func:`state_keys`)."""
        return state_keys(self.spec)

    def features(self, images: Tensor) -> Tensor:
        """Backbone features. Args: images ``(N, 3, S, S)``. Returns ``(N, C)``."""
        return self.backbone(images)

    def features_from(self, h: Tensor, cut: str) -> Tensor:
        """Backbone features from cached block inputs (:meth:`ResNet.forward_from`).
        Args: h ``(B, V, C, h, w)`` the input of block ``cut`` for each view. Returns ``(B, V, feature_dim)``."""
        return self.backbone.forward_from(h.flatten(0, 1), cut).unflatten(0, h.shape[:2])

    def initial_state(self, batch_shape: tuple[int, ...]) -> dict[str, Tensor]:
        """Mean parameters expanded to ``batch_shape``: phi6d (..., 6), theta6d (..., 126),
        beta (..., 10), and tau_n (..., 3) (= tau / 20) or cam (..., 3)."""
        return {k: getattr(self, f"init_{k}").expand(*batch_shape, -1) for k in self.state_keys}

    def mean_message(self, batch_shape: tuple[int, ...]) -> Tensor:
        """The "other view" input of iteration 1: mean theta6d and beta, ``(*batch_shape, 136)``."""
        return torch.cat((self.init_theta6d, self.init_beta)).expand(*batch_shape, -1)

    @staticmethod
    def message(state: Mapping[str, Tensor]) -> Tensor:
        """What a view sends after an iteration: ``cat(theta6d (..., 126), beta (..., 10))``."""
        return torch.cat((state["theta6d"], state["beta"]), dim=-1)

    def iterate(self, feat: Tensor, P: Tensor | None, state: Mapping[str, Tensor],
                other: Tensor | None = None) -> dict[str, Tensor]:
        """One regressor iteration for one view (any leading batch dims).

        Args:
            feat: ``(..., C)`` backbone feature.
            P: ``(..., 3)`` crop vector ``[bx, by, s]`` (Fullcam, AirPose; ignored otherwise).
            state: current parameters (see :meth:`initial_state`).
            other: ``(..., 136)`` fused message of the other views (Multi-view, AirPose; ignored
                otherwise).

        Returns:
            The updated state (residual update of every entry).
        """
        spec = self.spec
        parts = [feat]
        if spec.fullcam:
            if P is None:
                raise ValueError(f"variant {spec.name!r} needs the crop vector P")
            parts += [P.to(feat.dtype), state["tau_n"]]
        elif spec.multiview:
            parts.append(state["cam"])
        parts += [state["phi6d"], state["theta6d"], state["beta"]]
        if spec.multiview:
            if other is None:
                raise ValueError(f"variant {spec.name!r} needs the other views' message")
            parts.append(other)
        elif not spec.fullcam:
            parts.append(state["cam"])
        dpose, dbeta, dcam = self.regressor(torch.cat(parts, dim=-1))
        new = {"beta": state["beta"] + dbeta}
        if spec.fullcam:
            new["tau_n"] = state["tau_n"] + dpose[..., :3]
            dpose = dpose[..., 3:]
        else:
            new["cam"] = state["cam"] + dcam
        new["phi6d"] = state["phi6d"] + dpose[..., :6]
        new["theta6d"] = state["theta6d"] + dpose[..., 6:]
        return new

    def decode(self, state: Mapping[str, Tensor]) -> dict[str, Tensor]:
        """State -> network outputs (:func:`decode_state`)."""
        return decode_state(state, self.spec)

    def pack_state(self, state: Mapping[str, Tensor]) -> Tensor:
        """Concatenate a state into ``(..., 145)`` in :attr:`state_keys` order."""
        return torch.cat([state[k] for k in self.state_keys], dim=-1)

    def unpack_state(self, packed: Tensor) -> dict[str, Tensor]:
        """Inverse of :meth:`pack_state` (:func:`unpack_state`)."""
        return unpack_state(packed, self.spec)

    # -- the batched forward ------------------------------------------------------------------

    def regress(self, feat: Tensor, P: Tensor | None = None) -> dict:
        """The iterative regressor with the views' exchange, on backbone features.

        Args:
            feat: ``(B, V, C)`` features of the V views' crops.
            P: ``(B, V, 3)`` crop vectors (full-camera variants).

        Returns:
            :meth:`decode` of the final state, plus ``messages``: the (B, V, 136) message of each
            iteration.
        """
        B, V = feat.shape[:2]
        state = self.initial_state((B, V))
        other = self.mean_message((B, V)) if self.spec.multiview else None
        messages = []
        for k in range(self.num_iterations):
            if k > 0 and self.spec.multiview and V > 1:
                other = fuse_messages(messages[-1])
            # V == 1 with a multi-view variant: the lone view keeps the mean message, as a drone
            # whose partner never answers.
            state = self.iterate(feat, P, state, other)
            messages.append(self.message(state))
        out = self.decode(state)
        out["messages"] = messages
        return out

    def forward(self, images: Tensor, P: Tensor | None = None, K: Tensor | None = None) -> dict:
        """All views of a batch at once.

        Args:
            images: ``(B, V, 3, S, S)`` normalised crops.
            P: ``(B, V, 3)`` crop vectors (needed by Fullcam and AirPose; for the weak-camera
                variants only used to give ``tau`` when K is given).
            K: optional ``(B, V, 3, 3)`` full-image intrinsics; for Baseline and Multi-view it
                adds ``tau`` computed from the weak camera (``geometry.weak_perspective_to_translation``).

        Returns:
            dict with phi6d (B, V, 6), theta6d (B, V, 21, 6), beta (B, V, 10), tau (B, V, 3)
            metres (Fullcam/AirPose always; weak variants only with K), cam (B, V, 3) (weak
            variants), messages (list over iterations of (B, V, 136): what each view sent after
            that iteration; the first ``num_iterations - 1`` are the ones actually exchanged) and
            input_size (int S).
        """
        if images.dim() != 5:
            raise ValueError(f"images must be (B, V, 3, S, S), got {tuple(images.shape)}")
        B, V = images.shape[:2]
        feat = self.features(images.flatten(0, 1)).unflatten(0, (B, V))
        out = self.regress(feat, P)
        out["input_size"] = int(images.shape[-1])
        if not self.spec.fullcam and K is not None and P is not None:
            out["tau"] = weak_perspective_to_translation(out["cam"], P.to(out["cam"].dtype),
                                                         K.to(out["cam"].dtype), images.shape[-1])
        return out


def build_model(variant: str = "airpose", backbone: str = "resnet50", **kwargs) -> AirPoseNet:
    """Shorthand for :class:`AirPoseNet` (same arguments)."""
    return AirPoseNet(variant=variant, backbone=backbone, **kwargs)


_BACKBONE_PREFIXES = ("conv1.", "bn1.", "layer1.", "layer2.", "layer3.", "layer4.")
_REGRESSOR_PREFIXES = ("fc1.", "fc2.", "decpose.", "decshape.", "deccam.")


def convert_official_state_dict(state_dict: Mapping[str, Tensor], variant: str) -> dict[str, Tensor]:
    """Rename an official AirPose / SPIN-style checkpoint's keys to :class:`AirPoseNet`'s.

    The official networks keep backbone and regressor in one module (``conv1``, ``layer*``,
    ``fc1``, ``decpose``, ...; prefixed ``model.`` in the Lightning checkpoint) and their mean
    parameters as ``init_pose (1, 144)``, ``init_shape (1, 10)``, ``init_cam (1, 3)``. The
    unused ``deccam`` of the full-camera variants and everything else (body-model buffers) is
    dropped. Load the result with ``model.load_state_dict(..., strict=True)``.
    """
    fullcam = _spec(variant).fullcam
    out: dict[str, Tensor] = {}
    for key, value in state_dict.items():
        for prefix in ("state_dict.", "model.", "module."):
            if key.startswith(prefix):
                key = key[len(prefix):]
        if key.startswith(_BACKBONE_PREFIXES):
            out["backbone." + key] = value
        elif key.startswith(_REGRESSOR_PREFIXES):
            if not (fullcam and key.startswith("deccam.")):
                out["regressor." + key] = value
        elif key == "init_pose":
            pose = value.reshape(-1)
            out["init_phi6d"] = pose[:6].clone()
            out["init_theta6d"] = pose[6:6 + THETA_DIM].clone()
        elif key == "init_shape":
            out["init_beta"] = value.reshape(-1)[:BETA_DIM].clone()
        elif key == "init_cam" and not fullcam:
            out["init_cam"] = value.reshape(-1).clone()
    if fullcam:
        out.setdefault("init_tau_n", torch.tensor(TAU_INIT) / TAU_SCALE)
    return out
