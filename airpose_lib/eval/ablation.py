"""Table I of the paper (the ablation on synthetic data) and the kit's own version of it.

``PAPER_TABLE_I`` holds the paper's numbers; :func:`per_seed_table` reduces each run's per-view
table to its metric means, and :func:`ablation_table` aggregates those over seeds (mean and
standard deviation), puts the paper's numbers in adjacent columns, so every reproduction shows
both side by side, and adds the mean-body reference rows (:mod:`airpose_lib.eval.mean_body`: what
a stature-blind estimate with the ground-truth pose gets, neutral and of the true gender), the
scale MPE is read against. Whether the orderings are significant is :mod:`airpose_lib.eval.significance`.
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pandas as pd

from .mean_body import GENDERED_LABEL, MEAN_BODY_LABELS, NEUTRAL_LABEL, PROPORTION_LABEL

__all__ = ["VARIANT_LABELS", "PAPER_TABLE_I", "ROOT_FLIP_DEG", "PER_SEED_METRICS", "TABLE_COLUMNS", "per_seed_table",
           "ablation_table", "paper_gaps", "ablation_findings", "table_to_markdown", "table_to_latex"]

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


#: Root-orientation errors above this (degrees) are counted apart: a body turned more than a
#: quarter turn away from the truth (a front/back flip, not imprecision).
ROOT_FLIP_DEG = 90.0


def _share_above_flip_pct(errors_deg: pd.Series) -> float:
    """Percentage of the images whose geodesic root error exceeds :data:`ROOT_FLIP_DEG`."""
    return 100.0 * float((errors_deg > ROOT_FLIP_DEG).mean())


#: Per-seed metric -> (per-view column, how the images of one run are reduced: a pandas method's
#: name or a function of the column).
PER_SEED_METRICS = {
    "mpe_m": ("mpe_m", "mean"),
    "mpjpe_m": ("mpjpe_m", "mean"),
    "mpjpe_shape_m": ("mpjpe_shape_m", "mean"),
    "mpjpe_true_root_m": ("mpjpe_true_root_m", "mean"),
    "pa_mpjpe_m": ("pa_mpjpe_m", "mean"),
    "root_rot_median_deg": ("root_rot_deg", "median"),
    "root_yaw_median_deg": ("root_yaw_deg", "median"),
    "root_tilt_median_deg": ("root_tilt_deg", "median"),
    "root_above90_pct": ("root_rot_deg", _share_above_flip_pct),
}
#: Per-seed metric -> Table I column (``ablation_table``).
TABLE_COLUMNS = {
    "mpe_m": "MPE [m]",
    "mpjpe_m": "MPJPE [m]",
    "mpjpe_shape_m": "MPJPE shape-aware [m]",
    "mpjpe_true_root_m": "MPJPE true root [m]",
    "pa_mpjpe_m": "PA-MPJPE [m]",
    "root_rot_median_deg": "root orient. median [deg]",
    "root_yaw_median_deg": "root yaw median [deg]",
    "root_tilt_median_deg": "root tilt median [deg]",
    "root_above90_pct": "root orient. > 90 deg [%]",
    "mpe_tight_m": "MPE tight box [m]",
    "mpjpe_tight_m": "MPJPE tight box [m]",
    "mpe_camera0_m": "MPE camera 0 [m]",
}


def per_seed_table(per_view: Mapping[tuple[str, int], pd.DataFrame],
                   per_view_tight: Mapping[tuple[str, int], pd.DataFrame] | None = None,
                   wall_s: Mapping[tuple[str, int], float | None] | None = None,
                   camera0: bool = False) -> pd.DataFrame:
    """One row per (variant, seed): the run's metric means over its test images.

    Args:
        per_view: (variant, seed) -> per-view table (:func:`airpose_lib.eval.tables.per_view_table`
            columns; ``mpjpe_shape_m`` and ``root_rot_deg`` are optional).
        per_view_tight: the same on tight-box test crops (optional, per run).
        wall_s: (variant, seed) -> training wall time in seconds (optional, None when unknown).
        camera0: add ``mpe_camera0_m``, the MPE of view 0 alone (the official code prints camera
            0's; the kit's ``mpe_m`` averages both cameras).
    Returns:
        columns ``variant, method, seed`` and those of :data:`PER_SEED_METRICS` present in every
        table (root orientation: the medians over images of the geodesic, yaw and tilt errors and
        the percentage above :data:`ROOT_FLIP_DEG`), ``mpe_tight_m``, ``mpjpe_tight_m`` when
        every run has a tight-box table, ``images``, and ``wall_s`` when given; Table I order.
    """
    unknown = {v for v, _ in per_view} - set(VARIANT_LABELS)
    if unknown:
        raise ValueError(f"unknown variants {sorted(unknown)}; expected {list(VARIANT_LABELS)}")
    if not per_view:
        raise ValueError("no runs to tabulate")
    present = [m for m, (col, _) in PER_SEED_METRICS.items() if all(col in t for t in per_view.values())]
    tight = per_view_tight is not None and all(per_view_tight.get(k) is not None for k in per_view)
    rows = []
    for (variant, seed), t in per_view.items():
        row = {"variant": variant, "method": VARIANT_LABELS[variant], "seed": seed}
        for m in present:
            col, how = PER_SEED_METRICS[m]
            row[m] = float(how(t[col]) if callable(how) else getattr(t[col], how)())
        if tight:
            tt = per_view_tight[variant, seed]
            row["mpe_tight_m"], row["mpjpe_tight_m"] = float(tt["mpe_m"].mean()), float(tt["mpjpe_m"].mean())
        if camera0:
            row["mpe_camera0_m"] = float(t.loc[t["view"] == 0, "mpe_m"].mean())
        row["images"] = len(t)
        if wall_s is not None:
            w = wall_s.get((variant, seed))
            row["wall_s"] = float(w) if w is not None else float("nan")
        rows.append(row)
    out = pd.DataFrame(rows)
    order = {v: i for i, v in enumerate(VARIANT_LABELS)}
    return out.sort_values(["variant", "seed"], key=lambda c: c.map(order) if c.name == "variant" else c,
                           ignore_index=True)


def ablation_table(per_view: Mapping[tuple[str, int], pd.DataFrame],
                   references: pd.DataFrame | None = None,
                   per_view_tight: Mapping[tuple[str, int], pd.DataFrame] | None = None,
                   camera0: bool = False) -> pd.DataFrame:
    """Kit numbers (mean and std over seeds) next to the paper's, and the mean-body references.

    Args:
        per_view: (variant, seed) -> the per-view table of that run
            (:func:`airpose_lib.eval.tables.per_view_table`: columns ``mpe_m``, ``mpjpe_m``,
            ``pa_mpjpe_m``, optionally ``mpjpe_shape_m`` and ``root_rot_deg``; one row per test
            image and view).
        references: per-view rows of :func:`airpose_lib.eval.mean_body.mean_body_references`
            (``method``, ``mpe_m``): adds one row per reference (``method``), MPE only (its other
            columns are NaN, shown as ``-``).
        per_view_tight: the same runs evaluated on tight-box test crops: adds the tight-box
            MPE / MPJPE columns (only when every run has one).
        camera0: add ``MPE camera 0 [m]`` (the official code's printed MPE: view 0 alone).
    Returns:
        one row per variant (Table I order, paper labels) with columns ``MPE [m]``,
        ``MPE std [m]``, ``MPE paper [m]``, ``MPJPE [m]``, ``MPJPE std [m]``, ``MPJPE paper [m]``,
        then the extra columns present (``MPJPE shape-aware [m]``, ``MPJPE true root [m]`` (the
        body pose alone: Table I's MPJPE with the true root orientation), ``PA-MPJPE [m]``,
        ``root orient. median [deg]``, ``root yaw median [deg]``, ``root tilt median [deg]``,
        ``root orient. > 90 deg [%]``, ``MPE tight box [m]``, ``MPJPE tight box [m]``; means over
        seeds) and ``seeds``. The std is over the seeds' means (NaN for one seed).
    """
    runs = per_seed_table(per_view, per_view_tight, camera0=camera0)
    g = runs.groupby("method", sort=False)
    out = pd.DataFrame({
        "MPE [m]": g["mpe_m"].mean(),
        "MPE std [m]": g["mpe_m"].std(ddof=1),
        "MPE paper [m]": PAPER_TABLE_I["MPE [m]"],
        "MPJPE [m]": g["mpjpe_m"].mean(),
        "MPJPE std [m]": g["mpjpe_m"].std(ddof=1),
        "MPJPE paper [m]": PAPER_TABLE_I["MPJPE [m]"],
    })
    for m, column in TABLE_COLUMNS.items():
        if m not in ("mpe_m", "mpjpe_m") and m in runs:
            out[column] = g[m].mean()
    out["seeds"] = g["seed"].count().astype("Int64")
    out = out.loc[[m for m in VARIANT_LABELS.values() if m in g.groups]]  # Table I order
    if references is not None:
        mpe = references.groupby("method", sort=False)["mpe_m"].mean()
        mpe = mpe.reindex([m for m in MEAN_BODY_LABELS if m in mpe.index] + [m for m in mpe.index
                                                                              if m not in MEAN_BODY_LABELS])
        rows = pd.DataFrame({"MPE [m]": mpe.to_numpy(float)}, index=list(mpe.index))
        out = pd.concat([out, rows.reindex(columns=out.columns)])
        out["seeds"] = out["seeds"].astype("Int64")
    out.index.name = "method"
    return out


#: Stature-blind reference row -> its ratio column in :func:`paper_gaps` and its name in the findings.
_REFERENCE_NAMES = {NEUTRAL_LABEL: "neutral mean body", GENDERED_LABEL: "true-gender mean body"}
#: The reference that reads stature from the body's proportions, named the same way.
_PROPORTION_NAME = "body at its proportions' stature"


def _variant_rows(table: pd.DataFrame) -> list[str]:
    """The variant rows of :func:`ablation_table` (the mean-body reference rows left out)."""
    return [m for m in table.index if m not in MEAN_BODY_LABELS]


def paper_gaps(table: pd.DataFrame) -> pd.DataFrame:
    """How far each variant is from the paper and from the mean-body references, as ratios.

    Returns:
        one row per variant of :func:`ablation_table`: ``MPE kit / paper``, ``MPJPE kit / paper``
        and, per reference row, ``MPE kit / neutral mean body`` and ``MPE kit / true-gender mean
        body`` (how many times what a stature-blind estimate with the ground-truth pose gets) and
        ``MPE kit / body at its proportions' stature`` (what one that reads stature from the
        body's proportions gets).
    """
    rows = _variant_rows(table)
    out = pd.DataFrame({"MPE kit / paper": table.loc[rows, "MPE [m]"] / table.loc[rows, "MPE paper [m]"],
                        "MPJPE kit / paper": table.loc[rows, "MPJPE [m]"] / table.loc[rows, "MPJPE paper [m]"]})
    for label, name in {**_REFERENCE_NAMES, PROPORTION_LABEL: _PROPORTION_NAME}.items():
        if label in table.index:
            out[f"MPE kit / {name}"] = table.loc[rows, "MPE [m]"] / table.loc[label, "MPE [m]"]
    return out


def _signed_length(x_m: float) -> str:
    """A paired difference: millimetres below a metre, metres above."""
    return f"{x_m * 1000:+.1f} mm" if abs(x_m) < 1 else f"{x_m:+.3f} m"


def _listed(rows: pd.DataFrame) -> str:
    return "; ".join(f"{r['claim']} ({_signed_length(r['difference [m]'])})" for _, r in rows.iterrows()) or "none"


def _gains(claims: pd.DataFrame) -> str | None:
    """The effect-size line of :func:`ablation_findings` (None when the claims have no gains)."""
    if not {"gain [%]", "paper gain [%]", "of paper's size"} <= set(claims.columns):
        return None
    measured = claims[claims["gain [%]"].notna() & claims["paper gain [%]"].notna()]
    if measured.empty:
        return None
    sizes = "; ".join(f"{r['claim']} {r['gain [%]']:.1f} % ({r['gain CI low [%]']:.1f} to "
                      f"{r['gain CI high [%]']:.1f}) against the paper's {r['paper gain [%]']:.1f} %"
                      for _, r in measured.iterrows())
    reach = int(measured["of paper's size"].astype(bool).sum())
    return (f"* **Effect sizes** (relative gain, 95 % interval, the paper's): {reach} of {len(measured)} reach "
            f"a third of the paper's gain. {sizes}.")


def ablation_findings(table: pd.DataFrame, claims: pd.DataFrame | None = None) -> str:
    """What a run's Table I says, as Markdown built from its own tables (notebook 02's summary):
    no number in it is typed by hand, so it cannot contradict the tables above it.

    Args:
        table: :func:`ablation_table` (variant rows in Table I order, optional reference rows and
            extra columns; a column that is absent or NaN is left out of the text).
        claims: :func:`airpose_lib.eval.significance.claims_table` (index ``claim``, columns
            ``difference [m]`` and ``verdict``; or ``claim`` as a column, as in ``claims.csv``), or None.
    Returns:
        a bulleted Markdown paragraph: AirPose against the paper and the mean-body references, the claims'
        verdicts and (when ``claims`` has them) their relative gains next to the paper's, what the
        root orientation adds to MPJPE, and the seed count's caveat.
    """
    rows = _variant_rows(table)
    best = "AirPose" if "AirPose" in rows else rows[-1]
    r = table.loc[best]

    def has(column: str) -> bool:
        return column in table.columns and pd.notna(r.get(column))

    head = (f"* **{best}**: MPE {r['MPE [m]']:.3f} m (the paper's {r['MPE paper [m]']:.3f} m), "
            f"MPJPE {r['MPJPE [m]']:.3f} m (the paper's {r['MPJPE paper [m]']:.3f} m)")
    refs = {name: float(table.loc[label, "MPE [m]"]) for label, name in _REFERENCE_NAMES.items()
            if label in table.index}
    if refs:
        head += ("; a stature-blind estimate with the ground-truth pose gets MPE "
                 + " and ".join(f"{v:.3f} m with the {name}" for name, v in refs.items())
                 + f" on this data, so {best}'s MPE is "
                 + " and ".join(f"{r['MPE [m]'] / v:.2f} x the {name}'s" for name, v in refs.items())
                 + ", and the paper's " + " and ".join(
                     f"{'below' if r['MPE paper [m]'] < v else 'above'} the {name}'s" for name, v in refs.items()))
    if PROPORTION_LABEL in table.index:
        v = float(table.loc[PROPORTION_LABEL, "MPE [m]"])
        head += (f"; the subject's own body at the stature a linear model reads from its proportions "
                 f"gets {v:.3f} m, so an estimate that read the body's proportions could come that close")
    lines = [head + "."]
    if claims is not None and len(claims):
        claims = claims if "claim" in claims.columns else claims.reset_index()  # claims_table's index
        verdicts = claims["verdict"]
        lines.append(f"* **Claims**: {int((verdicts == 'holds').sum())} of the paper's {len(claims)} orderings "
                     f"hold with significance. Not significant: {_listed(claims[verdicts == 'not significant'])}. "
                     f"Reversed: {_listed(claims[verdicts == 'reversed'])}.")
        gains = _gains(claims)
        if gains is not None:
            lines.append(gains)
    if has("MPJPE true root [m]"):
        others = ", ".join(f"{m} {table.loc[m, 'MPJPE true root [m]']:.3f}" for m in rows if m != best)
        root = ""
        if has("root orient. median [deg]"):
            root = f"median root-orientation error {r['root orient. median [deg]']:.1f} deg"
            if all(has(c) for c in ("root yaw median [deg]", "root tilt median [deg]", "root orient. > 90 deg [%]")):
                root += (f": yaw {r['root yaw median [deg]']:.1f} deg and tilt {r['root tilt median [deg]']:.1f} deg "
                         f"median, {r['root orient. > 90 deg [%]']:.1f} % of the images above 90 deg")
            root = f" ({root})"
        lines.append(f"* **Root orientation**: with the ground-truth root orientation, {best}'s MPJPE is "
                     f"{r['MPJPE true root [m]']:.3f} m ({others}); the predicted root orientation{root} "
                     f"adds {(r['MPJPE [m]'] - r['MPJPE true root [m]']) * 1000:.1f} mm to the "
                     f"{r['MPJPE [m]']:.3f} m.")
    if has("PA-MPJPE [m]"):
        lines.append(f"* **Alignment**: PA-MPJPE, which aligns rotation and scale away, is "
                     f"{r['PA-MPJPE [m]']:.3f} m against MPJPE's {r['MPJPE [m]']:.3f} m.")
    seeds = int(r["seeds"]) if has("seeds") else 1
    if seeds == 1:
        lines.append("* **One seed**: no seed spread, so a claim that holds may hold by luck.")
    return "\n".join(lines)


def _fmt(x, digits: int) -> str:
    if x is None or x is pd.NA:
        return "-"
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
