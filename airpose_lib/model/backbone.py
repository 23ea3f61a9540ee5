"""ResNet feature extractors written in the kit (torchvision does not import on this CPU torch).

ResNet-50 (bottleneck blocks ``[3, 4, 6, 3]``) is the paper's backbone; ResNet-18 and ResNet-34
(basic blocks) are CPU options. The layer and parameter names follow ``torchvision.models.resnet``
exactly (``conv1``, ``bn1``, ``layer1.0.conv1``, ..., ``layer4.2.bn3``, ``downsample.0/1``), and
the classifier ``fc`` is left out, so an ImageNet state dict published for torchvision loads with
:meth:`ResNet.load_torchvision_state_dict` (it drops ``fc.*``). The pooling is global average
pooling, so any input size works (the paper uses 224x224, where it equals the 7x7 average pool of
HMR/SPIN).
"""
from __future__ import annotations

from collections.abc import Mapping

import torch
from torch import Tensor, nn

from airpose_lib.errors import ConfigError

__all__ = [
    "BasicBlock",
    "Bottleneck",
    "ResNet",
    "BACKBONES",
    "build_backbone",
    "resnet18",
    "resnet34",
    "resnet50",
]


def _conv3x3(cin: int, cout: int, stride: int = 1) -> nn.Conv2d:
    return nn.Conv2d(cin, cout, kernel_size=3, stride=stride, padding=1, bias=False)


def _conv1x1(cin: int, cout: int, stride: int = 1) -> nn.Conv2d:
    return nn.Conv2d(cin, cout, kernel_size=1, stride=stride, bias=False)


class BasicBlock(nn.Module):
    """Two 3x3 convolutions with an identity (or 1x1 projection) shortcut (ResNet-18/34)."""

    expansion = 1

    def __init__(self, inplanes: int, planes: int, stride: int = 1, downsample: nn.Module | None = None):
        super().__init__()
        self.conv1 = _conv3x3(inplanes, planes, stride)
        self.bn1 = nn.BatchNorm2d(planes)
        self.relu = nn.ReLU(inplace=True)
        self.conv2 = _conv3x3(planes, planes)
        self.bn2 = nn.BatchNorm2d(planes)
        self.downsample = downsample

    def forward(self, x: Tensor) -> Tensor:
        identity = x if self.downsample is None else self.downsample(x)
        out = self.relu(self.bn1(self.conv1(x)))
        out = self.bn2(self.conv2(out))
        return self.relu(out + identity)


class Bottleneck(nn.Module):
    """1x1 -> 3x3 (strided, as torchvision's "ResNet v1.5") -> 1x1 x4 block (ResNet-50)."""

    expansion = 4

    def __init__(self, inplanes: int, planes: int, stride: int = 1, downsample: nn.Module | None = None):
        super().__init__()
        self.conv1 = _conv1x1(inplanes, planes)
        self.bn1 = nn.BatchNorm2d(planes)
        self.conv2 = _conv3x3(planes, planes, stride)
        self.bn2 = nn.BatchNorm2d(planes)
        self.conv3 = _conv1x1(planes, planes * self.expansion)
        self.bn3 = nn.BatchNorm2d(planes * self.expansion)
        self.relu = nn.ReLU(inplace=True)
        self.downsample = downsample

    def forward(self, x: Tensor) -> Tensor:
        identity = x if self.downsample is None else self.downsample(x)
        out = self.relu(self.bn1(self.conv1(x)))
        out = self.relu(self.bn2(self.conv2(out)))
        out = self.bn3(self.conv3(out))
        return self.relu(out + identity)


def global_pool(x: Tensor) -> Tensor:
    """Mean over the feature map: ``(B, C, h, w)`` -> ``(B, C)``. A plain mean rather than
    ``nn.AdaptiveAvgPool2d(1)``, whose CUDA backward has no deterministic kernel (it would break the
    bit-identical resume on a GPU under ``use_deterministic_algorithms``); same numbers up to float
    summation order (tests/test_model_backbone.py)."""
    return x.mean(dim=(2, 3))


