"""The official AirPose checkpoints <-> the kit's :class:`~airpose_lib.model.variants.AirPoseNet`.

Supersedes :func:`airpose_lib.model.variants.convert_official_state_dict` with an exact key map,
a full accounting of every tensor and variant detection.

The four official networks (robot-perception-group/AirPose, ``copenet/src/copenet/``) are
PyTorch-Lightning modules (``hmr.py``, ``muhmr.py``, ``copenet_singleview.py``,
``copenet_twoview.py``) whose only sub-module is ``self.model``, built by
``models/model_hmr.py``, ``model_muhmr.py``, ``model_copenet_singleview.py`` and
``model_copenet.py``; the real-data modules (``copenet_real/src/copenet_real/hmr.py``,
``copenet_twoview.py``) have the same attributes (VPoser and SMPL-X are module globals there,
not in the checkpoint). Their Lightning checkpoints are ``{"state_dict": {...}, "epoch", "global_step",
"optimizer_states", "hyper_parameters", ...}`` with these tensors (``model.`` prefix):

======================================= ============================== =================================
official key                            shape                          kit key
======================================= ============================== =================================
``conv1``, ``bn1``, ``layer1-4.*``      torchvision ResNet names       ``backbone.<same>``
``fc1.weight`` / ``.bias``              ``(1024, F + extra)``          ``regressor.fc1.*``
``fc2.*``                               ``(1024, 1024)``               ``regressor.fc2.*``
``decpose.*``                           ``(132 or 135, 1024)``         ``regressor.decpose.*``
``decshape.*``                          ``(10, 1024)``                 ``regressor.decshape.*``
``deccam.*``                            ``(3, 1024)``                  ``regressor.deccam.*`` (weak
                                                                       camera); unused by the
                                                                       full-camera networks: ignored
``init_pose``                           ``(1, 144)`` SPIN mean, 24x6D  ``init_phi6d`` = [:6],
                                                                       ``init_theta6d`` = [6:132];
                                                                       [132:] (SMPL hands) ignored
``init_shape``                          ``(1, 10)``                    ``init_beta``
``init_cam``                            ``(1, 3)`` (not singleview)    ``init_cam`` (weak camera);
                                                                       ignored by ``copenet_twoview``
``init_position``                       ``(1, 3)`` singleview only     ignored: holds ``[0, 0, 200]``
                                                                       and is never read
``body_only_mask`` (no prefix)          ``(10475, 1)``                 ignored: a loss mask of the
                                                                       Lightning module
======================================= ============================== =================================

The full-camera networks take their initial translation as an argument: the Lightning modules
pass ``[0, 0, 10] m * 0.05`` and divide the output by 0.05 (``fwd_pass_and_loss`` of
``copenet_singleview.py`` / ``copenet_twoview.py``), which is the kit's
``init_tau_n = TAU_INIT / TAU_SCALE`` and ``tau = 20 tau_n`` (filled in, not read).

Input order of fc1 and output order of decpose are the kit's (``variants.py``): Baseline
``[feat, pose132, beta, cam]``; Multi-view ``[feat, cam, root6, pose126, beta, other126, other10]``;
Fullcam ``[feat, P, tau/20, pose132, beta]``; AirPose ``[feat, P, tau/20, root6, pose126, beta,
other126, other10]``; decpose gives ``[tau/20 (full camera only), root6, pose126]`` (the
``forward_reg`` methods of the four model files). 6D rotations are ``R[:, :2].reshape(6)`` in both
codes (``rot2cont_rep`` in ``copenet/src/copenet/utils/utils.py``). So weights load unchanged; the variant is recognised
from the fc1 input width minus the backbone's feature width: 145 (hmr), 281 (muhmr),
148 (copenet_singleview), 284 (copenet_twoview).

Loading never imports pytorch_lightning: objects of classes the kit does not have (the
``hyper_parameters`` AttributeDict, callbacks) are replaced by inert placeholders and no other code
in the file is run (:func:`read_official_checkpoint`).
"""
from __future__ import annotations

import io
import pickle
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

from airpose_lib.atomic import atomic_torch_save
from airpose_lib.errors import UserError
from airpose_lib.safe_pickle import torch_pickle_module

from .backbone import BACKBONES
from .variants import BETA_DIM, TAU_INIT, TAU_SCALE, THETA_DIM, WEAK_CAM_INIT, AirPoseNet, _spec

