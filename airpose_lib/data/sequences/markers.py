"""ArUco markers on the ground as ground truth for the drones' cameras.

The paper's scene had ArUco markers on the ground, "never used for any of our methods" (Fig. 1);
the official real data ships per-frame marker poses (``data.official.real``). This module is
the geometry without a renderer: a layout of square markers lying on the ground plane ``y = 0``
(world Y up, as the recordings), their images (``cv2.aruco``), a top-down image of the ground
with the markers (:func:`ground_board`) and its homography into a camera (for synthetic views),
their detection, each camera's pose from them (:func:`camera_pose_from_markers`) and UAV 2 in
UAV 1 from two such poses (:func:`relative_camera_from_markers`).

Conventions. A marker's own frame is OpenCV's (``x`` right and ``y`` up in the marker image,
``z`` out of it), its corners in ArUco's order: top-left, top-right, bottom-right, bottom-left,
at ``(-s/2, s/2), (s/2, s/2), (s/2, -s/2), (-s/2, -s/2)`` (``SOLVEPNP_IPPE_SQUARE``'s order).
On the ground the marker's ``z`` is world up, its ``x`` world ``x`` and its ``y`` world ``-z``
(markers are axis-aligned), so a marker's image pasted upright in a top-down image whose columns
run along world ``x`` and rows along world ``z`` is the marker as it lies. Camera poses are
OpenCV extrinsics ``x_cam = R x_world + t``.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import cv2
import numpy as np
import torch

from airpose_lib.config_fields import config_from
from airpose_lib.errors import ConfigError
from airpose_lib.geometry import relative_camera_pose

from .marker_poses import MarkerPoses

__all__ = [
    "MarkerLayout",
    "marker_layout",
    "R_WORLD_MARKER",
    "marker_image",
    "marker_tile",
    "marker_corners_world",
    "tile_corners_world",
    "ground_board",
    "ground_homography",
    "detect_markers",
    "marker_pose",
    "camera_pose_from_markers",
    "relative_camera_from_markers",
    "recording_lens_distortion",
    "sequence_marker_poses",
    "marker_relative_cameras",
]

#: Marker frame -> world rotation of a marker lying on the ground (columns: the marker's x, y, z
#: in the world): x -> world x, y -> world -z, z -> world y (up).
R_WORLD_MARKER = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


@dataclass(frozen=True)
class MarkerLayout:
    """Square ArUco markers lying axis-aligned on the ground ``y = 0``, each printed with a white
    margin of one cell (as printed markers are, so the border stands out from the ground).

    Attributes:
        ids: (M,) marker ids of the dictionary.
        centres_xz: (M, 2) world (x, z) of each marker's centre, metres. The default: four
            markers 3 m apart around the recordings' activity area (the person starts within
            1 m of the origin), in view of both drones most of the time.
        side_m: the black square's side (ArUco's marker length, without the white margin), metres.
        dictionary: a ``cv2.aruco.DICT_*`` name.
    """

    ids: tuple[int, ...] = (0, 1, 2, 3)
    centres_xz: tuple[tuple[float, float], ...] = ((-1.5, -1.5), (1.5, -1.5), (1.5, 1.5), (-1.5, 1.5))
    side_m: float = 0.6
    dictionary: str = "DICT_4X4_50"

    def __post_init__(self) -> None:
        # Lists (YAML, JSON) become tuples: the layout is hashable and compares equal after a
        # round trip through a recording's sequence.json.
        object.__setattr__(self, "ids", tuple(int(i) for i in self.ids))
        object.__setattr__(self, "centres_xz", tuple((float(x), float(z)) for x, z in self.centres_xz))
        object.__setattr__(self, "side_m", float(self.side_m))
        if len(self.ids) != len(self.centres_xz) or len(set(self.ids)) != len(self.ids):
            raise ConfigError("markers: one centre per marker and distinct ids")
        if not self.side_m > 0:
            raise ConfigError(f"markers: side_m must be > 0, got {self.side_m}")
        if not isinstance(getattr(cv2.aruco, self.dictionary, None), int) or not self.dictionary.startswith("DICT_"):
            raise ConfigError(f"markers: unknown ArUco dictionary {self.dictionary!r} (e.g. DICT_4X4_50)")
        size = self.aruco_dictionary().bytesList.shape[0]
        if max(self.ids) >= size or min(self.ids) < 0:
            raise ConfigError(f"markers: ids must be in [0, {size}) for {self.dictionary}, got {self.ids}")

    @property
    def cells(self) -> int:
        """Cells across a marker's black square (its bits and the black border)."""
        return self.aruco_dictionary().markerSize + 2

    @property
    def tile_m(self) -> float:
        """Side of a printed marker with its white margin (one cell each side), metres."""
        return self.side_m * (self.cells + 2) / self.cells

    def aruco_dictionary(self):
        return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))


