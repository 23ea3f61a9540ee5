"""The online runtime's throughput and latency table (notebook 06), from the drones' records.

Each run is what :func:`airpose_lib.experiments.online.run_schedule` returns: per drone its
``summary.json`` (drone id -> dict) and its records (objects with ``frames["latency"]`` in
seconds, a boolean ``valid`` per record and a length, as
:class:`airpose_lib.runtime.results.NodeResults`). Nothing here imports the runtime.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

__all__ = ["ONLINE_SUMMARY_COLUMNS", "online_summary_table"]

#: Columns of :func:`online_summary_table`.
ONLINE_SUMMARY_COLUMNS = ("nominal fps", "fps per drone", "latency p50 [ms]", "latency p95 [ms]", "dropped [%]",
                          "fallback [%]", "bytes / frame", "stage 1 [ms]")


def online_summary_table(runs: Mapping[str, tuple[Mapping[int, dict], Sequence]]) -> pd.DataFrame:
    """One row per run, rounded to 2 decimals.

    Args:
        runs: run name -> ``(summaries, results)``: ``summaries`` drone id (from 1) -> summary
            with ``nominal_fps``, ``fps``, ``fallback_frames``, ``valid``, ``bytes_per_frame`` and
            ``timing_median["stage1"]`` (s); ``results`` the drones' records.

    Returns:
        Indexed by run: the nominal schedule rate and drone 1's bytes per frame (the same for
        every drone); the mean achieved fps over drones; the median and 95th percentile latency
        (ms) of the frames completed in time, pooled over drones; the share of records dropped or
        skipped; the share of valid frames that ran a stage without some message (fallback); the
        median over drones of the median stage-1 time (ms).
    """
    rows = []
    for name, (summaries, res) in runs.items():
        lat = np.concatenate([r.frames["latency"][r.valid] for r in res])
        per_drone = list(summaries.values())
        rows.append({"run": name, "nominal fps": summaries[1]["nominal_fps"],
                     "fps per drone": np.mean([s["fps"] for s in per_drone]),
                     "latency p50 [ms]": 1000 * np.percentile(lat, 50),
                     "latency p95 [ms]": 1000 * np.percentile(lat, 95),
                     "dropped [%]": 100 * (1 - sum(r.valid.sum() for r in res) / sum(len(r) for r in res)),
                     "fallback [%]": 100 * sum(s["fallback_frames"] for s in per_drone)
                                     / max(1, sum(s["valid"] for s in per_drone)),
                     "bytes / frame": summaries[1]["bytes_per_frame"],
                     "stage 1 [ms]": 1000 * np.median([s["timing_median"]["stage1"] for s in per_drone])})
    return pd.DataFrame(rows).set_index("run").round(2)
