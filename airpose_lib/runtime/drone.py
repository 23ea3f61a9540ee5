"""One drone process put together: its keys, clock, camera, network, exchange and record stream
(:class:`DroneProcess`); :meth:`DroneProcess.run` is the whole life of the process. The parts
live in ``camera``, ``stages``, ``messaging``, ``startup``, ``loop`` and ``records``."""
from __future__ import annotations

import json
import logging
import math
import sys
import threading
from dataclasses import replace
from pathlib import Path

from . import results as R
from .backends import checkpoint_settings, warm_up
from .camera import DroneCamera
from .config import NodeConfig
from .keys import KEYS_ENV, SwarmKeyError, keys_folder, load_swarm_keys
from .loop import SlotLoop, last_slot
from .messaging import PeerMessaging
from .networks import make_stage_model
from .records import FrameRecords, node_meta
from .source import SourceError, open_source
from .stages import StagePipeline
from .startup import first_slot, sequence_start, wait_start
from .sync import Clock, Schedule
from .transport import Transport, endpoint
from .wire import BYE

__all__ = ["DroneProcess"]

log = logging.getLogger("airpose.runtime")


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
            raise SourceError(f"drone {c.drone_id}: view {self.view_index} not in the {self.src.num_views}-view "
                              f"source {c.source}; give --view 0..{self.src.num_views - 1} (default: drone id - 1)")
        self.view = self.src.view(self.view_index)
        if c.backend.kind == "torch" and c.backend.checkpoint:
            size = checkpoint_settings(c.backend.checkpoint).get("input_size")
            if size and size != c.backend.input_size:
                log.info("input size %d from the checkpoint", size)
                c.backend = replace(c.backend, input_size=size)
        self.proto = make_stage_model(c.backend)
        self.input_size = int(getattr(self.proto, "meta", {}).get("input_size", c.backend.input_size))
        self.fps = float(self.src.fps)
        self.tolerance_s = (0.5 / self.fps) if c.tolerance_ms is None else c.tolerance_ms / 1000.0
        self.messaging = PeerMessaging(c.drone_id, c.peers, c.peer_timeout_ms / 1000.0, int(self.proto.num_stages),
                                       self.tolerance_s, self.clock.now, c.backend.message_dtype,
                                       authenticated=self.keys is not None)
        self.camera = DroneCamera(self.view, self.clock, self.input_size, c.min_confidence, c.box_margin_px)
        self.stages = StagePipeline(self.proto, self.clock, self.messaging, c.fallback,
                                    None if c.comm_timeout_ms is None else c.comm_timeout_ms / 1000.0)
        self.records = FrameRecords(c, self.view_index, self.view, self.clock, self.messaging)
        self._stop = threading.Event()

    @property
    def num_stages(self) -> int:
        return self.stages.num_stages

    def _preload(self) -> None:
        """Decode the frames the schedule can select into memory (``--preload``)."""
        c = self.cfg
        start = sequence_start(self.src, c.start_s)
        sched = Schedule(0.0, c.period_s, c.deadline_s, self.fps)
        self.camera.preload(start, start + (sched.offset(c.frames) if c.frames is not None else math.inf) + 0.2)

    def run(self) -> dict:
        c = self.cfg
        logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                            format=f"%(asctime)s drone{c.drone_id} %(levelname)s %(message)s")
        warm_up(self.proto, self.input_size)
        self.camera.warm_up()
        if c.preload:
            self._preload()
        self.transport = Transport(endpoint(c.port, c.host), dict(c.peers), c.link, clock=self.clock.now,
                                   keys=self.keys)
        self.messaging.transport = self.transport
        try:
            t0 = wait_start(c.drone_id, c.t0)
            restart = self.clock.now() > t0
            schedule = Schedule(t0=t0, period_s=c.period_s, deadline_s=c.deadline_s, fps=self.fps,
                                margin_s=c.margin_ms / 1000.0, num_slots=c.frames)
            self.camera.start(t0, sequence_start(self.src, c.start_s))
            out = Path(c.out_dir)
            self.records.writer = R.ResultWriter(
                out / f"node_{c.drone_id}.jsonl",
                node_meta(c, self.view_index, self.camera.K, self.input_size, self.num_stages, t0,
                          self.tolerance_s, self.fps, restart))
            first = first_slot(schedule, self.clock.now(), restart)
            end = last_slot(schedule, self.camera.replay, c.frames)
            if restart:
                log.info("joining a running schedule at slot %d of %d", first, end)
            loop = SlotLoop(c, self.clock, schedule, self.transport, self.camera, self.stages, self.messaging,
                            self.records, self._stop)
            t_begin = loop.run(first, end) if first < end else self.clock.now()
            summary = self.records.summary(t_begin, schedule.period_s, loop.frames_started, self.transport)
            self.messaging.send(BYE)
            self.records.writer.write(summary)
            self.records.writer.close()
            R.write_npz(out / f"node_{c.drone_id}.jsonl", out / f"node_{c.drone_id}.npz")
            (out / f"node_{c.drone_id}.summary.json").write_text(json.dumps(R._jsonable(summary), indent=1))
            print("SUMMARY " + json.dumps(R._jsonable(summary)), flush=True)
            return summary
        finally:
            self._stop.set()
            self.transport.close()
