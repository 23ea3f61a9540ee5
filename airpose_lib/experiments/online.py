"""Notebook 06's hardware-in-the-loop test on one machine: drone fleets, online = offline, faults.

The paper ran AirPose on board two UAVs (Sec. III-D); the kit runs one drone process per camera
of a recorded sequence (:mod:`airpose_lib.runtime`). This module holds the runs notebook 06 shows:

* :func:`online_rig`: the recording, the backend (an ONNX export made once per backbone and crop
  size) and the fleet size of a run;
* :func:`run_schedule`: one fleet over the recording, ``fixed`` 240 ms windows (the paper) or
  ``pipelined`` at 20 fps (the paper's conjecture); :func:`airpose_lib.eval.online.online_summary_table`
  turns such runs into the throughput / latency table;
* :func:`online_offline_check`: the frames each fleet completed, recomputed in this process; every
  difference must be exactly zero;
* :func:`run_fault_scenario`: lost packets on every link and a drone killed and restarted;
* :func:`float16_cost`: what half-precision messages change, on the same frames in one process.
"""
from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd
import torch

from airpose_lib.assets import DataSource
from airpose_lib.body import load_body_model
from airpose_lib.data.sequences import ensure_sequences
from airpose_lib.data.sequences.reader import load_sequence
from airpose_lib.eval.metrics import mpjpe
from airpose_lib.model import posed_joints_and_vertices, to_smplx_params
from airpose_lib.model.onnx_export import export_onnx
from airpose_lib.runtime import results as R
from airpose_lib.runtime.backends import BackendSpec, build_torch_model
from airpose_lib.runtime.launcher import launch
from airpose_lib.runtime.offline import max_abs_difference, offline_inputs, offline_staged
from airpose_lib.viz.online import slot_states

from .configs import KitConfigs

__all__ = ["FIXED_PERIOD_S", "PIPELINED_PERIOD_S", "OnlineRig", "FleetRun", "OnlineOfflineCheck", "FaultRun",
           "online_rig", "run_schedule", "online_offline_check", "sequence_tau", "run_fault_scenario",
           "fault_summary_table", "float16_cost"]

#: The paper's fixed window per frame (140 ms acquisition + 2 x 25 ms exchange + inference).
FIXED_PERIOD_S = 0.240
#: The pipelined schedule: the paper's conjectured 20 fps.
PIPELINED_PERIOD_S = 1 / 20
#: The recording the fleets replay (the test person of the recordings experiment).
ONLINE_RECORDING = "person2"


@dataclass(frozen=True)
class OnlineRig:
    """What every run of notebook 06 shares.

    Attributes:
        sequence_root: the recording every drone replays (one camera each).
        spec: the backend every drone builds (its ``onnx_dir`` set for ``kind="onnx"``).
        drones: drone processes of the schedule runs.
        seconds: schedule length of each schedule run.
        out: the notebook's output folder; each run writes into a sub-folder.
    """

    sequence_root: str
    spec: BackendSpec
    drones: int
    seconds: float
    out: Path

    def node_options(self, **extra) -> dict:
        """The drone options that select this rig's backend (``airpose node`` flags)."""
        s = self.spec
        return {"backend": s.kind, "backbone": s.backbone, "input_size": s.input_size,
                "checkpoint": s.checkpoint, "onnx_dir": s.onnx_dir, **extra}


class FleetRun(NamedTuple):
    """One fleet run: ``summaries`` drone id -> its ``node_<id>.summary.json``; ``results`` the
    drones' records in drone order (:class:`~airpose_lib.runtime.results.NodeResults`)."""

    summaries: dict
    results: list


