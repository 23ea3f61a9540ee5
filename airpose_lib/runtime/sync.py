r"""Time on the drones: clocks, the frame schedule, frame selection and message matching.

Every drone runs the same schedule on its own clock (the paper's drones are NTP-synchronised; a
per-drone ``offset`` emulates the residual error). Slot k of the schedule targets the sequence
time ``start + g_k``, where ``g_k`` is ``k * period`` rounded to the camera's nominal frame grid
(``round(k * period * fps) / fps``), so the target falls on a shutter instant and every drone
picks the same frame even when the clocks disagree by up to half a frame period::

    local time    t0 + g_k + margin   wake up; select the frame whose stamp is nearest t0 + g_k
                                      (wait for its capture if it lies a little after)
    local time    t0 + g_k + deadline the frame must be done (fixed window: deadline = period)

A camera replays its recorded frames in real time: frame i is captured at the true (machine)
time ``t0 + stamps[i] - start`` and stamped with the drone's clock, i.e. ``+ offset``. Drones
match the other drones' messages to their own frame by that shutter stamp within a tolerance
(default half a frame period), as the paper's ROS synchronisation did.
"""
from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from .wire import Packet

__all__ = ["Clock", "Schedule", "CameraReplay", "Mailbox", "PeerTable"]


class Clock:
    """A drone's clock: the machine's wall clock plus ``offset_s`` seconds."""

    def __init__(self, offset_s: float = 0.0):
        self.offset_s = float(offset_s)

    def now(self) -> float:
        return time.time() + self.offset_s

    def to_true(self, local: float) -> float:
        """Local reading -> machine (true) time."""
        return local - self.offset_s

    def sleep_until(self, local: float, max_step_s: float = 0.05) -> None:
        """Sleep until the clock reads ``local`` (in bounded steps)."""
        while True:
            dt = local - self.now()
            if dt <= 0:
                return
            time.sleep(min(dt, max_step_s))


@dataclass(frozen=True)
class Schedule:
    """The common frame schedule.

    Args:
        t0: start, in each drone's own clock (s since the epoch).
        period_s: slot period (fixed window: the window; pipelined: 1 / rate).
        deadline_s: a frame must be complete this long after its target time (fixed window: the
            window; pipelined: the latency budget).
        fps: the cameras' nominal frame rate (targets are rounded to its grid; 0 = no rounding).
        margin_s: wake this long after the target (the frame must have been captured).
        num_slots: None = until the sequence ends.
    """

    t0: float
    period_s: float
    deadline_s: float
    fps: float = 0.0
    margin_s: float = 0.0
    num_slots: int | None = None

    def offset(self, k: int) -> float:
        """``g_k``: seconds from t0 to slot k's target."""
        g = k * self.period_s
        return round(g * self.fps) / self.fps if self.fps > 0 else g

    def target(self, k: int) -> float:
        return self.t0 + self.offset(k)

    def wake(self, k: int) -> float:
        return self.target(k) + self.margin_s

    def deadline(self, k: int) -> float:
        return self.target(k) + self.deadline_s

    def first_slot_after(self, local: float) -> int:
        """Smallest k whose wake time is not before ``local`` (a late joiner's first slot)."""
        k = max(0, math.floor((local - self.t0 - self.margin_s) / self.period_s) - 1)
        while self.wake(k) < local:
            k += 1
        return k


