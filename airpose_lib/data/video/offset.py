"""The time offset between two videos of one person, from the body pose each view's network
reads frame by frame.

The body pose ``theta`` (21 joint rotations relative to their parents) is the same whichever side
a camera sees the person from, so the two views' pose tracks line up at the true offset. Each
track is smoothed over a few frames; the offset is the lag that maximises the mean over pose
entries of the Pearson correlation between the two tracks, and the next-best lag outside the peak
says how sure it is (periodic motion, such as walking, gives runners-up a step period away).
Sign: frame ``i`` of UAV1 shows the instant of frame ``i + offset`` of UAV2.

It needs a network that reads the pose well and several seconds of varied motion; how often it
lands within one frame on the kit's recordings is measured in docs/own_videos.md.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["OffsetEstimate", "pose_signal", "correlation_curve", "estimate_offset"]


@dataclass(frozen=True)
class OffsetEstimate:
    """Attributes:
        frames: the offset in frames (frame ``i`` of UAV1 is frame ``i + frames`` of UAV2).
        correlation: the mean correlation at that lag.
        runner_up: the best correlation more than ``peak_width`` lags away.
        runner_up_frames: its lag.
        overlap: frame pairs behind the peak's correlation.
        lags, curve: every lag tried and its correlation (NaN: too little overlap).
    """

    frames: int
    correlation: float
    runner_up: float
    runner_up_frames: int
    overlap: int
    lags: np.ndarray
    curve: np.ndarray

    @property
    def confident(self) -> bool:
        """A clear, single peak: correlation >= 0.3 and at least 0.1 above the runner-up."""
        return self.correlation >= 0.3 and not self.correlation - self.runner_up < 0.1


def pose_signal(theta: np.ndarray, valid: np.ndarray | None = None, smooth: int = 5) -> np.ndarray:
    """One view's pose track.

    Args:
        theta: ``(F, 21, 3, 3)`` body rotations per frame.
        valid: ``(F,)`` frames with a detection (others become NaN).
        smooth: frames of the centred moving mean (1: none).

    Returns:
        ``(F, 189)`` the rotation matrices' entries, smoothed; NaN where not valid.
    """
    x = np.asarray(theta, dtype=np.float64).reshape(len(theta), -1)
    if valid is not None:
        x = np.where(np.asarray(valid, dtype=bool)[:, None], x, np.nan)
    if smooth > 1:
        k = np.ones(smooth)
        ok = np.isfinite(x)
        num = np.apply_along_axis(lambda c: np.convolve(c, k, mode="same"), 0, np.where(ok, x, 0.0))
        den = np.apply_along_axis(lambda c: np.convolve(c, k, mode="same"), 0, ok.astype(np.float64))
        with np.errstate(invalid="ignore", divide="ignore"):
            x = np.where(ok, num / den, np.nan)
    return x


def _pearson(a: np.ndarray, b: np.ndarray, min_pairs: int) -> tuple[float, int]:
    """Mean over columns of the correlation of ``a`` and ``b`` on rows where both are finite."""
    rs, n_max = [], 0
    for j in range(a.shape[1]):
        m = np.isfinite(a[:, j]) & np.isfinite(b[:, j])
        n = int(m.sum())
        if n < min_pairs:
            continue
        x, y = a[m, j] - a[m, j].mean(), b[m, j] - b[m, j].mean()
        d = np.sqrt((x * x).sum() * (y * y).sum())
        if d > 0:
            rs.append(float((x * y).sum() / d))
            n_max = max(n_max, n)
    return (float(np.mean(rs)) if rs else float("nan")), n_max


def correlation_curve(s1: np.ndarray, s2: np.ndarray, lags: np.ndarray, min_pairs: int = 30
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Mean correlation of ``s1[i]`` with ``s2[i + lag]`` for each lag; ``(curve, pairs)``."""
    curve, pairs = np.full(len(lags), np.nan), np.zeros(len(lags), dtype=np.int64)
    F1, F2 = len(s1), len(s2)
    for n, d in enumerate(lags):
        i0, i1 = max(0, -d), min(F1, F2 - d)
        if i1 - i0 < min_pairs:
            continue
        curve[n], pairs[n] = _pearson(s1[i0:i1], s2[i0 + d:i1 + d], min_pairs)
    return curve, pairs


def estimate_offset(s1: np.ndarray, s2: np.ndarray, lag_range: tuple[int, int] | None = None, min_pairs: int = 30,
                    peak_width: int = 6) -> OffsetEstimate | None:
    """The offset between two views' tracks sampled at one rate.

    Args:
        s1, s2: ``(F1, D)`` and ``(F2, D)`` tracks of UAV1 and UAV2 (:func:`pose_signal`).
        lag_range: the smallest and largest lag tried (default: all that leave ``min_pairs`` pairs).
        min_pairs: fewest frame pairs a lag's correlation is computed on.
        peak_width: lags within this distance of the peak belong to it (the runner-up lies beyond).

    Returns:
        the estimate, or None when no lag has ``min_pairs`` frame pairs valid in both views.
    """
    lo, hi = -(len(s1) - min_pairs), len(s2) - min_pairs
    if lag_range is not None:
        lo, hi = max(lo, lag_range[0]), min(hi, lag_range[1])
    if hi < lo:
        return None
    lags = np.arange(lo, hi + 1)
    curve, pairs = correlation_curve(s1, s2, lags, min_pairs)
    if not np.isfinite(curve).any():
        return None
    k = int(np.nanargmax(curve))
    far = np.abs(lags - lags[k]) > peak_width
    rest = np.where(far & np.isfinite(curve), curve, -np.inf)
    j = int(np.argmax(rest)) if far.any() else k
    runner = float(rest[j]) if np.isfinite(rest[j]) else float("nan")
    return OffsetEstimate(int(lags[k]), float(curve[k]), runner, int(lags[j]), int(pairs[k]), lags, curve)
