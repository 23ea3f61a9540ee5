"""What authenticating the drones' messages costs: bytes and latency per message, CurveZMQ vs plain.

Two :class:`airpose_lib.runtime.transport.Transport` endpoints on loopback exchange the paper's
message (a DATA packet: 40-byte header + 136 float32 = 584 bytes) in a ping-pong, once without
keys and once with the swarm's CURVE keys. It reports

* bytes on the TCP connection per message, counted by a forwarding proxy between the two
  (after the handshake; ZMTP framing included), and the handshake's bytes;
* the round trip p50 / p95 and the added one-way latency ((RTT_curve - RTT_plain) / 2).

    python benchmarks/online_auth.py [--messages 2000]

Timing depends on the machine's load, printed with the results; compare ratios of one run.
"""
from __future__ import annotations

import argparse
import os
import select
import socket
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from airpose_lib.runtime.keys import create_swarm_keys, load_swarm_keys
from airpose_lib.runtime.transport import Transport, endpoint, free_ports
from airpose_lib.runtime.wire import DATA, HELLO, encode_packet


class CountingProxy:
    """Forwards one TCP connection (listen port -> target port) and counts the bytes each way."""

    def __init__(self, listen: int, target: int):
        self.down = 0  # target (the PUB) -> client (the SUB)
        self.up = 0
        self._srv = socket.create_server(("127.0.0.1", listen))
        self._target = target
        self._stop = False
        threading.Thread(target=self._run, daemon=True).start()

    def _run(self) -> None:
        client, _ = self._srv.accept()
        server = socket.create_connection(("127.0.0.1", self._target))
        for s in (client, server):
            s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        while not self._stop:
            ready, _, _ = select.select([client, server], [], [], 0.1)
            for s in ready:
                data = s.recv(65536)
                if not data:
                    return
                if s is server:
                    self.down += len(data)
                    client.sendall(data)
                else:
                    self.up += len(data)
                    server.sendall(data)

    def close(self) -> None:
        self._stop = True
        self._srv.close()


def _recv(t: Transport, timeout_s: float = 2.0) -> list:
    t_end = time.perf_counter() + timeout_s
    while time.perf_counter() < t_end:
        got, _ = t.poll(0.001)
        if got:
            return got
    return []


def measure(n: int, keys_dir: Path | None) -> dict:
    """Ping-pong of ``n`` DATA packets between drones 1 and 2; drone 1 -> 2 goes through the proxy."""
    p1, p2, proxy_port = free_ports(3)
    k1 = load_swarm_keys(keys_dir, 1, [2]) if keys_dir else None
    k2 = load_swarm_keys(keys_dir, 2, [1]) if keys_dir else None
    proxy = CountingProxy(proxy_port, p1)
    a = Transport(endpoint(p1), {2: endpoint(p2)}, keys=k1)
    b = Transport(endpoint(p2), {1: endpoint(proxy_port)}, keys=k2)
    msg = encode_packet(DATA, 1, stage=1, payload=np.linspace(-1, 1, 136, dtype=np.float32))
    try:
        while not _recv(b, 0.05):  # subscriptions up both ways
            a.send(encode_packet(HELLO, 1))
        while not _recv(a, 0.05):
            b.send(encode_packet(HELLO, 2))
        for _ in range(20):  # drain
            _recv(a, 0.01), _recv(b, 0.01)
        handshake = proxy.down + proxy.up
        down0 = proxy.down
        rtt = []
        for _ in range(n):
            t = time.perf_counter()
            a.send(msg)
            got = _recv(b)
            assert got and got[-1][1] == msg, "lost a message"
            b.send(msg)
            assert _recv(a), "lost an echo"
            rtt.append(time.perf_counter() - t)
        per_message = (proxy.down - down0) / n
    finally:
        a.close()
        b.close()
        proxy.close()
    rtt_us = np.array(rtt) * 1e6
    return {"bytes": per_message, "packet": len(msg), "handshake": handshake,
            "rtt_p50_us": float(np.percentile(rtt_us, 50)), "rtt_p95_us": float(np.percentile(rtt_us, 95))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--messages", type=int, default=2000)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        keys = create_swarm_keys(Path(tmp) / "keys", [1, 2])
        plain = measure(args.messages, None)
        curve = measure(args.messages, keys)
        plain2 = measure(args.messages, None)  # again: drift of the machine's load
    print(f"load average {os.getloadavg()}, {args.messages} messages each")
    print(f"{'':<10}{'bytes/msg':>10}{'packet':>8}{'handshake B':>13}{'RTT p50 us':>12}{'RTT p95 us':>12}")
    for name, r in (("plain", plain), ("curve", curve), ("plain2", plain2)):
        print(f"{name:<10}{r['bytes']:>10.1f}{r['packet']:>8}{r['handshake']:>13}{r['rtt_p50_us']:>12.0f}"
              f"{r['rtt_p95_us']:>12.0f}")
    base = (plain["rtt_p50_us"] + plain2["rtt_p50_us"]) / 2
    print(f"CURVE adds {curve['bytes'] - plain['bytes']:.1f} bytes per message and "
          f"{(curve['rtt_p50_us'] - base) / 2:.0f} us one-way (p50; RTT ratio {curve['rtt_p50_us'] / base:.2f})")


if __name__ == "__main__":
    main()
