"""The mechanism probes and depth bounds against hand-computed values."""
import numpy as np
import pytest

from airpose_lib.eval.mechanism import (
    accuracy,
    depth_scaled,
    fit_mlp,
    fit_ridge,
    probe_interval,
    r2_score,
    relative_depth_error,
    view_error_correlation,
)
from airpose_lib.eval.significance import bootstrap_interval


def test_r2_and_accuracy_by_hand():
    y = np.array([1.0, 2.0, 3.0, 4.0])
    # residuals 0.5, -0.5, 0, 0: SSE 0.5 over a spread of 5
    assert r2_score(y, [1.5, 1.5, 3.0, 4.0]) == pytest.approx(0.9)
    assert r2_score(y, np.full(4, 2.5)) == pytest.approx(0.0)
    assert np.isnan(r2_score(np.ones(3), [1.0, 2.0, 3.0]))
    assert accuracy([0, 1, 1, 0], [0.2, 0.7, 0.4, 0.9]) == pytest.approx(0.5)


def test_view_error_correlation_by_hand():
    e0 = np.array([1.0, -1.0, 2.0, -2.0])
    assert view_error_correlation(np.stack([e0, 2 * e0], 1)) == pytest.approx(1.0)
    assert view_error_correlation(np.stack([e0, -e0], 1)) == pytest.approx(-1.0)
    # orthogonal centred columns
    assert view_error_correlation(np.stack([e0, [1.0, 1.0, -1.0, -1.0]], 1)) == pytest.approx(0.0)


def test_relative_depth_error_and_the_shared_scalar_bound():
    true = np.array([[[0.0, 0.0, 10.0], [1.0, 0.0, 8.0]]])
    pred = np.array([[[0.0, 0.0, 11.0], [0.9, 0.0, 7.2]]])  # +10 % and -10 % along each ray
    np.testing.assert_allclose(relative_depth_error(pred, true), [[0.1, -0.1]])
    # the views' mean relative error is 0: both estimates move back onto the truth
    np.testing.assert_allclose(depth_scaled(pred, true), true)
    np.testing.assert_allclose(depth_scaled(pred, true, shared=False), true)
    # equal errors: nothing to average, the shared bound keeps the estimate
    same = np.array([[[0.0, 0.0, 11.0], [1.1, 0.0, 8.8]]])
    np.testing.assert_allclose(depth_scaled(same, true), same)
    # an error across the ray stays with a perfect depth scale: (1, 0, 11) -> (10/11, 0, 10)
    off = np.array([[[1.0, 0.0, 11.0], [1.1, 0.0, 8.8]]])
    np.testing.assert_allclose(depth_scaled(off, true, shared=False)[0, 0], [10 / 11, 0.0, 10.0])


def test_ridge_and_mlp_recover_a_linear_and_a_nonlinear_target():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(2000, 5))
    y = 3.0 * X[:, 0] - X[:, 1] + 0.1 * rng.normal(size=2000)
    ridge = fit_ridge(X[:1500], y[:1500])
    assert r2_score(y[1500:], ridge(X[1500:])) > 0.99
    z = np.abs(X[:, 0])  # no linear readout finds it
    assert r2_score(z[1500:], fit_ridge(X[:1500], z[:1500])(X[1500:])) < 0.05
    assert r2_score(z[1500:], fit_mlp(X[:1500], z[:1500], hidden=32, steps=400)(X[1500:])) > 0.7


def test_bootstrap_interval_of_a_mean_matches_the_normal_interval():
    x = np.random.default_rng(1).normal(2.0, 1.0, size=400)
    value, low, high = bootstrap_interval(lambda idx: x[idx].mean(), len(x), n_resamples=2000, seed=0)
    half = 1.96 * x.std(ddof=1) / np.sqrt(len(x))
    assert value == pytest.approx(x.mean())
    assert low == pytest.approx(value - half, abs=0.1 * half) and high == pytest.approx(value + half, abs=0.1 * half)


