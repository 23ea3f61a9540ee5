#!/usr/bin/env python
"""One row per training run scored on the validation split, for a profile's ``selection/`` table.

    python scripts/selection_rows.py RUN [RUN ...] --settings steps trainable_from --out table.csv

Each RUN is the folder of an ``airpose train`` run on which ``airpose eval --checkpoint
RUN/checkpoints/last.pt --split val`` wrote ``RUN/eval_val/per_view.csv``. A row holds the run's
settings named by ``--settings`` (from its ``config.json``; ``pretrained`` is shortened to the
backbone's key), its variant and seed, the number of views, the means of the per-view errors, the
medians of the root-orientation errors and the share of views whose root is off by over 90 deg:
the numbers a choice on the validation split is made from.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import pandas as pd

MEANS = {"mpe_m": "MPE [m]", "mpjpe_m": "MPJPE [m]", "mpjpe_true_root_m": "MPJPE true root [m]",
         "pa_mpjpe_m": "PA-MPJPE [m]"}
MEDIANS = {"root_rot_deg": "root median [deg]", "root_yaw_deg": "root yaw median [deg]",
           "root_tilt_deg": "root tilt median [deg]"}


def selection_row(run: Path, settings: list[str]) -> dict:
    """The row of one run (see the module docstring)."""
    config = json.loads((run / "config.json").read_text())
    views = pd.read_csv(run / "eval_val" / "per_view.csv")
    row = {}
    for name in settings:
        value = config.get(name)
        row[f"train.{name}"] = Path(value).stem if name == "pretrained" and value else value
    row.update(variant=config["variant"], seed=config["seed"], split="val", views=len(views))
    row.update({label: round(float(views[col].mean()), 4) for col, label in MEANS.items()})
    row.update({label: round(float(views[col].median()), 4) for col, label in MEDIANS.items()})
    row["root > 90 deg [%]"] = round(100.0 * float((views["root_rot_deg"] > 90.0).mean()), 4)
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("runs", type=Path, nargs="+", help="training run folders with eval_val/per_view.csv")
    ap.add_argument("--settings", nargs="+", default=["steps"], help="config.json fields that tell the runs apart")
    ap.add_argument("--out", type=Path, required=True, help="CSV file")
    args = ap.parse_args(argv)
    missing = [str(r) for r in args.runs if not (r / "eval_val" / "per_view.csv").is_file()]
    if missing:
        print(f"selection_rows: error: no eval_val/per_view.csv in {', '.join(missing)}; run "
              "`airpose eval --checkpoint RUN/checkpoints/last.pt --split val` first", file=sys.stderr)
        return 2
    table = pd.DataFrame([selection_row(r, args.settings) for r in args.runs])
    table.to_csv(args.out, index=False, float_format="%.4f")
    with pd.option_context("display.width", 200):
        print(table.to_string(index=False))
    return 0


if __name__ == "__main__":
    sys.exit(main())
