"""Frames of a user's video: a video file (decoded by OpenCV's FFmpeg back end) or a folder of
images, read one frame at a time and written to a folder of numbered JPEGs that a recording in
the official layout links to.

A frame is named by its number in the source (0 = the first frame of the file), whatever
``start``, ``every`` and the time offset select, so every output of the video route refers to the
source's own frame numbers.
"""
from __future__ import annotations

import json
import os
import re
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from airpose_lib.atomic import atomic_path
from airpose_lib.errors import UserError

__all__ = ["VideoError", "VideoInfo", "IMAGE_SUFFIXES", "file_stamp", "video_info", "frame_numbers", "iter_frames",
           "decode_frames"]

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png")
_DONE = "frames.json"


class VideoError(UserError, ValueError):
    """A video that cannot be read as asked; the message names the file and the fix."""


@dataclass(frozen=True)
class VideoInfo:
    """What a source holds.

    Attributes:
        path: the video file or image folder.
        width, height: frame size in pixels.
        fps: frames per second (a folder's from the caller).
        n_frames: frames in the source (a file's as its container states).
    """

    path: str
    width: int
    height: int
    fps: float
    n_frames: int


def _folder_images(folder: Path) -> list[Path]:
    files = [p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and not p.name.startswith(".")]
    numbered = [p for p in files if re.fullmatch(r"\d+", p.stem)]
    # numbered frames by number (000010 after 000009), anything else by name
    return sorted(numbered, key=lambda p: int(p.stem)) if len(numbered) == len(files) else sorted(files)


def _imread(path: Path) -> np.ndarray:
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise VideoError(f"cannot read image {path} (damaged or not an image); replace it or remove it from the folder")
    return img[..., ::-1]


def file_stamp(path: str | Path) -> list[int]:
    """``[bytes, mtime_ns]`` of a video file (a folder: its image count and newest mtime): a replaced
    video is decoded again."""
    p = Path(path)
    if p.is_dir():
        images = _folder_images(p)
        return [len(images), max((q.stat().st_mtime_ns for q in images), default=0)]
    st = p.stat()
    return [st.st_size, st.st_mtime_ns]


def _quiet_ffmpeg() -> None:
    """FFmpeg's own log lines ("moov atom not found") would stand beside the one-line error that
    names the file and the fix; OpenCV reads this before it opens the first video."""
    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")


def video_info(path: str | Path, fps: float | None = None) -> VideoInfo:
    """Open ``path`` (a video file or a folder of images) and read its size, rate and length.

    Args:
        fps: the frame rate; required for a folder, overrides a file's stated rate.

    Raises:
        VideoError: missing, unreadable, empty, or a folder without ``fps``.
    """
    import cv2

    path = Path(path)
    if path.is_dir():
        images = _folder_images(path)
        if not images:
            raise VideoError(f"{path} holds no {'/'.join(IMAGE_SUFFIXES)} images; give a video file or a folder of frames")
        if fps is None:
            raise VideoError(f"{path} is a folder of frames: give its frame rate with --fps")
        h, w = _imread(images[0]).shape[:2]
        return VideoInfo(str(path), w, h, float(fps), len(images))
    if not path.is_file():
        raise VideoError(f"video {path} does not exist; give a video file (.mp4, .mov, ...) or a folder of frames")
    _quiet_ffmpeg()
    cap = cv2.VideoCapture(str(path))
    try:
        ok, frame = cap.read() if cap.isOpened() else (False, None)
        if not ok or frame is None:
            raise VideoError(f"cannot decode {path} (not a video, damaged, or a codec OpenCV's FFmpeg lacks); "
                             "re-encode it, e.g. `ffmpeg -i IN -c:v libx264 OUT.mp4`, or give a folder of frames")
        stated = cap.get(cv2.CAP_PROP_FPS)
        n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    finally:
        cap.release()
    rate = float(fps) if fps is not None else float(stated)
    if not rate > 0:
        raise VideoError(f"{path} states no frame rate; give it with --fps")
    return VideoInfo(str(path), frame.shape[1], frame.shape[0], rate, max(n, 1))


