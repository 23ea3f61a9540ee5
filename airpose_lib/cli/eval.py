"""``airpose eval``: a trained checkpoint's tables."""
from __future__ import annotations

import argparse
from pathlib import Path

from .common import require_file

__all__ = ['add_eval']

# Handlers import the library when they run, never at module level: the whole parser is built
# on every call (``airpose --help``, a drone's start-up) and must not import torch, ZeroMQ,
# smplx or papermill.


def _cmd_eval(args: argparse.Namespace) -> int:
    from airpose_lib.eval import paper_table
    from airpose_lib.train import evaluate_checkpoint

    require_file(args.checkpoint, "--checkpoint", "a checkpoints/*.pt of `airpose train`")
    tables = evaluate_checkpoint(args.checkpoint, split=args.split, method=args.method,
                                 batch_size=args.batch_size, device=args.device, max_samples=args.max_samples)
    out = args.out if args.out is not None else Path(args.checkpoint).resolve().parent.parent / f"eval_{args.split}"
    out.mkdir(parents=True, exist_ok=True)
    for name, table in tables.items():
        table.to_csv(out / f"{name}.csv", index=False)
    print(paper_table(tables["per_view"]).to_string(float_format=lambda x: f"{x:.3f}"))
    print(f"tables written to {out}")
    return 0


def add_eval(sub) -> None:
    ev = sub.add_parser(
        "eval", help="evaluate a trained checkpoint (MPE, MPJPE, PA-MPJPE ...)",
        description="Run a training checkpoint over a split of its still-frame dataset and write tidy "
                    "tables (per_view.csv, per_joint.csv, relative_camera.csv); prints Table I's columns.")
    ev.add_argument("--checkpoint", type=Path, required=True, help="a checkpoints/*.pt of `airpose train`")
    ev.add_argument("--split", default="test", help="(default: test)")
    ev.add_argument("--method", default=None, help="name in the tables (default: the variant)")
    ev.add_argument("--out", type=Path, default=None, help="(default: <run>/eval_<split>/)")
    ev.add_argument("--batch-size", type=int, default=8)
    ev.add_argument("--max-samples", type=int, default=None)
    ev.add_argument("--device", default="auto", help="auto (CUDA if available), cpu, cuda or cuda:N (default: auto)")
    ev.set_defaults(func=_cmd_eval)
