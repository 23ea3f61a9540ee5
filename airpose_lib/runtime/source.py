"""Where a drone's frames come from.

A :class:`ViewSource` is one camera of a recorded sequence: per-frame shutter time stamps, the
intrinsics K, the images (loaded on demand) and 2D keypoint detections. :func:`open_source` gives
the views of

* a sequence folder, through ``airpose_lib.data`` (the kit's sequence layout and the official
  real-data layout), or
* ``synthetic[:key=value,...]``: :class:`SyntheticSource`, a procedural stand-in (a textured box
  moving in front of a gradient, BODY_25-like keypoints inside it) for tests and benchmarks that
  need no data on disk.

How a frame becomes the network input (person box, margin, network camera, crop, normalisation,
the previous-box rule) is ``airpose_lib.data.network_input``, shared with fine-tuning.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np

from airpose_lib.errors import UserError

__all__ = [
    "ViewSource",
    "SyntheticSource",
    "SyntheticView",
    "SourceError",
    "open_source",
]


@runtime_checkable
class ViewSource(Protocol):
    """One camera of a sequence.

    Attributes:
        stamps: ``(N,)`` shutter time stamps in seconds (any origin shared by the views).
        K: ``(3, 3)`` intrinsics of the full frame.
    """

    stamps: np.ndarray
    K: np.ndarray

    def image(self, i: int) -> np.ndarray:
        """Frame i as ``(H, W, 3)`` uint8 RGB."""

    def keypoints(self, i: int) -> np.ndarray | None:
        """Detections of frame i: ``(J, 3)`` ``[x, y, confidence]`` full-frame pixels, or None."""


# -- the procedural stand-in ------------------------------------------------------------------
@dataclass
class SyntheticView:
    """One procedural camera (see :class:`SyntheticSource`)."""

    stamps: np.ndarray
    K: np.ndarray
    boxes: np.ndarray  # (N, 4) person box per frame
    size: tuple[int, int]  # (W, H)
    seed: int
    missing_detections: frozenset = frozenset()
    _background: np.ndarray | None = field(default=None, repr=False, compare=False)

    def image(self, i: int) -> np.ndarray:
        W, H = self.size
        x0, y0, x1, y1 = np.clip(self.boxes[i].round(), 0, [W, H, W, H]).astype(int)
        # A vertical gradient (made once) and a textured "person" box whose texture depends on
        # the frame, so every frame gives a different network input.
        if self._background is None:
            grad = np.linspace(40, 200, H, dtype=np.float32)[:, None, None] * np.array([0.6, 0.8, 1.0], np.float32)
            self._background = np.ascontiguousarray(np.broadcast_to(grad.astype(np.uint8), (H, W, 3)))
        img = self._background.copy()
        h, w = y1 - y0, x1 - x0
        if h > 0 and w > 0:
            tex = np.random.default_rng((self.seed, i)).integers(0, 256, size=(8, 4, 3), dtype=np.uint8)
            img[y0:y1, x0:x1] = tex[(np.arange(h) * 8 // h)[:, None], (np.arange(w) * 4 // w)[None, :]]
        return img

    def keypoints(self, i: int) -> np.ndarray | None:
        if i in self.missing_detections:
            return None
        x0, y0, x1, y1 = self.boxes[i]
        g = np.random.default_rng((self.seed, i, 1))
        u = g.uniform(0.1, 0.9, size=(25, 2))
        kp = np.stack((x0 + u[:, 0] * (x1 - x0), y0 + u[:, 1] * (y1 - y0), np.full(25, 0.9)), -1)
        # The extreme keypoints lie on the box (head top, feet, hands), so person_box recovers it.
        kp[0, :2] = (0.5 * (x0 + x1), y0)
        kp[11, :2] = (x0, 0.5 * (y0 + y1))
        kp[14, :2] = (x1, y1)
        kp[24, :2] = (x1, 0.5 * (y0 + y1))
        return kp.astype(np.float32)


class SyntheticSource:
    """Procedural multi-view sequence: no files, deterministic in ``seed``.

    Args:
        num_views: cameras (drones).
        num_frames: frames per camera.
        fps: nominal frame rate; stamps are ``i / fps`` plus per-view jitter.
        size: ``(W, H)`` of the frames.
        seed: everything random derives from it.
        stamp_jitter_s: uniform jitter of each stamp (a camera's shutter is not exactly periodic).
        missing_detections: frame indices (all views) without detections.
    """

    def __init__(self, num_views: int = 2, num_frames: int = 300, fps: float = 30.0,
                 size: tuple[int, int] = (960, 540), seed: int = 0, stamp_jitter_s: float = 0.001,
                 missing_detections: Sequence[int] = ()):
        self.fps = float(fps)
        W, H = size
        views = []
        for v in range(num_views):
            g = np.random.default_rng((seed, v))
            f = 1475.0 * W / 1920.0  # the synthetic data's focal length, scaled to the width
            K = np.array([[f, 0, W / 2], [0, f, H / 2], [0, 0, 1]], np.float64)
            t = np.arange(num_frames) / fps
            stamps = t + g.uniform(-stamp_jitter_s, stamp_jitter_s, num_frames)
            # The person box drifts on a smooth path; its size breathes a little.
            phase = g.uniform(0, 2 * np.pi, 3)
            cx = W * (0.5 + 0.25 * np.sin(0.4 * t + phase[0]))
            cy = H * (0.5 + 0.15 * np.sin(0.3 * t + phase[1]))
            hh = H * (0.45 + 0.1 * np.sin(0.5 * t + phase[2]))
            boxes = np.stack((cx - 0.2 * hh, cy - 0.5 * hh, cx + 0.2 * hh, cy + 0.5 * hh), -1)
            views.append(SyntheticView(stamps=stamps, K=K, boxes=boxes, size=(W, H), seed=seed * 1000 + v,
                                       missing_detections=frozenset(int(i) for i in missing_detections)))
        self.views = views

    @property
    def num_views(self) -> int:
        return len(self.views)

    def view(self, v: int) -> SyntheticView:
        return self.views[v]


class SourceError(UserError, ValueError):
    """A ``--source`` a drone cannot replay: an unknown or malformed ``synthetic:`` option, or a
    camera the source does not have. The message names the option and the fix."""


SYNTHETIC_EXAMPLE = "synthetic:views=2,frames=300,fps=30,size=960x540,seed=0,jitter_ms=1,missing=3+7"


def _size(value: str) -> tuple[int, int]:
    w, _, h = value.partition("x")
    return int(w), int(h)


# ``synthetic:`` key -> (SyntheticSource argument, parser of the value)
_SYNTHETIC_OPTIONS = {
    "views": ("num_views", int), "num_views": ("num_views", int),
    "frames": ("num_frames", int), "num_frames": ("num_frames", int),
    "fps": ("fps", float),
    "size": ("size", _size),
    "seed": ("seed", int),
    "jitter_ms": ("stamp_jitter_s", lambda v: float(v) / 1000.0),
    "missing": ("missing_detections", lambda v: [int(x) for x in v.split("+") if x]),
}


def _parse_synthetic(spec: str) -> SyntheticSource:
    kwargs: dict = {}
    _, _, rest = spec.partition(":")
    for item in filter(None, rest.split(",")):
        key, _, value = item.partition("=")
        key = key.strip()
        if key not in _SYNTHETIC_OPTIONS:
            raise SourceError(f"--source {spec}: unknown synthetic option {key!r}; known: "
                              f"{', '.join(_SYNTHETIC_OPTIONS)} (e.g. {SYNTHETIC_EXAMPLE})")
        name, parse = _SYNTHETIC_OPTIONS[key]
        try:
            kwargs[name] = parse(value)
        except ValueError:
            raise SourceError(f"--source {spec}: {key}={value!r} is not a valid value "
                              f"(e.g. {SYNTHETIC_EXAMPLE})") from None
    return SyntheticSource(**kwargs)


class _SequenceView:
    """One view of an ``airpose_lib.data`` :class:`~airpose_lib.data.sequences.reader.Sequence`
    as a :class:`ViewSource` (frame i = position i of the loaded frames)."""

    def __init__(self, seq, v: int, detector: str, stamps: np.ndarray):
        self._seq, self._v = seq, v
        self.stamps = stamps
        self.K = np.asarray(seq.K[v], np.float64)
        self.numbers = np.asarray(seq.frames)  # the image numbers of the official layout
        if detector not in seq.keypoints:
            raise SourceError(f"{seq.root}: no {detector!r} detections (have {sorted(seq.keypoints)})")
        self._kp = seq.keypoints[detector]  # (F, V, J, 3), missing = 0

    def image(self, i: int) -> np.ndarray:
        return self._seq.image(i, self._v)

    def keypoints(self, i: int) -> np.ndarray | None:
        return self._kp[i, self._v]


class _SequenceSource:
    """A recording in the official layout (real or generated), via ``data.load_sequence``.

    Stamps: ``timestamps.csv`` when present; otherwise frame number / fps (``fps`` from the
    kit's ``sequence.json``, else 30).
    """

    def __init__(self, root: str | Path, detector: str):
        # lazy: ~0.2 s of a drone's start-up, which a synthetic source skips
        from airpose_lib.data.sequences.reader import load_sequence

        seq = load_sequence(root, detectors=(detector,), missing_detections="zero", ground_truth=False)
        self.sequence = seq
        fps = (seq.meta.get("config") or {}).get("fps")
        if seq.timestamps is not None:
            stamps = np.asarray(seq.timestamps, np.float64)
            self.fps = float(fps) if fps else float(1.0 / np.median(np.diff(stamps[:, 0])))
        else:
            self.fps = float(fps) if fps else 30.0
            stamps = np.repeat((np.asarray(seq.frames, np.float64) / self.fps)[:, None], seq.num_views, 1)
        self.views = [_SequenceView(seq, v, detector, stamps[:, v]) for v in range(seq.num_views)]

    @property
    def num_views(self) -> int:
        return len(self.views)

    def view(self, v: int):
        return self.views[v]


def open_source(spec: str, detector: str = "openpose"):
    """``"synthetic[:views=2,frames=300,fps=30,size=960x540,seed=0,jitter_ms=1,missing=3+7]"`` or a
    sequence folder in the official layout (``airpose_lib.data.sequences.reader.load_sequence``).

    Returns an object with ``num_views``, ``fps`` and ``view(v) -> ViewSource``.
    """
    if spec.startswith("synthetic"):
        return _parse_synthetic(spec)
    return _SequenceSource(spec, detector)