def marker_layout(value, where: str, error: type[ConfigError] = ConfigError) -> MarkerLayout | None:
    """A ``markers:`` / ``field_markers:`` setting as a :class:`MarkerLayout`: None stays None (no
    markers), a mapping gives the layout's settings (``{}`` the default one), a layout passes.
    Anything else (``true``, a list) raises ``error`` naming ``where`` and the fix."""
    if value is None or isinstance(value, MarkerLayout):
        return value
    if not isinstance(value, Mapping):
        raise error(f"{where} takes a marker layout's settings, `{{}}` for the default, not {value!r}")
    return config_from(MarkerLayout, value, where, error=error)


def marker_image(layout: MarkerLayout, marker_id: int, side_px: int) -> np.ndarray:
    """(side_px, side_px) uint8 image of one marker's black square (black border bit included,
    no white margin), ``cv2.aruco.generateImageMarker``."""
    return cv2.aruco.generateImageMarker(layout.aruco_dictionary(), int(marker_id), int(side_px), borderBits=1)


def marker_tile(layout: MarkerLayout, marker_id: int, px_per_cell: int) -> np.ndarray:
    """(S, S) uint8 printed marker: the black square and a white margin of one cell,
    ``S = (cells + 2) px_per_cell``."""
    img = marker_image(layout, marker_id, layout.cells * px_per_cell)
    return np.pad(img, px_per_cell, constant_values=255)


def _square_corners(layout: MarkerLayout, side: float) -> np.ndarray:
    h = side / 2
    local = np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])  # marker frame
    centres = np.array([[x, 0.0, z] for x, z in layout.centres_xz])
    return local @ R_WORLD_MARKER.T + centres[:, None]


def marker_corners_world(layout: MarkerLayout) -> np.ndarray:
    """(M, 4, 3) world corners of each marker in ArUco's order (TL, TR, BR, BL), on ``y = 0``."""
    return _square_corners(layout, layout.side_m)


def tile_corners_world(layout: MarkerLayout) -> np.ndarray:
    """(M, 4, 3) world corners (TL, TR, BR, BL) of each printed marker, white margin included."""
    return _square_corners(layout, layout.tile_m)


def ground_board(layout: MarkerLayout, px_per_m: float, extent_xz: tuple[float, float, float, float],
                 background: int | np.ndarray = 110) -> np.ndarray:
    """Top-down image (H, W) uint8 of the ground with the markers lying on it.

    Pixel ``(col, row)`` covers world ``x = x0 + (col + 0.5) / px_per_m``, ``z = z0 + (row + 0.5)
    / px_per_m``; each marker is pasted with its white margin (:func:`marker_tile`).

    Args:
        layout: the markers.
        px_per_m: resolution.
        extent_xz: (x0, z0, x1, z1) world rectangle covered.
        background: the ground's grey level, or an (H, W) image of it.
    """
    x0, z0, x1, z1 = extent_xz
    W, H = int(round((x1 - x0) * px_per_m)), int(round((z1 - z0) * px_per_m))
    board = np.empty((H, W), np.uint8)
    board[...] = background
    cell = layout.side_m / layout.cells * px_per_m
    if abs(cell - round(cell)) > 1e-6:
        raise ValueError(f"px_per_m {px_per_m} gives {cell:.3f} px per marker cell; choose a whole number")
    for mid, (cx, cz) in zip(layout.ids, layout.centres_xz):
        tile = marker_tile(layout, mid, int(round(cell)))
        n = tile.shape[0]
        c0 = int(round((cx - x0) * px_per_m - n / 2))
        r0 = int(round((cz - z0) * px_per_m - n / 2))
        if r0 < 0 or c0 < 0 or r0 + n > H or c0 + n > W:
            raise ValueError(f"marker {mid} lies outside the board's extent {extent_xz}")
        board[r0:r0 + n, c0:c0 + n] = tile
    return board


