"""Paired bootstrap over two-view samples and Table I's claim table against cases with a known answer."""
import numpy as np
import pandas as pd
import pytest

from airpose_lib.eval.significance import (
    PAPER_GAIN_SHARE,
    claims_table,
    paired_bootstrap,
    paired_sample_errors,
    paper_relative_gain,
)


def test_interval_matches_the_normal_theory_interval():
    rng = np.random.default_rng(1)
    d = rng.normal(0.3, 0.5, size=(3, 800))  # three seeds, the same 800 images
    r = paired_bootstrap(d, n_resamples=4000, seed=2)
    # statistic = mean over images of the seed means; its standard error from the per-image means
    d_image = d.mean(axis=0)
    se = d_image.std(ddof=1) / np.sqrt(d.shape[1])
    assert r.mean == pytest.approx(d.mean(), abs=1e-12)
    half = 1.959964 * se
    assert r.low == pytest.approx(r.mean - half, abs=0.08 * half)
    assert r.high == pytest.approx(r.mean + half, abs=0.08 * half)
    np.testing.assert_allclose(r.per_seed, d.mean(axis=1))
    assert r.n_units == 800


def test_interval_covers_the_true_mean_about_95_percent_of_the_time():
    rng = np.random.default_rng(3)
    hits = [_covers(rng.normal(1.0, 2.0, size=(1, 200)), 1.0, seed) for seed in range(200)]
    assert 0.90 <= np.mean(hits) <= 0.99


def _covers(d, truth, seed):
    r = paired_bootstrap(d, n_resamples=1000, seed=seed)
    return r.low <= truth <= r.high


def test_zero_mean_differences_do_not_exclude_zero():
    rng = np.random.default_rng(4)
    d = rng.normal(0.0, 1.0, size=(2, 500))
    d -= d.mean()  # exactly zero mean
    r = paired_bootstrap(d, seed=0)
    assert r.low < 0 < r.high


def test_a_constant_shift_gives_a_degenerate_interval():
    r = paired_bootstrap(np.full((3, 50), 0.25), seed=0)
    assert r.low == pytest.approx(0.25) and r.high == pytest.approx(0.25) and r.mean == pytest.approx(0.25)


def test_fixed_seed_is_reproducible_and_the_seed_matters():
    d = np.random.default_rng(5).normal(size=(2, 100))
    a, b, c = paired_bootstrap(d, seed=7), paired_bootstrap(d, seed=7), paired_bootstrap(d, seed=8)
    assert (a.low, a.high) == (b.low, b.high) and (a.low, a.high) != (c.low, c.high)


def test_non_finite_differences_are_an_error():
    with pytest.raises(ValueError, match="finite"):
        paired_bootstrap(np.array([[0.1, np.nan]]))


def _table(values, samples=None):
    n = len(values) // 2
    samples = np.repeat(np.arange(n), 2) if samples is None else samples
    v = np.asarray(values, dtype=float)
    return pd.DataFrame({"method": "x", "sample": samples, "view": np.tile([0, 1], n),
                         "mpe_m": v, "mpjpe_m": v / 10})


def test_sample_errors_average_the_views_and_pair_by_sample():
    a = _table([1.0, 2.0, 3.0, 4.0])
    b = _table([0.5, 0.5, 0.5, 1.5]).iloc[::-1]  # another row order: pairing is by (sample, view)
    seeds, ea, eb = paired_sample_errors({("baseline", 1): a, ("multiview", 1): b}, "baseline", "multiview",
                                         "mpe_m")
    assert seeds == [1]
    np.testing.assert_allclose(ea, [[1.5, 3.5]])  # (1 + 2) / 2, (3 + 4) / 2
    np.testing.assert_allclose(eb, [[0.5, 1.0]])
    # a view missing in one seed drops its whole sample from every seed and both variants
    runs = {("baseline", 1): a, ("multiview", 1): b, ("baseline", 2): a.iloc[1:], ("multiview", 2): b}
    seeds, ea, eb = paired_sample_errors(runs, "baseline", "multiview", "mpe_m")
    assert seeds == [1, 2] and ea.shape == eb.shape == (2, 1)
    np.testing.assert_allclose(ea, [[3.5], [3.5]])
    # so does a non-finite error
    c = a.copy()
    c.loc[2, "mpe_m"] = np.nan
    seeds, ea, _ = paired_sample_errors({("baseline", 1): c, ("multiview", 1): b}, "baseline", "multiview", "mpe_m")
    np.testing.assert_allclose(ea, [[1.5]])
    with pytest.raises(ValueError, match="repeats"):
        paired_sample_errors({("baseline", 1): pd.concat([a, a]), ("multiview", 1): b}, "baseline", "multiview",
                             "mpe_m")


