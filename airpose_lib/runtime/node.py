r"""One drone: camera replay, person box, staged network, message exchange, result stream.

Run as its own process (``airpose node --id 1 --port 5001 --peers 2@5002 ...`` or
``python -m airpose_lib.cli.drone ...``; :mod:`.launcher` starts N of them on loopback).

Per schedule slot (see :mod:`.sync`) a drone

1. wakes when its clock reads the slot's target + margin, picks its camera frame nearest the
   target, takes the person box from the frame's 2D detections and crops (``crop_input``);
2. runs stage 1 (backbone + iteration 1) and publishes its message;
3. for k = 2, 3: waits for the other drones' stage k-1 messages whose frame stamp matches its
   own within the tolerance, runs stage k, publishes (the last stage's message is not needed);
4. writes the frame's record (:mod:`.results`).

Waiting for a drone ends when its message arrives, when the drone is not alive (no packet for
``peer_timeout``), or at the stage's wait deadline: the frame's deadline minus the time the
remaining stages take (and at most ``comm_timeout`` after this drone's own message, if set).
A stage that runs without some message uses the fallback: ``mean`` = the mean parameters in
place of the missing drones (with no drone at all that is exactly the Fullcam behaviour, as
iteration 1), ``last`` = that drone's last message received; the record is flagged.

Modes:

``fixed`` (the paper's hardware-in-the-loop test): one frame at a time; a slot of ``window``
    (240 ms) = acquisition + stage 1 + 2 exchanges + 2 stages; a frame not complete by the end of
    its window is discarded (``DROPPED``); a slot the drone is too late to start is ``SKIPPED``.
``pipelined``: slots every ``1 / rate`` (20 fps) with a ``latency_budget`` (150 ms) deadline; a
    camera thread acquires frame k + 2, an inference thread runs stage 1 of frame k + 1 and the
    main thread exchanges messages and runs stages 2-3 of frame k (torch and ONNX Runtime
    release the GIL); several frames in flight. A frame whose stage 1 could not finish by its
    deadline any more is skipped before it costs CPU.

Authentication: the links are CurveZMQ (:mod:`.keys`), each peer on its own SUB socket; a
packet whose drone id is not the drone at the other end of its link is rejected as ``spoofed``,
a repeated stage message as ``replay`` (both logged, rate-limited, and counted in the summary's
``rejected``); a message for a frame already finished is counted as late and logged.
``--insecure`` (NodeConfig.insecure) runs without keys.

Faults: malformed or wrong-version packets are rejected with a log line (rate-limited), and
counted; a drone that dies stops being waited for after ``peer_timeout``; when it restarts (same
address, same ``t0``) it joins the schedule at the next slot and the others use its messages
again as soon as they arrive (ZeroMQ reconnects by itself).
"""
from __future__ import annotations

import json
import logging
import math
import queue
import select
import statistics
import sys
import threading
import time
from collections import defaultdict, deque
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import zmq

from . import results as R
from .backends import BackendSpec, StageModel, checkpoint_settings, fresh_copy, to_numpy, warm_up
from .keys import KEYS_ENV, SwarmKeyError, keys_folder, load_swarm_keys
from .networks import make_stage_model
from .source import crop_input, open_source, person_box
from .sync import CameraReplay, Clock, Mailbox, PeerTable, Schedule
from .transport import LinkConfig, Transport, endpoint
from .wire import BYE, DATA, HELLO, SKIP, Packet, WireError, decode_packet, encode_packet

__all__ = ["NodeConfig", "DroneProcess", "main"]

log = logging.getLogger("airpose.runtime")
_WAKE_MARGIN_S = 0.005  # a stage is started this long before it must end at the latest


