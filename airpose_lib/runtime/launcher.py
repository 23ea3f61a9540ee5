"""Start N drone processes on loopback and collect what they report.

Each drone is ``python -m airpose_lib.cli.drone`` (= ``airpose node``) with its own id, a free port chosen at run
time, the others as peers and ``--t0 stdin``: the launcher waits until every drone printed
``READY`` (model loaded and warmed up, sockets bound), then sends them all the same start time
``START <t0>`` (now + ``lead_s``). Drone logs go to ``<out>/node_<id>.log``; each drone's
``SUMMARY`` line is parsed. Unless the options say ``insecure``, the launcher makes a CURVE key
pair per drone (and per ``extra_peers`` id) in ``<out>/keys/`` and passes ``--keys`` on
(:mod:`.keys`). :meth:`Fleet.kill` and :meth:`Fleet.restart` are the fault
injections of the tests (a restarted drone gets the original ``t0`` and rejoins the schedule).
"""
from __future__ import annotations

import json
import os
import queue
import subprocess
import sys
import threading
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

from airpose_lib.errors import UserError

from .keys import create_swarm_keys
from .transport import free_ports

__all__ = ["Fleet", "launch", "node_options", "format_summaries", "LaunchError"]


class LaunchError(UserError, RuntimeError):
    pass


def node_options(options: Mapping | None) -> list[str]:
    """``{"backend": "fake", "window_ms": 60, "preload": True, "checkpoint": None}`` ->
    ``["--backend", "fake", "--window-ms", "60", "--preload"]`` (None and False are left out,
    True is a flag, lists give several values)."""
    argv: list[str] = []
    for key, value in (options or {}).items():
        if value is None or value is False:
            continue
        argv.append("--" + key.replace("_", "-"))
        if value is True:  # a flag
            continue
        if isinstance(value, (list, tuple)):
            argv.extend(str(v) for v in value)
        else:
            argv.append(str(value))
    return argv


def _last_line(path: Path) -> str:
    try:
        lines = [line for line in path.read_text(errors="replace").splitlines() if line.strip()]
    except OSError:
        return "no log"
    return lines[-1][:300] if lines else "empty log"


def _port_of(endpoint: str) -> int:
    """``tcp://127.0.0.1:5555`` -> 5555."""
    return int(endpoint.rsplit(":", 1)[1])


def _reader(stream, q: queue.Queue, drone: int) -> None:
    for line in iter(stream.readline, ""):
        q.put((drone, line.rstrip("\n")))
    q.put((drone, None))


