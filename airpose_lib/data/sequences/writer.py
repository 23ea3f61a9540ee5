"""Writes a recording in the folder layout (:mod:`.layout`): frames, calibration, detector files
(:mod:`.detector_files`), time stamps, ground truth and settings."""
from __future__ import annotations

import json
from collections.abc import Mapping
from collections.abc import Sequence as SequenceABC
from pathlib import Path

import numpy as np

from airpose_lib import __version__  # the package root holds only the version
from airpose_lib.atomic import atomic_path

from .detector_files import write_detector_file
from .layout import DETECTOR_FILES, write_camera_calib

__all__ = ["OfficialLayoutWriter"]


class OfficialLayoutWriter:
    """Streams a sequence into the official layout.

    Example::

        w = OfficialLayoutWriter(root, num_views=2)
        for i, images in frames:            # images: [(H, W, 3) uint8 RGB per view]
            w.write_frame(i, images)
        w.finish(K, {"openpose": kp25, "alphapose": kp18}, timestamps, ground_truth, meta)

    Args:
        root: the sequence folder (created).
        num_views: number of machines.
        jpeg_quality: JPEG quality of the frames.
    """

    def __init__(self, root: str | Path, num_views: int, jpeg_quality: int = 92) -> None:
        self.root = Path(root)
        self.num_views = int(num_views)
        self.jpeg_quality = int(jpeg_quality)
        self.frames: list[int] = []
        self.image_sizes: list[tuple[int, int] | None] = [None] * self.num_views
        for v in range(self.num_views):
            (self.machine(v) / "images").mkdir(parents=True, exist_ok=True)

    def machine(self, view: int) -> Path:
        """Folder of view ``view`` (0-based): ``machine_{view + 1}``."""
        return self.root / f"machine_{view + 1}"

    def write_frame(self, index: int, images: SequenceABC[np.ndarray]) -> None:
        """Write one frame's images (RGB uint8 (H, W, 3), one per view)."""
        import cv2

        if len(images) != self.num_views:
            raise ValueError(f"frame {index}: {len(images)} images for {self.num_views} views")
        for v, img in enumerate(images):
            img = np.asarray(img)
            if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
                raise ValueError(f"frame {index} view {v}: expected (H, W, 3) uint8 RGB, got {img.shape} {img.dtype}")
            ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(img[..., ::-1]),
                                   [cv2.IMWRITE_JPEG_QUALITY, self.jpeg_quality])
            if not ok:
                raise RuntimeError(f"JPEG encoding failed for frame {index} view {v}")
            with atomic_path(self.machine(v) / "images" / f"{int(index):06d}.jpg") as tmp:
                tmp.write_bytes(buf.tobytes())
            self.image_sizes[v] = (img.shape[1], img.shape[0])
        self.frames.append(int(index))

    def finish(self, K: np.ndarray, keypoints: Mapping[str, np.ndarray], timestamps: np.ndarray | None = None,
               ground_truth: Mapping[str, np.ndarray] | None = None, meta: Mapping | None = None,
               frames: SequenceABC[int] | None = None) -> None:
        """Write calibration, detector files, time stamps, ground truth and metadata.

        Args:
            K: (V, 3, 3) intrinsics of the stored images.
            keypoints: detector name (``openpose`` / ``alphapose``) -> (F, V, J, 3) ``[x, y, c]``;
                a frame whose keypoints are all zero is written as "nobody detected".
            timestamps: (F, V) seconds, or None.
            ground_truth: arrays for ``ground_truth.npz``, or None.
            meta: JSON-able settings for ``sequence.json``.
            frames: the F frame indices (default: the frames written, in order).
        """
        frames = list(self.frames if frames is None else frames)
        F = len(frames)
        K = np.asarray(K, dtype=np.float64)
        if K.shape != (self.num_views, 3, 3):
            raise ValueError(f"K must be ({self.num_views}, 3, 3), got {K.shape}")
        for v in range(self.num_views):
            write_camera_calib(self.machine(v) / "camera_calib.yml", K[v], self.image_sizes[v])
        for name, kp in keypoints.items():
            if name not in DETECTOR_FILES:
                raise ValueError(f"unknown detector {name!r}; known: {tuple(DETECTOR_FILES)}")
            kp = np.asarray(kp, dtype=np.float64)
            J = DETECTOR_FILES[name][1]
            if kp.shape != (F, self.num_views, J, 3):
                raise ValueError(f"{name} keypoints must be ({F}, {self.num_views}, {J}, 3), got {kp.shape}")
            for v in range(self.num_views):
                write_detector_file(name, self.machine(v) / DETECTOR_FILES[name][0], frames, kp[:, v])
        if timestamps is not None:
            ts = np.asarray(timestamps, dtype=np.float64)
            if ts.shape != (F, self.num_views):
                raise ValueError(f"timestamps must be ({F}, {self.num_views}), got {ts.shape}")
            for v in range(self.num_views):
                lines = ["frame,timestamp"] + [f"{i},{t:.9f}" for i, t in zip(frames, ts[:, v])]
                with atomic_path(self.machine(v) / "timestamps.csv") as tmp:
                    tmp.write_bytes(("\n".join(lines) + "\n").encode())
        if ground_truth is not None:
            tmp = self.root / "ground_truth.tmp.npz"
            np.savez_compressed(tmp, **{k: np.asarray(v) for k, v in ground_truth.items()})
            tmp.replace(self.root / "ground_truth.npz")
        info = {"kit_version": __version__, "num_frames": F, "num_views": self.num_views,
                "frames": [frames[0], frames[-1]] if frames else [], **(dict(meta) if meta else {})}
        with atomic_path(self.root / "sequence.json") as tmp:
            tmp.write_bytes(json.dumps(info, indent=1, default=_json_default).encode())


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o)}")
