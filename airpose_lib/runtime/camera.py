"""A drone's camera: one view of the source replayed on the drone's clock, the person box from
each frame's 2D detections, and the network's input crop (``data.network_input``)."""
from __future__ import annotations

import logging
import time

import numpy as np

from airpose_lib.data.network_input import box_margin, crop_input, keep_previous_box, person_box

from . import results as R
from .source import ViewSource
from .sync import CameraReplay, Clock

__all__ = ["DroneCamera"]

log = logging.getLogger("airpose.runtime")


class DroneCamera:
    """Frame selection, person box and crop for one drone.

    Args:
        view: the drone's view of the source.
        clock: the drone's clock.
        input_size: crop side S, pixels.
        min_confidence, box_margin_px: the person box rule (``data.network_input.person_box``);
            a margin of None is ``network_box_margin`` of the view's K. No detection: the previous
            box (``keep_previous_box``); before the first detection the frame is skipped.
    """

    def __init__(self, view: ViewSource, clock: Clock, input_size: int, min_confidence: float,
                 box_margin_px: float | None) -> None:
        self.view = view
        self.K = np.asarray(view.K, np.float64)
        self.clock = clock
        self.input_size = input_size
        self.min_confidence = min_confidence
        self.box_margin_px = box_margin(box_margin_px, self.K)
        self.replay: CameraReplay | None = None  # from start()
        self._preloaded: dict[int, np.ndarray] = {}
        self._last_box: np.ndarray | None = None

    def warm_up(self) -> None:
        """Load, box and crop one frame before READY (first calls import cv2/torch, allocate)."""
        image = self.view.image(0)
        H, W = image.shape[:2]
        box = person_box(self.view.keypoints(0), (W, H), self.min_confidence, self.box_margin_px)
        crop_input(image, box if box is not None else np.array([0.0, 0.0, W - 1.0, H - 1.0]), self.K,
                   self.input_size)

    def preload(self, first_s: float, last_s: float) -> None:
        """Decode the frames stamped in ``[first_s - 0.2, last_s]`` (sequence time) into memory: the
        camera then hands over raw frames, as a real one does, and the replay's image decoding
        leaves the measurement."""
        stamps = np.asarray(self.view.stamps, np.float64)
        sel = np.nonzero((stamps >= first_s - 0.2) & (stamps <= last_s))[0]
        t = time.perf_counter()
        self._preloaded = {int(i): self.view.image(int(i)) for i in sel}
        log.info("preloaded %d frames in %.1f s", len(sel), time.perf_counter() - t)

    def start(self, t0: float, start_s: float) -> None:
        """The camera replays the sequence from ``start_s`` on the machine's (true) clock from
        ``t0``; it stamps with its own clock."""
        self.replay = CameraReplay(self.view.stamps, t0, start_s, self.clock.offset_s)

    def acquire(self, job):
        """Fill ``job`` (a :class:`~.stages.FrameJob`): the frame nearest its target (waiting for
        its capture), the box and the crop; flagged and skipped without any detection yet."""
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
        detected = person_box(self.view.keypoints(i), (W, H), self.min_confidence, self.box_margin_px)
        box = keep_previous_box(detected, self._last_box)
        if detected is None:
            job.flags |= R.NO_DETECTION
            if box is None:  # a live camera cannot look ahead: no box before the first detection
                job.flags |= R.SKIPPED
                job.skip_reason = "no detection yet"
                return job
        self._last_box = box
        job.crop, job.P = crop_input(image, box, self.K, self.input_size)
        job.bbox = box
        job.timing["acquire"] = time.perf_counter() - t_captured
        job.marks["acquired"] = self.clock.now()
        return job
