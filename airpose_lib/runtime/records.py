"""What a drone writes about its run: the meta record, one record per schedule slot (finished,
dropped or skipped; :mod:`.results` defines the stream and its flags) and the summary."""
from __future__ import annotations

import logging
import math
import statistics
import time
from collections import defaultdict

import numpy as np

from airpose_lib import __version__

from . import results as R
from .backends import to_numpy
from .config import NodeConfig
from .messaging import PeerMessaging
from .source import ViewSource
from .stages import FrameJob
from .sync import Clock
from .transport import Transport
from .wire import SKIP

__all__ = ["node_meta", "FrameRecords"]

log = logging.getLogger("airpose.runtime")


def node_meta(cfg: NodeConfig, view_index: int, K: np.ndarray, input_size: int, num_stages: int, t0: float,
              tolerance_s: float, fps: float, restart: bool) -> dict:
    """The first record of a drone's stream (a restarted drone writes another one)."""
    return {"drone": cfg.drone_id, "view": view_index, "kit_version": __version__,
            "config": cfg.to_dict(), "K": K, "input_size": input_size,
            "num_stages": num_stages, "t0": t0, "tolerance_s": tolerance_s,
            "fps": fps, "restart": restart, "started": time.time()}


class FrameRecords:
    """Writes the slots' records and keeps what the summary needs.

    Args:
        cfg: the drone's settings.
        view_index, view: the drone's camera.
        clock: the drone's clock.
        messaging: the exchange (a skipped slot is announced; finished frames are noted).
    """

    def __init__(self, cfg: NodeConfig, view_index: int, view: ViewSource, clock: Clock,
                 messaging: PeerMessaging) -> None:
        self.cfg = cfg
        self.view_index = view_index
        self.view = view
        self.clock = clock
        self.messaging = messaging
        self.writer: R.ResultWriter | None = None  # opened at the start
        self._records: list[dict] = []

    def record(self, job: FrameJob, done: bool) -> None:
        """Write the record of a finished (``done``) or skipped slot."""
        now = self.clock.now()
        rec = {"kind": "frame", "drone": self.cfg.drone_id, "view": self.view_index, "slot": job.slot,
               "frame_index": job.frame_index if job.frame_index >= 0 else None,
               "frame_number": (int(self.view.numbers[job.frame_index])
                                if job.frame_index >= 0 and hasattr(self.view, "numbers") else None),
               "stamp": None if math.isnan(job.stamp) else job.stamp,
               "shutter": None if math.isnan(job.shutter) else job.shutter, "target": job.target,
               "t_done": now, "used": job.used, "timing": job.timing, "divisor": job.divisor,
               "marks": {k: v - job.target for k, v in job.marks.items()}}
        if done:
            if now > job.deadline:
                job.flags |= R.DROPPED
            if self.messaging.peers.expected and not any(job.used) and not job.flags & R.LAST_USED:
                job.flags |= R.NO_PEERS
            rec["latency"] = self.clock.to_true(now) - job.shutter
            out = job.model.result()
            for key in R.PARAM_KEYS:
                if key in out:
                    rec[key] = to_numpy(out[key]).astype(np.float32).reshape(-1)
            rec["P"], rec["bbox"] = job.P.reshape(-1), job.bbox
            self.messaging.finished(job.stamp)
        else:
            rec["reason"] = job.skip_reason
            self.messaging.send(SKIP, job)  # so that the others do not wait for this drone
        rec["flags"] = job.flags
        self.writer.write(rec)
        self._records.append({k: rec.get(k) for k in ("slot", "flags", "latency", "timing", "used")})
        if job.flags & R.INVALID:
            log.debug("slot %d: %s", job.slot, R.describe_flags(job.flags))

    def summary(self, t_begin: float, period_s: float, frames_started: int, transport: Transport) -> dict:
        """The run's summary record: slots, valid frames, rates, latencies, traffic, refusals."""
        recs = self._records
        m = self.messaging
        flags = np.array([r["flags"] for r in recs], np.int64) if recs else np.zeros(0, np.int64)
        valid = (flags & R.INVALID) == 0
        lat = np.array([r["latency"] for r, ok in zip(recs, valid) if ok], np.float64)
        n = len(recs)
        taken = n - int(((flags & R.RATE_SKIPPED) != 0).sum())  # slots of the agreed rate
        span = n * period_s if n else math.nan
        timings = defaultdict(list)
        for r, ok in zip(recs, valid):
            if ok:
                for key, v in (r["timing"] or {}).items():
                    timings[key].append(v)

        def pct(a, q):
            return float(np.percentile(a, q)) if len(a) else None

        return {
            "kind": "summary", "drone": self.cfg.drone_id, "view": self.view_index, "mode": self.cfg.mode,
            "backend": self.cfg.backend.to_dict(), "slots": n, "valid": int(valid.sum()),
            "dropped": int(((flags & R.DROPPED) != 0).sum()), "skipped": int(((flags & R.SKIPPED) != 0).sum()),
            # among the frames completed in time:
            "fallback_frames": int((valid & ((flags & (R.FALLBACK_S2 | R.FALLBACK_S3)) != 0)).sum()),
            "no_peer_frames": int((valid & ((flags & R.NO_PEERS) != 0)).sum()),
            "stamp_mismatch_frames": int((valid & ((flags & R.STAMP_MISMATCH) != 0)).sum()),
            "nominal_fps": 1.0 / period_s,
            "fps": float(valid.sum() / span) if n else 0.0,
            # the swarm's agreed rate (runtime.rate) and the share of its slots not completed in time
            "rate_skipped": n - taken, "agreed_fps": taken / span if n else None,
            "drop_rate": float(1.0 - valid.sum() / taken) if taken else None,
            "latency_p50": pct(lat, 50), "latency_p95": pct(lat, 95), "latency_max": pct(lat, 100),
            "bytes_data": m.bytes_data, "data_packets": m.data_packets, "bytes_hello": m.bytes_hello,
            "frames_started": frames_started,
            "bytes_per_frame": m.bytes_data / frames_started if frames_started else None,
            "rejected": dict(m.rejected), "late_packets": m.late_packets,
            "authenticated": m.authenticated,
            "link_lost": transport.emulator.lost if transport.emulator else 0,
            "send_dropped": transport.send_dropped,
            "timing_median": {k: statistics.median(v) for k, v in timings.items()},
            "wall_s": self.clock.now() - t_begin,
        }
