"""ZeroMQ transport between drones, with optional link emulation.

Pattern: PUB/SUB. Each drone binds one PUB socket and connects one SUB socket to every other
drone's PUB. Why PUB/SUB rather than DEALER/ROUTER or REQ/REP:

* the exchange is a broadcast: after a stage a drone sends the same 136 numbers to all others
  (as a ROS topic in the paper), and PUB/SUB fans one send out to N - 1 drones;
* a sender never waits for a receiver: a dead or slow drone cannot block the others (PUB drops
  at the high-water mark instead of blocking; REQ/REP would deadlock on a lost reply);
* ZeroMQ reconnects by itself, so a drone that dies and restarts on the same address is
  rejoined without any code (the SUB sockets of the others reconnect to its new PUB).
The price is that PUB/SUB loses messages silently (slow-joiner, reconnect); the node handles a
missing message anyway (fallback), and heartbeats (HELLO) tell it who is alive.

:class:`LinkEmulator` delays, rate-limits and drops received packets per sending drone, to
emulate the paper's 5 GHz Wi-Fi (50 Mbps) on loopback.
"""
from __future__ import annotations

import heapq
import itertools
import socket
from dataclasses import dataclass

import numpy as np
import zmq

from .wire import HEADER_BYTES

__all__ = ["LinkConfig", "LinkEmulator", "Transport", "free_ports", "endpoint"]


def endpoint(port: int, host: str = "127.0.0.1") -> str:
    return f"tcp://{host}:{port}"


def free_ports(n: int, host: str = "127.0.0.1") -> list[int]:
    """n distinct TCP ports that are free on ``host`` right now (bound and released by the OS)."""
    socks, ports = [], []
    try:
        for _ in range(n):
            s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            s.bind((host, 0))
            socks.append(s)
            ports.append(s.getsockname()[1])
    finally:
        for s in socks:
            s.close()
    return ports


@dataclass(frozen=True)
class LinkConfig:
    """Emulated link from every other drone to this one.

    Args:
        latency_ms: one-way delay added to each packet.
        jitter_ms: extra uniform delay in ``[0, jitter_ms]``.
        bandwidth_mbps: serialisation rate of the link (None = unlimited); 50 = the paper's Wi-Fi.
        loss: probability that a packet is lost.
        seed: of the loss and jitter draws.
    """

    latency_ms: float = 0.0
    jitter_ms: float = 0.0
    bandwidth_mbps: float | None = None
    loss: float = 0.0
    seed: int = 0

    @property
    def active(self) -> bool:
        return bool(self.latency_ms or self.jitter_ms or self.bandwidth_mbps or self.loss)


class LinkEmulator:
    """Per-sender delay line: ``deliver = max(arrival, link_free) + bits / rate + latency + jitter``.

    The rate term queues packets of one sender behind each other (a link carries one packet at a
    time); loss is drawn per packet.
    """

    def __init__(self, config: LinkConfig):
        self.config = config
        self._rng = np.random.default_rng(config.seed)
        self._free: dict[int, float] = {}
        self._queue: list = []  # heap of (deliver_at, seq, buf)
        self._seq = itertools.count()
        self.lost = 0

    def admit(self, sender: int, buf: bytes, now: float) -> None:
        c = self.config
        if c.loss and self._rng.random() < c.loss:
            self.lost += 1
            return
        t = now
        if c.bandwidth_mbps:
            t = max(t, self._free.get(sender, 0.0)) + len(buf) * 8 / (c.bandwidth_mbps * 1e6)
            self._free[sender] = t
        t += c.latency_ms / 1000.0
        if c.jitter_ms:
            t += self._rng.uniform(0.0, c.jitter_ms / 1000.0)
        heapq.heappush(self._queue, (t, next(self._seq), buf))

    def release(self, now: float) -> list[bytes]:
        out = []
        while self._queue and self._queue[0][0] <= now:
            out.append(heapq.heappop(self._queue)[2])
        return out

    def next_due(self) -> float | None:
        return self._queue[0][0] if self._queue else None


class Transport:
    """One drone's sockets: a bound PUB, a SUB connected to the peers, an optional link emulator.

    Args:
        bind: this drone's endpoint (``tcp://127.0.0.1:PORT``).
        peers: the other drones' endpoints.
        link: optional :class:`LinkConfig` applied to received packets.
        clock: callable giving the local time (for the emulator).
        hwm: high-water mark (packets queued per peer before PUB drops).
    """

    def __init__(self, bind: str, peers: list[str], link: LinkConfig | None = None, clock=None, hwm: int = 256):
        import time

        self._clock = clock or time.time
        self.ctx = zmq.Context()
        self.pub = self.ctx.socket(zmq.PUB)
        self.sub = self.ctx.socket(zmq.SUB)
        for s in (self.pub, self.sub):
            s.setsockopt(zmq.LINGER, 0)
            s.setsockopt(zmq.RECONNECT_IVL, 50)  # ms; quick rejoin of a restarted drone
            s.setsockopt(zmq.RECONNECT_IVL_MAX, 500)
        self.pub.setsockopt(zmq.SNDHWM, hwm)
        self.sub.setsockopt(zmq.RCVHWM, hwm)
        self.sub.setsockopt(zmq.SUBSCRIBE, b"")  # everything: malformed packets must reach the parser
        self.pub.bind(bind)
        for p in peers:
            self.sub.connect(p)
        self.emulator = LinkEmulator(link) if link is not None and link.active else None
        self.poller = zmq.Poller()
        self.poller.register(self.sub, zmq.POLLIN)
        self.bytes_sent = 0
        self.packets_sent = 0
        self.send_dropped = 0

    def register(self, sock) -> None:
        """Also wake :meth:`poll` for this (e.g. inproc) socket."""
        self.poller.register(sock, zmq.POLLIN)

    def send(self, buf: bytes) -> bool:
        """Publish one packet; False if ZeroMQ dropped it (high-water mark)."""
        try:
            self.pub.send(buf, zmq.NOBLOCK)
        except zmq.Again:
            self.send_dropped += 1
            return False
        self.bytes_sent += len(buf)
        self.packets_sent += 1
        return True

    def poll(self, timeout_s: float) -> tuple[list[bytes], set]:
        """Wait up to ``timeout_s`` for packets; returns (packets now deliverable, ready extra
        sockets)."""
        if self.emulator is not None:
            due = self.emulator.next_due()
            if due is not None:
                timeout_s = min(timeout_s, max(0.0, due - self._clock()))
        events = dict(self.poller.poll(max(0, int(np.ceil(timeout_s * 1000)))))
        out = []
        if events.pop(self.sub, None):
            while True:
                try:
                    buf = self.sub.recv(zmq.NOBLOCK)
                except zmq.Again:
                    break
                if self.emulator is None:
                    out.append(buf)
                else:
                    sender = buf[6] if len(buf) >= HEADER_BYTES else 0
                    self.emulator.admit(sender, buf, self._clock())
        if self.emulator is not None:
            out.extend(self.emulator.release(self._clock()))
        return out, set(events)

    def close(self) -> None:
        self.ctx.destroy(linger=0)  # closes every socket of the context, inproc ones included
