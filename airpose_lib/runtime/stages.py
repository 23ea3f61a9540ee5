"""One frame's way through the staged network: stage 1 on the crop, then for k = 2, 3 waiting for
the other drones' stage k-1 messages (stamps matched within the tolerance), stage k on what came,
and publishing its message (the last stage's is not needed).

Waiting for a drone ends when its message arrives, when the drone is not alive (no packet for
``peer_timeout``), when it said it skips the slot, or at the stage's wait deadline: the frame's
deadline minus the time the remaining stages take (and at most ``comm_timeout`` after this
drone's own message, if set). A stage run without some message uses the fallback: ``mean`` = the
mean parameters in place of the missing drones (with no drone at all that is exactly the Fullcam
behaviour, as iteration 1), ``last`` = that drone's last message received; the record is flagged.
"""
from __future__ import annotations

import math
import statistics
import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from . import results as R
from .backends import StageModel, fresh_copy
from .messaging import PeerMessaging
from .sync import Clock
from .wire import DATA, Packet

__all__ = ["FrameJob", "StagePipeline"]

_WAKE_MARGIN_S = 0.005  # a stage is started this long before it must end at the latest


@dataclass
class FrameJob:
    """One frame in flight."""

    slot: int
    target: float
    deadline: float
    frame_index: int = -1
    stamp: float = math.nan
    shutter: float = math.nan  # true (machine) time of the shutter
    model: StageModel | None = None
    msg: np.ndarray | None = None  # last message produced
    k: int = 0
    wait_since: float = 0.0
    used: list = field(default_factory=list)
    flags: int = 0
    P: np.ndarray | None = None
    bbox: np.ndarray | None = None
    timing: dict = field(default_factory=dict)  # durations (s)
    marks: dict = field(default_factory=dict)  # local clock at the frame's events
    skip_reason: str | None = None
    crop: np.ndarray | None = None  # (1, 3, S, S) between acquisition and stage 1
    divisor: int = 1  # the swarm's slot divisor when the slot came up (runtime.rate)


class StagePipeline:
    """The stages of this drone's frames and the exchange between them.

    Args:
        proto: the loaded staged model; each frame runs on a fresh copy of it.
        clock: the drone's clock.
        messaging: the drone's exchange (peers, mailbox, sending).
        fallback: ``mean`` or ``last``.
        comm_timeout_s: the longest wait per exchange (None: as long as the deadline allows).
    """

    def __init__(self, proto: StageModel, clock: Clock, messaging: PeerMessaging, fallback: str = "mean",
                 comm_timeout_s: float | None = None) -> None:
        self.proto = proto
        self.num_stages = int(proto.num_stages)
        self.clock = clock
        self.messaging = messaging
        self.fallback = fallback
        self.comm_timeout_s = comm_timeout_s
        self._est_stage = deque([0.005], maxlen=32)  # seconds per later stage (recent)
        self._est_stage1 = deque([0.0], maxlen=15)  # seconds of stage 1 (recent)

    def stage1(self, job: FrameJob) -> FrameJob:
        """Stage 1 of an acquired frame (inference thread when pipelined)."""
        t = time.perf_counter()
        job.marks["stage1_start"] = self.clock.now()
        job.model = fresh_copy(self.proto)
        job.msg = job.model.stage1(job.crop, job.P)
        job.crop = None
        dt = time.perf_counter() - t
        job.k = 1
        job.timing["stage1"] = dt
        job.marks["stage1_end"] = self.clock.now()
        self._est_stage1.append(dt)
        return job

    def can_finish(self, job: FrameJob) -> bool:
        """Whether stage 1 and the later stages, at their typical (median: one slow outlier must
        not starve the following frames) recent durations, end before the frame's deadline."""
        need = statistics.median(self._est_stage1) + (self.num_stages - 1) * statistics.median(self._est_stage)
        return self.clock.now() + need <= job.deadline

    def lower_stage1_estimate(self) -> None:
        """After a skip: a drone that was too slow probes again later."""
        self._est_stage1.append(0.8 * statistics.median(self._est_stage1))

    def publish(self, job: FrameJob) -> None:
        """Send the message of the stage just completed (the last stage's is not needed)."""
        if job.k < self.num_stages:
            self.messaging.send(DATA, job, stage=job.k, payload=job.msg)
        job.wait_since = self.clock.now()

    def wait_deadline(self, job: FrameJob) -> float:
        """Local time until which ``job`` waits for the messages of its next stage."""
        # the remaining stages, plus a margin for waking up late on a busy CPU
        reserve = (self.num_stages - job.k) * max(self._est_stage) + _WAKE_MARGIN_S
        d = job.deadline - reserve
        if self.comm_timeout_s is not None:
            d = min(d, job.wait_since + self.comm_timeout_s)
        return d

    def advance(self, job: FrameJob, now: float) -> bool:
        """Run every stage whose inputs are there (or whose wait is over); True when done."""
        peers, mailbox, tol = self.messaging.peers, self.messaging.mailbox, self.messaging.tolerance_s
        while job.k < self.num_stages:
            k = job.k
            got: dict[int, Packet] = {}
            for d in sorted(peers.expected):
                p = mailbox.match(d, k, job.stamp, tol)
                if p is not None:
                    got[d] = p
            waiting = peers.alive(now) - set(got) - self.messaging.skipping(job.slot)
            if waiting and now < self.wait_deadline(job):
                return False
            msgs = [got[d].payload for d in sorted(got)]
            missing = sorted(peers.expected - set(got))
            if missing:
                job.flags |= R.fallback_flag(k + 1)
                for d in missing:
                    if mailbox.near_miss(d, k, job.slot, job.stamp, tol):
                        job.flags |= R.STAMP_MISMATCH
                    if self.fallback == "last":
                        p = mailbox.latest(d, job.stamp, k, tol)
                        if p is not None:
                            msgs.append(p.payload)
                            job.flags |= R.LAST_USED
            job.used.append(sorted(got))
            t = time.perf_counter()
            job.timing[f"wait{k + 1}"] = self.clock.now() - job.wait_since
            job.marks[f"stage{k + 1}_start"] = self.clock.now()
            job.msg = job.model.stage(k + 1, msgs)
            dt = time.perf_counter() - t
            job.timing[f"stage{k + 1}"] = dt
            job.marks[f"stage{k + 1}_end"] = self.clock.now()
            self._est_stage.append(dt)
            job.k = k + 1
            self.publish(job)
            now = self.clock.now()
        return True
