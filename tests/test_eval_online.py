"""The online runtime's summary table (notebook 06) on a small hand-made record set."""
from __future__ import annotations

import numpy as np
import pytest

from airpose_lib.eval.online import ONLINE_SUMMARY_COLUMNS, online_summary_table
from airpose_lib.runtime.results import DROPPED, FALLBACK_S2, SKIPPED, NodeResults


def _records(latency, flags):
    return NodeResults(meta={}, frames={"slot": np.arange(len(flags)), "flags": np.asarray(flags, np.int64),
                                        "latency": np.asarray(latency, np.float64)})


def _summary(fps, fallback, valid, stage1_s):
    return {"nominal_fps": 4.17, "fps": fps, "fallback_frames": fallback, "valid": valid,
            "bytes_per_frame": 1168, "timing_median": {"stage1": stage1_s}}


def test_online_summary_table_by_hand():
    # drone 1: 3 of 4 slots in time (one dropped, its latency must not count), one with a fallback;
    # drone 2: 1 of 2 (one skipped)
    res = [_records([0.1, 0.2, 0.3, 9.0], [0, FALLBACK_S2, 0, DROPPED]), _records([0.4, 0.0], [0, SKIPPED])]
    summaries = {1: _summary(3.0, 1, 3, 0.040), 2: _summary(2.0, 0, 1, 0.050)}
    table = online_summary_table({"fixed": (summaries, res), "again": (summaries, res)})
    assert list(table.index) == ["fixed", "again"] and tuple(table.columns) == ONLINE_SUMMARY_COLUMNS
    row = table.loc["fixed"]
    # valid latencies pooled over drones: 0.1 0.2 0.3 0.4 s; p95 interpolates 0.3 + 0.85 * 0.1
    assert row["latency p50 [ms]"] == pytest.approx(250.0)
    assert row["latency p95 [ms]"] == pytest.approx(385.0)
    assert row["dropped [%]"] == pytest.approx(33.33)  # 2 of 6 records, rounded to 2 decimals
    assert row["fallback [%]"] == pytest.approx(25.0)  # 1 fallback frame of 4 valid ones
    assert row["fps per drone"] == pytest.approx(2.5)
    assert row["stage 1 [ms]"] == pytest.approx(45.0)
    assert row["nominal fps"] == pytest.approx(4.17) and row["bytes / frame"] == 1168