__all__ = [
    "OfficialCheckpointError",
    "OFFICIAL_NAMES",
    "KIT_VARIANTS",
    "FC1_EXTRA_WIDTH",
    "IGNORED_KEYS",
    "OfficialConversion",
    "official_variant_name",
    "detect_backbone",
    "detect_variant",
    "read_official_checkpoint",
    "official_to_kit",
    "load_official_checkpoint",
    "to_official_state_dict",
    "write_official_checkpoint",
    "backbone_name",
]

#: kit variant -> official Lightning module name (README of the official repository).
OFFICIAL_NAMES: dict[str, str] = {"baseline": "hmr", "multiview": "muhmr", "fullcam": "copenet_singleview",
                                  "airpose": "copenet_twoview"}
#: official (or kit) name -> kit variant; ``copnet_singleview`` is the README's spelling.
KIT_VARIANTS: dict[str, str] = {**{v: k for k, v in OFFICIAL_NAMES.items()}, **{k: k for k in OFFICIAL_NAMES},
                                "copnet_singleview": "fullcam"}
#: fc1 input width beyond the backbone feature, per kit variant.
FC1_EXTRA_WIDTH: dict[str, int] = {"baseline": 145, "multiview": 281, "fullcam": 148, "airpose": 284}
#: Official keys (after the ``model.`` prefix; ``body_only_mask`` has none) that are deliberately
#: not loaded, with the reason. ``deccam.*`` / ``init_cam`` only for the full-camera networks.
IGNORED_KEYS: dict[str, str] = {
    "body_only_mask": "vertex mask of the Lightning module's losses, not part of the network",
    "init_position": "copenet_singleview buffer holding [0, 0, 200]; never read, the Lightning module "
                     "passes the initial translation [0, 0, 10] * 0.05",
    "deccam.weight": "camera head, unused by the full-camera networks",
    "deccam.bias": "camera head, unused by the full-camera networks",
    "init_cam": "weak-camera mean, unused by the full-camera networks",
}
_POSE_SLOTS = 6 + THETA_DIM  # 132 of init_pose's 144 values are read
_IDENTITY_6D = (1.0, 0.0, 0.0, 1.0, 0.0, 0.0)  # R[:, :2].reshape(6) of the identity
#: (block type, blocks per stage) -> backbone name.
_LAYOUTS = {("Bottleneck", (3, 4, 6, 3)): "resnet50", ("BasicBlock", (3, 4, 6, 3)): "resnet34",
            ("BasicBlock", (2, 2, 2, 2)): "resnet18"}


class OfficialCheckpointError(UserError, ValueError):
    """An official checkpoint cannot be converted (names the file and what is wrong)."""


def official_variant_name(variant: str) -> str:
    """Kit variant (``"airpose"`` ...) or official name (``"copenet_twoview"`` ...) -> kit variant."""
    try:
        return KIT_VARIANTS[variant]
    except KeyError:
        raise ValueError(f"unknown variant {variant!r}; use one of {sorted(OFFICIAL_NAMES)} or the official "
                         f"names {sorted(set(OFFICIAL_NAMES.values()))}") from None


# -- reading the file ---------------------------------------------------------------------------
def read_official_checkpoint(path: str | Path, map_location: str | torch.device = "cpu") -> dict:
    """Load a checkpoint file (read-only) without importing pytorch_lightning.

    Tried first with ``torch.load(weights_only=True)``; a file that holds other objects (the
    official ones pickle Lightning's ``AttributeDict`` of hyper-parameters) is read again with an
    unpickler that builds tensors and plain containers only and replaces any other object by an
    inert placeholder.

    Raises:
        OfficialCheckpointError: missing or unreadable file.
    """
    path = Path(path)
    if not path.is_file():
        raise OfficialCheckpointError(f"checkpoint {path} does not exist")
    data = path.read_bytes()
    try:
        return torch.load(io.BytesIO(data), map_location=map_location, weights_only=True)
    except pickle.UnpicklingError:
        pass
    except Exception as e:  # noqa: BLE001 - torch raises RuntimeError on a truncated zip
        raise OfficialCheckpointError(f"cannot read checkpoint {path} ({type(e).__name__}: {e}); the file is "
                                      f"truncated or not a PyTorch checkpoint, download it again") from None
    try:
        return torch.load(io.BytesIO(data), map_location=map_location, weights_only=False,
                          pickle_module=torch_pickle_module())
    except Exception as e:  # noqa: BLE001
        raise OfficialCheckpointError(f"cannot read checkpoint {path} ({type(e).__name__}: {e}); the file is "
                                      f"truncated or not a PyTorch checkpoint, download it again") from None


