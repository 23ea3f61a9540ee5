"""A run on shipped networks against its reference: hand-made tables, hand-computed verdicts."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from airpose_lib.eval.agreement import (
    agreement_message,
    claims_agreement,
    recordings_agreement,
    sample_standard_errors,
    table_agreement,
    write_check,
)


def _table(mpe, mpjpe, root):
    return pd.DataFrame({"MPE [m]": mpe, "MPJPE [m]": mpjpe, "root orient. median [deg]": root},
                        index=pd.Index(["Baseline", "AirPose"], name="method"))


def test_table_agreement_takes_relative_and_absolute_tolerances():
    ref = _table([1.00, 0.70], [0.090, 0.080], [10.0, 10.5])
    run = _table([1.04, 0.74], [0.090, 0.0839], [10.9, 11.6])
    rows = table_agreement(run, ref).set_index(["method", "quantity"])
    assert rows.loc[("Baseline", "MPE"), "difference"] == pytest.approx(0.04)
    assert bool(rows.loc[("Baseline", "MPE"), "within"])  # 4 % <= 5 %
    assert not bool(rows.loc[("AirPose", "MPE"), "within"])  # 0.04 / 0.70 = 5.7 %
    assert bool(rows.loc[("AirPose", "MPJPE"), "within"])  # 4.9 %
    assert bool(rows.loc[("Baseline", "root orientation median"), "within"])  # 0.9 deg
    assert not bool(rows.loc[("AirPose", "root orientation median"), "within"])  # 1.1 deg


def test_the_sampling_error_counts_two_view_samples_not_views():
    per_view = pd.DataFrame({"sample": [0, 0, 1, 1, 2, 2], "mpe_m": [1.0, 3.0, 2.0, 2.0, 4.0, 6.0], "mpjpe_m": 0.1})
    means = np.array([2.0, 2.0, 5.0])  # each sample's mean over its views
    assert sample_standard_errors(per_view, "mpe_m") == pytest.approx(means.std(ddof=1) / np.sqrt(3))
    ref = _table([2.0, 2.0], [0.1, 0.1], [1.0, 1.0])
    rows = table_agreement(ref, ref, {"Baseline": per_view}).set_index(["method", "quantity"])
    se = means.std(ddof=1) / np.sqrt(3) / 2.0
    assert rows.loc[("Baseline", "MPE"), "tolerance / SE"] == pytest.approx(0.05 / se)
    assert np.isnan(rows.loc[("AirPose", "MPE"), "tolerance / SE"])


def test_claims_keep_their_verdicts_or_not():
    ref = pd.DataFrame({"claim": ["a", "b"], "gain [%]": [1.0, 2.0], "verdict": ["holds", "holds"]})
    run = pd.DataFrame({"claim": ["a", "b"], "gain [%]": [1.1, 0.1], "verdict": ["holds", "not significant"]})
    out = claims_agreement(run, ref)
    assert out["within"].tolist() == [True, False]
    assert claims_agreement(run.set_index("claim"), ref)["within"].tolist() == [True, False]  # the kit's own table


def test_recordings_agreement_and_the_message(tmp_path):
    ref = pd.DataFrame({"sequence": ["p1", "p1", "p1"], "method": ["AirPose", "AirPose+", "Baseline"],
                        "rel_t_median_m": [2.0, 1.0, 9.0], "frames": [900, 900, 900]})
    run = pd.DataFrame({"sequence": ["p1", "p1", "p1"], "method": ["AirPose", "AirPose+", "Baseline"],
                        "rel_t_median_m": [2.3, 1.25, 1.0], "frames": [200, 200, 200]})
    rows = recordings_agreement(run, ref)
    assert rows["method"].tolist() == ["AirPose", "AirPose+"]  # Baseline is not compared
    assert rows["within"].tolist() == [True, False]  # 15 % and 25 % of the reference
    msg = agreement_message({"recordings": rows}, "results/x")
    assert msg.startswith("DIFFERS") and "1 of 2 recordings" in msg
    assert agreement_message({"recordings": rows.iloc[:1]}, "results/x").startswith("agrees with the committed")
    path = write_check(tmp_path, msg, rows)
    assert path.read_text().splitlines()[0] == msg and "AirPose+" in path.read_text()