def test_probe_interval_resamples_samples_whole():
    rng = np.random.default_rng(2)
    y = rng.normal(size=(300, 2))
    pred = y + 0.5 * rng.normal(size=(300, 2))
    value, low, high = probe_interval(r2_score, y, pred, n_resamples=500)
    assert value == pytest.approx(r2_score(y, pred)) and low < value < high
    exact = probe_interval(r2_score, y, y, n_resamples=50)
    assert exact == pytest.approx((1.0, 1.0, 1.0))


def test_probe_rows_score_held_out_samples_and_the_views_errors():
    from airpose_lib.experiments.mechanism import COLUMNS, probe_rows

    rng = np.random.default_rng(3)

    def split(n):
        stature = rng.normal(1.7, 0.1, n)
        gender = rng.integers(1, 3, n)
        tau = np.stack([rng.normal(0, 1, (n, 2)), rng.normal(0, 1, (n, 2)), rng.uniform(6, 14, (n, 2))], -1)
        P = rng.normal(size=(n, 2, 3))
        # features: stature and gender in both views alike, log depth per view, plus noise
        f = np.concatenate([np.repeat(stature[:, None, None], 2, 1), np.repeat(gender[:, None, None], 2, 1),
                            np.log(tau[..., 2:]), 0.01 * rng.normal(size=(n, 2, 5))], -1)
        return f, {"gender": gender, "tau": tau, "P": P}, stature

    rows = probe_rows(split(600), split(300), n_resamples=50, mlp_steps=100, log=lambda _: None)
    table = {(r["quantity"], r["input"], r["readout"], r["metric"]): r for r in rows}
    assert len(rows) == 28 and all(set(r) == set(COLUMNS) for r in rows)
    assert table["stature [m]", "features", "ridge", "R2"]["value"] > 0.99
    assert table["stature [m]", "features", "ridge", "R2 of the views' mean"]["value"] > 0.99
    assert table["gender (female = 1)", "features + P", "ridge", "accuracy"]["value"] == 1.0
    assert table["log depth", "features", "ridge", "R2"]["value"] > 0.99
    assert all(r["samples"] == 300 and r["CI low"] <= r["value"] <= r["CI high"] for r in rows)


def test_body_pose_rows_split_an_mpjpe_ordering_into_root_and_body_pose():
    import pandas as pd

    from airpose_lib.experiments.mechanism import COLUMNS, body_pose_rows

    def table(mpjpe, true_root):  # two samples, two views each: a sample's error is its views' mean
        return pd.DataFrame({"sample": [0, 0, 1, 1], "view": [0, 1, 0, 1], "mpjpe_m": mpjpe,
                             "mpjpe_true_root_m": true_root})

    per_view = {"multiview": table([0.08, 0.10, 0.08, 0.10], [0.06, 0.06, 0.06, 0.06]),
                "fullcam": table([0.08, 0.08, 0.08, 0.08], [0.07, 0.07, 0.07, 0.07])}
    rows = body_pose_rows(per_view, n_resamples=50, log=lambda _: None)
    assert all(set(r) == set(COLUMNS) and r["part"] == "d" and r["samples"] == 2 for r in rows)
    got = {(r["input"], r["readout"]): r["value"] for r in rows}
    assert got["predicted root (Table I)", "Baseline + Multi-view"] == pytest.approx(0.09)
    assert got["true root (the body pose alone)", "Baseline + Fullcam"] == pytest.approx(0.07)
    pair = "Baseline + Multi-view > Baseline + Fullcam"
    assert got["predicted root (Table I)", pair] == pytest.approx(100 * (0.09 - 0.08) / 0.09)
    assert got["true root for both (the body pose alone)", pair] == pytest.approx(100 * (0.06 - 0.07) / 0.06)
    assert got["true root for the second (an exact root orientation)", pair] == pytest.approx(100 * (0.09 - 0.07) / 0.09)
    per_view["fullcam"] = per_view["fullcam"].assign(sample=[0, 0, 2, 2])
    with pytest.raises(ValueError, match="different samples"):
        body_pose_rows(per_view, n_resamples=50, log=lambda _: None)