def test_hand_checkable_pair_interval():
    """Two samples whose view differences are (1, 3) and (0, 0): per-sample differences 2 and 0.
    A resample of the two samples has mean 0, 1 or 2 with probability 1/4, 1/2, 1/4, so the 95 %
    interval is exactly [0, 2] around the mean 1. Resampling the four views instead would count
    the view pair twice and draw means such as 0.25 or 1.75 as well."""
    a = _table([1.0, 3.0, 0.0, 0.0])
    b = _table([0.0, 0.0, 0.0, 0.0])
    _, ea, eb = paired_sample_errors({("baseline", 1): a, ("multiview", 1): b}, "baseline", "multiview", "mpe_m")
    np.testing.assert_allclose(ea - eb, [[2.0, 0.0]])
    r = paired_bootstrap(ea - eb, n_resamples=4000, seed=0)
    assert (r.mean, r.low, r.high, r.n_units) == (1.0, 0.0, 2.0, 2)


def _one_and_two_views(rng, n=300, seeds=(1, 2, 3)):
    """Per-view tables with one view per sample, and the same with that view duplicated."""
    level = rng.uniform(0.5, 1.5, size=n)
    one, two = {}, {}
    for s in seeds:
        for v, shift in (("baseline", 0.05), ("multiview", 0.0)):
            e = level + shift + rng.normal(0, 0.1, size=n)
            one[v, s] = pd.DataFrame({"sample": np.arange(n), "view": 0, "mpe_m": e, "mpjpe_m": e / 10})
            two[v, s] = pd.DataFrame({"sample": np.repeat(np.arange(n), 2), "view": np.tile([0, 1], n),
                                      "mpe_m": np.repeat(e, 2), "mpjpe_m": np.repeat(e, 2) / 10})
    return one, two


def test_two_identical_views_double_nothing():
    """Known answer: a second view that repeats the first adds no information, so the pair-level
    interval is exactly the one-view interval. The view-level bootstrap of before narrowed it by
    about sqrt(2), as if it had twice the samples."""
    one, two = _one_and_two_views(np.random.default_rng(11))
    t1, t2 = claims_table(one, order=("baseline", "multiview")), claims_table(two, order=("baseline", "multiview"))
    cols = ["difference [m]", "CI low [m]", "CI high [m]", "samples", "verdict"]
    pd.testing.assert_frame_equal(t1[cols], t2[cols], check_exact=True)
    assert (t2["samples"] == 300).all()
    # the old unit: one column per (sample, view)
    per_view = np.stack([two["baseline", s]["mpe_m"].to_numpy() - two["multiview", s]["mpe_m"].to_numpy()
                         for s in (1, 2, 3)])
    old = paired_bootstrap(per_view, n_resamples=4000, seed=0)
    new = paired_bootstrap(per_view.reshape(3, -1, 2).mean(-1), n_resamples=4000, seed=0)
    assert old.mean == pytest.approx(new.mean, abs=1e-12)
    assert (new.high - new.low) / (old.high - old.low) == pytest.approx(np.sqrt(2), rel=0.08)


def test_seeds_are_pooled_per_sample():
    """The unit is a sample with all its seeds: moving an error between seeds within a sample
    changes no interval; the per-seed means and the verdict's every-seed rule still see the seeds."""
    rng = np.random.default_rng(12)
    d = rng.normal(0.1, 1.0, size=(3, 400))
    shuffled = rng.permuted(d, axis=0)  # each column's seed values in another order
    a, b = paired_bootstrap(d, seed=3), paired_bootstrap(shuffled, seed=3)
    assert (a.low, a.high) == pytest.approx((b.low, b.high), abs=1e-12)
    assert not np.allclose(a.per_seed, b.per_seed)


def _runs(effects, seeds=(1, 2, 3), n=200, noise=0.05, seed_effects=None):
    """Per-view tables whose errors fall by ``effects[k]`` from variant k to k+1 (same for MPE, MPJPE x10)."""
    rng = np.random.default_rng(0)
    base = rng.uniform(0.5, 1.5, size=2 * n)  # per-image difficulty, shared by every variant
    runs = {}
    for s in seeds:
        level = 2.0
        for k, v in enumerate(("baseline", "multiview", "fullcam", "airpose")):
            if k:
                level -= (seed_effects or {}).get((k, s), effects[k - 1])
            runs[v, s] = _table(base + level + rng.normal(0, noise, size=2 * n))
    return runs


