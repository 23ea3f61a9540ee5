"""Camera intrinsics of a user's video: read in the formats users have, or a stated default, and
checked against the frames they are used with.

Formats (:func:`read_intrinsics`):

* OpenCV FileStorage (``%YAML:1.0``), as the authors' ``camera_calib.yml``: a 3x3 matrix ``K``
  (or ``camera_matrix``), optionally ``dist`` / ``distortion_coefficients`` and
  ``image_width`` / ``image_height``;
* YAML or JSON with ``fx, fy, cx, cy`` (optionally ``dist: [k1, k2, p1, p2, k3]``, ``width``,
  ``height``), or ``K: [[...], [...], [...]]``; one camera for both videos, or one per video
  under ``uav1`` / ``uav2`` (or a list ``cameras: [..., ...]``).

Without a file, :func:`default_intrinsics` puts the principal point at the image centre and the
focal length at a stated vertical field of view: the body's depth scales with the focal length,
so an assumed one gives depths in the right proportion but at an assumed scale.
"""
from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from airpose_lib.errors import UserError

__all__ = ["IntrinsicsError", "Intrinsics", "DEFAULT_FOV_Y_DEG", "read_intrinsics", "default_intrinsics",
           "check_intrinsics"]

#: Vertical field of view of the default camera (a DJI Mavic-class camera at 16:9 is about 46-50 deg).
DEFAULT_FOV_Y_DEG = 48.0
#: The principal point may sit this share of the image size away from the centre before a warning.
CENTRE_TOLERANCE = 0.15
#: fx and fy may differ by this share before a warning.
ASPECT_TOLERANCE = 0.05

_FIX = ("give fx, fy, cx, cy of this camera at the video's resolution "
        "(a YAML such as `fx: 1500\\nfy: 1500\\ncx: 960\\ncy: 540`), or leave --intrinsics out for the default")


class IntrinsicsError(UserError, ValueError):
    """Intrinsics that cannot be read or do not fit the video; the message names the file."""


@dataclass(frozen=True)
class Intrinsics:
    """One camera.

    Attributes:
        K: ``(3, 3)`` pixels, OpenCV convention (pixel centres at integers).
        dist: ``(5,)`` OpenCV distortion ``k1, k2, p1, p2, k3`` (zeros: none).
        size: ``(width, height)`` the calibration refers to, or None when the file does not say.
        source: where it came from (a file, or ``default``).
    """

    K: np.ndarray
    dist: np.ndarray
    size: tuple[int, int] | None
    source: str

    @property
    def distorted(self) -> bool:
        return bool(np.any(np.abs(self.dist) > 0))

    def as_dict(self) -> dict:
        return {"fx": float(self.K[0, 0]), "fy": float(self.K[1, 1]), "cx": float(self.K[0, 2]),
                "cy": float(self.K[1, 2]), "dist": [float(d) for d in self.dist],
                "size": None if self.size is None else list(self.size), "source": self.source}


def default_intrinsics(width: int, height: int, fov_y_deg: float = DEFAULT_FOV_Y_DEG) -> Intrinsics:
    """Square pixels, the principal point at the centre, ``fy = (H / 2) / tan(fov_y / 2)``."""
    if not 1.0 < fov_y_deg < 179.0:
        raise IntrinsicsError(f"field of view {fov_y_deg} deg: give a vertical field of view in (1, 179) deg")
    f = 0.5 * height / math.tan(math.radians(fov_y_deg) / 2)
    K = np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2], [0.0, 0.0, 1.0]])
    return Intrinsics(K, np.zeros(5), (int(width), int(height)), f"default ({fov_y_deg:g} deg vertical field of view)")


def _from_mapping(d: Mapping, where: str) -> Intrinsics:
    if "K" in d or "camera_matrix" in d:
        K = np.asarray(d.get("K", d.get("camera_matrix")), dtype=np.float64)
        if K.shape == (9,):
            K = K.reshape(3, 3)
    elif all(k in d for k in ("fx", "fy", "cx", "cy")):
        K = np.array([[d["fx"], 0.0, d["cx"]], [0.0, d["fy"], d["cy"]], [0.0, 0.0, 1.0]], dtype=np.float64)
    else:
        raise IntrinsicsError(f"{where}: no `fx, fy, cx, cy` nor a 3x3 `K`; {_FIX}")
    if K.shape != (3, 3) or not np.isfinite(K).all() or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise IntrinsicsError(f"{where}: K must be a finite 3x3 matrix with positive fx and fy; {_FIX}")
    dist = np.zeros(5)
    raw = d.get("dist", d.get("distortion_coefficients"))
    if raw is not None:
        raw = np.asarray(raw, dtype=np.float64).reshape(-1)
        if raw.size > 5 or not np.isfinite(raw).all():
            raise IntrinsicsError(f"{where}: `dist` must be up to 5 finite numbers k1, k2, p1, p2, k3")
        dist[: raw.size] = raw
    w, h = d.get("width", d.get("image_width")), d.get("height", d.get("image_height"))
    size = (int(w), int(h)) if w is not None and h is not None else None
    return Intrinsics(K, dist, size, where)


