"""A training on the GPU resumes bit for bit (scripts/gpu_check.sh, step smoke).

The smoke profile's AirPose regressor on ``--device`` with ``--precision``: 40 steps straight
against 20 steps, an interruption and 20 more from the checkpoint; the weights and the optimiser
state must be equal tensor for tensor.

    python scripts/gpu_resume_check.py RUNS_DIR [--device cuda] [--precision bf16]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import torch

from airpose_lib.engine.checkpoint import load_checkpoint
from airpose_lib.reproduce.configs import kit_configs
from airpose_lib.train import train


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", type=Path)
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--precision", default="bf16")
    ap.add_argument("--steps", type=int, default=40)
    args = ap.parse_args(argv)
    smoke = kit_configs("smoke").train_inputs()
    cfg = smoke.section.config("airpose", steps=args.steps, device=args.device, precision=args.precision,
                               checkpoint_every=args.steps // 2, progress=False)
    straight = train("airpose", smoke, config=cfg, out_dir=args.runs / "straight", resume=False)
    first = train("airpose", smoke, config=cfg, out_dir=args.runs / "resumed", resume=False, stop_at=args.steps // 2)
    assert first.stopped_early and first.step == args.steps // 2
    resumed = train("airpose", smoke, config=cfg, out_dir=args.runs / "resumed")
    a, b = load_checkpoint(straight.checkpoint), load_checkpoint(resumed.checkpoint)
    differ = [k for k in a["model"] if not torch.equal(a["model"][k], b["model"][k])]
    moments = [(k, n) for k, s in a["optimizer"]["state"].items() for n, v in s.items()
               if not torch.equal(v, b["optimizer"]["state"][k][n])]
    print(f"device {a['config']['device']}, precision {a['config']['precision']}, steps {a['step']} / {b['step']}")
    print(f"resumed == straight bit for bit: weights {len(differ)} of {len(a['model'])} tensors differ, "
          f"optimiser state {len(moments)} differ")
    if differ:
        worst = max(float((a["model"][k].float() - b["model"][k].float()).abs().max()) for k in differ)
        print(f"largest difference {worst:.3g} (first: {differ[:5]})")
    return 1 if differ or moments else 0


if __name__ == "__main__":
    raise SystemExit(main())