# -- detection ----------------------------------------------------------------------------------
def _network_tensors(state: Mapping[str, Any], where: str) -> tuple[dict[str, Tensor], dict[str, Tensor]]:
    """Split a Lightning checkpoint (or its state dict) into ``model.*`` tensors (prefix removed)
    and the other top-level tensors."""
    sd = state.get("state_dict", state) if isinstance(state, Mapping) else None
    if not isinstance(sd, Mapping) or not sd or not all(isinstance(v, Tensor) for v in sd.values()):
        raise OfficialCheckpointError(f"{where}: not a Lightning checkpoint (no 'state_dict' of tensors)")
    net = {k[len("model."):]: v for k, v in sd.items() if k.startswith("model.")}
    other = {k: v for k, v in sd.items() if not k.startswith("model.")}
    if not net:
        raise OfficialCheckpointError(f"{where}: no 'model.*' tensors; keys are e.g. {sorted(sd)[:5]}")
    return net, other


def detect_backbone(net: Mapping[str, Tensor]) -> str:
    """ResNet name (``resnet50`` / ``resnet34`` / ``resnet18``) from the tensors' block layout."""
    bottleneck = "layer1.0.conv3.weight" in net
    counts = []
    for stage in range(1, 5):
        blocks = {int(k.split(".")[1]) for k in net if k.startswith(f"layer{stage}.")}
        counts.append(max(blocks) + 1 if blocks else 0)
    name = _LAYOUTS.get(("Bottleneck" if bottleneck else "BasicBlock", tuple(counts)))
    if name is None:
        raise OfficialCheckpointError(f"unknown backbone: {'bottleneck' if bottleneck else 'basic'} blocks "
                                      f"{counts} per stage (known: {sorted(BACKBONES)})")
    return name


def _feature_dim(backbone: str) -> int:
    return 2048 if backbone == "resnet50" else 512


def detect_variant(net: Mapping[str, Tensor], backbone: str | None = None) -> str:
    """Kit variant from the fc1 input width (minus the feature width) and the decpose width."""
    if "fc1.weight" not in net or "decpose.weight" not in net:
        raise OfficialCheckpointError("no fc1/decpose weights: not an AirPose/HMR regressor")
    backbone = backbone or detect_backbone(net)
    extra = int(net["fc1.weight"].shape[1]) - _feature_dim(backbone)
    found = [v for v, w in FC1_EXTRA_WIDTH.items() if w == extra]
    if not found:
        raise OfficialCheckpointError(
            f"fc1 takes {int(net['fc1.weight'].shape[1])} inputs = {_feature_dim(backbone)} ({backbone} feature) + "
            f"{extra}, which is no AirPose variant (extra widths {FC1_EXTRA_WIDTH})")
    variant = found[0]
    pose_out = int(net["decpose.weight"].shape[0])
    want = (3 if _spec(variant).fullcam else 0) + _POSE_SLOTS
    if pose_out != want:
        raise OfficialCheckpointError(f"decpose gives {pose_out} values but a {variant} network gives {want}")
    return variant


# -- conversion ---------------------------------------------------------------------------------
@dataclass
class OfficialConversion:
    """Result of :func:`official_to_kit`.

    Attributes:
        state_dict: kit ``AirPoseNet`` state dict (every kit tensor filled).
        variant: kit variant; official: the official network name.
        backbone: ResNet name.
        used: official keys that were loaded.
        ignored: official key -> why it is not loaded.
        unused: official keys neither loaded nor on the ignore list (an error when strict).
        filled: kit keys set from constants rather than the file, with the reason.
    """

    state_dict: dict[str, Tensor]
    variant: str
    official: str
    backbone: str
    used: list[str] = field(default_factory=list)
    ignored: dict[str, str] = field(default_factory=dict)
    unused: list[str] = field(default_factory=list)
    filled: dict[str, str] = field(default_factory=dict)