def _read_filestorage(path: Path) -> Mapping:
    import cv2

    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except cv2.error as e:
        raise IntrinsicsError(f"cannot parse {path} as OpenCV FileStorage ({e}); {_FIX}") from None
    out = {}
    try:
        for key in ("K", "camera_matrix", "dist", "distortion_coefficients"):
            node = fs.getNode(key)
            if not node.empty():
                out[key] = node.mat()
        for key in ("image_width", "image_height"):
            node = fs.getNode(key)
            if not node.empty():
                out[key] = node.real()
    finally:
        fs.release()
    return out


def read_intrinsics(path: str | Path, view: int) -> Intrinsics:
    """The intrinsics of video ``view`` (0: UAV1, 1: UAV2) from ``path`` (formats: module docstring).

    Raises:
        IntrinsicsError: unreadable, or no camera for this view; the message names the file.
    """
    path = Path(path)
    if not path.is_file():
        raise IntrinsicsError(f"intrinsics file {path} does not exist; {_FIX}")
    text = path.read_text(errors="replace")
    where = str(path)
    if text.lstrip().startswith("%YAML"):
        return _from_mapping(_read_filestorage(path), where)
    try:
        if path.suffix.lower() == ".json":
            data = json.loads(text)
        else:
            import yaml

            data = yaml.safe_load(text)
    except Exception as e:  # noqa: BLE001 - the parser's own error, reported on the file
        raise IntrinsicsError(f"cannot parse {path}: {type(e).__name__}: {str(e).splitlines()[0]}; {_FIX}") from None
    if not isinstance(data, Mapping) and not isinstance(data, list):
        raise IntrinsicsError(f"{path}: expected a mapping of fx, fy, cx, cy; {_FIX}")
    if isinstance(data, list) or "cameras" in data:
        cams = data if isinstance(data, list) else data["cameras"]
        if not isinstance(cams, list) or len(cams) <= view or not isinstance(cams[view], Mapping):
            raise IntrinsicsError(f"{path}: `cameras` has no entry {view + 1} (one per video, UAV1 first)")
        return _from_mapping(cams[view], f"{where} (camera {view + 1})")
    key = f"uav{view + 1}"
    if key in data:
        if not isinstance(data[key], Mapping):
            raise IntrinsicsError(f"{path}: `{key}` must be a mapping of fx, fy, cx, cy")
        return _from_mapping(data[key], f"{where} ({key})")
    if any(k.startswith("uav") for k in data):
        raise IntrinsicsError(f"{path}: no `{key}` section (one per video: uav1, uav2)")
    return _from_mapping(data, where)


def check_intrinsics(intr: Intrinsics, width: int, height: int, video: str) -> list[str]:
    """Warnings for intrinsics that look wrong for frames of ``width`` x ``height``.

    Raises:
        IntrinsicsError: a calibration size that differs from the frames', or a principal point
            outside the image (both mean a calibration of another resolution or camera).
    """
    where = intr.source
    if intr.size is not None and tuple(intr.size) != (width, height):
        raise IntrinsicsError(
            f"{where}: calibrated for {intr.size[0]}x{intr.size[1]} but {video} is {width}x{height}; scale "
            f"fx, cx by {width / intr.size[0]:.4g} and fy, cy by {height / intr.size[1]:.4g}, or calibrate at this size")
    fx, fy, cx, cy = intr.K[0, 0], intr.K[1, 1], intr.K[0, 2], intr.K[1, 2]
    if not (0 <= cx < width and 0 <= cy < height):
        raise IntrinsicsError(f"{where}: principal point ({cx:.0f}, {cy:.0f}) lies outside {video}'s "
                              f"{width}x{height} frames: a calibration of another resolution? {_FIX}")
    warnings = []
    off = max(abs(cx - (width - 1) / 2) / width, abs(cy - (height - 1) / 2) / height)
    if off > CENTRE_TOLERANCE:
        warnings.append(f"{where}: principal point ({cx:.0f}, {cy:.0f}) is {100 * off:.0f} % of the image away from "
                        f"the centre of {video}'s {width}x{height} frames; check that it is this camera's, at this size")
    if abs(fx - fy) / max(fx, fy) > ASPECT_TOLERANCE:
        warnings.append(f"{where}: fx {fx:.1f} and fy {fy:.1f} differ by {100 * abs(fx - fy) / max(fx, fy):.0f} %; "
                        "square pixels have fx close to fy")
    return warnings
