r"""2D targets for fine-tuning: OpenPose keypoints that a second detector (AlphaPose) confirms.

The paper fine-tunes on OpenPose BODY_25 keypoints weighted by their confidence and drops a
joint "when OpenPose and AlphaPose disagree by more than 100 px". :func:`agreement_targets`
turns both detectors' output into the targets of the 2D loss: ``(F, V, 25, 3)`` ``[x, y, w]``
on the BODY_25 joints, full-image pixels, ``w`` = OpenPose confidence or 0.

Correspondence BODY_25 <-> COCO-18 (AlphaPose writes OpenPose's COCO-18 layout), matched by the
keypoint names of :mod:`airpose_lib.body.joint_sets` (:data:`BODY25_FROM_COCO18`):

=============================  ==============  =============================================
BODY_25 (index name)           COCO-18 index   note
=============================  ==============  =============================================
0 Nose, 1 Neck                 0, 1            AlphaPose derives its neck from the shoulders
2-4 RShoulder, RElbow, RWrist   2-4
5-7 LShoulder, LElbow, LWrist   5-7
8 MidHip                       --              no COCO counterpart
9-11 RHip, RKnee, RAnkle       8-10
12-14 LHip, LKnee, LAnkle      11-13
15-18 REye, LEye, REar, LEar   14-17
19-24 toes and heels           --              no COCO counterpart
=============================  ==============  =============================================

Rules, per frame, view and BODY_25 joint (``w = 0`` means the joint does not supervise):

1. OpenPose must see it: ``x, y, c`` finite and ``c >= min_confidence`` (OpenPose writes a
   missed joint as ``(0, 0, 0)``; its own renderer hides body joints below 0.05, the default);
2. a joint with a COCO-18 counterpart is kept only if AlphaPose also sees it (finite, ``c > 0``)
   within ``threshold_px`` (Euclidean distance; exactly ``threshold_px`` is kept). A joint AlphaPose
   misses is *unconfirmed* and dropped: the paper's check can only vouch for joints both detectors
   report, and the official code behaves the same way (it measures the distance to AlphaPose's
   ``(0, 0)`` placeholder, which exceeds 100 px);
3. the 7 joints COCO-18 lacks (MidHip, toes, heels) can never be confirmed. ``unmatched="drop"``
   (default) drops them for the same reason and as the official code does (its AlphaPose array is
   zero there); ``unmatched="keep"`` keeps OpenPose's joint unchecked, which adds pelvis and foot
   evidence at the price of unfiltered outliers.

Pixel units: the paper's 100 px is a full-resolution (1920 px wide) value. ``threshold_px`` may
be one value or one per view; :func:`resolution_scales` and :func:`pixel_settings` derive the
values for images of another width (``threshold_px x r``, ``w_j2d / r^2`` for the squared-pixel
2D loss, ``r = width / 1920``).

NaN or inf anywhere in a keypoint counts as missing (the kit's loader already turns them into
zeros); dropped targets hold ``(0, 0, 0)`` so the arrays are always finite.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from airpose_lib.body.joint_sets import BODY_25_NAMES, COCO18_NAMES
from airpose_lib.errors import ConfigError

__all__ = [
    "BODY25_FROM_COCO18",
    "UNMATCHED_BODY25",
    "AgreementMasks",
    "agreement_masks",
    "agreement_targets",
    "agreement_summary",
    "kept_targets",
    "true_targets",
    "REFERENCE_WIDTH",
    "resolution_scales",
    "pixel_settings",
]

REFERENCE_WIDTH = 1920.0
"""Width (px) of the frames the paper's pixel quantities refer to (its real data: 1920x1080)."""


def resolution_scales(image_sizes, reference_width: float = REFERENCE_WIDTH) -> np.ndarray:
    """``(V,)`` ``r = width / reference_width`` of each view.

    Args:
        image_sizes: ``(W, H)`` per view (a sequence of pairs or a ``(V, 2)`` array).
        reference_width: the width the paper's values refer to.
    """
    wh = np.asarray(image_sizes, np.float64).reshape(-1, 2)
    if not (wh[:, 0] > 0).all() or not reference_width > 0:
        raise ValueError(f"image widths and reference_width must be positive, got {wh[:, 0].tolist()}, "
                         f"{reference_width}")
    return wh[:, 0] / float(reference_width)