def ground_homography(K: np.ndarray, R_cw: np.ndarray, t_cw: np.ndarray, px_per_m: float,
                      origin_xz: tuple[float, float]) -> np.ndarray:
    """(3, 3) homography from :func:`ground_board` pixels to the camera's image.

    A ground point ``(x, 0, z)`` projects to ``K (x r1 + z r3 + t)`` (``r_i`` the columns of
    ``R_cw``), and board pixel ``(col, row)`` is ``x = x0 + (col + 0.5) / s``, ``z = z0 + (row +
    0.5) / s``.
    """
    R_cw = np.asarray(R_cw, dtype=np.float64)
    x0, z0 = origin_xz
    A = np.array([[1 / px_per_m, 0, x0 + 0.5 / px_per_m], [0, 1 / px_per_m, z0 + 0.5 / px_per_m], [0, 0, 1]])
    return np.asarray(K) @ np.column_stack([R_cw[:, 0], R_cw[:, 2], np.asarray(t_cw, dtype=np.float64)]) @ A


def detect_markers(image: np.ndarray, layout: MarkerLayout) -> dict[int, np.ndarray]:
    """Marker id -> (4, 2) detected corners (TL, TR, BR, BL, pixels) of the layout's markers.

    ``cv2.aruco.ArucoDetector`` with sub-pixel corner refinement (the pose needs corners better
    than a pixel); ids not in the layout are dropped. ``image``: (H, W) or (H, W, 3) RGB uint8.
    """
    gray = image if image.ndim == 2 else cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2GRAY)
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    corners, ids, _ = cv2.aruco.ArucoDetector(layout.aruco_dictionary(), params).detectMarkers(gray)
    if ids is None:
        return {}
    wanted = set(layout.ids)
    return {int(i): np.asarray(c, dtype=np.float64).reshape(4, 2) for c, i in zip(corners, ids.ravel())
            if int(i) in wanted}


def marker_pose(corners_px: np.ndarray, side_m: float, K: np.ndarray,
                dist: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """One marker's pose in the camera, ``x_cam = R x_marker + t``: (3, 3), (3,).

    ``cv2.solvePnP`` with ``SOLVEPNP_IPPE_SQUARE`` (Collins and Bartoli 2014, the square-marker
    solver; what ``estimatePoseSingleMarkers`` of the official scripts computes). ``corners_px``:
    (4, 2) in ArUco's order.
    """
    h = side_m / 2
    obj = np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])
    ok, rvec, tvec = cv2.solvePnP(obj, np.asarray(corners_px, dtype=np.float64).reshape(4, 1, 2), K, dist,
                                  flags=cv2.SOLVEPNP_IPPE_SQUARE)
    if not ok:
        raise RuntimeError("solvePnP (IPPE_SQUARE) failed")
    return cv2.Rodrigues(rvec)[0], tvec.reshape(3)


def camera_pose_from_markers(detections: Mapping[int, np.ndarray], layout: MarkerLayout, K: np.ndarray,
                             dist: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, float] | None:
    """A camera's world pose from all its detected markers jointly: ``R_cw (3, 3)``, ``t_cw (3,)``
    and the RMS reprojection error (pixels), or None without a detection.

    All corners lie on one plane, so ``SOLVEPNP_IPPE`` (planar PnP) gives the candidate poses
    of the plane's two-fold ambiguity; the one with the smaller reprojection error is refined
    by Levenberg-Marquardt on every corner. More markers spread over the ground constrain the
    pose much better than one marker's four corners (the ambiguity of a small square seen from
    afar is what makes single-marker poses flip).
    """
    ids = [i for i in layout.ids if i in detections]
    if not ids:
        return None
    world = marker_corners_world(layout)
    obj = np.concatenate([world[layout.ids.index(i)] for i in ids])  # (4n, 3)
    img = np.concatenate([np.asarray(detections[i], dtype=np.float64).reshape(4, 2) for i in ids])
    n, rvecs, tvecs, errs = cv2.solvePnPGeneric(obj, img[:, None], K, dist, flags=cv2.SOLVEPNP_IPPE)
    if n == 0:
        return None
    best = int(np.argmin(np.asarray(errs).ravel()))
    rvec, tvec = cv2.solvePnPRefineLM(obj, img[:, None], K, dist, rvecs[best].copy(), tvecs[best].copy())
    proj = cv2.projectPoints(obj, rvec, tvec, K, dist)[0].reshape(-1, 2)
    rms = float(np.sqrt(((proj - img) ** 2).sum(-1).mean()))
    return cv2.Rodrigues(rvec)[0], tvec.reshape(3), rms