def official_to_kit(state: Mapping[str, Any], variant: str | None = None, backbone: str | None = None, *,
                    strict: bool = True, where: str = "checkpoint") -> OfficialConversion:
    """Map an official checkpoint's tensors onto the kit network, accounting for every tensor.

    Args:
        state: the loaded Lightning checkpoint (or its ``state_dict``).
        variant: expected variant (kit or official name); None: detected.
        backbone: expected backbone; None: detected.
        strict: unused official tensors raise; False warns and reports them.
        where: the file name for messages.

    Raises:
        OfficialCheckpointError: another variant or backbone than asked, unused tensors (strict),
            a kit tensor left unfilled or a shape mismatch.
    """
    net, other = _network_tensors(state, where)
    found_backbone = detect_backbone(net)
    if backbone is not None and backbone != found_backbone:
        raise OfficialCheckpointError(f"{where} holds a {found_backbone} backbone, not {backbone}; pass "
                                      f"backbone={found_backbone!r} (or None to detect it)")
    found = detect_variant(net, found_backbone)
    if variant is not None and official_variant_name(variant) != found:
        want = official_variant_name(variant)
        raise OfficialCheckpointError(
            f"{where} is a {OFFICIAL_NAMES[found]} network (kit variant {found!r}; fc1 input "
            f"{int(net['fc1.weight'].shape[1])}), not {OFFICIAL_NAMES[want]} ({want!r}); load it with "
            f"variant={found!r} or pick the {OFFICIAL_NAMES[want]} checkpoint")
    spec = _spec(found)
    model = AirPoseNet(found, backbone=found_backbone)
    expected = model.state_dict()
    conv = OfficialConversion({}, found, OFFICIAL_NAMES[found], found_backbone)
    out = conv.state_dict

    for key in other:
        if key in IGNORED_KEYS:
            conv.ignored[key] = IGNORED_KEYS[key]
        else:
            conv.unused.append(key)
    for key, value in net.items():
        head = key.split(".")[0]
        if head in ("conv1", "bn1", "layer1", "layer2", "layer3", "layer4"):
            out[f"backbone.{key}"] = value
        elif head in ("fc1", "fc2", "decpose", "decshape") or (head == "deccam" and not spec.fullcam):
            out[f"regressor.{key}"] = value
        elif key == "init_pose":
            pose = value.reshape(-1)
            if pose.numel() < _POSE_SLOTS:
                raise OfficialCheckpointError(f"{where}: model.init_pose has {pose.numel()} values, need {_POSE_SLOTS}")
            out["init_phi6d"], out["init_theta6d"] = pose[:6].clone(), pose[6:_POSE_SLOTS].clone()
        elif key == "init_shape":
            out["init_beta"] = value.reshape(-1)[:BETA_DIM].clone()
        elif key == "init_cam" and not spec.fullcam:
            out["init_cam"] = value.reshape(-1).clone()
        elif key in IGNORED_KEYS and (spec.fullcam or key in ("init_position",)):
            conv.ignored[f"model.{key}"] = IGNORED_KEYS[key]
            continue
        else:
            conv.unused.append(f"model.{key}")
            continue
        conv.used.append(f"model.{key}")
    if spec.fullcam:
        out["init_tau_n"] = torch.tensor(TAU_INIT) / TAU_SCALE
        conv.filled["init_tau_n"] = "the official modules feed [0, 0, 10] m x 0.05 as the initial translation"

    missing = sorted(set(expected) - set(out))
    extra = sorted(set(out) - set(expected))
    if missing or extra:
        raise OfficialCheckpointError(f"{where}: kit tensors not filled {missing[:8]}, unexpected {extra[:8]} "
                                      f"(the file is not a complete {OFFICIAL_NAMES[found]} network)")
    bad = [f"{k} {tuple(out[k].shape)} vs kit {tuple(expected[k].shape)}" for k in expected
           if out[k].shape != expected[k].shape]
    if bad:
        raise OfficialCheckpointError(f"{where}: shape mismatch: {'; '.join(bad[:8])}")
    for k in expected:  # the kit's dtypes (the official mean parameters are float64)
        out[k] = out[k].to(expected[k].dtype)
    if conv.unused:
        msg = (f"{where}: {len(conv.unused)} tensor(s) neither loaded nor known to be unused: "
               f"{conv.unused[:10]}")
        if strict:
            raise OfficialCheckpointError(msg + "; pass strict=False to load anyway")
        warnings.warn(msg, stacklevel=2)
    return conv


