"""Table I on two independently pretrained backbones, side by side.

The three regressor seeds of a Table I all read one frozen backbone, so their spread leaves out
the backbone's own pretraining. Here the same seeds (the same regressor initialisations) are run
on a second backbone, pretrained from scratch with another seed, and each variant's mean is set
against the first backbone's with both seed spreads beside it; then each of the six claims on
both. Two backbones are one draw of the between-backbone difference, not its distribution.

    python scripts/backbone_spread.py results/cpu_four_stages results/cpu_backbone_seed1 \
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


def differences(first: pd.DataFrame, second: pd.DataFrame) -> pd.DataFrame:
    """Per variant and metric (one row each): each backbone's mean and SD over its seeds, the
    difference of the means (second - first) and that difference over the larger seed SD."""
    rows = []
    for variant, a in first.groupby("variant", sort=False):
        b = second[second["variant"] == variant]
        if b.empty:
            continue
        for col, label in METRICS.items():
            sd0, sd1 = a[col].std(ddof=1), b[col].std(ddof=1)
            diff = b[col].mean() - a[col].mean()
            rows.append({"method": a["method"].iloc[0], "metric": label, "mean 0": a[col].mean(), "sd 0": sd0,
                         "mean 1": b[col].mean(), "sd 1": sd1, "difference": diff,
                         "ratio": diff / max(sd0, sd1) if max(sd0, sd1) > 0 else float("nan"),
                         "seeds": f"{len(a)} / {len(b)}"})
    return pd.DataFrame(rows)


def variant_table(diffs: pd.DataFrame) -> pd.DataFrame:
    """:func:`differences` as printed: mean ± seed SD per backbone, the difference, its ratio."""
    return pd.DataFrame({
        "method": diffs["method"], "metric": diffs["metric"],
        "backbone 0": [f"{m:.4f} ± {s:.4f}" for m, s in zip(diffs["mean 0"], diffs["sd 0"])],
        "backbone 1": [f"{m:.4f} ± {s:.4f}" for m, s in zip(diffs["mean 1"], diffs["sd 1"])],
        "difference": [f"{d:+.4f}" for d in diffs["difference"]],
        "difference / seed SD": ["-" if pd.isna(r) else f"{r:+.1f}" for r in diffs["ratio"]],
        "seeds": diffs["seeds"]})


def paired_claims(first: pd.DataFrame, second: pd.DataFrame) -> pd.DataFrame:
    """``first``'s claims in its order, each with the second backbone's columns suffixed `` 1``
    (NaN where the second has no such claim)."""
    return first.merge(second, on="claim", how="left", suffixes=("", " 1"), validate="one_to_one")


def summary(diffs: pd.DataFrame, first: pd.DataFrame, second: pd.DataFrame) -> str:
    """What the two tables say, in numbers: per metric the range of the difference over the
    variants and of its ratio to the seed SD, whether all variants move the same way, and how
    many claims keep their verdict and have overlapping gain intervals."""
    lines = []
    for label, d in diffs.groupby("metric", sort=False):
        same = "all variants the same way" if (d["difference"] > 0).all() or (d["difference"] < 0).all() \
            else "the variants differ in sign"
        lines.append(f"- {label}: backbone 1 - backbone 0 from {d['difference'].min():+.4f} to "
                     f"{d['difference'].max():+.4f} ({same}); |difference| / seed SD "
                     f"{d['ratio'].abs().min():.1f} to {d['ratio'].abs().max():.1f}.")
    both = paired_claims(first, second).dropna(subset=["verdict 1"])
    same_verdict = int((both["verdict"] == both["verdict 1"]).sum())
    overlap = int(((both["gain CI low [%]"] <= both["gain CI high [%] 1"])
                   & (both["gain CI low [%] 1"] <= both["gain CI high [%]"])).sum())
    lines.append(f"- Claims: {same_verdict} of {len(both)} keep their verdict on the second backbone; "
                 f"the two gain intervals overlap for {overlap} of {len(both)}.")
    return "\n".join(lines)


def claims_table(first: pd.DataFrame, second: pd.DataFrame) -> pd.DataFrame:
    """Each claim's relative gain with its pair-bootstrap interval and verdict on both backbones."""
    def gain(r, k=""):
        if pd.isna(r[f"verdict{k}"]):
            return "-"
        return (f"{r[f'gain [%]{k}']:.1f} ({r[f'gain CI low [%]{k}']:.1f} to {r[f'gain CI high [%]{k}']:.1f}), "
                f"{r[f'verdict{k}']}")

    return pd.DataFrame([{"claim": r["claim"], "backbone 0 gain [%]": gain(r), "backbone 1 gain [%]": gain(r, " 1"),
                          "paper gain [%]": f"{r['paper gain [%]']:.1f}"}
                         for _, r in paired_claims(first, second).iterrows()])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("first", type=Path, help="the reference's folder (backbone 0)")
    ap.add_argument("second", type=Path, help="the second backbone's folder")
    args = ap.parse_args()
    per_seed = [pd.read_csv(d / "per_seed.csv") for d in (args.first, args.second)]
    claims = [pd.read_csv(d / "claims.csv") for d in (args.first, args.second)]
    print(f"Backbone 0: `{args.first}`; backbone 1: `{args.second}`. Mean ± SD over the regressor seeds "
          "(the same seeds on both).\n")
    diffs = differences(*per_seed)
    print(table_to_markdown(variant_table(diffs).set_index("method")))
    print("\nThe claims (pair bootstrap over two-view test samples pooled over the seeds, 95 %):\n")
    print(table_to_markdown(claims_table(*claims).set_index("claim")))
    print("\nIn numbers (from the two tables above):\n")
    print(summary(diffs, *claims))


if __name__ == "__main__":
    main()