def frame_numbers(info: VideoInfo, start: int = 0, end: int | None = None, every: int = 1) -> np.ndarray:
    """The source frame numbers ``start, start + every, ... < end`` (end: the source's length)."""
    if every < 1 or start < 0:
        raise VideoError(f"--every must be >= 1 and --start >= 0 (got {every}, {start})")
    stop = info.n_frames if end is None else min(int(end), info.n_frames)
    if start >= stop:
        raise VideoError(f"{info.path} has {info.n_frames} frames: --start {start} leaves none (--end {end})")
    return np.arange(start, stop, every, dtype=np.int64)


def iter_frames(info: VideoInfo, numbers: Sequence[int]) -> Iterator[tuple[int, np.ndarray]]:
    """``(number, (H, W, 3) uint8 RGB)`` for the increasing source frame ``numbers``, decoded in one
    pass (frames between them are read and dropped: seeking in compressed video is not exact).

    Raises:
        VideoError: the file ends before a requested frame (truncated or damaged).
    """
    import cv2

    numbers = [int(i) for i in numbers]
    if not numbers:
        return
    path = Path(info.path)
    if path.is_dir():
        images = _folder_images(path)
        for i in numbers:
            yield i, _imread(images[i])
        return
    _quiet_ffmpeg()
    cap = cv2.VideoCapture(str(path))
    try:
        want, pos = iter(numbers), 0
        target = next(want)
        while True:
            ok = cap.grab()
            if not ok:
                raise VideoError(f"{path} ends at frame {pos} but frame {target} was asked for (truncated or damaged, "
                                 f"or a container that overstates its {info.n_frames} frames); re-export the video or "
                                 f"give --end {pos}")
            if pos == target:
                ok, frame = cap.retrieve()
                if not ok:
                    raise VideoError(f"cannot decode frame {pos} of {path} (damaged); re-export the video")
                yield pos, frame[..., ::-1]
                target = next(want, None)
                if target is None:
                    return
            pos += 1
    finally:
        cap.release()


def decode_frames(info: VideoInfo, numbers: Sequence[int], out_dir: str | Path, *,
                  undistort: tuple[np.ndarray, np.ndarray] | None = None, jpeg_quality: int = 95,
                  progress: bool = False, desc: str = "frames") -> Path:
    """Write the source frames ``numbers`` as ``out_dir/%06d.jpg``, resuming where a killed run
    stopped (each image is written atomically; a finished folder carries ``frames.json``).

    Args:
        undistort: ``(K, dist)`` to undistort each frame with (OpenCV's model, same ``K`` after).

    Returns:
        ``out_dir``.
    """
    import cv2

    from airpose_lib.progress import progress_bar

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    record = {"video": asdict(info), "stamp": file_stamp(info.path), "frames": [int(numbers[0]), int(numbers[-1]), len(numbers)],
              "undistorted": undistort is not None}
    done = out / _DONE
    if done.is_file() and json.loads(done.read_text()) == record:
        return out
    todo = [int(i) for i in numbers if not (out / f"{int(i):06d}.jpg").is_file()]
    bar = progress_bar(total=len(numbers), initial=len(numbers) - len(todo), desc=desc, enabled=progress)
    for i, img in iter_frames(info, todo):
        bgr = np.ascontiguousarray(img[..., ::-1])
        if undistort is not None:
            bgr = cv2.undistort(bgr, undistort[0], undistort[1])
        ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality])
        if not ok:
            raise RuntimeError(f"JPEG encoding failed for frame {i} of {info.path}")
        with atomic_path(out / f"{i:06d}.jpg") as tmp:
            tmp.write_bytes(buf.tobytes())
        bar.update(1)
    bar.close()
    with atomic_path(done) as tmp:
        tmp.write_text(json.dumps(record))
    return out
