"""Issue 28's backbone spread: Table I on two independently pretrained backbones, side by side.

The three regressor seeds of a Table I all read one frozen backbone, so their spread leaves out
the backbone's own pretraining. Here the same seeds (the same regressor initialisations) are run
on a second backbone, pretrained from scratch with another seed, and each variant's mean is set
against the first backbone's with both seed spreads beside it; then each of the six claims on
both. Two backbones are one draw of the between-backbone difference, not its distribution.

    python results/cpu_backbone_seed1/backbone_spread.py results/cpu results/cpu_backbone_seed1 \
        > results/cpu_backbone_seed1/backbone_spread.md

Reads each folder's ``per_seed.csv`` and ``claims.csv`` (``airpose reproduce ... --write-reference``).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import pandas as pd

from airpose_lib.eval.ablation import table_to_markdown

METRICS = {"mpe_m": "MPE [m]", "mpjpe_m": "MPJPE [m]", "mpjpe_true_root_m": "MPJPE true root [m]",
           "root_rot_median_deg": "root median [deg]", "root_above90_pct": "root > 90 deg [%]"}


def variant_table(first: pd.DataFrame, second: pd.DataFrame) -> pd.DataFrame:
    """Per variant and metric: each backbone's mean and SD over its seeds, the difference of the
    means (second - first), and that difference over the larger of the two seed SDs."""
    rows = []
    for variant, a in first.groupby("variant", sort=False):
        b = second[second["variant"] == variant]
        if b.empty:
            continue
        for col, label in METRICS.items():
            sd = max(a[col].std(ddof=1), b[col].std(ddof=1))
            diff = b[col].mean() - a[col].mean()
            rows.append({"method": a["method"].iloc[0], "metric": label,
                         "backbone 0": f"{a[col].mean():.4f} ± {a[col].std(ddof=1):.4f}",
                         "backbone 1": f"{b[col].mean():.4f} ± {b[col].std(ddof=1):.4f}",
                         "difference": f"{diff:+.4f}", "difference / seed SD": f"{diff / sd:+.1f}" if sd > 0 else "-",
                         "seeds": f"{len(a)} / {len(b)}"})
    return pd.DataFrame(rows)


def claims_table(first: pd.DataFrame, second: pd.DataFrame) -> pd.DataFrame:
    """Each claim's relative gain with its pair-bootstrap interval and verdict on both backbones."""
    def gain(r):
        return f"{r['gain [%]']:.1f} ({r['gain CI low [%]']:.1f} to {r['gain CI high [%]']:.1f}), {r['verdict']}"

    b = second.set_index("claim")
    return pd.DataFrame([{"claim": r["claim"], "backbone 0 gain [%]": gain(r),
                          "backbone 1 gain [%]": gain(b.loc[r["claim"]]) if r["claim"] in b.index else "-",
                          "paper gain [%]": f"{r['paper gain [%]']:.1f}"} for _, r in first.iterrows()])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("first", type=Path, help="the reference's folder (backbone 0)")
    ap.add_argument("second", type=Path, help="the second backbone's folder")
    args = ap.parse_args()
    per_seed = [pd.read_csv(d / "per_seed.csv") for d in (args.first, args.second)]
    claims = [pd.read_csv(d / "claims.csv") for d in (args.first, args.second)]
    print(f"Backbone 0: `{args.first}`; backbone 1: `{args.second}`. Mean ± SD over the regressor seeds "
          "(the same seeds on both).\n")
    print(table_to_markdown(variant_table(*per_seed).set_index("method")))
    print("\nThe claims (pair bootstrap over two-view test samples pooled over the seeds, 95 %):\n")
    print(table_to_markdown(claims_table(*claims).set_index("claim")))


if __name__ == "__main__":
    main()