class Fleet:
    """The running drones of one launch."""

    def __init__(self, out_dir: Path, ports: dict[int, int], common: list[str], offsets: dict[int, float],
                 env: dict, host: str, extra_peers: Mapping[int, str] | None = None, keys: Path | None = None):
        self.out_dir = out_dir
        self.ports = ports
        self.common = common
        self.offsets = offsets
        self.env = env
        self.host = host
        self.extra_peers = dict(extra_peers or {})
        self.keys = keys  # swarm keys folder (None: insecure)
        self.procs: dict[int, subprocess.Popen] = {}
        self.summaries: dict[int, dict] = {}
        self.lines: queue.Queue = queue.Queue()
        self.t0: float | None = None
        self._ready: set[int] = set()

    def argv(self, drone: int, t0: str) -> list[str]:
        peers = [f"{j}@{self.host}:{p}" for j, p in sorted(self.ports.items()) if j != drone]
        peers += [f"{j}@{ep}" for j, ep in sorted(self.extra_peers.items())]
        return [sys.executable, "-m", "airpose_lib.cli.drone", "--id", str(drone),
                "--port", str(self.ports[drone]), "--host", self.host, "--peers", *peers, "--t0", t0,
                "--clock-offset-ms", str(self.offsets.get(drone, 0.0)), "--out", str(self.out_dir),
                *(["--keys", str(self.keys)] if self.keys is not None else []), *self.common]

    def _spawn(self, drone: int, t0: str) -> subprocess.Popen:
        log = open(self.out_dir / f"node_{drone}.log", "a")
        proc = subprocess.Popen(self.argv(drone, t0), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                stderr=log, text=True, env=self.env, bufsize=1)
        log.close()
        threading.Thread(target=_reader, args=(proc.stdout, self.lines, drone), daemon=True).start()
        self.procs[drone] = proc
        return proc

    def _pump(self, timeout: float) -> bool:
        """Handle one stdout line (READY / SUMMARY); False on timeout."""
        try:
            drone, line = self.lines.get(timeout=timeout)
        except queue.Empty:
            return False
        if line is None:
            return True
        if line.startswith("READY"):
            self._ready.add(drone)
        elif line.startswith("SUMMARY "):
            self.summaries[drone] = json.loads(line[len("SUMMARY "):])
        return True

    def _move_to_new_ports(self, dead: list[int]) -> None:
        """Start every drone again on new ports: a port chosen by :func:`free_ports` was taken by
        another process before its drone bound it. Only before START, so no schedule is lost."""
        self.stop()
        busy = {*self.ports.values(), *map(_port_of, self.extra_peers.values())}
        old = dict(self.ports)
        self.ports = dict(zip(self.ports, free_ports(len(self.ports), self.host, exclude=busy)))
        for d in dead:
            with open(self.out_dir / f"node_{d}.log", "a") as log:
                log.write(f"launcher: port {old[d]} was taken; starting the drones again, drone {d} on "
                          f"port {self.ports[d]}\n")
        self.lines, self._ready = queue.Queue(), set()  # the old readers keep filling the old queue
        for d in self.ports:
            self._spawn(d, "stdin")

    def start(self, lead_s: float = 1.0, ready_timeout_s: float = 120.0, port_retries: int = 3) -> float:
        """Wait for every drone's READY, then send the common start time; returns t0.

        A drone that exits because its port is already in use (a race of :func:`free_ports` with
        other processes) makes the whole fleet start again on new ports, up to ``port_retries``
        times; any other early exit raises :class:`LaunchError`."""
        deadline = time.time() + ready_timeout_s
        while self._ready != set(self.procs):
            dead = [d for d, p in self.procs.items() if p.poll() is not None and d not in self._ready]
            if dead and port_retries > 0 and all(
                    "Address already in use" in _last_line(self.out_dir / f"node_{d}.log") for d in dead):
                port_retries -= 1
                self._move_to_new_ports(dead)
                continue
            if dead:
                self.stop()
                why = "; ".join(f"drone {d}: {_last_line(self.out_dir / f'node_{d}.log')}" for d in dead)
                raise LaunchError(f"drone(s) {dead} exited before READY ({why}); see {self.out_dir}/node_<id>.log")
            if time.time() > deadline:
                self.stop()
                raise LaunchError(f"drones {sorted(set(self.procs) - self._ready)} not ready after {ready_timeout_s} s")
            self._pump(0.1)
        self.t0 = time.time() + lead_s
        for proc in self.procs.values():
            proc.stdin.write(f"START {self.t0!r}\n")
            proc.stdin.flush()
        return self.t0

    def kill(self, drone: int) -> None:
        """SIGKILL one drone (no BYE, no summary: a crash)."""
        self.procs[drone].kill()
        self.procs[drone].wait()

    def restart(self, drone: int) -> None:
        """Start a killed drone again with the original t0 (it rejoins at the next slot)."""
        if self.procs[drone].poll() is None:
            raise LaunchError(f"drone {drone} is still running")
        self._spawn(drone, repr(self.t0))

    def wait(self, timeout_s: float = 600.0) -> dict[int, dict]:
        """Wait for every drone to exit; returns their summaries (drones that crashed have none)."""
        deadline = time.time() + timeout_s
        while any(p.poll() is None for p in self.procs.values()):
            if time.time() > deadline:
                self.stop()
                raise LaunchError(f"drones still running after {timeout_s} s (killed)")
            self._pump(0.05)
        while self._pump(0.05):
            pass
        return dict(self.summaries)

    def returncodes(self) -> dict[int, int | None]:
        return {d: p.poll() for d, p in self.procs.items()}

    def stop(self) -> None:
        """Kill whatever still runs (only this fleet's processes)."""
        for p in self.procs.values():
            if p.poll() is None:
                p.kill()
                p.wait()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()