def online_rig(configs: KitConfigs, source: DataSource, out: str | Path, *, backend: str, backbone: str,
               input_size: int, drones: int, seconds: float, checkpoint: str | None = None,
               sequence_root: str | Path | None = None) -> OnlineRig:
    """The recording and backend of notebook 06's runs.

    Args:
        configs: the profile's configs (its ``person2`` recording is generated on first use).
        source: the resolved data source; official: the official real recording.
        out: output folder (the ONNX export goes to ``out/onnx_<backbone>_<input_size>``).
        backend: ``"onnx"`` or ``"torch"``.
        backbone, input_size, checkpoint: the network (random weights without a checkpoint).
        drones, seconds: fleet size and schedule length.
        sequence_root: a recording to use instead.
    """
    out = Path(out)
    if sequence_root is None and source.source == "official":
        sequence_root = source.roots["official_real"]
    if sequence_root is None:
        sequence_root = ensure_sequences(configs.sequences, configs.folders.sequences(), only=[ONLINE_RECORDING],
                                         progress=True)[ONLINE_RECORDING]
    onnx_dir = None
    if backend == "onnx":
        onnx_dir = out / f"onnx_{backbone}_{input_size}"
        if not (onnx_dir / "meta.json").is_file():  # exported once, reused by later runs
            export_onnx(build_torch_model(BackendSpec(backbone=backbone, input_size=input_size, checkpoint=checkpoint)),
                        onnx_dir, input_size)
    spec = BackendSpec(kind=backend, backbone=backbone, input_size=input_size, checkpoint=checkpoint,
                       onnx_dir=None if onnx_dir is None else str(onnx_dir))
    return OnlineRig(str(Path(sequence_root).resolve()), spec, drones, seconds, out)


def run_schedule(rig: OnlineRig, name: str, mode: str, offsets: Sequence[float] | None = None,
                 **extra) -> FleetRun:
    """Replay the recording with ``rig.drones`` processes for ``rig.seconds``.

    Args:
        name: sub-folder of ``rig.out`` for the drones' files.
        mode: ``"fixed"`` (240 ms windows) or ``"pipelined"`` (20 fps).
        offsets: per-drone clock error in ms (default none).
        **extra: more drone options (link emulation, timeouts ...).
    """
    period = FIXED_PERIOD_S if mode == "fixed" else PIPELINED_PERIOD_S
    options = rig.node_options(source=rig.sequence_root, mode=mode, preload=True,
                               frames=int(rig.seconds / period), max_runtime_s=rig.seconds + 120, **extra)
    fleet = launch(rig.drones, rig.out / name, options, clock_offsets_ms=offsets)
    summaries = fleet.wait(rig.seconds + 300)
    results = [R.load_node_results(rig.out / name / f"node_{d}.jsonl") for d in range(1, rig.drones + 1)]
    return FleetRun(summaries, results)


@dataclass
class OnlineOfflineCheck:
    """:func:`online_offline_check`'s answer.

    Attributes:
        table: one row per run: frames compared and the largest difference of each output.
        online: run name -> :func:`~airpose_lib.runtime.results.merge_views` of its records.
        offline: run name -> the same frames computed in this process.
    """

    table: pd.DataFrame
    online: dict
    offline: dict


def online_offline_check(rig: OnlineRig, runs: Mapping[str, FleetRun]) -> OnlineOfflineCheck:
    """Recompute the frames every run completed with the same backend and the same exchange
    (stages that ran with the mean parameters included) and compare.

    Raises:
        AssertionError: some output differs at all (online must equal offline bit for bit).
    """
    rows, online, offline = [], {}, {}
    for name, run in runs.items():
        m = R.merge_views(run.results)
        crops, P, _ = offline_inputs(rig.sequence_root, m["frame_index"], rig.spec.input_size, boxes=m["bbox"])
        off = offline_staged(rig.spec, crops, P, used=np.stack([m["used_s2"], m["used_s3"]], -1))
        diff = max_abs_difference(m, off)
        rows.append({"run": name, "frames": len(m["slot"]), **{f"max |d {k}|": v for k, v in diff.items()}})
        assert max(diff.values()) == 0.0, diff
        online[name], offline[name] = m, off
    return OnlineOfflineCheck(pd.DataFrame(rows).set_index("run"), online, offline)


def _load(sequence_root: str):
    return load_sequence(sequence_root, detectors=("openpose",), missing_detections="zero")


def sequence_tau(sequence_root: str) -> np.ndarray | None:
    """``(F, V, 3)`` ground-truth person position per camera of a recording (None: it has none)."""
    gt = _load(sequence_root).ground_truth
    return None if gt is None else gt["tau"]


class FaultRun(NamedTuple):
    """:func:`run_fault_scenario`'s answer: ``summaries`` drone id -> summary, ``states``
    ``(2, n_slots)`` per-slot state (:func:`~airpose_lib.viz.online.slot_states`), the slot
    ``period_s`` and the ``conditions`` in words."""

    summaries: dict
    states: np.ndarray
    period_s: float
    conditions: str


