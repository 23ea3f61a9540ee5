"""Table I of the paper (the ablation on synthetic data) and the kit's own version of it.

``PAPER_TABLE_I`` holds the paper's numbers; :func:`ablation_table` aggregates the kit's per-view
tables over seeds (mean and standard deviation) and puts the paper's numbers in adjacent columns,
so every reproduction shows both side by side.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

__all__ = ["VARIANT_LABELS", "PAPER_TABLE_I", "ablation_table", "ordering_checks", "table_to_markdown",
           "table_to_latex"]

#: Row names of Table I for the kit's variant names.
VARIANT_LABELS = {
    "baseline": "Baseline",
    "multiview": "Baseline + Multi-view",
    "fullcam": "Baseline + Fullcam",
    "airpose": "AirPose",
}

#: Table I of the paper (synthetic test set, metres).
PAPER_TABLE_I = pd.DataFrame(
    {"MPE [m]": [0.50, 0.46, 0.22, 0.15], "MPJPE [m]": [0.091, 0.084, 0.077, 0.072]},
    index=pd.Index(list(VARIANT_LABELS.values()), name="method"),
)


def ablation_table(per_view: Mapping[tuple[str, int], pd.DataFrame]) -> pd.DataFrame:
    """Kit numbers (mean and std over seeds) next to the paper's.

    Args:
        per_view: (variant, seed) -> the per-view table of that run
            (:func:`airpose_lib.eval.tables.per_view_table`: columns ``mpe_m``, ``mpjpe_m``,
            ``pa_mpjpe_m``, one row per test image and view).
    Returns:
        one row per variant (Table I order, paper labels) with columns ``MPE [m]``,
        ``MPE std [m]``, ``MPE paper [m]``, ``MPJPE [m]``, ``MPJPE std [m]``, ``MPJPE paper [m]``,
        ``PA-MPJPE [m]``, ``seeds``. The std is over the seeds' means (NaN for one seed).
    """
    rows = []
    for (variant, seed), table in per_view.items():
        rows.append({"variant": variant, "seed": seed, "mpe": table["mpe_m"].mean(),
                     "mpjpe": table["mpjpe_m"].mean(), "pa_mpjpe": table["pa_mpjpe_m"].mean()})
    runs = pd.DataFrame(rows)
    unknown = set(runs["variant"]) - set(VARIANT_LABELS)
    if unknown:
        raise ValueError(f"unknown variants {sorted(unknown)}; expected {list(VARIANT_LABELS)}")
    g = runs.groupby("variant")
    out = pd.DataFrame({
        "MPE [m]": g["mpe"].mean(),
        "MPE std [m]": g["mpe"].std(ddof=1),
        "MPJPE [m]": g["mpjpe"].mean(),
        "MPJPE std [m]": g["mpjpe"].std(ddof=1),
        "PA-MPJPE [m]": g["pa_mpjpe"].mean(),
        "seeds": g["seed"].count(),
    })
    out.index = [VARIANT_LABELS[v] for v in out.index]
    order = [label for label in VARIANT_LABELS.values() if label in out.index]
    out = out.loc[order]
    out.insert(2, "MPE paper [m]", PAPER_TABLE_I.loc[order, "MPE [m]"].to_numpy())
    out.insert(5, "MPJPE paper [m]", PAPER_TABLE_I.loc[order, "MPJPE [m]"].to_numpy())
    out.index.name = "method"
    return out


def ordering_checks(table: pd.DataFrame) -> pd.DataFrame:
    """The paper's qualitative claims about Table I, checked on an :func:`ablation_table`.

    Returns:
        one row per claim: ``claim``, ``holds`` (bool, or None when a variant is missing) and the
        kit's numbers it rests on.
    """
    B, M, F, A = (VARIANT_LABELS[v] for v in ("baseline", "multiview", "fullcam", "airpose"))
    mpe, mpjpe = table["MPE [m]"], table["MPJPE [m]"]

    def check(claim: str, names: Sequence[str], test) -> dict:
        if not all(n in table.index for n in names):
            return {"claim": claim, "holds": None, "kit values": "variant missing"}
        return {"claim": claim, "holds": bool(test()),
                "kit values": ", ".join(f"{n}: {mpe[n]:.3f} / {mpjpe[n]:.3f}" for n in names)}

    rows = [
        check("MPE: Baseline > Fullcam > AirPose", (B, F, A), lambda: mpe[B] > mpe[F] > mpe[A]),
        check("MPE: Multi-view within 25 % of Baseline (no P, no full camera)", (B, M),
              lambda: abs(mpe[M] - mpe[B]) <= 0.25 * mpe[B]),
        check("MPJPE decreases Baseline > Multi-view > Fullcam > AirPose", (B, M, F, A),
              lambda: mpjpe[B] > mpjpe[M] > mpjpe[F] > mpjpe[A]),
        check("MPJPE: AirPose < Baseline", (B, A), lambda: mpjpe[A] < mpjpe[B]),
    ]
    return pd.DataFrame(rows).set_index("claim")


def _fmt(x, digits: int) -> str:
    if isinstance(x, (float, np.floating)):
        return "-" if np.isnan(x) else f"{x:.{digits}f}"
    return str(x)


def table_to_markdown(table: pd.DataFrame, digits: int = 3) -> str:
    """A GitHub-flavoured Markdown table (no extra dependency such as ``tabulate``)."""
    head = [table.index.name or ""] + [str(c) for c in table.columns]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, row in table.astype(object).iterrows():  # object rows keep integer columns integer
        lines.append("| " + " | ".join([str(name)] + [_fmt(v, digits) for v in row]) + " |")
    return "\n".join(lines) + "\n"


def table_to_latex(table: pd.DataFrame, digits: int = 3, caption: str = "") -> str:
    """A booktabs LaTeX table."""
    esc = lambda s: str(s).replace("%", r"\%").replace("_", r"\_")  # noqa: E731
    cols = "l" + "r" * len(table.columns)
    lines = [r"\begin{table}[t]", r"\centering", rf"\begin{{tabular}}{{{cols}}}", r"\toprule",
             " & ".join([esc(table.index.name or "")] + [esc(c) for c in table.columns]) + r" \\",
             r"\midrule"]
    for name, row in table.astype(object).iterrows():
        lines.append(" & ".join([esc(name)] + [_fmt(v, digits) for v in row]) + r" \\")
    lines += [r"\bottomrule", r"\end{tabular}"]
    if caption:
        lines.append(rf"\caption{{{esc(caption)}}}")
    lines.append(r"\end{table}")
    return "\n".join(lines) + "\n"