@dataclass
class NodeConfig:
    """Everything one drone needs (all drones of a run share all but id, port, peers, offset).

    Times are milliseconds in the fields ending in ``_ms``.
    """

    drone_id: int
    port: int
    peers: dict[int, str]  # other drones: id -> endpoint
    source: str = "synthetic"
    view: int | None = None  # camera of the source; default drone_id - 1
    backend: BackendSpec = field(default_factory=BackendSpec)
    mode: str = "fixed"  # "fixed" or "pipelined"
    window_ms: float = 240.0  # fixed
    rate_hz: float = 20.0  # pipelined
    latency_budget_ms: float = 150.0  # pipelined
    tolerance_ms: float | None = None  # stamp matching; default half a frame period
    margin_ms: float = 0.0  # wake after the target shutter time
    clock_offset_ms: float = 0.0
    fallback: str = "mean"  # "mean" or "last"
    comm_timeout_ms: float | None = None
    peer_timeout_ms: float = 1000.0
    heartbeat_ms: float = 200.0
    frames: int | None = None  # schedule slots; None = until the sequence ends
    start_s: float | None = None  # sequence time of slot 0; default the first stamp
    t0: float | None = None  # start (epoch s, own clock); None = read "START <t0>" on stdin
    out_dir: str = "runs/online"
    link: LinkConfig = field(default_factory=LinkConfig)
    host: str = "127.0.0.1"
    max_runtime_s: float | None = None
    detector: str = "openpose"
    min_confidence: float = 0.2
    box_margin_px: float = 20.0
    preload: bool = False  # decode the replayed frames into memory before the start
    keys: str | None = None  # folder of the swarm's CURVE keys (runtime.keys); None: $AIRPOSE_SWARM_KEYS
    insecure: bool = False  # no authentication (trusted networks only)

    @property
    def period_s(self) -> float:
        return self.window_ms / 1000.0 if self.mode == "fixed" else 1.0 / self.rate_hz

    @property
    def deadline_s(self) -> float:
        return self.window_ms / 1000.0 if self.mode == "fixed" else self.latency_budget_ms / 1000.0

    def to_dict(self) -> dict:
        d = asdict(self)
        d["peers"] = {str(k): v for k, v in self.peers.items()}
        return d


@dataclass
class _Job:
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


