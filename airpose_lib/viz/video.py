"""A video of a drone's frames with the estimated body drawn over them."""
from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from airpose_lib.atomic import atomic_path

from .trajectories import overlay_mesh

__all__ = ["write_overlay_video", "plot_overlay_stills", "MESH_RGB"]

MESH_RGB = (0.55, 0.75, 0.95)


def write_overlay_video(frames: Iterable[tuple[np.ndarray, np.ndarray | None]], faces: np.ndarray, K: np.ndarray,
                        image_size: tuple[int, int], fps: float, out: str | Path, *, alpha: float = 0.7) -> Path:
    """Write an mp4 of ``(image (H, W, 3) uint8 RGB, vertices (N, 3) camera frame or None)`` pairs,
    the mesh blended over the image (None: the frame as it is), atomically.

    Args:
        faces: ``(M, 3)`` triangles; K: ``(3, 3)`` the images' intrinsics; image_size: ``(W, H)``.
    """
    import cv2

    from .render import OffscreenRenderer  # VTK only when a video is made

    out = Path(out)
    W, H = image_size
    with atomic_path(out) as tmp, OffscreenRenderer((W, H), np.asarray(K, dtype=np.float64)) as renderer:
        tmp_mp4 = tmp.with_suffix(".mp4")
        writer = cv2.VideoWriter(str(tmp_mp4), cv2.VideoWriter_fourcc(*"mp4v"), float(fps), (W, H))
        if not writer.isOpened():
            raise RuntimeError(f"OpenCV cannot write mp4 here ({tmp_mp4})")
        try:
            for image, vertices in frames:
                if vertices is not None and np.isfinite(vertices).all() and (vertices[:, 2] > 0).all():
                    rgb, depth = renderer.render(vertices, faces, MESH_RGB, return_depth=True)
                    image = overlay_mesh(image, rgb, depth, alpha)
                writer.write(np.ascontiguousarray(image[..., ::-1]))
        finally:
            writer.release()
        tmp_mp4.replace(tmp)
    return out


def plot_overlay_stills(videos: list[str | Path], n: int = 3, title: str | None = None, zoom: float = 0.6):
    """``n`` frames spread over each overlay video (one row per video), cropped to the middle
    ``zoom`` of the frame's width where the drones keep the person.

    Returns:
        the figure.
    """
    import cv2
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(len(videos), n, figsize=(3.2 * n, 2.2 * len(videos) + 0.4), squeeze=False,
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
                h, w = frame.shape[:2]
                x0, y0 = int(w * (1 - zoom) / 2), int(h * (1 - zoom) / 2)
                a.imshow(frame[y0:h - y0, x0:w - x0, ::-1])
            a.set_title(f"{Path(path).stem}, frame {i}", fontsize=9)
        cap.release()
    if title:
        fig.suptitle(title)
    return fig
