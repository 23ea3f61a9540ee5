"""The drone's schedule loop: which slot starts when, in either mode.

``fixed`` (the paper's hardware-in-the-loop test): one frame at a time; a slot of ``window``
(240 ms) = acquisition + stage 1 + 2 exchanges + 2 stages; a frame not complete by the end of its
window is discarded (``DROPPED``); a slot the drone is too late to start is ``SKIPPED``.

``pipelined``: slots every ``1 / rate`` (20 fps) with a ``latency_budget`` (150 ms) deadline; a
camera thread acquires frame k + 2, an inference thread runs stage 1 of frame k + 1 and the main
thread exchanges messages and runs stages 2-3 of frame k (torch and ONNX Runtime release the
GIL); several frames in flight. A frame whose stage 1 could not finish by its deadline any more
is skipped before it costs CPU. An overloaded swarm agrees on a lower common rate over the
heartbeat (:mod:`.rate`): only every m-th slot is acquired, by every drone alike.
"""
from __future__ import annotations

import logging
import math
import queue
import threading
import time

import zmq

from . import results as R
from .camera import DroneCamera
from .config import NodeConfig
from .messaging import PeerMessaging
from .rate import RateAgreement, takes_slot
from .records import FrameRecords
from .stages import FrameJob, StagePipeline
from .startup import Heartbeat
from .sync import CameraReplay, Clock, Schedule
from .transport import Transport

__all__ = ["last_slot", "SlotLoop"]

log = logging.getLogger("airpose.runtime")
_BUSY = "inference busy past the slot"


def last_slot(schedule: Schedule, replay: CameraReplay, frames: int | None) -> int:
    """Index one past the last slot: ``frames``, by default as many as the replay covers."""
    if frames is not None:
        return frames
    k = 0
    while schedule.target(k) <= replay.end_local:
        k += 1
    return k


