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

Each peer has its own SUB socket, so every received packet comes with the id of the drone at the
other end of its link. With :class:`~.keys.SwarmKeys` the links are CurveZMQ: the PUB socket is
a CURVE server that admits only the swarm's public keys (a ZAP handler), and the SUB socket of
peer ``j`` only completes its handshake with the holder of ``j``'s secret key; the node rejects a
packet whose drone id is not that of its link (:mod:`.keys`, :mod:`.node`).

:class:`LinkEmulator` delays, rate-limits and drops received packets per sending drone, to
emulate the paper's 5 GHz Wi-Fi (50 Mbps) on loopback.
"""
from __future__ import annotations

import heapq
import itertools
import logging
import socket
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import zmq

from airpose_lib.errors import ConfigError

from .keys import SwarmKeyError, SwarmKeys

log = logging.getLogger("airpose.runtime")

__all__ = ["LinkConfig", "LinkEmulator", "Transport", "free_ports", "endpoint", "parse_peers"]


def endpoint(port: int, host: str = "127.0.0.1") -> str:
    return f"tcp://{host}:{port}"


def parse_peers(items: list[str], host: str = "127.0.0.1") -> dict[int, str]:
    """``["2@5002", "3@127.0.0.1:5003", "4@tcp://10.0.0.4:5004"]`` -> ``{2: "tcp://127.0.0.1:5002", ...}``
    (commas also separate); a malformed entry raises :class:`~airpose_lib.errors.ConfigError`."""
    out = {}
    for item in items:
        for part in filter(None, item.split(",")):
            ident, sep, addr = part.partition("@")
            port = addr.rpartition(":")[2]
            if not (sep and ident.isdigit() and 1 <= int(ident) <= 255 and port.isdigit()
                    and 1 <= int(port) <= 65535):
                raise ConfigError(f"peer {part!r}: expected ID@PORT, ID@HOST:PORT or ID@tcp://HOST:PORT with a "
                                  "drone id 1..255 and a port 1..65535 (e.g. 2@5002)")
            if addr.startswith("tcp://"):
                ep = addr
            elif ":" in addr:
                ep = "tcp://" + addr
            else:
                ep = f"tcp://{host}:{int(addr)}"
            out[int(ident)] = ep
    return out


def free_ports(n: int, host: str = "127.0.0.1", exclude: Sequence[int] = ()) -> list[int]:
    """n distinct TCP ports that are free on ``host`` right now (bound and released by the OS),
    none of them in ``exclude`` (ports the caller is about to bind itself).

    Another process may still take one before the caller binds it: :meth:`Fleet.start` starts
    the drones again on new ports when that happens."""
    socks, ports = [], []
    try:
        while len(ports) < n:
            s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            s.bind((host, 0))
            socks.append(s)  # held until all are chosen, so the OS cannot hand one out twice
            if s.getsockname()[1] not in exclude:
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
        self._queue: list = []  # heap of (deliver_at, seq, sender, buf)
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
        heapq.heappush(self._queue, (t, next(self._seq), sender, buf))

    def release(self, now: float) -> list[tuple[int, bytes]]:
        """``(sender, packet)`` pairs due by ``now``."""
        out = []
        while self._queue and self._queue[0][0] <= now:
            _, _, sender, buf = heapq.heappop(self._queue)
            out.append((sender, buf))
        return out

    def next_due(self) -> float | None:
        return self._queue[0][0] if self._queue else None


class _SwarmMembers:
    """ZAP credentials check of the PUB socket: only the swarm's public keys may subscribe.

    A refused handshake is logged once per peer address (an outsider's socket retries every
    reconnect interval, which would flood the log); ``address`` is the peer of the request being
    checked, set by :class:`_Authenticator`.
    """

    def __init__(self, keys: SwarmKeys):
        self.allowed = {keys.public, *keys.peers.values()}
        self.address = "?"
        self.refused: set[str] = set()

    def callback(self, domain: str, key: bytes) -> bool:
        if key in self.allowed:
            return True
        if self.address not in self.refused:
            self.refused.add(self.address)
            log.warning("refused a CURVE handshake from %s: its key is not one of the swarm's "
                        "(further refusals from this address are not logged)", self.address)
        return False


def _authenticator(ctx, members: _SwarmMembers):
    """A started ZAP handler (pyzmq's thread authenticator) that checks CURVE keys with
    ``members`` and tells it the address of each request first (ZAP gives the callback none)."""
    from zmq.auth.thread import ThreadAuthenticator

    class _Authenticator(ThreadAuthenticator):
        async def handle_zap_message(self, msg: list[bytes]) -> None:
            if len(msg) >= 6:
                members.address = msg[3].decode("utf-8", "replace") or "?"
            await super().handle_zap_message(msg)

    auth = _Authenticator(ctx)
    auth.start()
    auth.configure_curve_callback(domain="*", credentials_provider=members)
    return auth


class Transport:
    """One drone's sockets: a bound PUB, one SUB per peer, an optional link emulator.

    Args:
        bind: this drone's endpoint (``tcp://127.0.0.1:PORT``).
        peers: the other drones, id -> endpoint (a plain list of endpoints: ids unknown, 0).
        link: optional :class:`LinkConfig` applied to received packets.
        clock: callable giving the local time (for the emulator).
        hwm: high-water mark (packets queued per peer before PUB drops).
        keys: this drone's CURVE keys and its peers' public keys (None: no authentication).
    """

    def __init__(self, bind: str, peers: Mapping[int, str] | Sequence[str], link: LinkConfig | None = None,
                 clock=None, hwm: int = 256, keys: SwarmKeys | None = None):
        import time

        self._clock = clock or time.time
        self.ctx = zmq.Context()
        self.keys = keys
        self.auth = None
        pairs = list(peers.items()) if isinstance(peers, Mapping) else [(0, ep) for ep in peers]
        self.pub = self.ctx.socket(zmq.PUB)
        self.pub.setsockopt(zmq.SNDHWM, hwm)
        if keys is not None:
            self.auth = _authenticator(self.ctx, _SwarmMembers(keys))
            self.pub.curve_secretkey = keys.secret
            self.pub.curve_publickey = keys.public
            self.pub.curve_server = True
        self.subs: dict = {}  # SUB socket -> the peer id at its other end
        for ident, _ in pairs:  # each SUB connects to its endpoint below, after every socket option
            sub = self.ctx.socket(zmq.SUB)
            sub.setsockopt(zmq.RCVHWM, hwm)
            if keys is not None:
                if ident not in keys.peers:
                    raise SwarmKeyError(f"no public key of drone {ident} in the swarm keys")
                sub.curve_secretkey = keys.secret
                sub.curve_publickey = keys.public
                sub.curve_serverkey = keys.peers[ident]
            sub.setsockopt(zmq.SUBSCRIBE, b"")  # everything: malformed packets must reach the parser
            self.subs[sub] = ident
        for s in (self.pub, *self.subs):
            s.setsockopt(zmq.LINGER, 0)
            s.setsockopt(zmq.RECONNECT_IVL, 50)  # ms; quick rejoin of a restarted drone
            s.setsockopt(zmq.RECONNECT_IVL_MAX, 500)
        self.pub.bind(bind)
        for sub, (_, ep) in zip(self.subs, pairs):
            sub.connect(ep)
        self.emulator = LinkEmulator(link) if link is not None and link.active else None
        self.poller = zmq.Poller()
        for sub in self.subs:
            self.poller.register(sub, zmq.POLLIN)
        self.bytes_sent = 0
        self.packets_sent = 0
        self.send_dropped = 0

    @property
    def authenticated(self) -> bool:
        return self.keys is not None

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

    def poll(self, timeout_s: float) -> tuple[list[tuple[int, bytes]], set]:
        """Wait up to ``timeout_s`` for packets; returns (``(sender, packet)`` pairs now
        deliverable, ready extra sockets). ``sender`` is the peer id of the link it came over."""
        if self.emulator is not None:
            due = self.emulator.next_due()
            if due is not None:
                timeout_s = min(timeout_s, max(0.0, due - self._clock()))
        events = dict(self.poller.poll(max(0, int(np.ceil(timeout_s * 1000)))))
        out = []
        for sub, sender in self.subs.items():
            if not events.pop(sub, None):
                continue
            while True:
                try:
                    buf = sub.recv(zmq.NOBLOCK)
                except zmq.Again:
                    break
                if self.emulator is None:
                    out.append((sender, buf))
                else:
                    self.emulator.admit(sender, buf, self._clock())
        if self.emulator is not None:
            out.extend(self.emulator.release(self._clock()))
        return out, set(events)

    def close(self) -> None:
        if self.auth is not None:
            self.auth.stop()
        self.ctx.destroy(linger=0)  # closes every socket of the context, inproc ones included