def test_claims_hold_when_every_seed_shows_a_clear_ordering():
    t = claims_table(_runs([0.05, 0.3, 0.1]))
    assert len(t) == 6 and (t["verdict"] == "holds").all() and t["sign in every seed"].all()
    assert t.loc["MPE: Baseline + Fullcam > AirPose", "difference [m]"] == pytest.approx(0.1, abs=0.01)
    assert t.loc["MPJPE: Baseline + Fullcam > AirPose", "difference [m]"] == pytest.approx(0.01, abs=0.001)
    assert (t["CI low [m]"] > 0).all() and (t["seeds"] == 3).all() and (t["samples"] == 200).all()


def test_no_effect_is_not_significant_and_a_reversal_is_reversed():
    t = claims_table(_runs([0.0, -0.2, 0.1]))
    assert t.loc["MPE: Baseline > Baseline + Multi-view", "verdict"] == "not significant"
    assert t.loc["MPE: Baseline + Multi-view > Baseline + Fullcam", "verdict"] == "reversed"
    assert t.loc["MPE: Baseline + Multi-view > Baseline + Fullcam", "CI high [m]"] < 0
    assert t.loc["MPJPE: Baseline + Fullcam > AirPose", "verdict"] == "holds"


def test_one_seed_against_the_claim_fails_it_even_with_a_significant_pooled_mean():
    # seeds 1 and 2: a large effect; seed 3: a small one the other way. Pooled mean > 0 and clear.
    t = claims_table(_runs([0.3, 0.3, 0.3], seed_effects={(1, 3): -0.05}))
    row = t.loc["MPE: Baseline > Baseline + Multi-view"]
    assert row["CI low [m]"] > 0 and not row["sign in every seed"]
    assert row["verdict"] == "not significant"
    assert "3: -0.0" in row["per-seed difference [m]"]


def test_a_missing_variant_is_reported_not_run():
    runs = {k: v for k, v in _runs([0.1, 0.1, 0.1]).items() if k[0] != "multiview"}
    t = claims_table(runs)
    assert (t.loc[["MPE: Baseline > Baseline + Multi-view", "MPE: Baseline + Multi-view > Baseline + Fullcam"],
                  "verdict"] == "not run").all()
    assert t.loc["MPE: Baseline + Fullcam > AirPose", "verdict"] == "holds"


def test_block_bootstrap_of_block_constant_series_matches_the_block_means_interval():
    """Each value repeated over a block of 30 frames: resampling whole blocks gives the interval of
    the 60 block means; resampling frames one by one would be sqrt(30) times too narrow."""
    rng = np.random.default_rng(6)
    means = rng.normal(0.2, 1.0, size=60)
    d = np.repeat(means, 30)
    r = paired_bootstrap(d, n_resamples=4000, seed=1, block=30)
    half = 1.959964 * means.std(ddof=1) / np.sqrt(means.size)
    assert r.mean == pytest.approx(means.mean(), abs=1e-12)
    assert r.high - r.low == pytest.approx(2 * half, rel=0.1)
    naive = paired_bootstrap(d, n_resamples=4000, seed=1)
    assert (naive.high - naive.low) < 0.3 * (r.high - r.low)
    with pytest.raises(ValueError, match="block"):
        paired_bootstrap(d, block=0)


def test_block_bootstrap_covers_the_mean_of_a_correlated_series():
    """AR(1) series (correlation 0.9 frame to frame, like a per-frame error along a recording):
    1-s blocks keep the coverage near 95 %, single frames do not. The last block is shorter."""
    def ar1(rng, n=901, rho=0.9):
        e = rng.normal(size=n)
        x = np.empty(n)
        x[0] = e[0] / np.sqrt(1 - rho ** 2)
        for t in range(1, n):
            x[t] = rho * x[t - 1] + e[t]
        return x

    rng = np.random.default_rng(7)
    series = [ar1(rng) for _ in range(150)]
    cover = lambda block: np.mean([(lambda r: r.low <= 0 <= r.high)(  # noqa: E731
        paired_bootstrap(x, n_resamples=500, seed=i, block=block)) for i, x in enumerate(series)])
    assert cover(30) >= 0.85 and cover(1) <= 0.6