def pixel_settings(scales: np.ndarray, threshold_px: float = 100.0, w_j2d: float = 0.01) -> dict:
    """The full-resolution pixel quantities at each view's resolution (for logs and provenance).

    Returns:
        ``scale (V,)``, ``threshold_px (V,)`` = threshold x r and ``w_j2d_per_px2 (V,)`` = w_j2d / r^2
        (the weight on squared pixels of the view's own image), as lists.
    """
    r = np.asarray(scales, np.float64).reshape(-1)
    return {"scale": r.tolist(), "threshold_px": (threshold_px * r).tolist(),
            "w_j2d_per_px2": (w_j2d / r ** 2).tolist(), "reference": {"threshold_px": threshold_px, "w_j2d": w_j2d}}

BODY25_FROM_COCO18: tuple[int, ...] = tuple(COCO18_NAMES.index(n) if n in COCO18_NAMES else -1
                                            for n in BODY_25_NAMES)
"""(25,) index of each BODY_25 keypoint in COCO-18 (-1: no counterpart), from the joint names."""
UNMATCHED_BODY25: tuple[int, ...] = tuple(j for j, k in enumerate(BODY25_FROM_COCO18) if k < 0)
"""BODY_25 keypoints without a COCO-18 counterpart: MidHip, the toes and the heels (8, 19-24)."""

_UNMATCHED_CHOICES = ("drop", "keep")


@dataclass(frozen=True)
class AgreementMasks:
    """Why each ``(F, V, 25)`` BODY_25 joint is kept or not (boolean arrays; exclusive reasons,
    in this order of precedence)."""

    missing: np.ndarray  # OpenPose does not report it (c <= 0 or NaN)
    low_confidence: np.ndarray  # reported, c < min_confidence
    unconfirmed: np.ndarray  # AlphaPose cannot confirm it (missed, or no counterpart with "drop")
    disagree: np.ndarray  # both see it, more than threshold_px apart
    kept: np.ndarray