class ResNet(nn.Module):
    """ResNet trunk without the classifier: image ``(B, 3, H, W)`` -> feature ``(B, feature_dim)``.

    Args:
        block: :class:`BasicBlock` or :class:`Bottleneck`.
        layers: number of blocks in each of the four stages, e.g. ``(3, 4, 6, 3)``.
        channels_last: keep weights and activations in NHWC memory layout (faster convolutions on
            CPU for training; the numbers are the same up to float rounding).
    """

    def __init__(self, block: type[BasicBlock] | type[Bottleneck], layers: tuple[int, int, int, int],
                 channels_last: bool = False):
        super().__init__()
        self.inplanes = 64
        self.conv1 = nn.Conv2d(3, 64, kernel_size=7, stride=2, padding=3, bias=False)
        self.bn1 = nn.BatchNorm2d(64)
        self.relu = nn.ReLU(inplace=True)
        self.maxpool = nn.MaxPool2d(kernel_size=3, stride=2, padding=1)
        self.layer1 = self._make_layer(block, 64, layers[0])
        self.layer2 = self._make_layer(block, 128, layers[1], stride=2)
        self.layer3 = self._make_layer(block, 256, layers[2], stride=2)
        self.layer4 = self._make_layer(block, 512, layers[3], stride=2)
        # Global pooling (:func:`global_pool`) instead of HMR's fixed 7x7 AvgPool2d: identical at
        # 224 px, and any input size (128 px for the CPU profile) still gives one feature vector.
        self.feature_dim = 512 * block.expansion
        self.layers = tuple(layers)
        self.block_name = block.__name__
        # Same initialisation as torchvision (used when no pretrained weights are loaded).
        for m in self.modules():
            if isinstance(m, nn.Conv2d):
                nn.init.kaiming_normal_(m.weight, mode="fan_out", nonlinearity="relu")
            elif isinstance(m, nn.BatchNorm2d):
                nn.init.ones_(m.weight)
                nn.init.zeros_(m.bias)
        self.channels_last = False
        self.set_channels_last(channels_last)

    def _make_layer(self, block, planes: int, blocks: int, stride: int = 1) -> nn.Sequential:
        downsample = None
        if stride != 1 or self.inplanes != planes * block.expansion:
            downsample = nn.Sequential(
                _conv1x1(self.inplanes, planes * block.expansion, stride),
                nn.BatchNorm2d(planes * block.expansion),
            )
        stage = [block(self.inplanes, planes, stride, downsample)]
        self.inplanes = planes * block.expansion
        stage += [block(self.inplanes, planes) for _ in range(1, blocks)]
        return nn.Sequential(*stage)

    def set_channels_last(self, enabled: bool = True) -> "ResNet":
        """Switch the weights (and, in :meth:`forward`, the input) to NHWC or back to NCHW."""
        fmt = torch.channels_last if enabled else torch.contiguous_format
        self.to(memory_format=fmt)
        self.channels_last = bool(enabled)
        return self

    def forward(self, x: Tensor) -> Tensor:
        """Args: x ``(B, 3, H, W)`` normalised RGB. Returns ``(B, feature_dim)``."""
        x = self.layer4(self.layer3(self.layer2(self.layer1(self._stem(x)))))
        return global_pool(x)

    def _stem(self, x: Tensor) -> Tensor:
        if self.channels_last:
            x = x.contiguous(memory_format=torch.channels_last)
        return self.maxpool(self.relu(self.bn1(self.conv1(x))))

    # -- the trunk cut in two at a block, for training only the blocks after the cut ------------

    def block_names(self) -> tuple[str, ...]:
        """The residual blocks in order: ``("layer1.0", ..., "layer4.1")`` (state-dict prefixes)."""
        return tuple(f"layer{i}.{j}" for i in range(1, 5) for j in range(len(getattr(self, f"layer{i}"))))

    def _cut_index(self, cut: str) -> int:
        names = self.block_names()
        if cut not in names:
            raise ValueError(f"unknown block {cut!r} of this {self.block_name} trunk; choose one of {list(names)}")
        return names.index(cut)

    def _blocks(self) -> list[nn.Module]:
        return [block for i in range(1, 5) for block in getattr(self, f"layer{i}")]

    def forward_until(self, x: Tensor, cut: str) -> Tensor:
        """The stem and the blocks before ``cut``.

        Args: x ``(B, 3, H, W)`` normalised RGB; cut: a name of :meth:`block_names`.
        Returns: the input of block ``cut``, ``(B, C, h, w)`` (e.g. ``(B, 256, 8, 8)`` for
        ``"layer4.0"`` of a ResNet-18 at 128 px).
        """
        x = self._stem(x)
        for block in self._blocks()[:self._cut_index(cut)]:
            x = block(x)
        return x

    def forward_from(self, h: Tensor, cut: str) -> Tensor:
        """Block ``cut``, the blocks after it and the pooling: ``forward(x) ==
        forward_from(forward_until(x, cut), cut)``.

        Args: h ``(B, C, h, w)`` the input of block ``cut``. Returns ``(B, feature_dim)``.
        """
        if self.channels_last:
            h = h.contiguous(memory_format=torch.channels_last)
        for block in self.blocks_from(cut):
            h = block(h)
        return global_pool(h)

    def blocks_from(self, cut: str) -> list[nn.Module]:
        """The modules :meth:`forward_from` runs with weights: block ``cut`` and those after it."""
        return self._blocks()[self._cut_index(cut):]

    def load_torchvision_state_dict(self, state_dict: Mapping[str, Tensor], strict: bool = True):
        """Load a torchvision-format ResNet state dict (e.g. ImageNet weights); ``fc.*`` is dropped.

        A ``module.`` prefix (DataParallel checkpoints) is stripped. Returns what
        ``load_state_dict`` returns.
        """
        cleaned = {}
        for key, value in state_dict.items():
            key = key[len("module."):] if key.startswith("module.") else key
            if not key.startswith("fc."):
                cleaned[key] = value
        return self.load_state_dict(cleaned, strict=strict)


def resnet18(channels_last: bool = False) -> ResNet:
    """ResNet-18 trunk, 512-d features (11,176,512 parameters)."""
    return ResNet(BasicBlock, (2, 2, 2, 2), channels_last)


def resnet34(channels_last: bool = False) -> ResNet:
    """ResNet-34 trunk, 512-d features."""
    return ResNet(BasicBlock, (3, 4, 6, 3), channels_last)


def resnet50(channels_last: bool = False) -> ResNet:
    """ResNet-50 trunk (the paper's), 2048-d features (23,508,032 parameters)."""
    return ResNet(Bottleneck, (3, 4, 6, 3), channels_last)


BACKBONES = {"resnet18": resnet18, "resnet34": resnet34, "resnet50": resnet50}


def build_backbone(name: str = "resnet50", channels_last: bool = False) -> ResNet:
    """Backbone by name: ``"resnet50"`` (paper), ``"resnet34"`` or ``"resnet18"`` (CPU options)."""
    try:
        return BACKBONES[name](channels_last=channels_last)
    except KeyError:
        raise ConfigError(f"unknown backbone {name!r}; choose one of {sorted(BACKBONES)}") from None