class SlotLoop:
    """Runs the slots ``first..end-1`` of one drone.

    Args:
        cfg: the drone's settings (mode, heartbeat, run-time limit).
        clock, schedule, transport: the drone's clock, the swarm's schedule, its sockets.
        camera, stages, messaging, records: the drone's parts.
        stop: set when the run ends (the pipelined threads watch it).
    """

    def __init__(self, cfg: NodeConfig, clock: Clock, schedule: Schedule, transport: Transport,
                 camera: DroneCamera, stages: StagePipeline, messaging: PeerMessaging, records: FrameRecords,
                 stop: threading.Event) -> None:
        self.cfg = cfg
        self.clock = clock
        self.schedule = schedule
        self.transport = transport
        self.camera = camera
        self.stages = stages
        self.messaging = messaging
        self.records = records
        self.rate = RateAgreement(cfg.period_s, adaptive=cfg.mode == "pipelined" and cfg.adaptive_rate,
                                  max_divisor=cfg.max_rate_divisor)
        messaging.on_rate = self.rate.heard
        self.heartbeat = Heartbeat(messaging, cfg.heartbeat_ms / 1000.0, divisor=lambda: self.rate.own)
        self._divisor = 1  # the swarm's, set by the main thread, read by the camera thread
        self._stop = stop
        self.frames_started = 0

    def new_job(self, k: int) -> FrameJob:
        s = self.schedule
        return FrameJob(slot=k, target=s.target(k), deadline=s.deadline(k))

    def too_late(self, k: int, now: float) -> bool:
        """A slot is started at most a quarter period after its wake time (else it is skipped)."""
        return now > self.schedule.wake(k) + 0.25 * self.schedule.period_s

    def run(self, first: int, end: int) -> float:
        """Heartbeats until the first slot, then every slot; returns the local start time."""
        c = self.cfg
        pipelined = c.mode == "pipelined"
        # Frames waiting for a late message cost no CPU: allow every frame of the budget in flight,
        # plus the one in stage 1 and the one being acquired.
        max_inflight = 1 if not pipelined else math.ceil(c.deadline_s / c.period_s) + 2
        inflight: list[FrameJob] = []
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
            self.heartbeat.beat(self.clock.now())
            bufs, _ = self.transport.poll(min(0.02, max(0.0, self.schedule.wake(first) - self.clock.now())))
            self.messaging.receive(bufs)
        log.info("start: slots %d..%d, mode %s, peers alive %s of %s", first, end - 1, c.mode,
                 sorted(self.messaging.peers.alive(self.clock.now())), sorted(self.messaging.peers.expected))
        t_begin = self.clock.now()
        if pipelined:
            for w in workers:
                w.start()
        worker_done = not pipelined
        while time.time() < hard_stop:
            now = self.clock.now()
            self.heartbeat.beat(now)
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
                        if job.skip_reason == _BUSY:
                            self.rate.overloaded(now)
                        self.records.record(job, done=False)
                        continue
                    self.rate.observe(now, job.timing["stage1"])
                    self.frames_started += 1
                    self.stages.publish(job)
                    inflight.append(job)
            elif not inflight and k < end and now >= self.schedule.wake(k):
                while k < end and self.too_late(k, now):
                    job = self.new_job(k)
                    job.flags |= R.SKIPPED
                    job.skip_reason = "busy past the slot"
                    self.records.record(job, done=False)
                    k += 1
                if k < end and now >= self.schedule.wake(k):  # (after skipping, not early)
                    job = self._acquire_and_stage1(self.new_job(k))
                    k += 1
                    if job.flags & R.SKIPPED:
                        self.records.record(job, done=False)
                    else:
                        self.frames_started += 1
                        self.stages.publish(job)
                        inflight.append(job)
            # exchange and later stages
            bufs, _ = self.transport.poll(0.0)
            self.messaging.receive(bufs)
            now = self.clock.now()
            for job in list(inflight):
                if self.stages.advance(job, now):
                    self.records.record(job, done=True)
                    inflight.remove(job)
                    if pipelined:
                        permits.release()
                    now = self.clock.now()
            self.messaging.mailbox.prune(now - 2.0)
            self._divisor = self.rate.divisor(self.messaging.peers.alive(now))
            finished = (k >= end if not pipelined else worker_done) and not inflight
            if finished:
                break
            # sleep until the next thing can happen
            wake = self.heartbeat.next
            if not pipelined and not inflight and k < end:
                wake = min(wake, self.schedule.wake(k))
            for job in inflight:
                wake = min(wake, self.stages.wait_deadline(job))
            bufs, ready = self.transport.poll(max(0.0, wake - self.clock.now()))
            if pipelined and sig_main in ready:
                while True:
                    try:
                        sig_main.recv(zmq.NOBLOCK)
                    except zmq.Again:
                        break
            self.messaging.receive(bufs)
        else:
            log.warning("max runtime reached; %d frames in flight abandoned", len(inflight))
        self._stop.set()
        return t_begin

    def _acquire_and_stage1(self, job: FrameJob) -> FrameJob:
        """Both, in this thread (fixed mode); a failure skips the slot instead of killing the drone."""
        try:
            job = self.camera.acquire(job)
            if not job.flags & R.SKIPPED:
                job = self.stages.stage1(job)
        except Exception as e:  # noqa: BLE001
            log.exception("slot %d: acquisition/stage 1 failed", job.slot)
            job.flags |= R.SKIPPED
            job.skip_reason = f"error: {e}"
        return job

    def _camera(self, first: int, end: int, acq_q: queue.Queue) -> None:
        """Pipelined mode, camera thread: acquire slot after slot (skip a slot it is late for)."""
        try:
            for k in range(first, end):
                self.clock.sleep_until(self.schedule.wake(k), 0.01)
                if self._stop.is_set():
                    return
                job = self.new_job(k)
                job.divisor = m = self._divisor
                if not takes_slot(k, m):
                    job.flags |= R.SKIPPED | R.RATE_SKIPPED
                    job.skip_reason = f"swarm rate 1/{m}"
                elif self.too_late(k, self.clock.now()):
                    job.flags |= R.SKIPPED
                    job.skip_reason = "camera busy past the slot"
                else:
                    try:
                        job = self.camera.acquire(job)
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
                    # complete (the paper's rule, applied up front).
                    if not self.stages.can_finish(job):
                        permits.release()
                        self.stages.lower_stage1_estimate()
                        job.flags |= R.SKIPPED
                        job.skip_reason = _BUSY
                    else:
                        try:
                            job = self.stages.stage1(job)
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
