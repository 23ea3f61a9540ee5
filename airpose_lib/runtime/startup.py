"""A drone's start and the swarm's handshake: READY to the launcher and ``START <t0>`` back (or a
given t0), HELLO heartbeats (before the first slot, so that every drone knows the others are
alive at the start, and during the run: peer liveness), the first slot of a drone that
restarts into a running schedule, and BYE at the end (sent by :class:`~.drone.DroneProcess`)."""
from __future__ import annotations

import select
import sys
from collections.abc import Callable

from .messaging import PeerMessaging
from .sync import Schedule
from .wire import HELLO

__all__ = ["wait_start", "sequence_start", "first_slot", "Heartbeat"]

_START_WAIT_S = 300.0  # how long a drone waits for the launcher's START


def wait_start(drone_id: int, t0: float | None) -> float:
    """Say ``READY <id>`` on stdout; return ``t0``, or read it from the launcher on stdin
    (``START <t0>``) when None."""
    print(f"READY {drone_id}", flush=True)
    if t0 is not None:
        return float(t0)
    ready, _, _ = select.select([sys.stdin], [], [], _START_WAIT_S)
    line = sys.stdin.readline() if ready else ""
    if not line.startswith("START"):
        raise RuntimeError(f"expected 'START <t0>' on stdin, got {line!r}")
    return float(line.split()[1])


def sequence_start(src, start_s: float | None) -> float:
    """Sequence time of slot 0: ``start_s``, by default the first stamp of any view of ``src``
    (a source of :func:`~.source.open_source`)."""
    if start_s is not None:
        return start_s
    return min(float(src.view(v).stamps[0]) for v in range(src.num_views))


def first_slot(schedule: Schedule, now: float, restart: bool) -> int:
    """Slot 0, or for a drone (re)started after t0 the next slot it can still make."""
    return schedule.first_slot_after(now + 0.05) if restart else 0


class Heartbeat:
    """HELLO every ``period_s`` seconds of the drone's clock, with the slot divisor that
    ``divisor()`` says this drone asks for (:mod:`.rate`)."""

    def __init__(self, messaging: PeerMessaging, period_s: float, divisor: Callable[[], int] = lambda: 1) -> None:
        self.messaging = messaging
        self.period_s = period_s
        self.divisor = divisor
        self.next = 0.0  # local time of the next HELLO

    def beat(self, now: float) -> None:
        """Send a HELLO if one is due at ``now``."""
        if now >= self.next:
            self.messaging.send(HELLO, rate_divisor=self.divisor())
            self.next = now + self.period_s