def _check(openpose: np.ndarray, alphapose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    op = np.asarray(openpose, np.float64)
    ap = np.asarray(alphapose, np.float64)
    if op.ndim != 4 or op.shape[2:] != (25, 3):
        raise ValueError(f"openpose keypoints must be (F, V, 25, 3) [x, y, confidence] (BODY_25), got {op.shape}")
    if ap.ndim != 4 or ap.shape[2:] != (18, 3):
        raise ValueError(f"alphapose keypoints must be (F, V, 18, 3) [x, y, confidence] (COCO-18), got {ap.shape}")
    if op.shape[:2] != ap.shape[:2]:
        raise ValueError(f"the detectors disagree on (frames, views): openpose has {op.shape[:2]}, alphapose "
                         f"{ap.shape[:2]}; load both from the same sequence and frame selection")
    with np.errstate(invalid="ignore"):
        if (op[..., 2] < 0).any() or (ap[..., 2] < 0).any():
            raise ValueError("negative keypoint confidences: expected [x, y, confidence] with confidence in [0, 1]")
    return op, ap


def agreement_masks(openpose: np.ndarray, alphapose: np.ndarray, *, threshold_px=100.0,
                    min_confidence: float = 0.05, unmatched: str = "drop") -> AgreementMasks:
    """The per-joint decisions of :func:`agreement_targets` (same arguments)."""
    thr = np.asarray(threshold_px, np.float64)
    if not (thr > 0).all() or thr.ndim > 1:
        raise ConfigError(f"threshold_px must be positive (one value or one per view), got {threshold_px}")
    if unmatched not in _UNMATCHED_CHOICES:
        raise ConfigError(f"unmatched must be one of {_UNMATCHED_CHOICES}, got {unmatched!r}")
    op, ap = _check(openpose, alphapose)
    if thr.ndim == 1 and thr.shape[0] != op.shape[1]:
        raise ValueError(f"threshold_px has {thr.shape[0]} values for {op.shape[1]} views")
    thr = thr.reshape(-1, 1) if thr.ndim == 1 else thr  # (V, 1) broadcasts over (F, V, 25)
    op_ok = np.isfinite(op).all(-1)
    with np.errstate(invalid="ignore"):
        seen = op_ok & (op[..., 2] > 0)
        missing = ~seen
        low = seen & (op[..., 2] < min_confidence)
        candidate = seen & ~low
        idx = np.asarray(BODY25_FROM_COCO18)
        has_match = idx >= 0
        ap25 = ap[..., np.maximum(idx, 0), :]  # (F, V, 25, 3); unmatched columns are ignored
        ap_seen = np.isfinite(ap25).all(-1) & (ap25[..., 2] > 0) & has_match
        dist = np.linalg.norm(np.where(op_ok[..., None], op[..., :2], 0.0)
                              - np.where(ap_seen[..., None], ap25[..., :2], 0.0), axis=-1)
    if unmatched == "keep":
        confirmable = ap_seen | ~has_match  # no counterpart: nothing to check against
    else:
        confirmable = ap_seen
    unconfirmed = candidate & ~confirmable
    disagree = candidate & ap_seen & (dist > thr)
    kept = candidate & ~unconfirmed & ~disagree
    return AgreementMasks(missing=missing, low_confidence=low, unconfirmed=unconfirmed, disagree=disagree,
                          kept=kept)


def agreement_targets(openpose: np.ndarray, alphapose: np.ndarray, *, threshold_px=100.0,
                      min_confidence: float = 0.05, unmatched: str = "drop") -> np.ndarray:
    """2D targets of the fine-tuning loss from two detectors.

    Args:
        openpose: ``(F, V, 25, 3)`` BODY_25 ``[x, y, confidence]`` full-image pixels (missing = 0).
        alphapose: ``(F, V, 18, 3)`` COCO-18 ``[x, y, confidence]`` of the same frames and views.
        threshold_px: largest distance (pixels of the view's image) at which the detectors still
            agree: one value or ``(V,)`` (e.g. ``100 x resolution_scales(...)``).
        min_confidence: OpenPose joints below it are dropped.
        unmatched: ``"drop"`` (default) or ``"keep"`` the BODY_25 joints COCO-18 lacks.

    Returns:
        ``(F, V, 25, 3)`` float32 ``[x, y, w]``: OpenPose's position and confidence where kept,
        ``(0, 0, 0)`` elsewhere.

    Raises:
        ValueError: wrong shapes, frame/view counts that differ, negative confidences.
    """
    return kept_targets(openpose, agreement_masks(openpose, alphapose, threshold_px=threshold_px,
                                                  min_confidence=min_confidence, unmatched=unmatched))


def kept_targets(openpose: np.ndarray, masks: AgreementMasks) -> np.ndarray:
    """The targets of :func:`agreement_targets` from masks already computed (the filter once, its
    counts and its targets from the same :class:`AgreementMasks`).

    Args:
        openpose: ``(F, V, 25, 3)`` BODY_25 ``[x, y, confidence]``; masks: its
            :func:`agreement_masks`.

    Returns:
        ``(F, V, 25, 3)`` float32: OpenPose's ``[x, y, confidence]`` where kept, ``(0, 0, 0)`` elsewhere.
    """
    return np.where(masks.kept[..., None], np.asarray(openpose, np.float64), 0.0).astype(np.float32)


def true_targets(kp2d: np.ndarray, depth: np.ndarray, image_size: np.ndarray) -> np.ndarray:
    """2D targets from a recording's ground truth: what a perfect detector would report.

    A control for fine-tuning (``FineTuneConfig.targets="ground_truth"``): the same frames and
    crops as the detector targets, but targets without noise, swaps or misses, so a change in the
    test person's errors cannot come from the detectors.

    Args:
        kp2d: ``(F, V, 25, 2)`` projected BODY_25 keypoints (``ground_truth.npz`` ``kp2d_body25``).
        depth: ``(F, V, 25)`` their depth along the optical axis (``kp_depth_body25``), metres.
        image_size: ``(V, 2)`` width, height of each view's image.

    Returns:
        ``(F, V, 25, 3)`` float32 ``[x, y, w]``: ``w = 1`` for a keypoint in front of the camera and
        inside the image, else ``(0, 0, 0)`` (a detector cannot see it either).
    """
    kp = np.asarray(kp2d, np.float64)
    z = np.asarray(depth, np.float64)
    wh = np.asarray(image_size, np.float64).reshape(1, -1, 1, 2)
    if kp.ndim != 4 or kp.shape[-1] != 2 or z.shape != kp.shape[:-1] or wh.shape[1] != kp.shape[1]:
        raise ValueError(f"true_targets: kp2d (F, V, 25, 2), depth (F, V, 25) and image_size (V, 2) expected, "
                         f"got {kp.shape}, {z.shape}, {np.shape(image_size)}")
    seen = np.isfinite(kp).all(-1) & np.isfinite(z) & (z > 0) & ((kp >= 0) & (kp <= wh - 1)).all(-1)
    out = np.where(seen[..., None], np.concatenate([kp, np.ones_like(kp[..., :1])], -1), 0.0)
    return out.astype(np.float32)


def agreement_summary(masks: AgreementMasks) -> dict[str, int]:
    """Counts of joints per decision (for logs and provenance)."""
    return {name: int(getattr(masks, name).sum())
            for name in ("kept", "missing", "low_confidence", "unconfirmed", "disagree")}