# -- effect sizes ---------------------------------------------------------------------------------
def test_paper_relative_gains_from_its_table_i():
    # hand-computed from the paper's Table I: MPE 0.50 0.46 0.22 0.15, MPJPE 0.091 0.084 0.077 0.072
    assert paper_relative_gain("baseline", "multiview", "MPE") == pytest.approx(0.04 / 0.50)
    assert paper_relative_gain("fullcam", "airpose", "MPE") == pytest.approx(0.07 / 0.22)  # 32 %
    assert paper_relative_gain("multiview", "fullcam", "MPJPE") == pytest.approx(0.007 / 0.084)  # 8.3 %
    assert np.isnan(paper_relative_gain("baseline", "multiview", "PA-MPJPE"))


def test_hand_checkable_relative_gain_interval():
    """e_A = (1, 3), e_B = (1, 1): the gain is the ratio of the means, (0 + 2) / (1 + 3) = 0.5 (not
    the mean of the ratios, 1/3). The resamples {0, 0}, {0, 1}, {1, 1} give 0, 2/4 and 4/6, so the
    95 % interval is [0, 2/3]."""
    e_a, e_b = np.array([[1.0, 3.0]]), np.array([[1.0, 1.0]])
    r = paired_bootstrap(e_a - e_b, n_resamples=4000, seed=0, base=e_a)
    assert r.relative == 0.5 and r.relative_low == 0.0 and r.relative_high == pytest.approx(2 / 3)
    assert np.isnan(paired_bootstrap(e_a - e_b, n_resamples=10).relative)  # no base, no gain
    with pytest.raises(ValueError, match="base"):
        paired_bootstrap(e_a - e_b, base=e_a[:, :1])


def test_relative_gain_interval_is_paired():
    """B removes exactly 10 % of A's error on every sample, however hard the sample: every resample
    gives 10 %, so the interval is the point. Resampling A and B independently would not."""
    rng = np.random.default_rng(13)
    e_a = rng.uniform(0.2, 3.0, size=(3, 500))
    r = paired_bootstrap(e_a - 0.9 * e_a, seed=1, base=e_a)
    assert (r.relative, r.relative_low, r.relative_high) == pytest.approx((0.1, 0.1, 0.1), abs=1e-12)


def _scaled_runs(factors, n=50):
    """Per-view tables whose errors are ``factor x`` a per-sample difficulty shared by the variants."""
    difficulty = np.random.default_rng(14).uniform(0.5, 2.0, size=2 * n)
    return {(v, 1): _table(f * difficulty) for v, f in zip(("baseline", "multiview", "fullcam", "airpose"), factors)}


def test_claims_give_the_kit_gain_next_to_the_papers_and_whether_it_reaches_a_third():
    # MPE gains: 3 % (paper 8 %: a third is 2.67 %), 17 % (paper 52.2 %: 17.39 %), 11 % (paper 31.8 %: 10.6 %)
    f = np.cumprod([1.0, 0.97, 0.83, 0.89])
    t = claims_table(_scaled_runs(f), n_resamples=500)
    mpe = t[t["metric"] == "MPE"]
    np.testing.assert_allclose(mpe["gain [%]"], [3.0, 17.0, 11.0], atol=1e-9)
    np.testing.assert_allclose(mpe["gain CI low [%]"], [3.0, 17.0, 11.0], atol=1e-9)  # a shared difficulty
    np.testing.assert_allclose(mpe["paper gain [%]"], [8.0, 100 * 0.24 / 0.46, 100 * 0.07 / 0.22])
    assert list(mpe["of paper's size"]) == [True, False, True]
    assert PAPER_GAIN_SHARE == pytest.approx(1 / 3)
    # a reversal is a negative gain, never of the paper's size
    t = claims_table(_scaled_runs([1.0, 1.05, 0.5, 0.4]), n_resamples=200)
    row = t.loc["MPJPE: Baseline > Baseline + Multi-view"]
    assert row["gain [%]"] == pytest.approx(-5.0) and not row["of paper's size"]
    # a missing variant: the paper's gain is still shown
    t = claims_table({k: v for k, v in _scaled_runs(f).items() if k[0] != "airpose"}, n_resamples=200)
    row = t.loc["MPE: Baseline + Fullcam > AirPose"]
    assert row["verdict"] == "not run" and row["paper gain [%]"] == pytest.approx(100 * 0.07 / 0.22)
    assert np.isnan(row["gain [%]"])
