"""``airpose backbone import``: ImageNet (or any torchvision ResNet) weights as a kit backbone file."""
from __future__ import annotations

import argparse
from pathlib import Path

from .common import require_file

__all__ = ["add_backbone"]


def _cmd_import(args: argparse.Namespace) -> int:
    from airpose_lib.train.pretrain import import_torchvision_backbone

    require_file(args.weights, "FILE", f"a torchvision {args.backbone} state dict (torch.save of model.state_dict())")
    path = import_torchvision_backbone(args.weights, args.backbone, args.out)
    print(f"backbone {path}\n  start a training from it: airpose train --variant airpose --profile paper "
          f"--set pretrained={path}")
    return 0


def add_backbone(sub) -> None:
    bb = sub.add_parser("backbone", help="backbone files (import ImageNet weights)",
                        description="Backbone files that trainings start from (`train: pretrained: FILE`).")
    group = bb.add_subparsers(dest="backbone_command", metavar="SUBCOMMAND", required=True)
    imp = group.add_parser(
        "import", help="a torchvision ResNet state dict (e.g. ImageNet weights) as a kit backbone file",
        description="Convert a torchvision ResNet state dict that you downloaded (e.g. torch.save("
                    "torchvision.models.resnet50(weights='IMAGENET1K_V2').state_dict(), 'resnet50.pth')) into "
                    "the kit's backbone file (float32, fc dropped); the paper's trainings start from ImageNet "
                    "weights: --set pretrained=<the printed file>.")
    imp.add_argument("weights", type=Path, metavar="FILE", help="the .pth state dict")
    imp.add_argument("--backbone", choices=("resnet50", "resnet34", "resnet18"), default="resnet50",
                     help="its architecture (default: resnet50, the paper's)")
    imp.add_argument("--out", type=Path, default=None,
                     help="the backbone file to write (default: <cache>/backbones/imagenet-<backbone>-<sha>.pt)")
    imp.set_defaults(func=_cmd_import)
