"""Where a drone's frames come from, and how a frame becomes the network input (crop, P).

A :class:`ViewSource` is one camera of a recorded sequence: per-frame shutter time stamps, the
intrinsics K, the images (loaded on demand) and 2D keypoint detections. :func:`open_source` gives
the views of

* a sequence folder, through ``airpose_lib.data`` (the kit's sequence layout and the official
  real-data layout), or
* ``synthetic[:key=value,...]``: :class:`SyntheticSource`, a procedural stand-in (a textured box
  moving in front of a gradient, BODY_25-like keypoints inside it) for tests and benchmarks that
  need no data on disk.

:func:`person_box` turns detections into the person box (its callers' default margin,
:func:`box_margin` -> :func:`network_box_margin`, frames the person as the training crops did)
and :func:`crop_input` turns the image and the box into the normalised ``(1, 3, S, S)`` crop
and ``P (1, 3)``, the same preprocessing as the still-frame training samples
(aspect-preserving, black padding), formed in the network's
virtual camera (``geometry.virtual_crop``): any camera gives the input a training camera
(:func:`network_camera`, f = 1475 px at 1920x1080) would give, and the predicted translation is
in the real camera's frame.
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
    "person_box",
    "crop_input",
    "network_camera",
    "network_box_margin",
    "box_margin",
    "IMAGENET_MEAN",
    "IMAGENET_STD",
]

IMAGENET_MEAN = np.array([0.485, 0.456, 0.406], np.float32)
IMAGENET_STD = np.array([0.229, 0.224, 0.225], np.float32)


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
    """One view of an ``airpose_lib.data`` :class:`~airpose_lib.data.official_layout.Sequence`
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
        # lazy, as data.scene below: ~0.2 s each of a drone's start-up, which a synthetic source skips
        from airpose_lib.data.official_layout import load_sequence

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
    sequence folder in the official layout (``airpose_lib.data.official_layout.load_sequence``).

    Returns an object with ``num_views``, ``fps`` and ``view(v) -> ViewSource``.
    """
    if spec.startswith("synthetic"):
        return _parse_synthetic(spec)
    return _SequenceSource(spec, detector)


# -- detections -> box -> network input ----------------------------------------------------
def person_box(keypoints: np.ndarray | None, image_size: tuple[int, int], min_confidence: float = 0.2,
               margin_px: float = 20.0, min_points: int = 4) -> np.ndarray | None:
    """The person box from 2D detections.

    Args:
        keypoints: ``(J, 3)`` ``[x, y, confidence]`` (BODY_25 or COCO), full-frame pixels, or None.
        image_size: ``(W, H)``.
        min_confidence: keypoints below it are ignored.
        margin_px: added on every side (the synthetic data's boxes are the joints +/- 20 px).
        min_points: fewer confident keypoints = no detection.

    Returns:
        ``(4,)`` ``[x0, y0, x1, y1]`` clipped to the image, or None.
    """
    if keypoints is None:
        return None
    kp = np.asarray(keypoints, np.float64).reshape(-1, 3)
    ok = (kp[:, 2] >= min_confidence) & np.isfinite(kp[:, :2]).all(1)
    if ok.sum() < min_points:
        return None
    W, H = image_size
    x0, y0 = kp[ok, :2].min(0) - margin_px
    x1, y1 = kp[ok, :2].max(0) + margin_px
    box = np.array([max(x0, 0.0), max(y0, 0.0), min(x1, W - 1.0), min(y1, H - 1.0)])
    if box[2] - box[0] < 2 or box[3] - box[1] < 2:
        return None
    return box


def network_camera() -> np.ndarray:
    """``(3, 3)`` intrinsics of the camera every kit and official network is trained with: the
    still-frame data's (``data.scene.SceneConfig``: f = 1475 px, 1920x1080, principal point at
    the image centre). A checkpoint records its own (``model.record``, ``camera_K``)."""
    from airpose_lib.data.scene import SceneConfig  # lazy: see _SequenceSource

    return SceneConfig().K


def network_box_margin(K: np.ndarray, K_net: np.ndarray | None = None) -> float:
    """The person-box margin, in pixels of an image with intrinsics ``K (3, 3)``, that frames the
    person as the training crops do on average.

    A training box is the joints +- ``bbox_margin_px`` with each side moved out by
    ``U(0, bbox_jitter_px)`` (``data.scene.SceneConfig``: 20 + U(0, 200) px at f = 1475, as
    ``copenet/dsets/aerialpeople.py`` for both of its splits): 120 px on average in the network
    camera. A box much tighter than that puts the crop scale s of P outside the training range
    (Table I's tight-box column: AirPose MPJPE 0.143 vs 0.106 m on the same samples). The
    official real-data loader (``copenet_real/dsets/copenet_real.py``) uses OpenPose +- 50 px at
    1920x1080 and then fine-tunes on those crops; pass that as an explicit margin to follow it.

    Args:
        K: ``(3, 3)`` intrinsics of the image the box is drawn in.
        K_net: ``(3, 3)`` the network's camera (default :func:`network_camera`).

    Returns:
        the margin in the image's pixels: 120 px scaled by ``f / f_net`` (mean of fx and fy), the
        same margin in the virtual camera whatever the image's resolution.
    """
    from airpose_lib.data.scene import SceneConfig  # lazy: see _SequenceSource

    sc = SceneConfig()
    K = np.asarray(K, np.float64)
    K_net = np.asarray(network_camera() if K_net is None else K_net, np.float64)
    f_ratio = (K[0, 0] + K[1, 1]) / (K_net[0, 0] + K_net[1, 1])
    return float((sc.bbox_margin_px + sc.bbox_jitter_px / 2.0) * f_ratio)


def box_margin(margin_px: float | None, K: np.ndarray, K_net: np.ndarray | None = None) -> float:
    """The person-box margin to use in an image with intrinsics ``K (3, 3)``: ``margin_px`` when
    given, else :func:`network_box_margin` (the default of the drones, the offline inputs and the
    recordings' predictions)."""
    return network_box_margin(K, K_net) if margin_px is None else float(margin_px)


def crop_input(image: np.ndarray, bbox: np.ndarray, K: np.ndarray, input_size: int,
               K_net: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The network input of one view.

    Args:
        image: ``(H, W, 3)`` uint8 RGB full frame.
        bbox: ``(4,)`` ``[x0, y0, x1, y1]`` full-frame pixels.
        K: ``(3, 3)`` full-frame intrinsics of ``image``.
        input_size: S.
        K_net: ``(3, 3)`` intrinsics the network was trained with (default :func:`network_camera`).

    Returns:
        ``crop (1, 3, S, S)`` float32 (RGB/255, ImageNet mean/std) and ``P (1, 3)`` float32, both
        formed in the virtual camera ``K_net`` (``geometry.virtual_crop``; convert a weak camera
        to a translation with ``K_net``). The box is resized keeping its aspect ratio into the
        centre of the S x S square and everything outside the box is black, by the rule of the
        training crops (``geometry.pad_outside_box``): the same box gives the same array.

    Raises:
        ValueError: the box is empty or entirely outside the image (the crop would be black).
    """
    # lazy, both (geometry imports torch): a drone's start-up imports this module and must stay
    # free of torch
    import torch

    from airpose_lib.geometry import crop_from_image, virtual_box, virtual_crop

    H, W = image.shape[:2]
    x0, y0, x1, y1 = (float(v) for v in np.asarray(bbox, np.float64).reshape(4))
    if not (x0 < W and y0 < H and x1 > 0 and y1 > 0 and x1 > x0 and y1 > y0):  # nothing of the image in it
        raise ValueError(f"person box [{x0:.1f}, {y0:.1f}, {x1:.1f}, {y1:.1f}] does not overlap the "
                         f"{W}x{H} image (or is empty); check the detections or the box margin")
    box_t = torch.as_tensor(np.asarray(bbox, np.float64))
    K_t = torch.as_tensor(np.asarray(K, np.float64))
    K_net_t = torch.as_tensor(np.asarray(network_camera() if K_net is None else K_net, np.float64))
    A, P = virtual_crop(box_t, K_t, K_net_t, input_size)
    # The box is blacked out where the virtual camera sees it, by the training crops' rule.
    box_v, _ = virtual_box(box_t, K_t, K_net_t)
    out = crop_from_image(image, A.numpy(), box_v.numpy(), input_size)
    x = (out.astype(np.float32) / 255.0 - IMAGENET_MEAN) / IMAGENET_STD
    return np.ascontiguousarray(x.transpose(2, 0, 1)[None]), P.numpy().astype(np.float32)[None]
