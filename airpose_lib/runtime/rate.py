"""The swarm's common frame rate (pipelined mode): overloaded drones agree on a lower one.

Every drone asks for a *slot divisor* m: process every m-th slot of the schedule (slots k with
k % m == 0), that is a rate of ``rate_hz / m``. It derives m from its own recent stage-1 time
(the part that scales with the CPU it gets) and sends it with every heartbeat (HELLO); each drone
uses the largest m asked by itself or a drone it still hears from. Because the slots are picked
by their absolute number, drones with the same m process the same frames and exchange messages
for all of them; a drone that is overloaded no longer skips slots on its own (which costs the
others a wait and a fallback for every frame it misses).

The divisor rises as soon as the stage-1 time needs it and falls one step at a time, only after
``settle_s`` seconds in which stage 1 would have fitted one step down even with that step's
extra load: a lower rate removes load and so shortens stage 1, which would otherwise speed the
swarm up again at once and make the rate oscillate.
"""
from __future__ import annotations

import math
import statistics
from collections import deque
from collections.abc import Iterable

__all__ = ["needed_divisor", "takes_slot", "RateAgreement"]


def needed_divisor(stage1_s: float, period_s: float, headroom: float = 0.8, max_divisor: int = 8) -> int:
    """Smallest m such that one stage 1 fits in ``headroom`` of m slot periods (1..max_divisor).

    The inference thread runs one stage 1 after the other, so a drone keeps up with every m-th
    slot when stage 1 takes at most m periods; ``headroom`` keeps the rest of the period for
    acquisition, the later stages and the messages.
    """
    if not math.isfinite(stage1_s) or stage1_s <= 0:
        return 1
    return max(1, min(max_divisor, math.ceil(stage1_s / (headroom * period_s) - 1e-9)))


def takes_slot(slot: int, divisor: int) -> bool:
    """Whether a swarm at slot divisor ``divisor`` processes ``slot`` (by its absolute number, so
    that drones with the same divisor process the same frames)."""
    return slot % divisor == 0


class RateAgreement:
    """One drone's side of the agreement.

    Args:
        period_s: slot period of the schedule (1 / rate_hz).
        adaptive: False: the divisor stays 1 (every slot, each drone skipping on its own).
        headroom: fraction of the m periods stage 1 may fill (see :func:`needed_divisor`).
        max_divisor: the lowest rate asked for is ``rate_hz / max_divisor``.
        settle_s: how long the lower divisor must have had room before the divisor falls.
        window: stage-1 times in the median (recent frames).
    """

    def __init__(self, period_s: float, adaptive: bool = True, headroom: float = 0.8, max_divisor: int = 8,
                 settle_s: float = 2.0, window: int = 9) -> None:
        self.period_s = period_s
        self.adaptive = adaptive
        self.headroom = headroom
        self.max_divisor = max_divisor
        self.settle_s = settle_s
        self.own = 1  # the divisor this drone asks for
        self._stage1: deque = deque(maxlen=window)
        self._room_since: float | None = None  # since when a lower divisor would have had room
        self._last_rise = -math.inf
        self._peers: dict[int, int] = {}  # drone id -> the divisor it asked for last

    def observe(self, now: float, stage1_s: float) -> None:
        """A stage 1 that took ``stage1_s`` seconds ended at ``now`` (the drone's clock)."""
        if not self.adaptive:
            return
        self._stage1.append(stage1_s)
        t = statistics.median(self._stage1)
        need = needed_divisor(t, self.period_s, self.headroom, self.max_divisor)
        if need > self.own:
            self.own, self._room_since, self._last_rise = need, None, now
            return
        # The divisor falls only if stage 1 would still fit one step down with the load of that
        # step: when the whole swarm speeds up, the cores are shared by own / (own - 1) more work.
        room = self.own > 1 and needed_divisor(t * self.own / (self.own - 1), self.period_s, self.headroom,
                                               self.max_divisor) < self.own
        if not room:
            self._room_since = None
        elif self._room_since is None:
            self._room_since = now
        elif now - self._room_since >= self.settle_s:
            self.own -= 1
            self._room_since = None
            self._stage1.clear()  # measure the new rate afresh

    def overloaded(self, now: float) -> None:
        """A frame was skipped at ``now`` because stage 1 could not finish in time: ask for one
        step more (at most one step per half ``settle_s``: a backlog skips several in a row)."""
        if not self.adaptive or self.own >= self.max_divisor or now - self._last_rise < 0.5 * self.settle_s:
            return
        self.own += 1
        self._last_rise, self._room_since = now, None
        self._stage1.clear()

    def heard(self, drone: int, divisor: int) -> None:
        """A heartbeat of ``drone`` asked for ``divisor``."""
        self._peers[drone] = max(1, int(divisor))

    def divisor(self, alive: Iterable[int]) -> int:
        """The swarm's divisor: the largest asked by this drone or a living peer."""
        return max([self.own] + [self._peers.get(d, 1) for d in alive])