class DroneProcess:
    """A drone node; :meth:`run` is the whole life of the process."""

    def __init__(self, config: NodeConfig):
        self.cfg = c = config
        self.keys = None
        if not c.insecure:  # before anything slow: a drone without its keys fails at once
            folder = keys_folder(c.keys)
            if folder is None:
                raise SwarmKeyError(
                    f"drone {c.drone_id}: no swarm keys; give --keys DIR or set {KEYS_ENV} "
                    "(make them with `airpose keys --drones N --out DIR`; `airpose launch` makes its own), "
                    "or pass --insecure on a trusted network")
            self.keys = load_swarm_keys(folder, c.drone_id, c.peers)
        self.clock = Clock(c.clock_offset_ms / 1000.0)
        self.view_index = c.drone_id - 1 if c.view is None else c.view
        self.src = open_source(c.source, c.detector)
        if not 0 <= self.view_index < self.src.num_views:
            raise ValueError(f"drone {c.drone_id}: view {self.view_index} not in a {self.src.num_views}-view source")
        self.view = self.src.view(self.view_index)
        self.K = np.asarray(self.view.K, np.float64)
        if c.backend.kind == "torch" and c.backend.checkpoint:
            size = checkpoint_settings(c.backend.checkpoint).get("input_size")
            if size and size != c.backend.input_size:
                log.info("input size %d from the checkpoint", size)
                c.backend = replace(c.backend, input_size=size)
        self.proto = make_stage_model(c.backend)
        self.input_size = int(getattr(self.proto, "meta", {}).get("input_size", c.backend.input_size))
        self.num_stages = int(self.proto.num_stages)
        fps = float(self.src.fps)
        self.tolerance_s = (0.5 / fps) if c.tolerance_ms is None else c.tolerance_ms / 1000.0
        self.fps = fps
        self.peers = PeerTable(frozenset(c.peers), c.peer_timeout_ms / 1000.0)
        self.mailbox = Mailbox()
        self.rejected: dict[str, int] = defaultdict(int)
        self.late_packets = 0
        self._seen: deque = deque(maxlen=4096)  # recent (drone, kind, stage, slot, stamp): replays
        self._seen_set: set = set()
        self.bytes_hello = 0
        self.bytes_data = 0
        self.data_packets = 0
        self.frames_started = 0
        self._est_stage = deque([0.005], maxlen=32)  # seconds per later stage (recent)
        self._est_stage1 = deque([0.0], maxlen=15)  # seconds of stage 1 (recent)
        self._preloaded: dict[int, np.ndarray] = {}
        self._last_box: np.ndarray | None = None
        self._finished_stamps: deque = deque(maxlen=64)
        self._skips: deque = deque(maxlen=256)  # (drone, slot) the others said they skip
        self._records: list[dict] = []
        self._stop = threading.Event()

    # -- setup -----------------------------------------------------------------------------
    def _meta(self, t0: float, restart: bool) -> dict:
        from airpose_lib import __version__

        return {"drone": self.cfg.drone_id, "view": self.view_index, "kit_version": __version__,
                "config": self.cfg.to_dict(), "K": self.K, "input_size": self.input_size,
                "num_stages": self.num_stages, "t0": t0, "tolerance_s": self.tolerance_s,
                "fps": self.fps, "restart": restart, "started": time.time()}

    def _warm_up_acquisition(self) -> None:
        """Load, box and crop one frame before READY (first calls import cv2/torch, allocate)."""
        image = self.view.image(0)
        H, W = image.shape[:2]
        box = person_box(self.view.keypoints(0), (W, H), self.cfg.min_confidence, self.cfg.box_margin_px)
        crop_input(image, box if box is not None else np.array([0.0, 0.0, W - 1.0, H - 1.0]), self.K,
                   self.input_size)

    def _preload(self) -> None:
        """Decode the frames the schedule can select into memory: the camera then hands over raw
        frames, as a real one does, and the replay's image decoding leaves the measurement."""
        c = self.cfg
        stamps = np.asarray(self.view.stamps, np.float64)
        start = c.start_s if c.start_s is not None else min(
            float(self.src.view(v).stamps[0]) for v in range(self.src.num_views))
        sched = Schedule(0.0, c.period_s, c.deadline_s, self.fps)
        last = start + (sched.offset(c.frames) if c.frames is not None else math.inf) + 0.2
        sel = np.nonzero((stamps >= start - 0.2) & (stamps <= last))[0]
        t = time.perf_counter()
        self._preloaded = {int(i): self.view.image(int(i)) for i in sel}
        log.info("preloaded %d frames in %.1f s", len(sel), time.perf_counter() - t)

    def _wait_start(self) -> float:
        """t0 from the config, or from the launcher on stdin ("START <t0>")."""
        print(f"READY {self.cfg.drone_id}", flush=True)
        if self.cfg.t0 is not None:
            return float(self.cfg.t0)
        ready, _, _ = select.select([sys.stdin], [], [], 300.0)
        line = sys.stdin.readline() if ready else ""
        if not line.startswith("START"):
            raise RuntimeError(f"expected 'START <t0>' on stdin, got {line!r}")
        return float(line.split()[1])

    # -- messaging ---------------------------------------------------------------------------
    def _send(self, kind: int, job: _Job | None = None, stage: int = 0, payload=None) -> None:
        now = self.clock.now()
        buf = encode_packet(kind, self.cfg.drone_id, stage=stage,
                            frame_index=max(job.frame_index, 0) if job else 0, slot=job.slot if job else 0,
                            stamp=job.stamp if job and not math.isnan(job.stamp) else now, sent=now,
                            payload=payload,
                            dtype=self.cfg.backend.message_dtype)
        if self.transport.send(buf):
            if kind == DATA:
                self.bytes_data += len(buf)
                self.data_packets += 1
            else:
                self.bytes_hello += len(buf)

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

    def _receive(self, received: list[tuple[int, bytes]]) -> None:
        now = self.clock.now()
        for sender, buf in received:
            try:
                pkt = decode_packet(buf)
            except WireError as e:
                self._reject(e.code, str(e), len(buf))
                continue
            if sender and pkt.drone != sender:
                self._reject("spoofed", f"claims to be drone {pkt.drone} but came over the link of drone "
                             f"{sender}{' (authenticated)' if self.keys is not None else ''}", len(buf))
                continue
            if pkt.drone == self.cfg.drone_id:
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

    # -- one frame -----------------------------------------------------------------------------
    def _new_job(self, k: int) -> _Job:
        s = self.schedule
        return _Job(slot=k, target=s.target(k), deadline=s.deadline(k))

    def _acquire(self, job: _Job) -> _Job:
        """Frame selection (waiting for its capture), box and crop (camera thread when pipelined)."""
        t_start = time.perf_counter()
        job.marks["wake"] = self.clock.now()
        i = self.replay.select(job.target)
        self.clock.sleep_until(self.replay.local_stamps[i])  # not captured yet: a few ms at most
        t_captured = time.perf_counter()
        job.marks["captured"] = self.clock.now()
        job.frame_index = i
        job.stamp = float(self.replay.local_stamps[i])
        job.shutter = float(self.replay.true_shutter[i])
        image = self._preloaded.get(i) if self._preloaded else None
        image = self.view.image(i) if image is None else image
        H, W = image.shape[:2]
        box = person_box(self.view.keypoints(i), (W, H), self.cfg.min_confidence, self.cfg.box_margin_px)
        if box is None:
            box = self._last_box
            job.flags |= R.NO_DETECTION
            if box is None:
                job.flags |= R.SKIPPED
                job.skip_reason = "no detection yet"
                return job
        self._last_box = box
        job.crop, job.P = crop_input(image, box, self.K, self.input_size)
        job.bbox = box
        job.timing["acquire"] = time.perf_counter() - t_captured
        job.marks["acquired"] = self.clock.now()
        return job

    def _stage1(self, job: _Job) -> _Job:
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

    def _acquire_and_stage1(self, job: _Job) -> _Job:
        """Both, in this thread (fixed mode); a failure skips the slot instead of killing the drone."""
        try:
            job = self._acquire(job)
            if not job.flags & R.SKIPPED:
                job = self._stage1(job)
        except Exception as e:  # noqa: BLE001
            log.exception("slot %d: acquisition/stage 1 failed", job.slot)
            job.flags |= R.SKIPPED
            job.skip_reason = f"error: {e}"
        return job

    def _publish(self, job: _Job) -> None:
        """Send the message of the stage just completed (the last stage's is not needed)."""
        if job.k < self.num_stages:
            self._send(DATA, job, stage=job.k, payload=job.msg)
        job.wait_since = self.clock.now()

    def _wait_deadline(self, job: _Job) -> float:
        # the remaining stages, plus a margin for waking up late on a busy CPU
        reserve = (self.num_stages - job.k) * max(self._est_stage) + _WAKE_MARGIN_S
        d = job.deadline - reserve
        if self.cfg.comm_timeout_ms is not None:
            d = min(d, job.wait_since + self.cfg.comm_timeout_ms / 1000.0)
        return d

    def _advance(self, job: _Job, now: float) -> bool:
        """Run every stage whose inputs are there (or whose wait is over); True when done."""
        while job.k < self.num_stages:
            k = job.k
            got: dict[int, Packet] = {}
            for d in sorted(self.peers.expected):
                p = self.mailbox.match(d, k, job.stamp, self.tolerance_s)
                if p is not None:
                    got[d] = p
            waiting = self.peers.alive(now) - set(got) - {d for d, s in self._skips if s == job.slot}
            if waiting and now < self._wait_deadline(job):
                return False
            msgs = [got[d].payload for d in sorted(got)]
            missing = sorted(self.peers.expected - set(got))
            if missing:
                job.flags |= R.fallback_flag(k + 1)
                for d in missing:
                    if self.mailbox.near_miss(d, k, job.slot, job.stamp, self.tolerance_s):
                        job.flags |= R.STAMP_MISMATCH
                    if self.cfg.fallback == "last":
                        p = self.mailbox.latest(d, job.stamp, k, self.tolerance_s)
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
            self._publish(job)
            now = self.clock.now()
        return True

    def _record(self, job: _Job, done: bool) -> None:
        now = self.clock.now()
        rec = {"kind": "frame", "drone": self.cfg.drone_id, "view": self.view_index, "slot": job.slot,
               "frame_index": job.frame_index if job.frame_index >= 0 else None,
               "frame_number": (int(self.view.numbers[job.frame_index])
                                if job.frame_index >= 0 and hasattr(self.view, "numbers") else None),
               "stamp": None if math.isnan(job.stamp) else job.stamp,
               "shutter": None if math.isnan(job.shutter) else job.shutter, "target": job.target,
               "t_done": now, "used": job.used, "timing": job.timing,
               "marks": {k: v - job.target for k, v in job.marks.items()}}
        if done:
            if now > job.deadline:
                job.flags |= R.DROPPED
            if self.peers.expected and not any(job.used) and not job.flags & R.LAST_USED:
                job.flags |= R.NO_PEERS
            rec["latency"] = self.clock.to_true(now) - job.shutter
            out = job.model.result()
            for key in R.PARAM_KEYS:
                if key in out:
                    rec[key] = to_numpy(out[key]).astype(np.float32).reshape(-1)
            rec["P"], rec["bbox"] = job.P.reshape(-1), job.bbox
            self._finished_stamps.append(job.stamp)
        else:
            rec["reason"] = job.skip_reason
            self._send(SKIP, job)  # so that the others do not wait for this drone
        rec["flags"] = job.flags
        self.writer.write(rec)
        self._records.append({k: rec.get(k) for k in ("slot", "flags", "latency", "timing", "used")})
        if job.flags & R.INVALID:
            log.debug("slot %d: %s", job.slot, R.describe_flags(job.flags))

    # -- the schedule ---------------------------------------------------------------------------
    def _last_slot(self) -> int:
        """Index one past the last slot."""
        if self.cfg.frames is not None:
            return self.cfg.frames
        k = 0
        while self.schedule.target(k) <= self.replay.end_local:
            k += 1
        return k

    def _too_late(self, k: int, now: float) -> bool:
        """A slot is started at most a quarter period after its wake time (else it is skipped)."""
        return now > self.schedule.wake(k) + 0.25 * self.schedule.period_s

    def run(self) -> dict:
        c = self.cfg
        logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                            format=f"%(asctime)s drone{c.drone_id} %(levelname)s %(message)s")
        warm_up(self.proto, self.input_size)
        self._warm_up_acquisition()
        if c.preload:
            self._preload()
        self.transport = Transport(endpoint(c.port, c.host), dict(c.peers), c.link, clock=self.clock.now,
                                   keys=self.keys)
        try:
            t0 = self._wait_start()
            restart = self.clock.now() > t0
            self.schedule = Schedule(t0=t0, period_s=c.period_s, deadline_s=c.deadline_s, fps=self.fps,
                                     margin_s=c.margin_ms / 1000.0, num_slots=c.frames)
            start = c.start_s if c.start_s is not None else min(
                float(self.src.view(v).stamps[0]) for v in range(self.src.num_views))
            # The cameras replay on the machine's (true) clock from t0; each stamps with its own clock.
            self.replay = CameraReplay(self.view.stamps, t0, start, self.clock.offset_s)
            out = Path(c.out_dir)
            self.writer = R.ResultWriter(out / f"node_{c.drone_id}.jsonl", self._meta(t0, restart))
            first = self.schedule.first_slot_after(self.clock.now() + 0.05) if restart else 0
            end = self._last_slot()
            if restart:
                log.info("joining a running schedule at slot %d of %d", first, end)
            summary = self._loop(first, end) if first < end else self._summary(self.clock.now())
            self._send(BYE)
            self.writer.write(summary)
            self.writer.close()
            R.write_npz(out / f"node_{c.drone_id}.jsonl", out / f"node_{c.drone_id}.npz")
            (out / f"node_{c.drone_id}.summary.json").write_text(json.dumps(R._jsonable(summary), indent=1))
            print("SUMMARY " + json.dumps(R._jsonable(summary)), flush=True)
            return summary
        finally:
            self._stop.set()
            self.transport.close()

    def _loop(self, first: int, end: int) -> dict:
        c = self.cfg
        pipelined = c.mode == "pipelined"
        # Frames waiting for a late message cost no CPU: allow every frame of the budget in flight,
        # plus the one in stage 1 and the one being acquired.
        max_inflight = 1 if not pipelined else math.ceil(c.deadline_s / c.period_s) + 2
        inflight: list[_Job] = []
        next_hello = 0.0
        hard_stop = time.time() + c.max_runtime_s if c.max_runtime_s else math.inf
        k = first
        done_q: queue.Queue = queue.Queue()
        if pipelined:
            sig_main = self.transport.ctx.socket(zmq.PAIR)
            sig_main.bind(f"inproc://jobs{id(self)}")
            self.transport.register(sig_main)
            permits = threading.Semaphore(max_inflight)
            acq_q: queue.Queue = queue.Queue(maxsize=1)
            workers = [threading.Thread(target=self._camera, args=(first, end, acq_q), daemon=True),
                       threading.Thread(target=self._inference, args=(acq_q, done_q, permits), daemon=True)]
        # Before t0: heartbeats so that every drone knows the others are alive at the start.
        while self.clock.now() < self.schedule.wake(first) - 0.001 and time.time() < hard_stop:
            if self.clock.now() >= next_hello:
                self._send(HELLO)
                next_hello = self.clock.now() + c.heartbeat_ms / 1000.0
            bufs, _ = self.transport.poll(min(0.02, max(0.0, self.schedule.wake(first) - self.clock.now())))
            self._receive(bufs)
        log.info("start: slots %d..%d, mode %s, peers alive %s of %s", first, end - 1, c.mode,
                 sorted(self.peers.alive(self.clock.now())), sorted(self.peers.expected))
        t_begin = self.clock.now()
        if pipelined:
            for w in workers:
                w.start()
        worker_done = not pipelined
        while time.time() < hard_stop:
            now = self.clock.now()
            if now >= next_hello:
                self._send(HELLO)
                next_hello = now + c.heartbeat_ms / 1000.0
            # new frames
            if pipelined:
                while True:
                    try:
                        job = done_q.get_nowait()
                    except queue.Empty:
                        break
                    if job is None:
                        worker_done = True
                        continue
                    if job.flags & R.SKIPPED:  # (holds no permit)
                        self._record(job, done=False)
                        continue
                    self.frames_started += 1
                    self._publish(job)
                    inflight.append(job)
            elif not inflight and k < end and now >= self.schedule.wake(k):
                while k < end and self._too_late(k, now):
                    job = self._new_job(k)
                    job.flags |= R.SKIPPED
                    job.skip_reason = "busy past the slot"
                    self._record(job, done=False)
                    k += 1
                if k < end and now >= self.schedule.wake(k):  # (after skipping, not early)
                    job = self._acquire_and_stage1(self._new_job(k))
                    k += 1
                    if job.flags & R.SKIPPED:
                        self._record(job, done=False)
                    else:
                        self.frames_started += 1
                        self._publish(job)
                        inflight.append(job)
            # exchange and later stages
            bufs, _ = self.transport.poll(0.0)
            self._receive(bufs)
            now = self.clock.now()
            for job in list(inflight):
                if self._advance(job, now):
                    self._record(job, done=True)
                    inflight.remove(job)
                    if pipelined:
                        permits.release()
                    now = self.clock.now()
            self.mailbox.prune(now - 2.0)
            finished = (k >= end if not pipelined else worker_done) and not inflight
            if finished:
                break
            # sleep until the next thing can happen
            wake = next_hello
            if not pipelined and not inflight and k < end:
                wake = min(wake, self.schedule.wake(k))
            for job in inflight:
                wake = min(wake, self._wait_deadline(job))
            bufs, ready = self.transport.poll(max(0.0, wake - self.clock.now()))
            if pipelined and sig_main in ready:
                while True:
                    try:
                        sig_main.recv(zmq.NOBLOCK)
                    except zmq.Again:
                        break
            self._receive(bufs)
        else:
            log.warning("max runtime reached; %d frames in flight abandoned", len(inflight))
        self._stop.set()
        return self._summary(t_begin)

    def _camera(self, first: int, end: int, acq_q: queue.Queue) -> None:
        """Pipelined mode, camera thread: acquire slot after slot (skip a slot it is late for)."""
        try:
            for k in range(first, end):
                self.clock.sleep_until(self.schedule.wake(k), 0.01)
                if self._stop.is_set():
                    return
                job = self._new_job(k)
                if self._too_late(k, self.clock.now()):
                    job.flags |= R.SKIPPED
                    job.skip_reason = "camera busy past the slot"
                else:
                    try:
                        job = self._acquire(job)
                    except Exception as e:  # noqa: BLE001 -- a bad frame must not kill the drone
                        log.exception("slot %d: acquisition failed", k)
                        job.flags |= R.SKIPPED
                        job.skip_reason = f"error: {e}"
                while not self._stop.is_set():
                    try:
                        acq_q.put(job, timeout=0.01)  # blocks while inference is behind
                        break
                    except queue.Full:
                        pass
        finally:
            acq_q.put(None)

    def _inference(self, acq_q: queue.Queue, done_q: queue.Queue, permits: threading.Semaphore) -> None:
        """Pipelined mode, inference thread: stage 1 of acquired frames, handed to the main thread
        (which exchanges and runs the later stages). A frame that cannot finish by its deadline
        any more is skipped rather than started."""
        sig = self.transport.ctx.socket(zmq.PAIR)
        sig.connect(f"inproc://jobs{id(self)}")
        try:
            while not self._stop.is_set():
                try:
                    job = acq_q.get(timeout=0.01)
                except queue.Empty:
                    continue
                if job is None:
                    break
                if not job.flags & R.SKIPPED:
                    while not permits.acquire(timeout=0.01):
                        if self._stop.is_set():
                            return
                    # A frame that would finish after its deadline is skipped before it costs a
                    # stage 1, so that an overloaded drone spends its CPU on frames it can still
                    # complete (the paper's rule, applied up front). Typical times are medians
                    # (one slow outlier must not starve the following frames); each skip lowers
                    # the estimate a little, so a drone that was too slow probes again later.
                    est1 = statistics.median(self._est_stage1)
                    need = est1 + (self.num_stages - 1) * statistics.median(self._est_stage)
                    if self.clock.now() + need > job.deadline:
                        permits.release()
                        self._est_stage1.append(0.8 * est1)
                        job.flags |= R.SKIPPED
                        job.skip_reason = "inference busy past the slot"
                    else:
                        try:
                            job = self._stage1(job)
                        except Exception as e:  # noqa: BLE001
                            log.exception("slot %d: stage 1 failed", job.slot)
                            permits.release()
                            job.flags |= R.SKIPPED
                            job.skip_reason = f"error: {e}"
                done_q.put(job)
                sig.send(b"j")
        finally:
            done_q.put(None)
            try:
                sig.send(b"j", zmq.NOBLOCK)
            except zmq.ZMQError:
                pass
            sig.close(0)

    def _summary(self, t_begin: float) -> dict:
        recs = self._records
        flags = np.array([r["flags"] for r in recs], np.int64) if recs else np.zeros(0, np.int64)
        valid = (flags & R.INVALID) == 0
        lat = np.array([r["latency"] for r, ok in zip(recs, valid) if ok], np.float64)
        n = len(recs)
        span = n * self.schedule.period_s if n else math.nan
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
            "nominal_fps": 1.0 / self.schedule.period_s,
            "fps": float(valid.sum() / span) if n else 0.0,
            "drop_rate": float(1.0 - valid.mean()) if n else None,
            "latency_p50": pct(lat, 50), "latency_p95": pct(lat, 95), "latency_max": pct(lat, 100),
            "bytes_data": self.bytes_data, "data_packets": self.data_packets, "bytes_hello": self.bytes_hello,
            "frames_started": self.frames_started,
            "bytes_per_frame": self.bytes_data / self.frames_started if self.frames_started else None,
            "rejected": dict(self.rejected), "late_packets": self.late_packets,
            "authenticated": self.keys is not None,
            "link_lost": self.transport.emulator.lost if self.transport.emulator else 0,
            "send_dropped": self.transport.send_dropped,
            "timing_median": {k: statistics.median(v) for k, v in timings.items()},
            "wall_s": self.clock.now() - t_begin,
        }
