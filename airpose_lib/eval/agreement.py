"""Does a run on shipped networks agree with the reference that made them?

A profile that runs another profile's shipped networks (``networks: {shipped: cpu}``) on data
rendered fresh can only differ from that profile's committed reference (``results/cpu/``) by
the fresh test split's sampling error and the CPU's rounding: the networks are the same. Each
quantity has a tolerance (:data:`TOLERANCES`), and :func:`table_agreement` /
:func:`recordings_agreement` say per row whether this run is within it. The claims keep their
verdicts or they do not: a verdict has no tolerance.

Next to each Table I tolerance stands the fresh split's own sampling error (the standard error of
the variant's mean over two-view samples): the tolerance in those units says how much room it
leaves (``tolerance / SE``), so that a pass is not one machine's last digits.

Pure pandas / numpy.
"""
from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pandas as pd

from .ablation import table_to_markdown

__all__ = ["TOLERANCES", "CHECK_FILE", "table_agreement", "claims_agreement", "recordings_agreement",
           "agreement_message", "sample_standard_errors", "write_check"]

#: What a notebook writes into its output folder: the message line, then the comparison's rows.
CHECK_FILE = "reference_check.md"

#: quantity -> (column, kind, tolerance): ``relative`` (a share of the reference) or ``absolute``.
TOLERANCES = {
    "MPE": ("MPE [m]", "relative", 0.05),
    "MPJPE": ("MPJPE [m]", "relative", 0.05),
    "root orientation median": ("root orient. median [deg]", "absolute", 1.0),
    "UAV2 in UAV1 position median": ("rel_t_median_m", "relative", 0.20),
}
#: Table I columns -> the per-view column whose sample means give their sampling error.
_PER_VIEW = {"MPE [m]": "mpe_m", "MPJPE [m]": "mpjpe_m"}


def _within(value: float, reference: float, kind: str, tolerance: float) -> tuple[float, bool]:
    """``(difference in the tolerance's units, within)``: relative differences as a share."""
    diff = (value - reference) / abs(reference) if kind == "relative" else value - reference
    return float(diff), bool(np.isfinite(diff) and abs(diff) <= tolerance)


def sample_standard_errors(per_view: pd.DataFrame, column: str) -> float:
    """Standard error of a per-view column's mean, the unit of sampling a two-view sample (its
    views averaged first: they share the person)."""
    per_sample = per_view.groupby("sample")[column].mean()
    return float(per_sample.std(ddof=1) / np.sqrt(len(per_sample))) if len(per_sample) > 1 else float("nan")


def table_agreement(table: pd.DataFrame, reference: pd.DataFrame,
                    per_view: Mapping[str, pd.DataFrame] | None = None) -> pd.DataFrame:
    """This run's Table I against the reference's, variant by variant.

    Args:
        table: :func:`airpose_lib.eval.ablation.ablation_table` of this run (index ``method``).
        reference: the reference's ``table1.csv`` (index ``method``).
        per_view: method -> this run's per-view table, for the sampling error (optional).
    Returns:
        one row per variant and quantity: ``this run``, ``reference``, ``difference`` (a share
        for relative tolerances), ``tolerance``, ``tolerance / SE`` and ``within``.
    """
    rows = []
    for method in [m for m in table.index if m in reference.index and pd.notna(table.loc[m].get("MPJPE [m]"))]:
        for quantity, (column, kind, tol) in TOLERANCES.items():
            if column not in table.columns or column not in reference.columns:
                continue
            value, ref = float(table.loc[method, column]), float(reference.loc[method, column])
            diff, ok = _within(value, ref, kind, tol)
            se = float("nan")
            if per_view is not None and column in _PER_VIEW and method in per_view:
                se = sample_standard_errors(per_view[method], _PER_VIEW[column])
                se = se / abs(ref) if kind == "relative" else se
            rows.append({"method": method, "quantity": quantity, "this run": value, "reference": ref,
                         "difference": diff, "kind": kind, "tolerance": tol,
                         "tolerance / SE": tol / se if se and np.isfinite(se) else float("nan"), "within": ok})
    return pd.DataFrame(rows)


def claims_agreement(claims: pd.DataFrame, reference: pd.DataFrame) -> pd.DataFrame:
    """Each claim's verdict here and in the reference (``within``: the same verdict); either table
    may hold the claim as a column or as its index."""
    as_column = lambda t: t if "claim" in t.columns else t.reset_index()  # noqa: E731
    ref = as_column(reference).set_index("claim")["verdict"]
    out = as_column(claims)[["claim", "gain [%]", "verdict"]].copy()
    out["reference verdict"] = out["claim"].map(ref)
    out["within"] = out["verdict"] == out["reference verdict"]
    return out.reset_index(drop=True)


def recordings_agreement(errors: pd.DataFrame, reference: pd.DataFrame,
                         methods: tuple[str, ...] = ("AirPose", "AirPose+")) -> pd.DataFrame:
    """UAV2's position in UAV1's frame, median over each recording's frames, against the reference.

    Args:
        errors: this run's recording error table (``sequence``, ``method``, ``rel_t_median_m``).
        reference: the reference's (``results/<profile>/recordings/recording_errors.csv``).
    """
    column, kind, tol = TOLERANCES["UAV2 in UAV1 position median"]
    ref = reference.set_index(["sequence", "method"])[column]
    rows = []
    for _, r in errors[errors["method"].isin(methods)].iterrows():
        key = (r["sequence"], r["method"])
        if key not in ref.index:
            continue
        diff, ok = _within(float(r[column]), float(ref[key]), kind, tol)
        rows.append({"sequence": key[0], "method": key[1], "quantity": "UAV2 in UAV1 position median",
                     "this run": float(r[column]), "reference": float(ref[key]), "frames": int(r["frames"]),
                     "difference": diff, "kind": kind, "tolerance": tol, "within": ok})
    return pd.DataFrame(rows)


def agreement_message(parts: Mapping[str, pd.DataFrame], reference: str | Path) -> str:
    """One line: "agrees with the committed reference" or how many rows are outside."""
    checked = {k: v for k, v in parts.items() if v is not None and not v.empty}
    if not checked:
        return f"nothing to compare with {reference}"
    bad = {k: int((~v["within"].astype(bool)).sum()) for k, v in checked.items()}
    n = sum(len(v) for v in checked.values())
    if not any(bad.values()):
        return f"agrees with the committed reference {reference}: all {n} comparisons within their tolerances"
    where = ", ".join(f"{b} of {len(checked[k])} {k}" for k, b in bad.items() if b)
    return f"DIFFERS from the committed reference {reference}: {where} outside their tolerances (rows below)"


def write_check(out: str | Path, message: str, rows: pd.DataFrame | None) -> Path:
    """``<out>/reference_check.md``: the message, then the rows (``airpose reproduce`` prints it)."""
    path = Path(out) / CHECK_FILE
    body = "" if rows is None or rows.empty else "\n\n" + table_to_markdown(rows.set_index(rows.columns[0]), 4)
    path.write_text(message + body + "\n")
    return path
