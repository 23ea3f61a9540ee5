"""Are Table I's orderings real? A paired bootstrap over test images, pooled over seeds.

The paper reads two orderings off Table I: MPE and MPJPE both fall from Baseline to
Baseline + Multi-view to Baseline + Fullcam to AirPose. With a few seeds and a few hundred test
images a difference of means can come from noise, so each adjacent pair is tested:

* per seed s and test image i = (sample, view), the paired difference d_si = e_A(s, i) - e_B(s, i)
  of the two variants' errors on the same image (both networks of one seed see the same test set);
* the statistic is the mean of d over seeds and images;
* its 95 % interval is the percentile interval of the statistic over bootstrap resamples of the
  image set, one set of resampled indices shared by every seed (images are the unit of sampling;
  seeds are kept, since a claim must survive every training seed);
* "A > B" holds when the per-seed mean difference is positive in *every* seed and the interval
  lies above zero; it is "reversed" when the opposite claim holds by the same rule, and "not
  significant" otherwise.

Pure numpy / pandas.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from .ablation import VARIANT_LABELS

__all__ = ["PAPER_ORDER", "CLAIM_METRICS", "BootstrapResult", "paired_differences", "paired_bootstrap",
           "claims_table"]

#: The paper's ordering of Table I, largest error first.
PAPER_ORDER = ("baseline", "multiview", "fullcam", "airpose")
#: Table I metric -> per-view column.
CLAIM_METRICS = {"MPE": "mpe_m", "MPJPE": "mpjpe_m"}

_KEYS = ["sample", "view"]


@dataclass(frozen=True)
class BootstrapResult:
    """Paired-bootstrap summary of per-seed, per-image differences.

    Attributes:
        mean: mean difference over seeds and images.
        low, high: percentile interval of that mean over the resamples.
        per_seed: ``(S,)`` mean difference of each seed over the images.
        n_images: images per seed.
    """

    mean: float
    low: float
    high: float
    per_seed: np.ndarray
    n_images: int


def paired_bootstrap(diffs: np.ndarray, n_resamples: int = 2000, confidence: float = 0.95,
                     seed: int = 0, chunk: int = 250, block: int = 1) -> BootstrapResult:
    """Percentile interval of the mean paired difference, resampling images (or blocks of them).

    Args:
        diffs: ``(S, n)`` differences; column i is the same test image in every seed (a 1-D
            array is one seed).
        n_resamples: bootstrap resamples.
        confidence: interval mass (0.95: the 2.5 and 97.5 percentiles).
        seed: seed of the resampling generator (fixed: the same data give the same interval).
        chunk: resamples drawn at once (bounds memory to ``chunk x n`` indices).
        block: images per resampled unit. 1 for independent images (Table I); for the frames of a
            recording, whose errors are correlated in time, consecutive non-overlapping blocks of
            ``block`` frames are resampled whole (a block bootstrap; the last block may be shorter),
            so the interval is not narrowed by counting correlated frames as independent.
    Returns:
        :class:`BootstrapResult`.
    """
    d = np.atleast_2d(np.asarray(diffs, dtype=np.float64))
    S, n = d.shape
    if n == 0 or not np.isfinite(d).all():
        raise ValueError(f"paired_bootstrap needs finite differences on at least one image, got shape {d.shape}")
    if block < 1:
        raise ValueError(f"block must be >= 1, got {block}")
    # The statistic mean_{s, i in resample} d_si equals the resample mean of the per-image seed means
    # because every seed uses the same resampled indices.
    d_image = d.mean(axis=0)
    starts = np.arange(0, n, block)
    sums, counts = np.add.reduceat(d_image, starts), np.diff(np.append(starts, n)).astype(np.float64)
    rng = np.random.default_rng(seed)
    stats = np.empty(n_resamples)
    for start in range(0, n_resamples, chunk):
        stop = min(start + chunk, n_resamples)
        idx = rng.integers(0, len(starts), size=(stop - start, len(starts)))
        stats[start:stop] = sums[idx].sum(axis=1) / counts[idx].sum(axis=1)
    alpha = (1.0 - confidence) / 2.0
    low, high = np.quantile(stats, [alpha, 1.0 - alpha])
    return BootstrapResult(float(d_image.mean()), float(low), float(high), d.mean(axis=1), n)


def paired_differences(per_view_by_run: Mapping[tuple[str, int], pd.DataFrame], a: str, b: str,
                       metric: str) -> tuple[list[int], np.ndarray]:
    """Per-seed, per-image differences ``metric(a) - metric(b)``, aligned over seeds.

    Args:
        per_view_by_run: (variant, seed) -> per-view table (``sample``, ``view``, ``metric``).
        a, b: variant names.
        metric: a per-view column, e.g. ``mpe_m``.
    Returns:
        the seeds that have both variants, and ``(S, n)`` differences over the images
        (sample, view) that every one of those seeds scored finitely for both variants, in
        sorted (sample, view) order.
    """
    seeds = sorted(s for (v, s) in per_view_by_run if v == a and (b, s) in per_view_by_run)
    if not seeds:
        raise ValueError(f"no seed has both {a!r} and {b!r}")
    per_seed = []
    for s in seeds:
        ta = per_view_by_run[a, s].set_index(_KEYS)[metric]
        tb = per_view_by_run[b, s].set_index(_KEYS)[metric]
        for name, t in ((a, ta), (b, tb)):
            if not t.index.is_unique:
                raise ValueError(f"{name} seed {s}: the per-view table repeats a (sample, view) pair")
        d = (ta - tb).dropna()  # aligns on (sample, view); an image only one variant scored drops out
        per_seed.append(d)
    common = per_seed[0].index
    for d in per_seed[1:]:
        common = common.intersection(d.index)
    if len(common) == 0:
        raise ValueError(f"{a} vs {b}: no test image is scored in every seed")
    common = common.sort_values()
    return seeds, np.stack([d.loc[common].to_numpy(np.float64) for d in per_seed])


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
        ``CI low [m]``, ``CI high [m]``, ``sign in every seed`` (bool), ``per-seed difference [m]``
        (text, ``seed: value``), ``seeds``, ``images``, ``verdict`` (``holds``, ``not significant``,
        ``reversed``, or ``not run`` when a variant is missing).
    """
    rows = []
    for name, column in metrics.items():
        for a, b in zip(order[:-1], order[1:]):
            row = {"claim": f"{name}: {VARIANT_LABELS[a]} > {VARIANT_LABELS[b]}", "metric": name}
            try:
                seeds, diffs = paired_differences(per_view_by_run, a, b, column)
            except ValueError as e:
                rows.append({**row, "verdict": "not run", "note": str(e)})
                continue
            r = paired_bootstrap(diffs, n_resamples, confidence, seed)
            rows.append({
                **row, "difference [m]": r.mean, "CI low [m]": r.low, "CI high [m]": r.high,
                "sign in every seed": bool((r.per_seed > 0).all()),
                "per-seed difference [m]": ", ".join(f"{s}: {v:+.4f}" for s, v in zip(seeds, r.per_seed)),
                "seeds": len(seeds), "images": r.n_images, "verdict": _verdict(r.per_seed, r.low, r.high),
            })
    cols = ["claim", "metric", "difference [m]", "CI low [m]", "CI high [m]", "sign in every seed",
            "per-seed difference [m]", "seeds", "images", "verdict"]
    out = pd.DataFrame(rows)
    out = out[cols + (["note"] if "note" in out else [])]
    return out.set_index("claim")
