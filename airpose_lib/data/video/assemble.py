"""Decoded videos as recordings in the official layout (:mod:`airpose_lib.data.sequences.layout`),
so that the network, AirPose+ and the evaluation read a user's videos as they read the authors'.

A recording's images are links to the decoded frames (nothing is copied). :func:`single_view`
makes one drone's recording (the pose each view reads alone, which the time offset is estimated
from); :func:`two_view` pairs the two drones' frames at an offset under UAV1's frame numbers.
"""
from __future__ import annotations

import json
import os
import shutil
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from airpose_lib.atomic import atomic_path
from airpose_lib.data.sequences.detector_files import write_detector_file
from airpose_lib.data.sequences.layout import DETECTOR_FILES, write_camera_calib

__all__ = ["single_view", "two_view", "paired_frames"]


def _link(src: Path, dst: Path) -> None:
    if dst.is_symlink() or dst.exists():
        dst.unlink()
    try:
        os.link(src, dst)  # a hard link survives moving the output folder
    except OSError:
        shutil.copyfile(src, dst)


def _machine(root: Path, k: int, frames_dir: Path, numbers: Sequence[int], names: Sequence[int], K: np.ndarray,
             image_size: tuple[int, int], keypoints: np.ndarray, detector: str, fps: float) -> None:
    m = root / f"machine_{k}"
    images = m / "images"
    if images.exists():
        shutil.rmtree(images)
    images.mkdir(parents=True)
    for src, name in zip(numbers, names):
        _link(frames_dir / f"{int(src):06d}.jpg", images / f"{int(name):06d}.jpg")
    write_camera_calib(m / "camera_calib.yml", K, image_size)
    if keypoints is not None:
        write_detector_file(detector, m / DETECTOR_FILES[detector][0], list(names), keypoints)
    lines = ["frame,timestamp"] + [f"{int(n)},{int(s) / fps:.9f}" for n, s in zip(names, numbers)]
    with atomic_path(m / "timestamps.csv") as tmp:
        tmp.write_text("\n".join(lines) + "\n")


def paired_frames(numbers1: Sequence[int], numbers2: Sequence[int], offset: int) -> tuple[np.ndarray, np.ndarray]:
    """UAV1's frames ``i`` whose instant UAV2 holds (its frame ``i + offset``), and those UAV2 frames."""
    n1, n2 = np.asarray(numbers1, dtype=np.int64), np.asarray(numbers2, dtype=np.int64)
    keep = np.isin(n1 + offset, n2)
    return n1[keep], n1[keep] + offset


def single_view(root: str | Path, frames_dir: Path, numbers: Sequence[int], K: np.ndarray,
                image_size: tuple[int, int], keypoints: np.ndarray | None, detector: str, fps: float) -> Path:
    """One drone's recording under ``root``: ``machine_1`` only, frames named by their source numbers.

    Args:
        keypoints: ``(F, 25, 3)`` at ``numbers`` (None: no detector file, for a detector to
            write); ``detector``: its name in the layout.
    """
    root = Path(root)
    _machine(root, 1, Path(frames_dir), numbers, numbers, K, image_size, keypoints, detector, fps)
    return root


def two_view(root: str | Path, frames_dirs: Sequence[Path], numbers: Sequence[Sequence[int]], offset: int,
             K: Sequence[np.ndarray], image_sizes: Sequence[tuple[int, int]], keypoints: Sequence[np.ndarray],
             detector: str, fps: float) -> np.ndarray:
    """The two drones' recording under ``root``, UAV2's frame ``i + offset`` stored as frame ``i``.

    Args:
        numbers: each video's decoded source frames; keypoints: each ``(F_v, 25, 3)`` at them.

    Returns:
        ``(F,)`` UAV1's frame numbers that both views hold (the recording's frames).
    """
    root = Path(root)
    f1, f2 = paired_frames(numbers[0], numbers[1], offset)
    pos = [{int(n): i for i, n in enumerate(nums)} for nums in numbers]
    for k, (src, kp) in enumerate(((f1, keypoints[0]), (f2, keypoints[1]))):
        rows = [pos[k][int(n)] for n in src]
        _machine(root, k + 1, Path(frames_dirs[k]), src, f1, K[k], image_sizes[k], kp[rows], detector, fps)
    with atomic_path(root / "sequence.json") as tmp:
        tmp.write_text(json.dumps({"source": "airpose video", "offset_frames": int(offset), "fps": fps,
                                   "num_frames": int(len(f1))}))
    return f1