def load_official_checkpoint(path: str | Path, variant: str | None = None, backbone: str | None = "resnet50", *,
                             strict: bool = True, **model_kwargs) -> AirPoseNet:
    """An official AirPose checkpoint as a kit :class:`AirPoseNet` (eval mode, CPU).

    Args:
        path: the ``.ckpt`` file (opened read-only).
        variant: expected variant (``baseline`` / ``multiview`` / ``fullcam`` / ``airpose`` or the
            official ``hmr`` / ``muhmr`` / ``copenet_singleview`` / ``copenet_twoview``); None:
            detected from the tensors.
        backbone: expected backbone (the official ones are ``resnet50``); None: detected.
        strict: see :func:`official_to_kit`.
        **model_kwargs: extra :class:`AirPoseNet` arguments (``num_iterations``, ``dropout``).

    The conversion report is attached as ``model.official_conversion`` (without the tensors).
    """
    path = Path(path)
    conv = official_to_kit(read_official_checkpoint(path), variant, backbone, strict=strict, where=str(path))
    model = AirPoseNet(conv.variant, backbone=conv.backbone, **model_kwargs)
    model.load_state_dict(conv.state_dict, strict=True)
    conv.state_dict = {}
    model.official_conversion = conv
    return model.eval()


# -- writing ------------------------------------------------------------------------------------
def backbone_name(model: AirPoseNet) -> str:
    """The name (``resnet50`` ...) of a network's backbone, from its block type and layer counts."""
    bb = model.backbone
    try:
        return _LAYOUTS[(bb.block_name, tuple(bb.layers))]
    except KeyError:
        raise ValueError(f"backbone {bb.block_name} {bb.layers} is none of {sorted(BACKBONES)}") from None


def to_official_state_dict(model: AirPoseNet, num_vertices: int = 10475) -> dict[str, Tensor]:
    """The Lightning ``state_dict`` an official module with the same weights would have.

    Keys as in the module docstring; ``init_pose`` is padded to SPIN's 24 joints with identity
    rotations, the full-camera networks get a zero ``deccam`` (never used) and the official
    constants (``init_position = [0, 0, 200]`` for ``copenet_singleview``, ``init_cam`` for
    ``copenet_twoview``), and ``body_only_mask`` is ones of ``(num_vertices, 1)``.

    Raises:
        ValueError: the model's initial translation is not the official constant (the official
            modules hard-code it, so the file could not hold it).
    """
    spec = model.spec
    sd = {k: v.detach().cpu().contiguous().clone() for k, v in model.state_dict().items()}
    out: dict[str, Tensor] = {}
    for k, v in sd.items():
        if k.startswith("backbone."):
            out["model." + k[len("backbone."):]] = v
        elif k.startswith("regressor."):
            out["model." + k[len("regressor."):]] = v
    hidden = out["model.fc2.weight"].shape[0]
    pad = torch.tensor(_IDENTITY_6D * 2, dtype=sd["init_phi6d"].dtype)
    out["model.init_pose"] = torch.cat([sd["init_phi6d"], sd["init_theta6d"], pad])[None]
    out["model.init_shape"] = sd["init_beta"][None].clone()
    if spec.fullcam:
        tau_n = torch.tensor(TAU_INIT, dtype=sd["init_tau_n"].dtype) / TAU_SCALE
        if not torch.allclose(sd["init_tau_n"], tau_n):
            raise ValueError(f"init_tau_n is {sd['init_tau_n'].tolist()}, but the official modules hard-code "
                             f"{tau_n.tolist()}; such a model has no official equivalent")
        out["model.deccam.weight"] = torch.zeros(3, hidden)
        out["model.deccam.bias"] = torch.zeros(3)
        if spec.multiview:
            out["model.init_cam"] = torch.tensor([WEAK_CAM_INIT], dtype=torch.float32)
        else:
            out["model.init_position"] = torch.tensor([[0.0, 0.0, 10.0 / 0.05]])
    else:
        out["model.init_cam"] = sd["init_cam"][None].clone()
    out["body_only_mask"] = torch.ones(num_vertices, 1)
    return out


def write_official_checkpoint(model: AirPoseNet, path: str | Path, *, epoch: int = 0, global_step: int = 0,
                              extra: Mapping[str, Any] | None = None) -> Path:
    """Write ``model`` as an official Lightning checkpoint (atomically).

    Holds ``state_dict`` (:func:`to_official_state_dict`), ``epoch``, ``global_step``,
    ``pytorch-lightning_version`` ("1.2.0", the official pin), ``hparams_name`` and
    ``hyper_parameters`` (``{"model": <official name>}``), plus ``extra`` entries.
    """

    path = Path(path)
    ckpt = {"epoch": int(epoch), "global_step": int(global_step), "pytorch-lightning_version": "1.2.0",
            "state_dict": to_official_state_dict(model), "optimizer_states": [], "lr_schedulers": [],
            "hparams_name": "hparams", "hyper_parameters": {"model": OFFICIAL_NAMES[model.variant]}}
    ckpt.update(dict(extra or {}))
    return atomic_torch_save(ckpt, path)