class CameraReplay:
    """Real-time replay of one recorded camera.

    Args:
        stamps: ``(N,)`` recorded shutter stamps (s).
        t0: true time at which sequence time ``start`` is replayed.
        start: sequence time of slot 0 (default: the first stamp).
        offset_s: this drone's clock offset (stamps it reports are true shutter + offset).
    """

    def __init__(self, stamps: np.ndarray, t0: float, start: float | None = None, offset_s: float = 0.0):
        stamps = np.asarray(stamps, np.float64)
        if stamps.ndim != 1 or stamps.size == 0 or np.any(np.diff(stamps) <= 0):
            raise ValueError("stamps must be a non-empty, strictly increasing (N,) array")
        start = float(stamps[0]) if start is None else float(start)
        self.true_shutter = t0 + (stamps - start)
        self.local_stamps = self.true_shutter + offset_s

    def select(self, target_local: float) -> int:
        """Index of the frame whose (local) stamp is nearest ``target_local``; the caller waits
        until :attr:`local_stamps` ``[i]`` if the frame has not been captured yet."""
        j = int(np.searchsorted(self.local_stamps, target_local))
        cands = [i for i in (j - 1, j) if 0 <= i < len(self.local_stamps)]
        return min(cands, key=lambda i: abs(self.local_stamps[i] - target_local))

    @property
    def end_local(self) -> float:
        return float(self.local_stamps[-1])


@dataclass
class _Entry:
    packet: Packet
    received: float  # local time


class Mailbox:
    """The other drones' DATA packets, by (drone, stage), matched to a frame by stamp."""

    def __init__(self, depth: int = 64):
        self._boxes: dict[tuple[int, int], deque] = {}
        self._depth = depth

    def put(self, packet: Packet, received: float) -> None:
        key = (packet.drone, packet.stage)
        box = self._boxes.get(key)
        if box is None:
            box = self._boxes[key] = deque(maxlen=self._depth)
        box.append(_Entry(packet, received))

    def match(self, drone: int, stage: int, stamp: float, tolerance_s: float) -> Packet | None:
        """The packet of ``drone`` for ``stage`` whose stamp is nearest ``stamp``, if within the
        tolerance."""
        best, err = None, tolerance_s
        for e in self._boxes.get((drone, stage), ()):
            d = abs(e.packet.stamp - stamp)
            if d <= err:
                best, err = e.packet, d
        return best

    def near_miss(self, drone: int, stage: int, slot: int, stamp: float, tolerance_s: float) -> bool:
        """True if ``drone`` sent ``stage`` for the same schedule slot but a frame whose stamp is
        outside the tolerance (its clock or its frame selection disagrees with ours)."""
        return any(e.packet.slot == slot and abs(e.packet.stamp - stamp) > tolerance_s
                   for e in self._boxes.get((drone, stage), ()))

    def latest(self, drone: int, stamp: float, stage: int, tolerance_s: float) -> Packet | None:
        """The most recent message of ``drone`` not newer than (this frame, ``stage``): its
        earlier stage of this frame, else its last message of an earlier frame (the "last
        parameters" fallback)."""
        best, key = None, None
        for (d, s), box in self._boxes.items():
            if d != drone or s > stage:
                continue
            for e in box:
                if e.packet.stamp > stamp + tolerance_s:
                    continue
                k = (e.packet.stamp, s)
                if key is None or k > key:
                    best, key = e.packet, k
        return best

    def prune(self, older_than_stamp: float) -> None:
        for box in self._boxes.values():
            while box and box[0].packet.stamp < older_than_stamp:
                box.popleft()


@dataclass
class PeerTable:
    """Which of the expected drones are alive (heard from within ``timeout_s``)."""

    expected: frozenset[int]
    timeout_s: float = 1.0
    last_heard: dict[int, float] = field(default_factory=dict)
    gone: set[int] = field(default_factory=set)  # said BYE

    def heard(self, drone: int, local: float) -> bool:
        """Record a packet; returns True if the drone was not alive before (joined/rejoined)."""
        was = self.is_alive(drone, local)
        self.last_heard[drone] = local
        self.gone.discard(drone)
        return not was

    def bye(self, drone: int) -> None:
        self.gone.add(drone)

    def is_alive(self, drone: int, local: float) -> bool:
        t = self.last_heard.get(drone)
        return t is not None and drone not in self.gone and local - t < self.timeout_s

    def alive(self, local: float) -> set[int]:
        return {d for d in self.expected if self.is_alive(d, local)}

    def all_heard(self, ids: Iterable[int] | None = None) -> bool:
        return all(d in self.last_heard for d in (self.expected if ids is None else ids))
