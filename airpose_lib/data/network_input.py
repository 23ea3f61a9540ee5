"""How a camera frame becomes the network's input: person box, margin, network camera, crop,
normalisation, and the previous-box rule.

This is the one home of the input rule shared by the drones (``runtime``: a live camera and the
offline reference) and the recordings' predictions (``finetune.predict``), so both see the same
crops:

* :func:`person_box` turns one frame's 2D detections into the person box; its callers' default
  margin (:func:`box_margin` -> :func:`network_box_margin`) frames the person as the training
  crops did.
* :func:`hold_boxes` / :func:`keep_previous_box` are the one "no detection: keep the previous
  box" rule, with one documented choice for the frames before the first detection (``leading``).
* :func:`crop_input` turns the image and the box into the normalised ``(1, 3, S, S)`` crop and
  ``P (1, 3)``, the same preprocessing as the still-frame training samples (aspect-preserving,
  black padding), formed in the network's virtual camera (``geometry.virtual_crop``): any camera
  gives the input a training camera (:func:`network_camera`, f = 1475 px at 1920x1080) would
  give, and the predicted translation is in the real camera's frame.
* :func:`normalize` is the ImageNet normalisation of both the crops and the training samples
  (``data.still.dataset.normalize_images``).

No torch at import: a drone's start-up imports this module (``crop_input`` imports it when
called).
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = [
    "IMAGENET_MEAN",
    "IMAGENET_STD",
    "LEADING",
    "normalize",
    "person_box",
    "keep_previous_box",
    "hold_boxes",
    "NETWORK_IMAGE_SIZE",
    "NETWORK_FOCAL",
    "BOX_MARGIN_PX",
    "BOX_JITTER_PX",
    "full_frame_intrinsics",
    "network_camera",
    "network_box_margin",
    "box_margin",
    "crop_input",
]

IMAGENET_MEAN = np.array([0.485, 0.456, 0.406], np.float32)
IMAGENET_STD = np.array([0.229, 0.224, 0.225], np.float32)


def normalize(rgb: np.ndarray) -> np.ndarray:
    """``(..., S, S, 3)`` uint8 RGB -> ``(..., 3, S, S)`` float32: /255, then ImageNet mean/std
    (in float32, so the crops and the training samples get the same bits)."""
    x = (np.asarray(rgb).astype(np.float32) / 255.0 - IMAGENET_MEAN) / IMAGENET_STD
    return np.ascontiguousarray(np.moveaxis(x, -1, -3))


# -- detections -> box ----------------------------------------------------------------------
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


# -- the previous-box rule --------------------------------------------------------------------
def keep_previous_box(box: np.ndarray | None, previous: np.ndarray | None) -> np.ndarray | None:
    """No detection: keep the previous box. ``box``, ``previous``: ``(4,)`` or None; returns
    ``box`` when there is one, else ``previous`` (None before the first detection). A live camera
    (``runtime.camera``) applies it frame by frame and cannot look ahead, so its leading frames
    have no box (:func:`hold_boxes` with ``leading="none"``)."""
    return previous if box is None else box


#: what :func:`hold_boxes` does with the frames before a view's first detection
LEADING = ("first", "none")


def hold_boxes(detected: Sequence[np.ndarray | None], leading: str = "first") -> tuple[np.ndarray, np.ndarray]:
    """Person boxes of one view over a run of frames by the previous-box rule.

    A frame without a detection (None) takes the box of the closest earlier frame that has one
    (:func:`keep_previous_box`). The frames before the first detection:

    * ``"first"`` (default; offline only, it looks ahead): the view's first box. What the
      recordings' predictions use (``finetune.predict.detection_boxes``): every frame gets an
      output, flagged not valid.
    * ``"none"``: no box (NaN rows), what a live camera does (it skips them); also
      ``runtime.offline_inputs`` without boxes, which refuses such a frame (the offline
      reference does not invent a crop no drone made).

    A view with no detection at all: NaN boxes with either (the callers check ``valid.any()``).

    Args:
        detected: ``F`` entries, each a ``(4,)`` ``[x0, y0, x1, y1]`` box or None.
        leading: ``"first"`` or ``"none"``.

    Returns:
        ``boxes (F, 4)`` float64 and ``valid (F,)`` bool (True: the frame's own detection).
    """
    if leading not in LEADING:
        raise ValueError(f"leading must be one of {LEADING}, got {leading!r}")
    F = len(detected)
    boxes = np.full((F, 4), np.nan)
    valid = np.zeros(F, bool)
    last = None
    for f, box in enumerate(detected):
        valid[f] = box is not None
        last = keep_previous_box(box, last)
        if last is not None:
            boxes[f] = last
    if leading == "first" and valid.any():
        first = int(np.argmax(valid))
        boxes[:first] = boxes[first]
    return boxes, valid


# -- the network camera and the box margin ------------------------------------------------------
#: The camera every kit and official network is trained with, the still frames' default scene
#: (``data.still.scene.SceneConfig`` takes its defaults from here): ``(W, H)`` pixels and f in pixels.
NETWORK_IMAGE_SIZE: tuple[int, int] = (1920, 1080)
NETWORK_FOCAL = 1475.0
#: A training box: the joints +- ``BOX_MARGIN_PX``, each side moved out by ``U(0, BOX_JITTER_PX)``
#: pixels of the network camera (the paper: between the tight box and a 200 px margin).
BOX_MARGIN_PX = 20.0
BOX_JITTER_PX = 200.0


def full_frame_intrinsics(image_size: tuple[int, int], focal: float,
                          principal_point: tuple[float, float] | None = None) -> np.ndarray:
    """``K (3, 3)`` with ``fx = fy = focal`` and the principal point (default: the image centre)."""
    W, H = image_size
    cx, cy = principal_point if principal_point is not None else ((W - 1) / 2.0, (H - 1) / 2.0)
    return np.array([[focal, 0.0, cx], [0.0, focal, cy], [0.0, 0.0, 1.0]])


def network_camera() -> np.ndarray:
    """``(3, 3)`` intrinsics of the camera every kit and official network is trained with
    (:data:`NETWORK_IMAGE_SIZE`, :data:`NETWORK_FOCAL`, principal point at the image centre). A
    checkpoint records its own (``model.record``, ``camera_K``)."""
    return full_frame_intrinsics(NETWORK_IMAGE_SIZE, NETWORK_FOCAL)


def network_box_margin(K: np.ndarray, K_net: np.ndarray | None = None) -> float:
    """The person-box margin, in pixels of an image with intrinsics ``K (3, 3)``, that frames the
    person as the training crops do on average.

    A training box is the joints +- :data:`BOX_MARGIN_PX` with each side moved out by
    ``U(0,`` :data:`BOX_JITTER_PX` ``)`` (20 + U(0, 200) px at f = 1475, as
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
    K = np.asarray(K, np.float64)
    K_net = np.asarray(network_camera() if K_net is None else K_net, np.float64)
    f_ratio = (K[0, 0] + K[1, 1]) / (K_net[0, 0] + K_net[1, 1])
    return float((BOX_MARGIN_PX + BOX_JITTER_PX / 2.0) * f_ratio)


def box_margin(margin_px: float | None, K: np.ndarray, K_net: np.ndarray | None = None) -> float:
    """The person-box margin to use in an image with intrinsics ``K (3, 3)``: ``margin_px`` when
    given, else :func:`network_box_margin` (the default of the drones, the offline inputs and the
    recordings' predictions)."""
    return network_box_margin(K, K_net) if margin_px is None else float(margin_px)


# -- box -> crop ------------------------------------------------------------------------------
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
        ``crop (1, 3, S, S)`` float32 (:func:`normalize`) and ``P (1, 3)`` float32, both
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
    return normalize(out)[None], P.numpy().astype(np.float32)[None]