def launch(num_drones: int, out_dir: str | Path, options: Mapping | Sequence[str] | None = None,
           clock_offsets_ms: Sequence[float] | None = None, lead_s: float = 1.0, ready_timeout_s: float = 120.0,
           threads: int = 1, host: str = "127.0.0.1", start: bool = True,
           extra_peers: Mapping[int, str] | None = None) -> Fleet:
    """Start ``num_drones`` drone processes on ``host`` (loopback) and give them a common t0.

    Args:
        num_drones: drones 1..N (drone d runs camera view d - 1).
        out_dir: where the drones write ``node_<id>.{jsonl,npz,summary.json,log}``.
        options: node options (:func:`node_options` dict, or an argv list), e.g.
            ``{"backend": "fake", "mode": "pipelined", "frames": 40}``.
        clock_offsets_ms: per-drone clock error (default 0).
        lead_s: t0 = this long after the last READY.
        threads: OMP/MKL threads per drone process.
        start: False = only spawn (call :meth:`Fleet.start` yourself).
        extra_peers: more drones every launched drone listens to (id -> ``tcp://`` endpoint), e.g.
            a test posing as a drone.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    busy = [_port_of(ep) for ep in (extra_peers or {}).values()]  # the caller binds these itself
    ports = dict(zip(range(1, num_drones + 1), free_ports(num_drones, host, exclude=busy)))
    if not isinstance(options, (list, tuple)):
        options = dict(options or {})
        src = options.get("source", "synthetic")
        if src.startswith("synthetic") and "views=" not in src:  # one synthetic camera per drone
            options["source"] = f"{src}{',' if ':' in src else ':'}views={num_drones}"
    common = list(options) if isinstance(options, (list, tuple)) else node_options(options)
    offsets = {d: float(clock_offsets_ms[d - 1]) if clock_offsets_ms else 0.0 for d in ports}
    env = dict(os.environ, OMP_NUM_THREADS=str(threads), MKL_NUM_THREADS=str(threads), PYTHONUNBUFFERED="1")
    keys = None if "--insecure" in common else create_swarm_keys(out_dir / "keys", [*ports, *(extra_peers or {})])
    fleet = Fleet(out_dir, ports, common, offsets, env, host, extra_peers, keys)
    for d in ports:
        fleet._spawn(d, "stdin")
    if start:
        fleet.start(lead_s, ready_timeout_s)
    return fleet


def format_summaries(summaries: dict[int, dict]) -> str:
    """One line per drone: fps, latency, drops, bytes."""
    rows = ["drone  slots  valid  fps    agreed  drop%  p50 ms  p95 ms  fallback  bytes/frame  rejected"]
    for d in sorted(summaries):
        s = summaries[d]
        ms = (lambda x: f"{1000 * x:6.1f}" if x is not None else "     -")  # noqa: E731
        agreed = s.get("agreed_fps")
        rows.append(f"{d:<6} {s['slots']:<6} {s['valid']:<6} {s['fps']:<6.2f} "
                    f"{agreed if agreed is not None else s['nominal_fps']:<7.2f} {100 * (s['drop_rate'] or 0):5.1f}  "
                    f"{ms(s['latency_p50'])}  {ms(s['latency_p95'])}  {s['fallback_frames']:<8}  "
                    f"{s['bytes_per_frame'] or 0:<11.0f}  {json.dumps(s['rejected'])}")
    return "\n".join(rows)