def relative_camera_from_markers(R1: np.ndarray, t1: np.ndarray, R2: np.ndarray,
                                 t2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """UAV 2's camera in UAV 1's from both cameras' poses relative to the same markers.

    Both cameras see the same marker (or world) frame, ``x_ck = R_k x_m + t_k``, as the networks'
    two views see one body, so the relative pose is the same elimination
    (:func:`airpose_lib.geometry.relative_camera_pose`): ``R_12 = R1 R2^T``, ``t_12 = t1 - R_12
    t2`` (``x_c1 = R_12 x_c2 + t_12``; ``t_12`` is UAV 2's position in UAV 1's frame).

    Args:
        R1, t1, R2, t2: (..., 3, 3), (..., 3) marker/world -> camera poses of UAV 1 and UAV 2
            (:func:`camera_pose_from_markers`, or ``data.sequences.marker_poses.MarkerPoses``).
    Returns:
        ``R_12 (..., 3, 3)``, ``t_12 (..., 3)``, float64.
    """
    R, t = relative_camera_pose(*(torch.as_tensor(np.asarray(x, dtype=np.float64)) for x in (R1, t1, R2, t2)))
    return R.numpy(), t.numpy()


def recording_lens_distortion(seq) -> np.ndarray | None:
    """OpenCV distortion coefficients ``(k1, k2, 0, 0)`` of a generated recording's stored frames
    (its field pipeline's ``distortion``), or None when they are pinhole images. A real drone's
    calibration gives them; here the renderer knows them, and ignoring them would put the
    markers' corners pixels off near the image border."""
    settings = ((seq.meta or {}).get("config") or {}).get("field") or {}
    k = settings.get("distortion") if settings.get("enabled") else None
    if k is None or not any(k):
        return None
    return np.array([float(k[0]), float(k[1]), 0.0, 0.0])


def sequence_marker_poses(seq, layout: MarkerLayout | None = None, min_markers: int = 1,
                          dist: np.ndarray | None = None) -> tuple[MarkerPoses, np.ndarray, np.ndarray]:
    """Each drone's camera pose from the markers in every frame of a recording.

    Args:
        seq: a recording (:class:`~airpose_lib.data.sequences.reader.Sequence`: ``frames``,
            ``images[view][i]`` RGB, ``K`` (V, 3, 3) of the stored images).
        layout: the markers on its ground; default: a generated recording's own
            (``SequenceConfig.markers`` in its ``sequence.json``).
        min_markers: fewer detected markers than this leave the view invalid (two markers from
            12 m can be tens of centimetres off along the line of sight; three or four are not).
        dist: OpenCV distortion coefficients of the stored images; default: a generated
            recording's own (:func:`recording_lens_distortion`).
    Returns:
        :class:`~airpose_lib.data.sequences.marker_poses.MarkerPoses` in the layout's (world) frame
        (``R_cm``, ``t_cm`` = ``R_cw``, ``t_cw``; identity / zero where invalid), the number of
        markers detected ``(F, V)`` and the RMS reprojection error ``(F, V)`` pixels (NaN where
        no pose).
    """
    if layout is None:
        stored = (seq.meta or {}).get("config", {}).get("markers")
        if stored is None:
            raise ConfigError(f"recording {seq.root} has no markers on its ground (a profile's `sequences: "
                              "markers: {}` adds them, `field_markers: {}` to its field recordings); "
                              "give their layout")
        layout = MarkerLayout(**stored)
    if dist is None:
        dist = recording_lens_distortion(seq)
    F, V = seq.num_frames, seq.num_views
    R = np.tile(np.eye(3), (F, V, 1, 1))
    t = np.zeros((F, V, 3))
    count = np.zeros((F, V), np.int64)
    rms = np.full((F, V), np.nan)
    for i in range(F):
        for v in range(V):
            det = detect_markers(seq.image(i, v), layout)
            count[i, v] = len(det)
            pose = camera_pose_from_markers(det, layout, seq.K[v], dist) if len(det) >= max(min_markers, 1) else None
            if pose is not None:
                R[i, v], t[i, v], rms[i, v] = pose
    return MarkerPoses(np.asarray(seq.frames), R, t, ~np.isnan(rms)), count, rms


def marker_relative_cameras(poses: MarkerPoses) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """UAV 2 in UAV 1 per frame from marker poses (the official release's
    ``markerposes_corrected_all.pkl`` through ``data.official.real.load_marker_poses``, or
    :func:`sequence_marker_poses`): ``R_12 (F, 3, 3)``, ``t_12 (F, 3)`` and ``valid (F,)`` (both
    views posed; elsewhere the values are meaningless)."""
    R_12, t_12 = relative_camera_from_markers(poses.R_cm[:, 0], poses.t_cm[:, 0], poses.R_cm[:, 1], poses.t_cm[:, 1])
    return R_12, t_12, poses.valid[:, 0] & poses.valid[:, 1]
