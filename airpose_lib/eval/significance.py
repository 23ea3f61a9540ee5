"""Are Table I's orderings real? A paired bootstrap over two-view test samples, pooled over seeds.

The paper reads two orderings off Table I: MPE and MPJPE both fall from Baseline to
Baseline + Multi-view to Baseline + Fullcam to AirPose. With a few seeds and a few hundred test
samples a difference of means can come from noise, so each adjacent pair is tested:

* the unit of sampling is the test *sample*, the pair of views of one person at one instant: its
  two views share the person and, in the multi-view variants, the exchanged messages, so they are
  not two independent draws. Per seed s and sample i, e_A(s, i) is variant A's error averaged over
  the views of the sample, and d_si = e_A(s, i) - e_B(s, i) the paired difference of the two
  variants on the same sample (both networks of one seed see the same test set);
* the statistic is the mean of d over seeds and samples;
* its 95 % interval is the percentile interval of the statistic over bootstrap resamples of the
  sample indices, one set of resampled indices shared by every seed and by both variants (a drawn
  sample brings every seed's errors of it: seeds are pooled, not resampled, since a claim must
  survive every training seed);
* "A > B" holds when the per-seed mean difference is positive in *every* seed and the interval
  lies above zero; it is "reversed" when the opposite claim holds by the same rule, and "not
  significant" otherwise;
* its size is the relative gain ``(e_A - e_B) / e_A`` of the means, with its interval from the same
  resamples (the ratio of the resampled means, so numerator and denominator stay paired), next to
  the paper's relative gain from its Table I (``eval.ablation.PAPER_TABLE_I``); a gain is of the
  paper's size here when it reaches :data:`PAPER_GAIN_SHARE` of the paper's (the kit's bar for an effect).

What the seeds vary: the kit's networks, the regressor's initialisation, the order of its training
batches and their random augmentation (``train.config.TrainConfig.seed``); the official
checkpoints, the jitter of the test crops. All variants of all seeds read one pretrained backbone
(the ``cpu`` profile caches its features), so the seed spread does not include the backbone's
own variability.

Pure numpy / pandas.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from .ablation import PAPER_TABLE_I, VARIANT_LABELS

__all__ = ["PAPER_ORDER", "CLAIM_METRICS", "PAPER_GAIN_SHARE", "BootstrapResult", "paired_sample_errors",
           "paired_bootstrap", "bootstrap_interval", "relative_gain", "paper_relative_gain", "claims_table"]

#: The paper's ordering of Table I, largest error first.
PAPER_ORDER = ("baseline", "multiview", "fullcam", "airpose")
#: Table I metric -> per-view column.
CLAIM_METRICS = {"MPE": "mpe_m", "MPJPE": "mpjpe_m"}
#: Share of the paper's relative gain a kit gain must reach to count as an effect of the paper's
#: size ("at least a third of the paper's relative gain").
PAPER_GAIN_SHARE = 1 / 3

_KEYS = ["sample", "view"]


@dataclass(frozen=True)
class BootstrapResult:
    """Paired-bootstrap summary of per-seed, per-unit differences.

    Attributes:
        mean: mean difference over seeds and units.
        low, high: percentile interval of that mean over the resamples.
        per_seed: ``(S,)`` mean difference of each seed over the units.
        n_units: resampled units per seed (two-view samples for Table I, frames for a recording).
        relative, relative_low, relative_high: with ``base``, the relative difference
            ``mean(diffs) / mean(base)`` and its percentile interval over the same resamples (NaN
            without ``base``).
    """

    mean: float
    low: float
    high: float
    per_seed: np.ndarray
    n_units: int
    relative: float = float("nan")
    relative_low: float = float("nan")
    relative_high: float = float("nan")


def paired_bootstrap(diffs: np.ndarray, n_resamples: int = 2000, confidence: float = 0.95,
                     seed: int = 0, chunk: int = 250, block: int = 1,
                     base: np.ndarray | None = None) -> BootstrapResult:
    """Percentile interval of the mean paired difference, resampling units (or blocks of them).

    Args:
        diffs: ``(S, n)`` differences; column i is the same unit (a two-view test sample, a frame)
            in every seed (a 1-D array is one seed). Everything that is not independent of the
            rest must be inside one column: the views of a sample are averaged before this call
            (:func:`paired_sample_errors`).
        n_resamples: bootstrap resamples.
        confidence: interval mass (0.95: the 2.5 and 97.5 percentiles).
        seed: seed of the resampling generator (fixed: the same data give the same interval).
        chunk: resamples drawn at once (bounds memory to ``chunk x n`` indices).
        block: units per resampled block. 1 for independent units (Table I's samples); for the
            frames of a recording, whose errors are correlated in time, consecutive
            non-overlapping blocks of ``block`` frames are resampled whole (a block bootstrap; the
            last block may be shorter), so the interval is not narrowed by counting correlated
            frames as independent.
        base: ``(S, n)`` like ``diffs``, optional: the errors of the variant claimed worse (A of
            ``d = e_A - e_B``); adds the relative difference ``mean(d) / mean(base)`` and its
            interval, each resample's ratio taken over the same drawn units.
    Returns:
        :class:`BootstrapResult`.
    """
    d = np.atleast_2d(np.asarray(diffs, dtype=np.float64))
    S, n = d.shape
    if n == 0 or not np.isfinite(d).all():
        raise ValueError(f"paired_bootstrap needs finite differences on at least one unit, got shape {d.shape}")
    if block < 1:
        raise ValueError(f"block must be >= 1, got {block}")
    if base is not None:
        base = np.atleast_2d(np.asarray(base, dtype=np.float64))
        if base.shape != d.shape or not np.isfinite(base).all():
            raise ValueError(f"base must be finite with the shape of diffs {d.shape}, got {base.shape}")
    # The statistic mean_{s, i in resample} d_si equals the resample mean of the per-unit seed means
    # because every seed uses the same resampled indices.
    d_unit = d.mean(axis=0)
    starts = np.arange(0, n, block)
    sums, counts = np.add.reduceat(d_unit, starts), np.diff(np.append(starts, n)).astype(np.float64)
    base_sums = np.add.reduceat(base.mean(axis=0), starts) if base is not None else None
    rng = np.random.default_rng(seed)
    stats, rel = np.empty(n_resamples), np.empty(n_resamples)
    for start in range(0, n_resamples, chunk):
        stop = min(start + chunk, n_resamples)
        idx = rng.integers(0, len(starts), size=(stop - start, len(starts)))
        d_sum = sums[idx].sum(axis=1)
        stats[start:stop] = d_sum / counts[idx].sum(axis=1)
        if base_sums is not None:
            rel[start:stop] = d_sum / base_sums[idx].sum(axis=1)
    alpha = (1.0 - confidence) / 2.0
    low, high = np.quantile(stats, [alpha, 1.0 - alpha])
    out = BootstrapResult(float(d_unit.mean()), float(low), float(high), d.mean(axis=1), n)
    if base is None:
        return out
    rel_low, rel_high = np.quantile(rel, [alpha, 1.0 - alpha])
    return dataclasses.replace(out, relative=float(d.mean() / base.mean()), relative_low=float(rel_low),
                               relative_high=float(rel_high))


def bootstrap_interval(statistic: Callable[[np.ndarray], float], n_units: int, n_resamples: int = 2000,
                       confidence: float = 0.95, seed: int = 0) -> tuple[float, float, float]:
    """Percentile interval of any statistic of independent units (two-view samples), for a
    statistic that is not a mean (an R^2, a correlation); a mean's is :func:`paired_bootstrap`'s.

    Args:
        statistic: indices ``(n,)`` of the units drawn (with repeats) -> the statistic over them;
            every value of a unit (both views of a sample) must enter through its one index.
        n_units: units to draw from (indices ``0 .. n_units - 1``).
        n_resamples, confidence, seed: as :func:`paired_bootstrap`.
    Returns:
        ``(value on all units, low, high)``.
    """
    if n_units < 2:
        raise ValueError(f"bootstrap_interval needs at least two units, got {n_units}")
    rng = np.random.default_rng(seed)
    stats = np.array([statistic(rng.integers(0, n_units, size=n_units)) for _ in range(n_resamples)])
    alpha = (1.0 - confidence) / 2.0
    low, high = np.nanquantile(stats, [alpha, 1.0 - alpha])
    return float(statistic(np.arange(n_units))), float(low), float(high)


def relative_gain(worse: float, better: float) -> float:
    """``(worse - better) / worse``: the share of the error that the claimed-better variant removes
    (negative when it is worse after all)."""
    return (worse - better) / worse


def paper_relative_gain(a: str, b: str, metric: str) -> float:
    """The paper's relative gain from variant ``a`` to ``b`` in its Table I (:data:`PAPER_TABLE_I`).

    Args:
        a, b: variant names (``baseline`` ...), a claimed worse.
        metric: Table I metric (``MPE``, ``MPJPE``); NaN for one the paper does not report.
    """
    column = f"{metric} [m]"
    if column not in PAPER_TABLE_I:
        return float("nan")
    return relative_gain(float(PAPER_TABLE_I.loc[VARIANT_LABELS[a], column]),
                         float(PAPER_TABLE_I.loc[VARIANT_LABELS[b], column]))


def paired_sample_errors(per_view_by_run: Mapping[tuple[str, int], pd.DataFrame], a: str, b: str,
                         metric: str) -> tuple[list[int], np.ndarray, np.ndarray]:
    """Per-seed, per-sample errors of two variants, each sample's the mean over its views.

    Args:
        per_view_by_run: (variant, seed) -> per-view table (``sample``, ``view``, ``metric``).
        a, b: variant names.
        metric: a per-view column, e.g. ``mpe_m``.
    Returns:
        the seeds that have both variants, and ``e_a``, ``e_b``: ``(S, N)`` errors over the N
        samples whose every view (any view present in one of the tables) both variants scored
        finitely in every seed, in sorted sample order; row s is seed ``seeds[s]``. A sample with
        a view missing anywhere drops out of every seed and both variants, so the pairs stay
        paired and each sample's error averages the same views.
    """
    seeds = sorted(s for (v, s) in per_view_by_run if v == a and (b, s) in per_view_by_run)
    if not seeds:
        raise ValueError(f"no seed has both {a!r} and {b!r}")
    columns = {}
    for s in seeds:
        for v in (a, b):
            t = per_view_by_run[v, s].set_index(_KEYS)[metric].astype(np.float64)
            if not t.index.is_unique:
                raise ValueError(f"{v} seed {s}: the per-view table repeats a (sample, view) pair")
            columns[v, s] = t
    wide = pd.concat(columns, axis=1)  # rows: the union of (sample, view); NaN where a table lacks one
    complete = pd.Series(np.isfinite(wide.to_numpy()).all(axis=1), index=wide.index)
    keep = complete.groupby(level="sample").all()
    keep = keep[keep].index
    if len(keep) == 0:
        raise ValueError(f"{a} vs {b}: no test sample is scored on every view in every seed")
    per_sample = wide[wide.index.get_level_values("sample").isin(keep)].groupby(level="sample").mean()
    per_sample = per_sample.sort_index()
    e_a = np.stack([per_sample[a, s].to_numpy() for s in seeds])
    e_b = np.stack([per_sample[b, s].to_numpy() for s in seeds])
    return seeds, e_a, e_b


def _verdict(per_seed: np.ndarray, low: float, high: float) -> str:
    if (per_seed > 0).all() and low > 0:
        return "holds"
    if (per_seed < 0).all() and high < 0:
        return "reversed"
    return "not significant"


def claims_table(per_view_by_run: Mapping[tuple[str, int], pd.DataFrame],
                 order: Sequence[str] = PAPER_ORDER, metrics: Mapping[str, str] = CLAIM_METRICS,
                 n_resamples: int = 2000, confidence: float = 0.95, seed: int = 0) -> pd.DataFrame:
    """Every adjacent ordering claim of Table I, tested with :func:`paired_bootstrap`.

    Args:
        per_view_by_run: (variant, seed) -> per-view table (``run.tables["per_view"]``).
        order: variants from largest to smallest expected error (the paper's Table I order).
        metrics: Table I name -> per-view column.
        n_resamples, confidence, seed: of the bootstrap.
    Returns:
        one row per claim ("MPE: Baseline > Baseline + Multi-view" ...), columns ``metric``,
        ``difference [m]`` (mean of error(A) - error(B): positive when A is worse, as claimed),
        ``CI low [m]``, ``CI high [m]``, the relative gain ``gain [%]`` (``100 (e_A - e_B) / e_A`` of
        the means) with ``gain CI low [%]`` / ``gain CI high [%]`` from the same resamples, the
        paper's ``paper gain [%]`` from its Table I, ``of paper's size`` (the kit's gain is at least
        :data:`PAPER_GAIN_SHARE` of the paper's; a point-estimate check), ``sign in every seed``
        (bool), ``per-seed difference [m]``
        (text, ``seed: value``), ``seeds``, ``samples`` (two-view test samples per seed),
        ``verdict`` (``holds``, ``not significant``, ``reversed``, or ``not run`` when a variant is
        missing).
    """
    rows = []
    for name, column in metrics.items():
        for a, b in zip(order[:-1], order[1:]):
            paper = paper_relative_gain(a, b, name)
            row = {"claim": f"{name}: {VARIANT_LABELS[a]} > {VARIANT_LABELS[b]}", "metric": name,
                   "paper gain [%]": 100 * paper}
            try:
                seeds, e_a, e_b = paired_sample_errors(per_view_by_run, a, b, column)
            except ValueError as e:
                rows.append({**row, "verdict": "not run", "note": str(e)})
                continue
            r = paired_bootstrap(e_a - e_b, n_resamples, confidence, seed, base=e_a)
            rows.append({
                **row, "difference [m]": r.mean, "CI low [m]": r.low, "CI high [m]": r.high,
                "gain [%]": 100 * r.relative, "gain CI low [%]": 100 * r.relative_low,
                "gain CI high [%]": 100 * r.relative_high,
                "of paper's size": bool(r.relative >= PAPER_GAIN_SHARE * paper) if np.isfinite(paper) else None,
                "sign in every seed": bool((r.per_seed > 0).all()),
                "per-seed difference [m]": ", ".join(f"{s}: {v:+.4f}" for s, v in zip(seeds, r.per_seed)),
                "seeds": len(seeds), "samples": r.n_units, "verdict": _verdict(r.per_seed, r.low, r.high),
            })
    cols = ["claim", "metric", "difference [m]", "CI low [m]", "CI high [m]", "gain [%]", "gain CI low [%]",
            "gain CI high [%]", "paper gain [%]", "of paper's size", "sign in every seed",
            "per-seed difference [m]", "seeds", "samples", "verdict"]
    out = pd.DataFrame(rows)
    out = out.reindex(columns=cols + (["note"] if "note" in out else []))
    return out.set_index("claim")
