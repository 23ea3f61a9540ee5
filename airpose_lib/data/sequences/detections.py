"""Simulated 2D keypoint detectors: an OpenPose-like BODY_25 and an AlphaPose-like COCO-18 source.

The paper fine-tunes on OpenPose keypoints, drops joints where OpenPose and AlphaPose disagree by
more than 100 px, and fits AirPose+ to both. On generated sequences the kit needs two
*independent* keypoint sources that fail like real detectors. Each :class:`DetectorModel` turns
the projected ground-truth keypoints into detections by the documented model below; every
random draw comes from one ``numpy.random.Generator`` seeded by the caller (same seed, same
detections), in a fixed order.

Detector model (per frame f, view v, keypoint j; ``s`` = apparent person size in pixels = the
larger side of the tight box of the projected joints, ``k_j`` = per-keypoint difficulty
:data:`JOINT_DIFFICULTY`):

1. **Localisation noise**: Gaussian per coordinate with std
   ``sigma_j = k_j (sigma_px + sigma_rel * s)`` pixels, temporally correlated as AR(1) over frames
   (``temporal_corr``; the marginal std stays ``sigma_j``). Relative to the person's size the
   error ``sigma_j / s = k_j (sigma_rel + sigma_px / s)`` grows like ``1 / apparent size``, i.e.
   with distance (and so does its metric size at the person, ``sigma_j * depth / f``): a detector
   sees a far person with fewer pixels.
2. **Outliers**: with probability ``outlier_rate * k_j`` a keypoint lands anywhere within
   ``+- 0.3 s`` of its true position (a limb confused with the background or another limb).
3. **Left/right swaps**: per frame and view, with probability ``swap_rate`` every left/right pair
   is exchanged (the whole person read mirrored, typical for back views), else with probability
   ``limb_swap_rate`` only the arms or only the legs are exchanged. Swapped keypoints keep the
   confidence of their own location: detectors are confidently wrong on swaps.
4. **A limb on a background object**: per frame and view, with probability
   ``background_limb_rate`` one limb (an arm: shoulder-elbow-wrist, or a leg: hip-knee-ankle and
   the foot points; chosen uniformly) is read on something else in the scene: the whole chain
   moves rigidly by ``U(background_shift) x s`` pixels in a uniform direction, with the confidence
   of a well-localised keypoint (detectors are confidently wrong on these too).
5. **Misses**: keypoints outside the image or behind the camera are missed; any other keypoint is
   missed with probability ``min(0.5, miss_rate * k_j * miss_size_ref / s)`` (more for small
   persons); with probability ``frame_miss_rate`` the person is not found at all in a frame.
6. **Confidence**: ``conf = conf_max * exp(-0.5 (e / (conf_err_frac * s + 1))^2) + N(0, conf_noise)``
   clipped to [0.05, 1] from the realised error ``e`` (px) of a detected keypoint (for swapped ones
   the error of the unswapped location), so confidence falls as the error grows.

Rates (:data:`OPENPOSE`, :data:`ALPHAPOSE`; per frame and view unless said otherwise). They are
the kit's assumptions, not measurements: chosen so that every failure the paper names (left/right
swaps, "errors in keypoint detection ... common with 2D detectors") occurs several times in a
30 s recording, and the two detectors fail independently (their own random streams), which is
what the paper's two-detector filter relies on:

=========================  ========  =========  =====================================================
failure                    OpenPose  AlphaPose  disagreement it causes
=========================  ========  =========  =====================================================
whole-body left/right swap 3 %       2 %        every L/R pair; above the 100 px threshold only for
                                                limbs far apart (arms spread, legs in a stride)
arms-only or legs-only     5 %       3 %        one limb pair
swap
limb on a background       2 %       1 %        0.5-1.5 person sizes: almost always above 100 px
object
person missed              2 %       1 %        none (no target; the box is the previous frame's)
outlier keypoint           1 % k_j   0.6 % k_j  within 0.3 person sizes
=========================  ========  =========  =====================================================

The filter's effect on a recording is in :func:`airpose_lib.finetune.keypoints.agreement_summary`
(fine-tuning reports it); :func:`detection_summary` counts the simulated failures.

Conventions: keypoints are ``(F, V, J, 3)`` float64 ``[x, y, confidence]`` in pixels of the image
the detector saw; a missed keypoint is ``(0, 0, 0)`` exactly as OpenPose writes it (never NaN).
Inputs may contain NaN (e.g. a point behind the camera): such keypoints are treated as missed.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from airpose_lib.body.joint_sets import BODY_25_NAMES, COCO18_NAMES, left_right_permutation
from airpose_lib.errors import ConfigError

__all__ = [
    "KEYPOINT_SETS",
    "JOINT_DIFFICULTY",
    "DetectorModel",
    "Detections",
    "OPENPOSE",
    "ALPHAPOSE",
    "DEFAULT_DETECTORS",
    "detect_keypoints",
    "simulate_detections",
    "detection_summary",
    "DETECTOR_VERSION",
]

#: Bumped whenever the same ground truth and seed would give different detections (the recordings'
#: detector files are then re-simulated without re-rendering, ``data.sequences.ensure_sequences``).
DETECTOR_VERSION = 2

KEYPOINT_SETS: dict[str, tuple[str, ...]] = {"body25": BODY_25_NAMES, "coco18": COCO18_NAMES}
"""Keypoint names of each layout (OpenPose BODY_25; OpenPose-style COCO-18 as AlphaPose writes)."""

JOINT_DIFFICULTY: dict[str, float] = {
    "Nose": 0.8, "REye": 0.7, "LEye": 0.7, "REar": 0.9, "LEar": 0.9, "Neck": 1.0,
    "RShoulder": 1.0, "LShoulder": 1.0, "RElbow": 1.2, "LElbow": 1.2, "RWrist": 1.5,
    "LWrist": 1.5, "MidHip": 1.3, "RHip": 1.5, "LHip": 1.5, "RKnee": 1.2, "LKnee": 1.2,
    "RAnkle": 1.3, "LAnkle": 1.3, "LBigToe": 1.5, "LSmallToe": 1.6, "LHeel": 1.5,
    "RBigToe": 1.5, "RSmallToe": 1.6, "RHeel": 1.5,
}
"""Relative difficulty ``k_j`` of each keypoint: scales its noise, outlier and miss rates (hips
are ill-defined under clothes, wrists and feet are small and fast, the face is easy)."""

_ARMS = ("Shoulder", "Elbow", "Wrist")
_LEGS = ("Hip", "Knee", "Ankle", "BigToe", "SmallToe", "Heel")
#: The chains a background object can take over: (side, parts).
_LIMBS = (("L", _ARMS), ("R", _ARMS), ("L", _LEGS), ("R", _LEGS))


def _limb_mask(names: Sequence[str], side: str, parts: Sequence[str]) -> np.ndarray:
    """(J,) bool: the keypoints of one limb (e.g. ``LShoulder, LElbow, LWrist``)."""
    return np.array([len(n) > 1 and n[0] == side and n[1:] in parts for n in names])


@dataclass(frozen=True)
class DetectorModel:
    """Parameters of one simulated detector (see the module doc for the model).

    Attributes:
        name: ``openpose`` / ``alphapose`` (the official files' names).
        keypoints: ``body25`` or ``coco18``.
        sigma_px: constant part of the localisation std, pixels.
        sigma_rel: part of the std proportional to the apparent person size.
        temporal_corr: AR(1) correlation of the noise between consecutive frames, in [0, 1).
        outlier_rate: per-keypoint outlier probability (times ``k_j``).
        swap_rate: per frame/view probability of a whole-body left/right swap.
        limb_swap_rate: per frame/view probability of an arms-only or legs-only swap.
        background_limb_rate: per frame/view probability that one limb lies on a background object.
        background_shift: ``(min, max)`` displacement of that limb, in person sizes.
        miss_rate: per-keypoint miss probability at ``miss_size_ref`` (times ``k_j``).
        miss_size_ref: person size (px) at which ``miss_rate`` applies.
        frame_miss_rate: probability that the person is not detected in a frame.
        conf_max, conf_err_frac, conf_noise: confidence model.
    """

    name: str
    keypoints: str = "body25"
    sigma_px: float = 1.5
    sigma_rel: float = 0.012
    temporal_corr: float = 0.5
    outlier_rate: float = 0.01
    swap_rate: float = 0.03
    limb_swap_rate: float = 0.05
    background_limb_rate: float = 0.02
    background_shift: tuple[float, float] = (0.5, 1.5)
    miss_rate: float = 0.03
    miss_size_ref: float = 200.0
    frame_miss_rate: float = 0.02
    conf_max: float = 0.92
    conf_err_frac: float = 0.04
    conf_noise: float = 0.05

    def __post_init__(self) -> None:
        if self.keypoints not in KEYPOINT_SETS:
            raise ConfigError(f"keypoints must be one of {tuple(KEYPOINT_SETS)}, got {self.keypoints!r}")
        if not 0 <= self.temporal_corr < 1:
            raise ConfigError("temporal_corr must be in [0, 1)")
        lo, hi = self.background_shift
        if not 0 <= lo <= hi:
            raise ConfigError(f"background_shift must be (min, max) with 0 <= min <= max, got {self.background_shift}")
        for k in ("outlier_rate", "swap_rate", "limb_swap_rate", "background_limb_rate", "miss_rate",
                  "frame_miss_rate"):
            if not 0 <= getattr(self, k) <= 1:
                raise ConfigError(f"{k} must be a probability, got {getattr(self, k)}")

    @property
    def names(self) -> tuple[str, ...]:
        return KEYPOINT_SETS[self.keypoints]

    @property
    def difficulty(self) -> np.ndarray:
        """(J,) ``k_j`` of this detector's keypoints."""
        return np.array([JOINT_DIFFICULTY[n] for n in self.names])

    def sigma(self, size_px: np.ndarray) -> np.ndarray:
        """Noise std (..., J) pixels for apparent person sizes ``size_px`` (...,)."""
        s = np.asarray(size_px, dtype=np.float64)[..., None]
        return self.difficulty * (self.sigma_px + self.sigma_rel * s)

    def miss_probability(self, size_px: np.ndarray) -> np.ndarray:
        """Per-keypoint miss probability (..., J) of an in-frame keypoint."""
        s = np.maximum(np.asarray(size_px, dtype=np.float64)[..., None], 1.0)
        return np.minimum(0.5, self.miss_rate * self.difficulty * self.miss_size_ref / s)


OPENPOSE = DetectorModel("openpose", "body25")
"""OpenPose-like BODY_25: noisier, more misses and swaps, strongly correlated in time."""
ALPHAPOSE = DetectorModel("alphapose", "coco18", sigma_px=1.0, sigma_rel=0.010, temporal_corr=0.3,
                          outlier_rate=0.006, swap_rate=0.02, limb_swap_rate=0.03, background_limb_rate=0.01,
                          miss_rate=0.015, frame_miss_rate=0.01, conf_max=0.88)
"""AlphaPose-like COCO-18: a little more precise and fewer misses, its own error stream."""
DEFAULT_DETECTORS: dict[str, DetectorModel] = {"openpose": OPENPOSE, "alphapose": ALPHAPOSE}


@dataclass
class Detections:
    """Output of one simulated detector.

    Attributes:
        keypoints: (F, V, J, 3) ``[x, y, conf]``; missed keypoints are ``(0, 0, 0)``.
        names: the J keypoint names.
        detector: the model that made them.
        sigma_px: (F, V, J) localisation std used.
        missed: (F, V, J) bool.
        outlier: (F, V, J) bool.
        swap: (F, V) int8: 0 none, 1 whole body, 2 arms, 3 legs.
        frame_missed: (F, V) bool: nobody detected.
        background: (F, V, J) bool: the keypoint lies on a background object (a moved limb).
    """

    keypoints: np.ndarray
    names: tuple[str, ...]
    detector: DetectorModel
    sigma_px: np.ndarray
    missed: np.ndarray
    outlier: np.ndarray
    swap: np.ndarray
    frame_missed: np.ndarray
    background: np.ndarray | None = None


def detect_keypoints(kp2d: np.ndarray, size_px: np.ndarray, image_size: np.ndarray,
                     model: DetectorModel, rng: np.random.Generator,
                     depth: np.ndarray | None = None, frame_step: float = 1.0) -> Detections:
    """Simulate a detector on projected ground-truth keypoints.

    Args:
        kp2d: (F, V, J, 2) true keypoint pixels (J = the model's layout); NaN allowed.
        size_px: (F, V) apparent person size, pixels.
        image_size: (V, 2) or (2,) image (W, H) per view.
        model: the detector.
        rng: the random source.
        depth: (F, V, J) keypoint depth; ``<= 0`` (behind the camera) is missed. Optional.
        frame_step: video frames between consecutive rows of ``kp2d`` (a recording that keeps
            every k-th frame of its video: k); the noise's correlation from one row to the next
            is then ``temporal_corr ** frame_step``, that of k video frames.
    Returns:
        :class:`Detections`.
    """
    kp2d = np.asarray(kp2d, dtype=np.float64)
    F, V, J, _ = kp2d.shape
    if J != len(model.names):
        raise ValueError(f"{model.name}: {J} keypoints given, its {model.keypoints} layout has {len(model.names)}")
    size = np.nan_to_num(np.asarray(size_px, dtype=np.float64).reshape(F, V), nan=1.0)
    size = np.maximum(size, 1.0)
    wh = np.broadcast_to(np.asarray(image_size, dtype=np.float64).reshape(-1, 2), (V, 2))
    sigma = model.sigma(size)  # (F, V, J)
    k = model.difficulty

    # 1. AR(1) noise over frames, marginal N(0, 1) per coordinate before scaling.
    rho = model.temporal_corr ** float(frame_step)
    white = rng.standard_normal((F, V, J, 2))
    noise = np.empty_like(white)
    noise[0] = white[0]
    c = np.sqrt(1.0 - rho * rho)
    for f in range(1, F):
        noise[f] = rho * noise[f - 1] + c * white[f]
    det = kp2d + noise * sigma[..., None]
    # 2. outliers
    outlier = rng.random((F, V, J)) < np.minimum(1.0, model.outlier_rate * k)
    jump = rng.uniform(-0.3, 0.3, (F, V, J, 2)) * size[..., None, None]
    det = np.where(outlier[..., None], kp2d + jump, det)
    err = np.linalg.norm(det - kp2d, axis=-1)  # error of each location before any swap
    # 6. confidence from the error of the location itself
    conf = model.conf_max * np.exp(-0.5 * (err / (model.conf_err_frac * size[..., None] + 1.0)) ** 2)
    conf = np.clip(conf + model.conf_noise * rng.standard_normal((F, V, J)), 0.05, 1.0)
    # 3. swaps: the labels of left/right pairs are exchanged (locations keep their confidence)
    u = rng.random((F, V))
    limb = rng.random((F, V)) < 0.5
    swap = np.zeros((F, V), dtype=np.int8)
    swap[u < model.swap_rate] = 1
    part = (u >= model.swap_rate) & (u < model.swap_rate + model.limb_swap_rate)
    swap[part & limb] = 2
    swap[part & ~limb] = 3
    perms = {1: left_right_permutation(model.names), 2: left_right_permutation(model.names, _ARMS),
             3: left_right_permutation(model.names, _LEGS)}
    for code, perm in perms.items():
        m = swap == code
        det[m] = det[m][:, perm]
        conf[m] = conf[m][:, perm]
    # 4. a limb on a background object: drawn after the swaps (it moves whatever the labels say)
    hit = rng.random((F, V)) < model.background_limb_rate
    which = rng.integers(0, len(_LIMBS), (F, V))
    lo, hi = model.background_shift
    dist = rng.uniform(lo, hi, (F, V)) * size
    ang = rng.uniform(0.0, 2.0 * np.pi, (F, V))
    bg_conf = model.conf_max * rng.uniform(0.6, 1.0, (F, V))
    limbs = np.stack([_limb_mask(model.names, side, parts) for side, parts in _LIMBS])  # (4, J)
    background = hit[..., None] & limbs[which]  # (F, V, J)
    shift = np.stack((np.cos(ang), np.sin(ang)), -1) * dist[..., None]  # (F, V, 2)
    det = np.where(background[..., None], det + shift[:, :, None, :], det)
    conf = np.where(background, bg_conf[..., None], conf)
    # 5. misses
    finite = np.isfinite(kp2d).all(-1)
    x, y = kp2d[..., 0], kp2d[..., 1]
    inside = finite & (x >= 0) & (y >= 0) & (x <= wh[None, :, None, 0] - 1) & (y <= wh[None, :, None, 1] - 1)
    if depth is not None:
        inside &= np.nan_to_num(np.asarray(depth, dtype=np.float64), nan=-1.0) > 0
    for code, perm in perms.items():  # a swapped label is missed where its source is
        m = swap == code
        inside[m] = inside[m][:, perm]
    missed = ~inside | (rng.random((F, V, J)) < model.miss_probability(size))
    frame_missed = rng.random((F, V)) < model.frame_miss_rate
    missed |= frame_missed[..., None]
    missed |= ~np.isfinite(det).all(-1)
    with np.errstate(invalid="ignore"):  # a detector reports nothing outside its image
        missed |= (det[..., 0] < 0) | (det[..., 1] < 0) | (det[..., 0] > wh[None, :, None, 0] - 1) \
            | (det[..., 1] > wh[None, :, None, 1] - 1)
    out = np.concatenate([det, conf[..., None]], -1)
    out[missed] = 0.0
    return Detections(out, model.names, model, sigma, missed, outlier & ~missed, swap, frame_missed,
                      background & ~missed)


def simulate_detections(gt: Mapping[str, np.ndarray], model: DetectorModel,
                        seed: int | Sequence[int] = 0, frame_step: float = 1.0) -> Detections:
    """Run a simulated detector on a sequence's ground truth.

    Args:
        gt: ground-truth arrays of :func:`airpose_lib.data.sequences.simulate_sequence`
            (``kp2d_<layout>``, ``kp_depth_<layout>``, ``person_size_px``, ``image_size``).
        model: the detector.
        seed: seed (or seed sequence) of its random stream.
        frame_step: video frames from one recorded frame to the next (:func:`detect_keypoints`).
    """
    rng = np.random.default_rng(seed)
    return detect_keypoints(gt[f"kp2d_{model.keypoints}"], gt["person_size_px"], gt["image_size"],
                            model, rng, depth=gt.get(f"kp_depth_{model.keypoints}"), frame_step=frame_step)


def detection_summary(det: Detections) -> dict[str, int]:
    """Counts of the simulated failures (for ``sequence.json`` and reports): frame/view pairs with
    a whole-body swap, a one-limb swap, a limb on the background, nobody detected; keypoints that
    are outliers, on the background, missed; and the detected keypoints."""
    bg = det.background if det.background is not None else np.zeros_like(det.missed)
    return {"views": int(det.swap.size), "whole_body_swaps": int((det.swap == 1).sum()),
            "limb_swaps": int(((det.swap == 2) | (det.swap == 3)).sum()),
            "background_limbs": int(bg.any(-1).sum()), "persons_missed": int(det.frame_missed.sum()),
            "outlier_keypoints": int(det.outlier.sum()), "background_keypoints": int(bg.sum()),
            "missed_keypoints": int(det.missed.sum()), "detected_keypoints": int((~det.missed).sum())}
