"""What a drone writes: one record per schedule slot, streamed to ``node_<id>.jsonl``.

The stream survives a killed node (one flushed line per frame; a restarted node appends after a
new ``meta`` line); at a clean exit the node also writes ``node_<id>.npz`` (same content as
arrays) and ``node_<id>.summary.json``. JSON keeps float32 values exactly (a float32 widened
to float64 prints and parses back to the same number).

A frame record holds the slot, the camera frame index and shutter stamp, the timing, the
per-stage list of drones whose messages were used, the :data:`FLAGS`, the crop (``bbox``, ``P``)
and this view's outputs with the network's keys (``phi6d (6)``, ``theta6d (21, 6)``,
``beta (10)``, ``tau (3)`` or ``cam (3)``). :func:`predictions` turns a file into the same dict
of tensors as ``AirPoseNet.forward`` for one view (leading ``(N,)``), plus ``P (N, 3)`` and
``K (N, 3, 3)`` (the camera's) and ``K_net (N, 3, 3)`` (the network's virtual camera that P
refers to, ``data.network_input.crop_input``), so ``model.to_smplx_params(pred, pred["P"], pred["K_net"])``
and ``eval`` read it like offline predictions; :func:`merge_views` joins the drones' files into ``(F, V, ...)``.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from airpose_lib.atomic import atomic_path
from airpose_lib.data.network_input import network_camera

__all__ = [
    "FLAGS",
    "FALLBACK_S2",
    "FALLBACK_S3",
    "NO_PEERS",
    "LAST_USED",
    "STAMP_MISMATCH",
    "NO_DETECTION",
    "DROPPED",
    "SKIPPED",
    "RATE_SKIPPED",
    "INVALID",
    "fallback_flag",
    "describe_flags",
    "ResultWriter",
    "NodeResults",
    "load_node_results",
    "predictions",
    "merge_views",
    "PARAM_KEYS",
    "mask_to_ids",
    "read_jsonl",
    "write_npz",
]

FALLBACK_S2 = 1  # stage 2 ran without some expected drone's stage-1 message
FALLBACK_S3 = 2  # stage 3 ran without some expected drone's stage-2 message
NO_PEERS = 4  # no other drone contributed to this frame: the Fullcam behaviour
LAST_USED = 8  # a missing message was replaced by that drone's last parameters (fallback "last")
STAMP_MISMATCH = 16  # a drone sent this stage for a frame outside the stamp tolerance
NO_DETECTION = 32  # no detection in this frame: the previous box was used
DROPPED = 64  # completed after its deadline: discarded (the paper's fixed window)
SKIPPED = 128  # never started (the node was busy past the slot, or no frame/box)
RATE_SKIPPED = 256  # with SKIPPED: not a slot of the swarm's agreed lower rate (runtime.rate)
INVALID = DROPPED | SKIPPED
FLAGS = {"fallback_s2": FALLBACK_S2, "fallback_s3": FALLBACK_S3, "no_peers": NO_PEERS,
         "last_used": LAST_USED, "stamp_mismatch": STAMP_MISMATCH, "no_detection": NO_DETECTION,
         "dropped": DROPPED, "skipped": SKIPPED, "rate_skipped": RATE_SKIPPED}

PARAM_KEYS = ("phi6d", "theta6d", "beta", "tau", "cam")
_SHAPES = {"phi6d": (6,), "theta6d": (21, 6), "beta": (10,), "tau": (3,), "cam": (3,), "P": (3,),
           "bbox": (4,)}


def fallback_flag(stage: int) -> int:
    """Flag of "stage k ran without some expected message" (k = 2, 3, ...)."""
    return 1 << (stage - 2) if stage <= 3 else FALLBACK_S3


def describe_flags(flags: int) -> list[str]:
    return [name for name, bit in FLAGS.items() if flags & bit]


def _jsonable(x):
    if isinstance(x, np.ndarray):
        return x.astype(np.float64).tolist() if x.dtype.kind == "f" else x.tolist()
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    return x


class ResultWriter:
    """Append-only record stream of one drone.

    Args:
        path: ``.jsonl`` file (appended to; a restarted node continues the same file).
        meta: run description written first (config, K, kit version, ...).
    """

    def __init__(self, path: str | Path, meta: dict):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._f = open(self.path, "a", buffering=1)
        self.write({"kind": "meta", **meta})

    def write(self, record: dict) -> None:
        self._f.write(json.dumps(_jsonable(record), separators=(",", ":")) + "\n")
        self._f.flush()

    def close(self) -> None:
        if not self._f.closed:
            self._f.close()


@dataclass
class NodeResults:
    """One drone's records as arrays (one row per slot record, in file order).

    ``frames`` holds ``slot, frame_index`` (position in the source), ``frame_number`` (image
    number of the official layout, -1 for synthetic), ``flags`` (int64), ``stamp, shutter, target, t_done,
    latency`` (float64, s), ``used_s2, used_s3`` (bit mask of the drones whose messages that stage
    used, bit ``id - 1``; -1 = stage not run; :func:`mask_to_ids`) and
    the params ``phi6d (N, 6)``, ``theta6d (N, 21, 6)``, ``beta (N, 10)``, ``tau``/``cam (N, 3)``,
    ``P (N, 3)`` (float32) and ``bbox (N, 4)`` (float64), NaN where a slot has none;
    ``timing_<name>`` (durations: acquire, stage1, wait2, stage2, ...) and ``marks_<event>``
    (seconds from the slot's target time: wake, captured, acquired, stage1_start, stage1_end,
    stage2_start, ...).
    """

    meta: dict
    frames: dict[str, np.ndarray]
    summary: dict | None = None

    @property
    def valid(self) -> np.ndarray:
        """``(N,)`` bool: completed in time (not dropped or skipped)."""
        return (self.frames["flags"] & INVALID) == 0

    def __len__(self) -> int:
        return len(self.frames["slot"])


def _mask(ids) -> int:
    """Drone ids (1..62) -> bit mask ``sum(1 << (id - 1))``."""
    return sum(1 << (int(d) - 1) for d in ids)


def mask_to_ids(mask: int) -> list[int]:
    """Inverse of the ``used_s<k>`` bit masks: the 1-based drone ids."""
    return [b + 1 for b in range(63) if int(mask) >> b & 1]


def _records_to_arrays(records: list[dict]) -> dict[str, np.ndarray]:
    n = len(records)
    out: dict[str, np.ndarray] = {}
    for key in ("slot", "frame_index", "frame_number", "flags", "drone", "view", "divisor"):
        out[key] = np.array([r.get(key, -1) if r.get(key) is not None else -1 for r in records], np.int64)
    for key in ("stamp", "shutter", "target", "t_done", "latency"):
        out[key] = np.array([np.nan if r.get(key) is None else r[key] for r in records], np.float64)
    for k in (2, 3):
        out[f"used_s{k}"] = np.array([_mask(r["used"][k - 2]) if r.get("used") and len(r["used"]) > k - 2 else -1
                                      for r in records], np.int64)
    present = {k for r in records for k in r}
    for key, shape in _SHAPES.items():
        if key not in present:
            continue
        dtype = np.float64 if key == "bbox" else np.float32  # the box as computed (P follows from it)
        arr = np.full((n, *shape), np.nan, dtype)
        for i, r in enumerate(records):
            if r.get(key) is not None:
                arr[i] = np.asarray(r[key], dtype).reshape(shape)
        out[key] = arr
    for group in ("timing", "marks"):
        for key in sorted({k for r in records for k in (r.get(group) or {})}):
            out[f"{group}_{key}"] = np.array([(r.get(group) or {}).get(key, np.nan) for r in records], np.float64)
    return out


def read_jsonl(path: str | Path) -> tuple[dict, list[dict], dict | None]:
    """(last meta record, frame records, last summary record) of a ``.jsonl`` stream; a
    truncated last line (killed writer) is ignored."""
    meta, frames, summary = {}, [], None
    with open(path) as f:
        for line in f:
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:
                continue
            kind = rec.get("kind")
            if kind == "meta":
                meta = rec
            elif kind == "frame":
                frames.append(rec)
            elif kind == "summary":
                summary = rec
    return meta, frames, summary


def write_npz(jsonl: str | Path, npz: str | Path) -> Path:
    """Convert a record stream into an ``.npz`` (arrays of :class:`NodeResults` plus ``meta``)."""
    meta, frames, summary = read_jsonl(jsonl)
    arrays = _records_to_arrays(frames)
    arrays["meta_json"] = np.array(json.dumps(meta))
    if summary is not None:
        arrays["summary_json"] = np.array(json.dumps(summary))
    npz = Path(npz)
    with atomic_path(npz) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **arrays)
    return npz


def load_node_results(path: str | Path) -> NodeResults:
    """Read ``node_<id>.jsonl`` or ``node_<id>.npz``."""
    path = Path(path)
    if path.suffix == ".npz":
        with np.load(path) as z:
            frames = {k: z[k] for k in z.files if not k.endswith("_json")}
            meta = json.loads(str(z["meta_json"]))
            summary = json.loads(str(z["summary_json"])) if "summary_json" in z.files else None
        return NodeResults(meta, frames, summary)
    meta, records, summary = read_jsonl(path)
    return NodeResults(meta, _records_to_arrays(records), summary)


def predictions(res: NodeResults, valid_only: bool = True) -> dict:
    """One drone's outputs as the network's output dict with a leading ``(N,)``.

    Returns torch tensors ``phi6d (N, 6)``, ``theta6d (N, 21, 6)``, ``beta (N, 10)``,
    ``tau (N, 3)`` or ``cam (N, 3)``, ``P (N, 3)``, ``K (N, 3, 3)``, ``K_net (N, 3, 3)`` (the
    virtual camera of P: convert a weak camera with it) and numpy ``frame_index``,
    ``stamp``, ``slot``, ``flags``; ``input_size`` (int). With ``valid_only`` only frames completed
    in time (and not skipped) are kept.
    """
    import torch

    keep = res.valid if valid_only else np.ones(len(res), bool)
    out: dict = {}
    for key in (*PARAM_KEYS, "P"):
        if key in res.frames:
            out[key] = torch.from_numpy(np.ascontiguousarray(res.frames[key][keep]))
    K = np.asarray(res.meta.get("K", np.eye(3)), np.float32)
    out["K"] = torch.from_numpy(np.broadcast_to(K, (int(keep.sum()), 3, 3)).copy())
    K_net = np.asarray(res.meta.get("K_net", network_camera()), np.float32)
    out["K_net"] = torch.from_numpy(np.broadcast_to(K_net, (int(keep.sum()), 3, 3)).copy())
    for key in ("frame_index", "stamp", "slot", "flags"):
        out[key] = res.frames[key][keep]
    out["input_size"] = int(res.meta.get("input_size", 224))
    return out


def merge_views(results: list[NodeResults], valid_only: bool = True) -> dict:
    """Join the drones' records on the schedule slot: ``(F, V, ...)`` arrays over the slots every
    drone completed (with ``valid_only``; otherwise all slots, NaN where a view has none), ordered
    by view index.

    Returns numpy ``slot (F,)``, ``frame_index (F, V)``, ``stamp (F, V)``, ``flags (F, V)``,
    ``used_s2 / used_s3 (F, V)`` (masks), ``bbox (F, V, 4)`` and
    the params ``phi6d (F, V, 6)``, ``theta6d (F, V, 21, 6)``, ``beta``, ``tau``/``cam``, ``P``,
    plus ``K (V, 3, 3)`` and ``K_net (V, 3, 3)`` (the virtual camera of P).
    """
    results = sorted(results, key=lambda r: r.meta.get("view", 0))
    rows = []
    for r in results:
        keep = r.valid if valid_only else np.ones(len(r), bool)
        # a restarted node may have written a slot twice; the last record wins
        rows.append({int(s): i for i, s in zip(np.nonzero(keep)[0], r.frames["slot"][keep])})
    slots = sorted(set.intersection(*(set(m) for m in rows)) if valid_only else set.union(*(set(m) for m in rows)))
    out: dict = {"slot": np.array(slots, np.int64)}
    for key in ("frame_index", "stamp", "flags", "used_s2", "used_s3", *PARAM_KEYS, "P", "bbox"):
        if not all(key in r.frames for r in results):
            continue
        cols = []
        for r, m in zip(results, rows):
            a = r.frames[key]
            fill = -1 if a.dtype.kind == "i" else np.nan
            col = np.full((len(slots), *a.shape[1:]), fill, a.dtype)
            for j, s in enumerate(slots):
                if s in m:
                    col[j] = a[m[s]]
            cols.append(col)
        out[key] = np.stack(cols, axis=1)
    out["K"] = np.stack([np.asarray(r.meta.get("K", np.eye(3)), np.float64) for r in results])
    out["K_net"] = np.stack([np.asarray(r.meta.get("K_net", network_camera()), np.float64) for r in results])
    return out
