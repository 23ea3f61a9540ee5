#!/usr/bin/env python
"""The detector report of generated recordings as one CSV (``airpose_lib.experiments.detector_report``).

Runs in the kit's environment:

    python scripts/detector_report.py OUT/person1 OUT/person2 --out report.csv \\
        --detectors mediapipe openpose alphapose

prints the per-view summary (all joints) and writes every row (views x detectors x references x
joint groups) to ``--out``; ``--labels`` names the recordings in the ``recording`` column (default:
their paths, :func:`~airpose_lib.paths.portable`), ``--markdown`` also writes the summary against
the true keypoints as a Markdown table.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's kit

import pandas as pd  # noqa: E402

from airpose_lib.data.sequences.reader import load_sequence  # noqa: E402
from airpose_lib.errors import UserError  # noqa: E402
from airpose_lib.experiments.detector_report import detector_report, write_report  # noqa: E402
from airpose_lib.experiments.recording_tables import markdown_table  # noqa: E402
from airpose_lib.paths import portable  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("recordings", type=Path, nargs="+", help="generated recordings (official layout)")
    ap.add_argument("--detectors", nargs="+", default=["mediapipe", "openpose", "alphapose"])
    ap.add_argument("--out", type=Path, required=True, help="CSV file")
    ap.add_argument("--labels", nargs="+", help="one name per recording for the `recording` column")
    ap.add_argument("--markdown", type=Path, help="also the summary against the true keypoints, as Markdown")
    args = ap.parse_args(argv)
    # a table to commit: the default labels name no folder of this machine
    labels = args.labels or [portable(str(r)) for r in args.recordings]
    if len(labels) != len(args.recordings):
        ap.error(f"--labels: give one per recording ({len(args.recordings)}), not {len(labels)}")
    rows = []
    for root, label in zip(args.recordings, labels, strict=True):
        try:
            seq = load_sequence(root, detectors=args.detectors)
        except UserError as e:
            print(f"detector_report: error: {e}", file=sys.stderr)
            return 2
        rows += detector_report(seq, args.detectors, recording=label)
    write_report(rows, args.out)
    df = pd.DataFrame(rows)
    cols = ["recording", "view", "detector", "reference", "detection_rate", "keypoint_rate", "pairs",
            "median_px", "p90_px", "pck_0.05", "pck_0.1", "pck_0.2"]
    with pd.option_context("display.width", 200, "display.max_rows", 1000):
        print(df[df.group == "all"][cols].round(3).to_string(index=False))
    print(f"written {args.out}")
    if args.markdown is not None:
        truth = df[(df.group == "all") & (df.reference == "truth")][[c for c in cols if c != "reference"]]
        args.markdown.write_text(markdown_table(truth.reset_index(drop=True), digits=3))
        print(f"written {args.markdown}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
