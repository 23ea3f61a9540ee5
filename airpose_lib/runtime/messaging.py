"""A drone's side of the message exchange: packets out (counted by kind), packets in (checked,
then handed to the peer table and the mailbox).

A received packet is refused, counted and logged (the first 3 of each kind, then every 100th)
when it is malformed or of another wire version, claims a drone id other than the drone at the
other end of its link (``spoofed``), carries this drone's own id, an unknown drone's id, a stage
out of range, or repeats a stage or skip message seen before (``replay``). A stage message for a
frame this drone already finished is kept but counted as late.
"""
from __future__ import annotations

import logging
import math
from collections import defaultdict, deque
from collections.abc import Callable, Iterable

import numpy as np

from .sync import Mailbox, PeerTable
from .transport import Transport
from .wire import BYE, DATA, HELLO, SKIP, Packet, WireError, decode_packet, encode_packet

__all__ = ["PeerMessaging"]

log = logging.getLogger("airpose.runtime")


class PeerMessaging:
    """What one drone sends to and has received from the others.

    Args:
        drone_id: this drone.
        peers: the other drones' ids.
        peer_timeout_s: silence after which a drone is no longer counted alive.
        num_stages: stages of the network (a stage message of a later stage is refused).
        tolerance_s: stamp matching tolerance (a message within it of a finished frame is late).
        now: this drone's clock, seconds.
        message_dtype: ``float32`` or ``float16`` payloads.
        authenticated: the links are CurveZMQ (only said in the log of a spoofed packet).
    """

    def __init__(self, drone_id: int, peers: Iterable[int], peer_timeout_s: float, num_stages: int,
                 tolerance_s: float, now: Callable[[], float], message_dtype: str = "float32",
                 authenticated: bool = False) -> None:
        self.drone_id = drone_id
        self.num_stages = num_stages
        self.tolerance_s = tolerance_s
        self.now = now
        self.message_dtype = message_dtype
        self.authenticated = authenticated
        self.transport: Transport | None = None  # attached once the sockets are open
        self.peers = PeerTable(frozenset(peers), peer_timeout_s)
        self.mailbox = Mailbox()
        self.rejected: dict[str, int] = defaultdict(int)
        self.late_packets = 0
        self.bytes_hello = 0
        self.bytes_data = 0
        self.data_packets = 0
        self._seen: deque = deque(maxlen=4096)  # recent (drone, kind, stage, slot, stamp): replays
        self._seen_set: set = set()
        self._finished_stamps: deque = deque(maxlen=64)
        self._skips: deque = deque(maxlen=256)  # (drone, slot) the others said they skip
        self.on_rate: Callable[[int, int], None] | None = None  # (drone, divisor) of each HELLO

    # -- out -----------------------------------------------------------------------------------
    def send(self, kind: int, job=None, stage: int = 0, payload: np.ndarray | None = None,
             rate_divisor: int = 1) -> None:
        """Publish a packet about ``job`` (a :class:`~.stages.FrameJob`; None: a HELLO or BYE
        stamped now); a HELLO carries the slot divisor this drone asks for."""
        now = self.now()
        buf = encode_packet(kind, self.drone_id, stage=stage,
                            frame_index=max(job.frame_index, 0) if job else 0, slot=job.slot if job else 0,
                            stamp=job.stamp if job and not math.isnan(job.stamp) else now, sent=now,
                            payload=payload, dtype=self.message_dtype, rate_divisor=rate_divisor)
        if self.transport.send(buf):
            if kind == DATA:
                self.bytes_data += len(buf)
                self.data_packets += 1
            else:
                self.bytes_hello += len(buf)

    # -- in ------------------------------------------------------------------------------------
    def receive(self, received: list[tuple[int, bytes]]) -> None:
        """Check and file ``(sender's drone id over its link or 0, packet bytes)`` pairs."""
        now = self.now()
        for sender, buf in received:
            try:
                pkt = decode_packet(buf)
            except WireError as e:
                self._reject(e.code, str(e), len(buf))
                continue
            if sender and pkt.drone != sender:
                self._reject("spoofed", f"claims to be drone {pkt.drone} but came over the link of drone "
                             f"{sender}{' (authenticated)' if self.authenticated else ''}", len(buf))
                continue
            if pkt.drone == self.drone_id:
                self._reject("own_id", f"own drone id {pkt.drone} (two drones with one id?)", len(buf))
                continue
            if pkt.drone not in self.peers.expected:
                self._reject("unknown_drone", f"unexpected drone id {pkt.drone}", len(buf))
                continue
            if pkt.kind == BYE:
                self.peers.bye(pkt.drone)
                log.info("drone %d said bye", pkt.drone)
                continue
            if self.peers.heard(pkt.drone, now):
                log.info("drone %d is alive", pkt.drone)
            if pkt.kind == HELLO and self.on_rate is not None:
                self.on_rate(pkt.drone, pkt.rate_divisor)
            if pkt.kind in (SKIP, DATA) and self._replayed(pkt):
                self._reject("replay", f"replay of drone {pkt.drone}'s {pkt.kind_name} message of slot {pkt.slot} "
                             f"(stage {pkt.stage}, stamp {pkt.stamp:.3f})", len(buf))
                continue
            if pkt.kind == SKIP:
                self._skips.append((pkt.drone, pkt.slot))
                continue
            if pkt.kind == DATA:
                if pkt.stage >= self.num_stages:
                    self._reject("stage", f"stage {pkt.stage} out of range", len(buf))
                    continue
                if any(abs(pkt.stamp - s) <= self.tolerance_s for s in self._finished_stamps):
                    self.late_packets += 1
                    if self.late_packets <= 3 or self.late_packets % 100 == 0:
                        log.warning("drone %d's stage %d message of slot %d came after its frame was finished "
                                    "(%d late so far)", pkt.drone, pkt.stage, pkt.slot, self.late_packets)
                self.mailbox.put(pkt, now)

    def skipping(self, slot: int) -> set[int]:
        """The drones that said they skip ``slot`` (not to be waited for)."""
        return {d for d, s in self._skips if s == slot}

    def finished(self, stamp: float) -> None:
        """This drone finished the frame stamped ``stamp``: later messages for it are late."""
        self._finished_stamps.append(stamp)

    def _reject(self, code: str, reason: str, nbytes: int) -> None:
        """Count and log (the first 3 of each kind, then every 100th) a packet that was refused."""
        self.rejected[code] += 1
        n = self.rejected[code]
        if n <= 3 or n % 100 == 0:
            log.warning("rejected a %d-byte packet: %s (%d of this kind so far)", nbytes, reason, n)

    def _replayed(self, pkt: Packet) -> bool:
        """True if this stage/skip message was received before (remembers the last 4096)."""
        key = (pkt.drone, pkt.kind, pkt.stage, pkt.slot, pkt.stamp)
        if key in self._seen_set:
            return True
        if len(self._seen) == self._seen.maxlen:
            self._seen_set.discard(self._seen[0])
        self._seen.append(key)
        self._seen_set.add(key)
        return False