#: Columns of the fault run's per-drone summary shown by the notebook.
FAULT_SUMMARY_KEYS = ("slots", "valid", "fallback_frames", "no_peer_frames", "link_lost", "rejected")


def run_fault_scenario(rig: OnlineRig, name: str = "faults", n_slots: int = 400, link_loss: float = 0.2,
                       kill_after_s: float = 2.0, down_s: float = 0.6) -> FaultRun:
    """Two drones, pipelined at 20 fps, on the procedural stand-in camera (a recording may be
    only a few seconds long): ``link_loss`` of the packets lost on every link (50 Mbps, 2-5 ms),
    drone 2 killed ``kill_after_s`` after the start and restarted ``down_s`` later.

    ``n_slots`` = 400 (20 s): a restarted drone needs several seconds to load on a busy CPU.
    """
    out = rig.out / name
    options = rig.node_options(source="synthetic:views=2,frames=700,size=960x540", mode="pipelined", preload=True,
                               frames=n_slots, peer_timeout_ms=300, link_loss=link_loss, link_bandwidth_mbps=50,
                               link_latency_ms=2, link_jitter_ms=3, max_runtime_s=180)
    fleet = launch(2, out, options)
    time.sleep(max(0.0, fleet.t0 + kill_after_s - time.time()))
    fleet.kill(2)
    time.sleep(down_s)
    fleet.restart(2)
    summaries = fleet.wait(300)
    states = np.stack([slot_states(R.load_node_results(out / f"node_{d}.jsonl").frames, n_slots, R)
                       for d in (1, 2)])
    conditions = (f"pipelined 20 fps, {100 * link_loss:.0f} % of the packets lost on every link, 50 Mbps, "
                  f"2-5 ms latency; drone 2 killed {kill_after_s:g} s after the start and restarted at once")
    return FaultRun(summaries, states, PIPELINED_PERIOD_S, conditions)


def fault_summary_table(run: FaultRun) -> pd.DataFrame:
    """Per drone (columns): slots, valid frames, fallbacks, frames without peers, lost and rejected packets."""
    return pd.DataFrame({d: {k: s[k] for k in FAULT_SUMMARY_KEYS} for d, s in run.summaries.items()})


def _joints22(body, out: Mapping[str, np.ndarray], P: np.ndarray, K: np.ndarray) -> torch.Tensor:
    """``(n, V, 22, 3)`` camera-frame body joints of staged outputs ``out`` (``(n, V, ...)``) for
    crop vectors ``P (n, V, 3)`` and camera ``K (3, 3)`` (float64)."""
    n, V = P.shape[:2]
    t = {k: torch.from_numpy(out[k]).double() for k in ("phi6d", "theta6d", "beta", "tau")}
    p = to_smplx_params(t, torch.from_numpy(P).double(), torch.from_numpy(np.broadcast_to(K, (n, V, 3, 3)).copy()))
    return posed_joints_and_vertices(body, p, joints_only=True)["joints"][..., :22, :]


def float16_cost(rig: OnlineRig, n_frames: int = 40) -> pd.Series:
    """Float32 against float16 messages on the first ``n_frames`` frames of the recording, in one
    process with a perfect exchange; joints from the open neutral body."""
    seq = _load(rig.sequence_root)
    n = min(n_frames, len(seq.frames))
    idx = np.repeat(np.arange(n)[:, None], 2, 1)
    crops, P, _ = offline_inputs(rig.sequence_root, idx, rig.spec.input_size)
    body = load_body_model("open", "neutral")
    a = offline_staged(rig.spec, crops, P)
    b = offline_staged(dataclasses.replace(rig.spec, message_dtype="float16"), crops, P)
    change = mpjpe(_joints22(body, a, P, seq.K), _joints22(body, b, P, seq.K)).mean()
    return pd.Series({"frames x views": 2 * n, "MPJPE change [mm]": float(1000 * change),
                      "max |d theta6d|": float(np.abs(a["theta6d"] - b["theta6d"]).max()),
                      "max |d tau| [m]": float(np.abs(a["tau"] - b["tau"]).max()),
                      "bytes / frame (float32 -> float16)": "1168 -> 624"}, name="float16 messages")
