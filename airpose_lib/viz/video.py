"""A video of a drone's frames with the estimated body drawn over them."""
from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from airpose_lib.atomic import atomic_path

from .trajectories import overlay_mesh

__all__ = ["write_mp4", "write_overlay_video", "plot_overlay_stills", "MESH_RGB"]

MESH_RGB = (0.55, 0.75, 0.95)


def write_mp4(images: Iterable[np.ndarray], image_size: tuple[int, int], fps: float, out: str | Path) -> Path:
    """Write ``(H, W, 3)`` uint8 RGB images as an mp4 (OpenCV's ``mp4v``), atomically.

    Args:
        image_size: ``(W, H)`` of every image.
    """
    import cv2

    out = Path(out)
    with atomic_path(out) as tmp:
        tmp_mp4 = tmp.with_suffix(".mp4")  # OpenCV picks the container by the file's ending
        writer = cv2.VideoWriter(str(tmp_mp4), cv2.VideoWriter_fourcc(*"mp4v"), float(fps), tuple(image_size))
        if not writer.isOpened():
            raise RuntimeError(f"OpenCV cannot write mp4 here ({tmp_mp4})")
        try:
            for image in images:
                writer.write(np.ascontiguousarray(image[..., ::-1]))
        finally:
            writer.release()
        tmp_mp4.replace(tmp)
    return out


def write_overlay_video(frames: Iterable[tuple[np.ndarray, np.ndarray | None]], faces: np.ndarray, K: np.ndarray,
                        image_size: tuple[int, int], fps: float, out: str | Path, *, alpha: float = 0.7) -> Path:
    """Write an mp4 of ``(image (H, W, 3) uint8 RGB, vertices (N, 3) camera frame or None)`` pairs,
    the mesh blended over the image (None: the frame as it is), atomically.

    Args:
        faces: ``(M, 3)`` triangles; K: ``(3, 3)`` the images' intrinsics; image_size: ``(W, H)``.
    """
    from .render import OffscreenRenderer  # VTK only when a video is made

    with OffscreenRenderer(tuple(image_size), np.asarray(K, dtype=np.float64)) as renderer:
        def blended():
            for image, vertices in frames:
                if vertices is not None and np.isfinite(vertices).all() and (vertices[:, 2] > 0).all():
                    rgb, depth = renderer.render(vertices, faces, MESH_RGB, return_depth=True)
                    image = overlay_mesh(image, rgb, depth, alpha)
                yield image

        return write_mp4(blended(), image_size, fps, out)


def plot_overlay_stills(videos: list[str | Path], n: int = 3, title: str | None = None,
                        boxes: list[np.ndarray] | None = None, scale: float = 1.1):
    """``n`` frames spread over each overlay video (one row per video), each cut to a square of
    ``scale`` times the person's box around it (``boxes``: per video ``(F, 4)`` ``[x0, y0, x1, y1]``
    of its frames; None: the whole frame).

    Returns:
        the figure.
    """
    import cv2
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(len(videos), n, figsize=(2.6 * n, 2.6 * len(videos) + 0.4), squeeze=False,
                           layout="constrained")
    for r, path in enumerate(videos):
        cap = cv2.VideoCapture(str(path))
        count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        for c, i in enumerate(np.linspace(0, count - 1, n + 2).round().astype(int)[1:-1]):
            cap.set(cv2.CAP_PROP_POS_FRAMES, int(i))
            ok, frame = cap.read()
            a = ax[r, c]
            a.set_xticks([])
            a.set_yticks([])
            if ok:
                img = frame[..., ::-1]
                if boxes is not None and np.isfinite(boxes[r][i]).all():
                    x0, y0, x1, y1 = boxes[r][i]
                    half = 0.5 * scale * max(x1 - x0, y1 - y0)
                    cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
                    h, w = img.shape[:2]
                    img = img[int(max(cy - half, 0)):int(min(cy + half, h)), int(max(cx - half, 0)):int(min(cx + half, w))]
                a.imshow(img)
            a.set_title(f"UAV{r + 1}, paired frame {i}", fontsize=9)
        cap.release()
    if title:
        fig.suptitle(title)
    return fig
