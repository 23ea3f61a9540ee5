"""Accuracy cost of the int8 stage 1: MPJPE, MPE and PA-MPJPE of a trained network on a test
split, float32 against int8, with the targets (int8 - fp32: MPJPE <= 2 mm, MPE <= 2 cm).

    python benchmarks/quantization.py --checkpoint runs/train/cpu/airpose/seed123/checkpoints/last.pt
    python benchmarks/quantization.py --checkpoint CKPT --max-samples 50 --calibration-samples 64

Three runs of the same samples, each evaluated against the ground truth as ``airpose eval`` does
(``airpose_lib.train.evaluate.predict`` and ``eval.per_view_table``): the torch network (batched forward, the reference), ONNX
Runtime float32 and ONNX Runtime int8 (``airpose export --checkpoint CKPT --quantize int8``,
calibrated on the checkpoint's training crops unless ``--calibration DIR``), both run stage by
stage per view with the drones' message exchange (``runtime.offline.offline_staged``). Also
printed: the distance between the int8 and the float32 predictions themselves (joints and
translation), which does not depend on how good the network is.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import torch
from torch import nn

MPJPE_TARGET_MM = 2.0
MPE_TARGET_CM = 2.0


class StagedOnnx(nn.Module):
    """An ONNX stage model run per view with the exchange, shaped like ``AirPoseNet.forward``
    (so that ``train.evaluate`` can evaluate it): images ``(B, V, 3, S, S)``, P ``(B, V, 3)`` ->
    phi6d, theta6d, beta, tau / cam ``(B, V, ...)``."""

    def __init__(self, proto):
        super().__init__()
        self.proto = proto

    def forward(self, images: torch.Tensor, P: torch.Tensor) -> dict:
        from airpose_lib.runtime.offline import offline_staged

        out = offline_staged(self.proto, images.numpy(), P.numpy())
        res = {k: torch.from_numpy(v) for k, v in out.items()}
        res["input_size"] = int(images.shape[-1])
        return res


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--checkpoint", required=True, help="a checkpoints/*.pt of `airpose train`")
    parser.add_argument("--split", default="test")
    parser.add_argument("--max-samples", type=int, default=None, help="(default: the whole split)")
    parser.add_argument("--calibration", default=None, help="still-frame dataset of the calibration crops")
    parser.add_argument("--calibration-samples", type=int, default=32)
    parser.add_argument("--calibration-method", choices=("minmax", "percentile", "entropy"), default="minmax")
    parser.add_argument("--quantize-regressor", action="store_true",
                        help="quantise the regressor's layers too (default: backbone only)")
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    if not Path(args.checkpoint).is_file():
        print(f"quantization.py: error: no checkpoint at {args.checkpoint} (pass a checkpoints/*.pt of "
              "`airpose train`)", file=sys.stderr)
        return 2
    torch.set_num_threads(args.threads)

    import pandas as pd

    from airpose_lib.data.still.dataset import StillFrameDataset
    from airpose_lib.eval import paper_table, per_view_table
    from airpose_lib.model.quantize import QuantSettings
    from airpose_lib.runtime.backends import BackendSpec
    from airpose_lib.runtime.edge import ensure_export
    from airpose_lib.runtime.networks import make_stage_model
    from airpose_lib.train.evaluate import load_trained_model, predict
    from airpose_lib.train.loop import default_dataset_factory
    from airpose_lib.train.run import prepare_data

    model, cfg = load_trained_model(args.checkpoint)
    cfg = prepare_data(cfg, progress=False)
    dataset = default_dataset_factory(cfg, args.split)
    # A regressor-task checkpoint evaluates in torch on the cached backbone features; the ONNX
    # networks need the crops themselves (the same crops the features were computed from).
    images = dataset
    if cfg.task == "regressor":
        crops = cfg.data.get("crops", "jittered")
        images = StillFrameDataset(cfg.data["root"], split=args.split, crops=crops,
                                   **{k: v for k, v in cfg.data.items() if k not in ("root", "profile", "source", "crops")})
    spec = BackendSpec(kind="onnx-int8", checkpoint=args.checkpoint, threads=args.threads)
    t = time.time()
    settings = QuantSettings(calibration=args.calibration_method, backbone_only=not args.quantize_regressor)
    folder = ensure_export(spec, calibration_root=args.calibration, calibration_samples=args.calibration_samples,
                           settings=settings, progress=True)
    print(f"export {folder} ({time.time() - t:.0f} s); load average {os.getloadavg()[0]:.2f}")
    runs = {"torch fp32": model,
            "ONNX fp32": StagedOnnx(make_stage_model(BackendSpec(**{**spec.to_dict(), "kind": "onnx",
                                                                    "onnx_dir": str(folder)}))),
            "ONNX int8": StagedOnnx(make_stage_model(BackendSpec(**{**spec.to_dict(), "onnx_dir": str(folder)})))}
    tables, preds = {}, {}
    for name, net in runs.items():
        t = time.time()
        preds[name], gt = predict(net, dataset if name == "torch fp32" else images, batch_size=4, max_samples=args.max_samples, body=cfg.body_source)
        tables[name] = per_view_table(preds[name], gt, name, gt.get("index"))
        print(f"{name}: {len(tables[name])} views in {time.time() - t:.0f} s", flush=True)

    n = len(tables["ONNX int8"]) // max(dataset.num_views, 1)
    print(f"\n{args.checkpoint}: {cfg.variant}, {cfg.backbone}, {args.split} split, {n} samples; int8 "
          f"settings {settings.to_dict()}, {args.calibration_samples} calibration samples")
    table = paper_table(pd.concat(tables.values()))
    print(table.to_string(float_format=lambda x: f"{x:.4f}"))
    mean = {k: t[["mpjpe_m", "mpe_m", "pa_mpjpe_m"]].mean() for k, t in tables.items()}
    d_mpjpe = 1000 * (mean["ONNX int8"]["mpjpe_m"] - mean["ONNX fp32"]["mpjpe_m"])
    d_mpe = 100 * (mean["ONNX int8"]["mpe_m"] - mean["ONNX fp32"]["mpe_m"])
    d_pa = 1000 * (mean["ONNX int8"]["pa_mpjpe_m"] - mean["ONNX fp32"]["pa_mpjpe_m"])
    q, f = preds["ONNX int8"], preds["ONNX fp32"]
    joint_gap = 1000 * (q["joints"] - f["joints"]).norm(dim=-1).mean().item()
    tau_gap = 100 * (q["tau"] - f["tau"]).norm(dim=-1).mean().item()
    fp_gap = 1000 * (f["joints"] - preds["torch fp32"]["joints"]).norm(dim=-1).max().item()
    print(f"\nint8 - fp32: MPJPE {d_mpjpe:+.2f} mm (target <= {MPJPE_TARGET_MM}: "
          f"{'met' if abs(d_mpjpe) <= MPJPE_TARGET_MM else 'NOT met'}), MPE {d_mpe:+.2f} cm (target <= "
          f"{MPE_TARGET_CM}: {'met' if abs(d_mpe) <= MPE_TARGET_CM else 'NOT met'}), PA-MPJPE {d_pa:+.2f} mm")
    print(f"int8 vs fp32 predictions: joints {joint_gap:.2f} mm apart on average (camera frame), "
          f"translation {tau_gap:.2f} cm; ONNX fp32 vs torch: {fp_gap:.4f} mm at most")
    print(f"load average {'/'.join(f'{x:.2f}' for x in os.getloadavg())} (shared machine)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
