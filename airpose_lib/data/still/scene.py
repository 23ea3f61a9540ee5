"""Scene sampler of the synthetic two-drone dataset: person, cameras, crop boxes, environment.

The protocol follows the paper's synthetic data (Sec. IV-A): a person stands somewhere in the
square ``[-2.75, 2.75]^2`` m of the ground (world Y up, ground ``y = 0``) with a random heading;
``num_views`` cameras (2 in the paper) move independently around the origin at about 10 m, look
at the region where the person can be, pitched down by 0-45 degrees, and take 1920x1080 frames
with ``f = 1475`` px and the principal point at the image centre. Samples where the person leaves
a frame are dropped (the generator counts them).

Everything here is numpy and deterministic given a ``numpy.random.Generator``: the generator
draws from one Generator per sample attempt, always in the same order.

Frames and symbols: ``R_wb, t_wb`` is the body (model origin, paper root convention) in the
world, ``R_cw, t_cw`` are a camera's extrinsics (world -> OpenCV camera), ``K`` its full-frame
intrinsics.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from airpose_lib.body.genders import GENDER_CODES
from airpose_lib.config_fields import check_fields, ranged
from airpose_lib.errors import ConfigError

from ..network_input import BOX_JITTER_PX, BOX_MARGIN_PX, NETWORK_FOCAL, NETWORK_IMAGE_SIZE, full_frame_intrinsics

__all__ = [
    "SceneConfig",
    "PersonSample",
    "CameraSample",
    "Distractor",
    "EnvironmentSample",
    "sample_person",
    "body_world_pose",
    "sample_cameras",
    "look_at_extrinsics",
    "points_in_frame",
    "tight_bbox",
    "jitter_bbox",
    "sample_environment",
]

#: Shape coefficients drawn per subject.
NUM_BETAS = 10


@dataclass(frozen=True)
class SceneConfig:
    """What the scene sampler draws from; the defaults are the paper's protocol.

    Attributes:
        num_views: cameras (drones) per sample.
        image_size: full frame ``(W, H)`` in pixels.
        focal: focal length in pixels (``fx = fy``).
        principal_point: ``(cx, cy)``; None = the image centre ``((W - 1) / 2, (H - 1) / 2)``
            (OpenCV pixel centres at integers).
        camera_distance: mean distance of a camera from the point it looks at, metres.
        camera_distance_jitter: the distance is uniform in ``camera_distance +- jitter``.
        pitch_range_deg: downward pitch of the optical axis, uniform in this range (degrees).
        target_jitter: the looked-at point is uniform in ``[-j, j]^2`` m around the origin on the
            ground axes (the cameras face the person's region, not the person).
        target_height_range: height of the looked-at point above the ground, metres.
        roll_jitter_deg: camera roll, uniform in ``+-`` this (0: horizon level, as a gimbal).
        person_extent: the person's ground position is uniform in ``[-e, e]^2`` m.
        genders: ground-truth genders to draw from (uniformly).
        beta_std: standard deviation of the shape coefficients (N(0, 1) in the shape space): one
            for all ten, or a tuple of ten (e.g. a narrower first coefficient, which in the open
            body carries the stature: 8.8 cm a unit for the male body, 9.3 cm for the female).
        beta_clip: betas are clipped to ``+-`` this many units (avoids rare extreme bodies).
        bbox_from: ``"joints"`` (the 76 SMPL-X output joints, as the paper's boxes) or
            ``"vertices"`` (the whole mesh) for the tight box.
        bbox_margin_px: the tight box is the projected points ``+-`` this (paper: 20 px).
        bbox_jitter_px: each side of a training box moves outwards by ``U(0, jitter)`` px
            (paper: between the tight box and a 200 px margin).
        frame_margin_px: every mesh vertex must project at least this far inside the frame.
        num_distractors: ``(min, max)`` boxes / cylinders on the ground per sample.
        distractor_radius: ``(min, max)`` distance of distractors from the origin, metres.
        distractor_clearance: minimum gap (m) between a distractor and the person or any
            camera's line of sight to the person, so that it never hides the person.
    """

    num_views: int = ranged(2, ge=1)
    image_size: tuple[int, int] = NETWORK_IMAGE_SIZE
    focal: float = NETWORK_FOCAL
    principal_point: tuple[float, float] | None = None
    camera_distance: float = 10.0
    camera_distance_jitter: float = 1.5
    pitch_range_deg: tuple[float, float] = (0.0, 45.0)
    target_jitter: float = 0.5
    target_height_range: tuple[float, float] = (0.5, 1.2)
    roll_jitter_deg: float = 0.0
    person_extent: float = 2.75
    genders: tuple[str, ...] = ("male", "female")
    beta_std: float | tuple[float, ...] = 1.0
    beta_clip: float = 3.0
    bbox_from: str = "joints"
    bbox_margin_px: float = BOX_MARGIN_PX
    bbox_jitter_px: float = BOX_JITTER_PX
    frame_margin_px: float = 0.0
    num_distractors: tuple[int, int] = (0, 4)
    distractor_radius: tuple[float, float] = (1.5, 12.0)
    distractor_clearance: float = 1.0

    def __post_init__(self) -> None:
        check_fields(self, convert=False)  # types and declared ranges before the rules below compare them
        if self.bbox_from not in ("joints", "vertices"):
            raise ConfigError(f"bbox_from must be 'joints' or 'vertices', got {self.bbox_from!r}")
        bad = [g for g in self.genders if g not in GENDER_CODES]
        if bad or not self.genders:
            raise ConfigError(f"genders must be a non-empty subset of {tuple(GENDER_CODES)}, got {self.genders}")
        std = np.atleast_1d(np.asarray(self.beta_std, dtype=np.float64))
        if std.shape not in ((1,), (NUM_BETAS,)) or (std < 0).any():
            raise ConfigError(f"beta_std must be one non-negative number or {NUM_BETAS}, got {self.beta_std}")
        lo, hi = self.pitch_range_deg
        if not -89.0 <= lo <= hi <= 89.0:
            raise ConfigError(f"pitch_range_deg must satisfy -89 <= lo <= hi <= 89, got {self.pitch_range_deg}")

    @property
    def K(self) -> np.ndarray:
        """Full-frame intrinsics ``(3, 3)``, float64."""
        return full_frame_intrinsics(self.image_size, self.focal, self.principal_point)


# -- person ---------------------------------------------------------------------------------------
@dataclass
class PersonSample:
    """One subject: identity, articulation and where it stands.

    Attributes:
        gender: ``"male"``, ``"female"`` or ``"neutral"`` (which body model is the ground truth).
        betas: ``(10,)`` shape coefficients.
        theta: ``(21, 3)`` body pose, axis-angle.
        position: ``(2,)`` ground position ``(x, z)`` of the model origin, metres.
        heading: rotation about world Y, radians (0 = facing +Z).
    """

    gender: str
    betas: np.ndarray
    theta: np.ndarray
    position: np.ndarray
    heading: float


def sample_person(rng: np.random.Generator, cfg: SceneConfig, pose_sampler) -> PersonSample:
    """Draw a subject: gender, betas ~ N(0, beta_std^2) clipped, a pose, a position and a heading.

    Args:
        rng: the attempt's generator.
        cfg: scene settings.
        pose_sampler: ``f(rng, n) -> (n, 21, 3)`` axis-angle poses
            (:func:`airpose_lib.data.still.poses.sample_body_pose`).
    """
    gender = cfg.genders[int(rng.integers(len(cfg.genders)))]
    betas = np.clip(rng.standard_normal(NUM_BETAS) * np.asarray(cfg.beta_std), -cfg.beta_clip, cfg.beta_clip)
    theta = np.asarray(pose_sampler(rng, 1), dtype=np.float64).reshape(21, 3)
    position = rng.uniform(-cfg.person_extent, cfg.person_extent, size=2)
    heading = float(rng.uniform(-math.pi, math.pi))
    return PersonSample(gender, betas, theta, position, heading)


def body_world_pose(person: PersonSample, v0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World root pose ``R_wb (3, 3)``, ``t_wb (3,)`` that stands the body on the ground.

    ``v0 (V, 3)`` are the vertices posed with identity root and zero translation (the model's own
    frame, Y up). The body turns by ``heading`` about Y; ``t_wb`` puts the model origin over
    ``position`` and lifts it so that the lowest vertex touches ``y = 0``.
    """
    c, s = math.cos(person.heading), math.sin(person.heading)
    R_wb = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    # A rotation about Y keeps heights, so the lift only depends on v0's y.
    lift = -float(np.min(v0[:, 1]))
    t_wb = np.array([person.position[0], lift, person.position[1]])
    return R_wb, t_wb


# -- cameras --------------------------------------------------------------------------------------
@dataclass
class CameraSample:
    """One drone camera.

    Attributes:
        K: ``(3, 3)`` full-frame intrinsics.
        R_cw: ``(3, 3)`` world -> camera rotation (OpenCV axes).
        t_cw: ``(3,)`` world -> camera translation, metres.
        centre: ``(3,)`` optical centre in the world.
        target: ``(3,)`` the point it looks at.
        distance: distance from the target, metres.
        pitch: downward pitch of the optical axis, radians.
        azimuth: direction of the camera seen from the target, radians about Y (0 = +Z).
    """

    K: np.ndarray
    R_cw: np.ndarray
    t_cw: np.ndarray
    centre: np.ndarray
    target: np.ndarray
    distance: float
    pitch: float
    azimuth: float


def look_at_extrinsics(eye: np.ndarray, target: np.ndarray, roll: float = 0.0
                       ) -> tuple[np.ndarray, np.ndarray]:
    """World -> camera ``R (3, 3), t (3,)`` of an OpenCV camera at ``eye`` looking at ``target``.

    World Y is up; the camera's x (image right) is horizontal before ``roll`` (radians, about the
    optical axis) is applied. The view must not be vertical.
    """
    eye = np.asarray(eye, dtype=np.float64)
    z = np.asarray(target, dtype=np.float64) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, np.array([0.0, 1.0, 0.0]))  # image right = forward x up
    nx = np.linalg.norm(x)
    if nx < 1e-9:
        raise ValueError("look_at_extrinsics: vertical viewing direction")
    x /= nx
    y = np.cross(z, x)  # image down
    if roll:
        c, s = math.cos(roll), math.sin(roll)
        x, y = c * x + s * y, -s * x + c * y
    R = np.stack([x, y, z])
    return R, -R @ eye


def sample_cameras(rng: np.random.Generator, cfg: SceneConfig) -> list[CameraSample]:
    """Draw ``cfg.num_views`` independent cameras around the origin (the person's region).

    Each camera looks at a point jittered around the origin at a random height, from a random
    azimuth, a pitch in ``cfg.pitch_range_deg`` and a distance ``camera_distance +- jitter``.
    """
    K = cfg.K
    cams = []
    for _ in range(cfg.num_views):
        target = np.array([rng.uniform(-cfg.target_jitter, cfg.target_jitter),
                           rng.uniform(*cfg.target_height_range),
                           rng.uniform(-cfg.target_jitter, cfg.target_jitter)])
        azimuth = float(rng.uniform(-math.pi, math.pi))
        pitch = math.radians(float(rng.uniform(*cfg.pitch_range_deg)))
        distance = float(cfg.camera_distance + rng.uniform(-1.0, 1.0) * cfg.camera_distance_jitter)
        roll = math.radians(float(rng.uniform(-1.0, 1.0) * cfg.roll_jitter_deg))
        # The camera sits on the far side of the target, pitched down towards it.
        back = np.array([math.cos(pitch) * math.sin(azimuth), math.sin(pitch),
                         math.cos(pitch) * math.cos(azimuth)])
        centre = target + distance * back
        R, t = look_at_extrinsics(centre, target, roll)
        cams.append(CameraSample(K.copy(), R, t, centre, target, distance, pitch, azimuth))
    return cams


def points_in_frame(uv: np.ndarray, z: np.ndarray, image_size: tuple[int, int],
                    margin: float = 0.0) -> np.ndarray:
    """Which points are in front of the camera and inside the frame.

    Args:
        uv: ``(..., N, 2)`` pixels; z: ``(..., N)`` depths; image_size: ``(W, H)``;
        margin: required distance from the frame border, pixels.
    Returns:
        ``(..., N)`` bool. Pixel centres are integers, so the frame spans ``[-0.5, W - 0.5]``.
    """
    W, H = image_size
    u, v = uv[..., 0], uv[..., 1]
    return ((z > 0) & (u >= -0.5 + margin) & (u <= W - 0.5 - margin)
            & (v >= -0.5 + margin) & (v <= H - 0.5 - margin))


# -- crop boxes -----------------------------------------------------------------------------------
def tight_bbox(uv: np.ndarray, margin: float) -> np.ndarray:
    """``[x0, y0, x1, y1]`` around pixels ``uv (N, 2)``, grown by ``margin`` px on every side."""
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    return np.array([lo[0] - margin, lo[1] - margin, hi[0] + margin, hi[1] + margin])


def jitter_bbox(bbox: np.ndarray, rng: np.random.Generator, max_margin: float,
                image_size: tuple[int, int]) -> np.ndarray:
    """Grow each side of ``bbox (4,)`` by ``U(0, max_margin)`` px, then clip it to the frame.

    Clipping keeps the crop inside the image, so the rendered crop never shows what a real
    camera could not have seen. Returns ``(4,)``.
    """
    grow = rng.uniform(0.0, max_margin, size=4) if max_margin > 0 else np.zeros(4)
    box = bbox + grow * np.array([-1.0, -1.0, 1.0, 1.0])
    W, H = image_size
    return np.clip(box, [-0.5, -0.5, -0.5, -0.5], [W - 0.5, H - 0.5, W - 0.5, H - 0.5])


# -- environment ----------------------------------------------------------------------------------
@dataclass
class Distractor:
    """A box or cylinder standing on the ground.

    Attributes:
        kind: ``"box"`` or ``"cylinder"``.
        position: ``(2,)`` ground position ``(x, z)`` of its centre, metres.
        size: ``(3,)`` width (x), height (y), depth (z) in metres (diameters for a cylinder).
        yaw: rotation about Y, radians.
        color: ``(3,)`` RGB in [0, 1].
    """

    kind: str
    position: np.ndarray
    size: np.ndarray
    yaw: float
    color: np.ndarray


@dataclass
class EnvironmentSample:
    """Ground, sky, light and clutter of one sample.

    Attributes:
        ground_texture: index into the renderer's texture bank.
        ground_tile: side of one texture tile on the ground, metres.
        ground_rotation: rotation of the texture on the ground, radians.
        ground_offset: ``(2,)`` texture offset in tiles.
        ground_tint: ``(3,)`` RGB multiplier of the (grey) texture.
        sky_color: ``(3,)`` background RGB in [0, 1].
        light_dir: ``(3,)`` unit direction the sunlight travels, world frame (downwards).
        light_intensity: key-light intensity.
        ambient: ambient share of the materials.
        distractors: boxes and cylinders.
    """

    ground_texture: int
    ground_tile: float
    ground_rotation: float
    ground_offset: np.ndarray
    ground_tint: np.ndarray
    sky_color: np.ndarray
    light_dir: np.ndarray
    light_intensity: float
    ambient: float
    distractors: list[Distractor] = field(default_factory=list)


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Distance of 2D point ``p`` from the segment ``a``-``b``."""
    ab = b - a
    t = float(np.clip(np.dot(p - a, ab) / max(np.dot(ab, ab), 1e-12), 0.0, 1.0))
    return float(np.linalg.norm(p - (a + t * ab)))


def sample_environment(rng: np.random.Generator, cfg: SceneConfig, num_textures: int,
                       person_xz: np.ndarray, camera_centres: np.ndarray,
                       max_tries: int = 20) -> EnvironmentSample:
    """Draw ground texture and its placement, sky colour, sun and distractor objects.

    Distractors keep ``cfg.distractor_clearance`` from the person and from every camera's
    ground-projected line of sight to the person, so they may appear in a crop but never hide
    the person. ``person_xz (2,)``; ``camera_centres (V, 3)``.
    """
    tex = int(rng.integers(num_textures))
    tile = float(rng.uniform(2.0, 5.0))
    rot = float(rng.uniform(0.0, 2.0 * math.pi))
    offset = rng.uniform(0.0, 1.0, size=2)
    # Earthy tints (greens, browns, greys) with some spread.
    base = np.array([[0.55, 0.75, 0.40], [0.75, 0.65, 0.50], [0.80, 0.80, 0.80],
                     [0.60, 0.55, 0.45], [0.85, 0.78, 0.62]])[int(rng.integers(5))]
    tint = np.clip(base * rng.uniform(0.75, 1.2) + rng.normal(0.0, 0.05, size=3), 0.15, 1.0)
    sky_lo, sky_hi = np.array([0.55, 0.68, 0.85]), np.array([0.88, 0.90, 0.93])
    sky = np.clip(sky_lo + rng.uniform() * (sky_hi - sky_lo) + rng.normal(0.0, 0.03, size=3), 0.0, 1.0)
    elev = math.radians(float(rng.uniform(25.0, 80.0)))
    az = float(rng.uniform(-math.pi, math.pi))
    light_dir = -np.array([math.cos(elev) * math.sin(az), math.sin(elev), math.cos(elev) * math.cos(az)])
    intensity = float(rng.uniform(0.6, 1.1))
    ambient = float(rng.uniform(0.25, 0.45))

    n = int(rng.integers(cfg.num_distractors[0], cfg.num_distractors[1] + 1))
    person_xz = np.asarray(person_xz, dtype=np.float64)
    cams_xz = np.asarray(camera_centres, dtype=np.float64)[:, [0, 2]]
    distractors: list[Distractor] = []
    for _ in range(n):
        kind = "box" if rng.uniform() < 0.5 else "cylinder"
        if kind == "box":
            size = np.array([rng.uniform(0.3, 1.5), rng.uniform(0.3, 1.8), rng.uniform(0.3, 1.5)])
        else:
            d = rng.uniform(0.2, 1.0)
            size = np.array([d, rng.uniform(0.4, 2.0), d])
        yaw = float(rng.uniform(0.0, math.pi))
        color = np.clip(rng.uniform(0.1, 0.9, size=3), 0.0, 1.0)
        radius = 0.5 * float(np.hypot(size[0], size[2]))
        for _ in range(max_tries):
            r = rng.uniform(*cfg.distractor_radius)
            a = rng.uniform(-math.pi, math.pi)
            pos = np.array([r * math.sin(a), r * math.cos(a)])
            gap = radius + cfg.distractor_clearance
            clear = np.linalg.norm(pos - person_xz) > gap + 0.5 and all(
                _segment_distance(pos, c, person_xz) > gap for c in cams_xz)
            if clear:
                distractors.append(Distractor(kind, pos, size, yaw, color))
                break
    return EnvironmentSample(tex, tile, rot, offset, tint, sky, light_dir, intensity, ambient,
                             distractors)
