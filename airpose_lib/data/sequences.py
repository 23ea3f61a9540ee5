"""Simulated two-drone recordings: a moving person, a hovering and a circling UAV, full frames.

Stands in for the paper's real data (Sec. IV-A "Real Data"): two DJI drones, one hovering, one
flown around a person who walks, turns, twists and moves the arms; about 7,000 frames per person
per drone at 1920x1080; person 1 for fine-tuning, person 2 (many twisting poses) for testing.
Unlike the real data, every frame here has complete ground truth (body pose and shape, world
root pose, per-camera extrinsics, per-view ``phi``/``tau``, 2D and 3D joints), so the kit can
*measure* what the paper could only plot.

Model of one recording (all numbers configurable in :class:`SequenceConfig`):

* **Time.** Camera ``v`` takes frame ``i`` at ``t = i / fps + time_offsets[v]`` (default 30 fps,
  offsets ``(0, 7 ms)``: a constant offset between the two devices, as the paper found when
  synchronising its recordings). Everything of a view, the person's pose included, is evaluated
  at that view's own time, so the two views of "frame i" see the person 7 ms apart.
* **Person.** A :class:`~airpose_lib.data.motions.MotionScript` drawn for the person's style
  (``varied`` for person 1, ``twisting`` for person 2), feet on the ground ``y = 0``.
* **UAV 1 hovers**: fixed position ``distance_m`` (camera to person) from the activity area,
  on a line of sight ``pitch_deg`` downwards, slow drift of a few centimetres, its gimbal partly follows the person
  (the person moves across the frame).
* **UAV 2 circles** the person: the orbit radius, the pitch and the orbit's angular position vary
  smoothly (radius in ``distance_m``, pitch in ``pitch_deg``), its camera keeps the person near
  the image centre with a small aiming wobble.
* **Cameras**: each view has its own intrinsics; by default the paper's two calibrated DJI
  cameras (``cam0`` f = (1537.83, 1517.66), c = (1018.55, 577.52); ``cam1`` f = (1361.11,
  1378.80), c = (978.02, 667.23); 1920x1080).
* **Rendering** scale: frames are rendered at ``render_scale`` times the full size (0.5 ->
  960x540) directly with the scaled intrinsics ``fx' = s fx``, ``cx' = s (cx + 0.5) - 0.5``
  (OpenCV pixel centres at integers; exactly what resizing a full frame by ``s`` does). The
  stored ``K``, image sizes and all 2D ground truth refer to the stored images. The scene (ground
  texture, sky, sun, background objects beyond the orbit, per-vertex clothing colours) reuses the
  still-frame renderer :class:`airpose_lib.data.render.SceneRenderer` and appearance model.

Ground-truth arrays (:data:`GROUND_TRUTH_KEYS`; F frames, V views; the paper's root convention
``V_world = R_wb V0 + t_wb`` about the model origin, cameras OpenCV ``x_cam = R_cw x_world +
t_cw``) are documented in :func:`simulate_sequence`.
"""
from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from airpose_lib.body.forward import rest_body
from airpose_lib.body.genders import GENDER_CODES
from airpose_lib.body.joint_sets import BODY_25_FROM_SMPLX, COCO18_FROM_SMPLX
from airpose_lib.profiles import profile_section

from .motions import MotionScript, evaluate_motion, sample_script, world_root_pose

#: Bumped whenever the same settings would produce a different recording.
SEQUENCE_GENERATOR_VERSION = 1

__all__ = [
    "CameraSpec",
    "PAPER_CAMERAS",
    "PersonSpec",
    "PERSONS",
    "FlightConfig",
    "SequenceConfig",
    "SimulatedSequence",
    "GROUND_TRUTH_KEYS",
    "scale_intrinsics",
    "simulate_sequence",
    "SequenceRenderer",
    "render_sequence",
    "generate_sequence",
    "recording_detections",
    "refresh_detections",
    "sequence_configs_from_profile",
    "profile_sequences",
    "default_sequence_root",
    "ensure_sequences",
    "SEQUENCE_GENERATOR_VERSION",
    "look_at_rotation",
]



# ------------------------------------------------------------------------------------------
# Cameras and persons

@dataclass(frozen=True)
class CameraSpec:
    """A drone camera: full-frame pinhole intrinsics (no distortion) and image size.

    Attributes:
        name: a label (``cam0``).
        fx, fy, cx, cy: pixels at full resolution (OpenCV convention).
        width, height: full-resolution image size in pixels.
    """

    name: str
    fx: float
    fy: float
    cx: float
    cy: float
    width: int = 1920
    height: int = 1080

    @property
    def K(self) -> np.ndarray:
        """(3, 3) full-resolution intrinsics."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def scaled(self, scale: float) -> tuple[np.ndarray, tuple[int, int]]:
        """Intrinsics (3, 3) and (W, H) of the image rendered at ``scale``."""
        size = (int(round(self.width * scale)), int(round(self.height * scale)))
        return scale_intrinsics(self.K, size[0] / self.width, size[1] / self.height), size


PAPER_CAMERAS: tuple[CameraSpec, CameraSpec] = (
    CameraSpec("cam0", 1537.83, 1517.66, 1018.55, 577.52),
    CameraSpec("cam1", 1361.11, 1378.80, 978.02, 667.23),
)
"""The paper's two calibrated DJI cameras (1920x1080): UAV 1 (hovering) and UAV 2 (circling)."""


def scale_intrinsics(K: np.ndarray, sx: float, sy: float | None = None) -> np.ndarray:
    """Intrinsics (..., 3, 3) of an image resized by ``sx`` (and ``sy``, default ``sx``).

    OpenCV puts pixel centres at integers, so a pixel coordinate maps as
    ``u' = sx (u + 0.5) - 0.5``: ``fx' = sx fx``, ``cx' = sx (cx + 0.5) - 0.5``.
    """
    sy = sx if sy is None else sy
    K = np.array(K, dtype=np.float64, copy=True)
    K[..., 0, 0] *= sx
    K[..., 0, 1] *= sx
    K[..., 1, 1] *= sy
    K[..., 0, 2] = sx * (K[..., 0, 2] + 0.5) - 0.5
    K[..., 1, 2] = sy * (K[..., 1, 2] + 0.5) - 0.5
    return K


@dataclass(frozen=True)
class PersonSpec:
    """One recorded person.

    Attributes:
        name: ``person1`` / ``person2``.
        gender: ``male``, ``female`` or ``neutral`` (the ground-truth model).
        betas: (10,) shape coefficients.
        style: motion style (:data:`airpose_lib.data.motions.PERSON_STYLES`).
        appearance_seed: seed of the clothing colours.
    """

    name: str
    gender: str
    betas: tuple[float, ...]
    style: str = "varied"
    appearance_seed: int = 0

    def __post_init__(self) -> None:
        if self.gender not in GENDER_CODES:
            raise ValueError(f"gender must be one of {tuple(GENDER_CODES)}, got {self.gender!r}")
        if len(self.betas) != 10:
            raise ValueError(f"betas must have 10 values, got {len(self.betas)}")


PERSONS: dict[str, PersonSpec] = {
    # Appearance seeds give clothes that stand out from the grass (beige shirt / dark trousers;
    # dark blue shirt / light trousers).
    # person 1 (fine-tuning): a taller male, varied activities
    "person1": PersonSpec("person1", "male", (0.8, 0.4, -0.3, 0.2, 0.0, -0.2, 0.1, 0.0, 0.1, -0.1),
                          style="varied", appearance_seed=3),
    # person 2 (test): a smaller female with many twisting poses, as in the paper
    "person2": PersonSpec("person2", "female", (-0.7, -0.5, 0.4, -0.2, 0.3, 0.1, -0.1, 0.2, 0.0, 0.1),
                          style="twisting", appearance_seed=2),
}
"""The two persons of the real-data protocol (fine-tune on person 1, test on person 2)."""


@dataclass(frozen=True)
class FlightConfig:
    """How the two drones fly.

    Attributes:
        distance_m: (min, max) distance of a drone's camera from the person (the point aimed
            at), metres.
        pitch_deg: (min, max) downward pitch of the line of sight to the person, degrees.
        aim_height_m: height above the ground of the point the cameras aim at (~the pelvis).
        hover_drift_m: amplitude of UAV 1's position drift (per axis), metres.
        hover_follow: share of the person's displacement UAV 1's gimbal follows (0 = fixed
            camera, 1 = always centred).
        orbit_period_s: time of one full orbit of UAV 2, seconds (sign picked at random).
        orbit_centre_follow: share of the person's displacement the orbit centre follows.
        aim_wobble_m: amplitude of the aiming error (smooth), metres at the person.
    """

    distance_m: tuple[float, float] = (8.0, 12.0)
    pitch_deg: tuple[float, float] = (15.0, 45.0)
    aim_height_m: float = 1.0
    hover_drift_m: float = 0.08
    hover_follow: float = 0.6
    orbit_period_s: float = 40.0
    orbit_centre_follow: float = 0.5
    aim_wobble_m: float = 0.2


@dataclass(frozen=True)
class SequenceConfig:
    """Everything that defines one generated recording.

    Attributes:
        person: a key of :data:`PERSONS` or a :class:`PersonSpec`.
        n_frames: frames per camera.
        fps: frame rate of both cameras.
        time_offsets: (V,) start time of each camera, seconds (camera 2 runs 7 ms behind).
        cameras: (V,) camera specs; default the paper's two DJI cameras.
        render_scale: rendered image size / full size (0.5 -> 960x540).
        seed: seed of the motion, the flights and the environment.
        flight: the drones' behaviour.
        jpeg_quality: quality of the stored frames.
        bbox_margin_px: full-resolution margin of the ground-truth person box (scaled with the
            image), as the still frames' joints +- 20 px.
        detector_seed: seed of the simulated keypoint detectors (None: derived from ``seed``).
        anti_aliasing: MSAA on the renders (as the still frames); about half the speed on a CPU.
    """

    person: str | PersonSpec = "person1"
    n_frames: int = 120
    fps: float = 30.0
    time_offsets: tuple[float, ...] = (0.0, 0.007)
    cameras: tuple[CameraSpec, ...] = PAPER_CAMERAS
    render_scale: float = 0.5
    seed: int = 0
    flight: FlightConfig = field(default_factory=FlightConfig)
    jpeg_quality: int = 92
    bbox_margin_px: float = 20.0
    detector_seed: int | None = None
    anti_aliasing: bool = True

    def __post_init__(self) -> None:
        if self.n_frames < 1:
            raise ValueError(f"n_frames must be >= 1, got {self.n_frames}")
        if not self.fps > 0:
            raise ValueError(f"fps must be > 0, got {self.fps}")
        if len(self.time_offsets) != len(self.cameras):
            raise ValueError(f"{len(self.time_offsets)} time offsets for {len(self.cameras)} cameras")
        if min(self.time_offsets) < 0:
            raise ValueError("time offsets must be >= 0")
        if not 0 < self.render_scale <= 1:
            raise ValueError(f"render_scale must be in (0, 1], got {self.render_scale}")

    @property
    def person_spec(self) -> PersonSpec:
        if isinstance(self.person, PersonSpec):
            return self.person
        if self.person not in PERSONS:
            raise ValueError(f"unknown person {self.person!r}; choose from {tuple(PERSONS)}")
        return PERSONS[self.person]

    @property
    def num_views(self) -> int:
        return len(self.cameras)

    def to_dict(self) -> dict:
        """Plain (JSON-able) settings, recorded with every generated sequence."""
        d = dataclasses.asdict(self)
        d["person"] = dataclasses.asdict(self.person_spec)
        return d

    @classmethod
    def from_dict(cls, d: Mapping) -> SequenceConfig:
        """Inverse of :meth:`to_dict`; also accepts a profile's YAML section (lists, names)."""
        d = dict(d)
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"unknown sequence setting(s) {unknown}; known: {sorted(known)}")
        if isinstance(d.get("person"), Mapping):
            p = dict(d["person"])
            p["betas"] = tuple(p["betas"])
            d["person"] = PersonSpec(**p)
        if "cameras" in d:
            d["cameras"] = tuple(c if isinstance(c, CameraSpec) else CameraSpec(**c) for c in d["cameras"])
        if isinstance(d.get("flight"), Mapping):
            d["flight"] = FlightConfig(**{k: tuple(v) if isinstance(v, list) else v
                                          for k, v in d["flight"].items()})
        if "time_offsets" in d:
            d["time_offsets"] = tuple(float(x) for x in d["time_offsets"])
        return cls(**d)


# ------------------------------------------------------------------------------------------
# Smooth random signals and drone flights (closed form in time: any camera time stamps)

class _SmoothNoise:
    """Sum of a few sinusoids with random frequencies and phases: smooth, zero-mean, bounded by
    ``amplitude`` per dimension; deterministic given the generator."""

    def __init__(self, rng: np.random.Generator, dims: int, amplitude: float,
                 freq_hz: tuple[float, float] = (0.03, 0.3), terms: int = 3) -> None:
        self.freq = rng.uniform(*freq_hz, size=(terms, dims))
        self.phase = rng.uniform(0, 2 * np.pi, size=(terms, dims))
        w = rng.uniform(0.5, 1.0, size=(terms, dims))
        self.weight = amplitude * w / w.sum(0, keepdims=True)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        """(T,) seconds -> (T, dims)."""
        t = np.asarray(t, dtype=np.float64)[:, None, None]
        return (self.weight * np.sin(2 * np.pi * self.freq * t + self.phase)).sum(1)


def look_at_rotation(eye: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World-to-camera ``R_cw (T, 3, 3)``, ``t_cw (T, 3)`` of level (no roll) OpenCV cameras at
    ``eye (T, 3)`` looking at ``target (T, 3)``; world Y up."""
    z = target - eye
    z = z / np.linalg.norm(z, axis=-1, keepdims=True)
    x = np.cross(z, np.array([0.0, 1.0, 0.0]))
    x = x / np.linalg.norm(x, axis=-1, keepdims=True)
    y = np.cross(z, x)
    R = np.stack([x, y, z], axis=-2)
    return R, -np.einsum("tij,tj->ti", R, eye)


class _Flights:
    """Closed-form positions and aim points of the hovering and the circling drone."""

    def __init__(self, rng: np.random.Generator, cfg: FlightConfig, centre_xz: np.ndarray) -> None:
        self.cfg = cfg
        self.centre = np.asarray(centre_xz, dtype=np.float64)
        d_lo, d_hi = cfg.distance_m
        p_lo, p_hi = np.deg2rad(cfg.pitch_deg)
        # UAV 1: the person roams +-2.75 m, so hover in the middle of the ranges.
        self.az1 = rng.uniform(-np.pi, np.pi)
        self.d1 = rng.uniform(d_lo + 0.25 * (d_hi - d_lo), d_hi)
        self.p1 = rng.uniform(p_lo + 0.25 * (p_hi - p_lo), p_hi - 0.25 * (p_hi - p_lo))
        self.drift = _SmoothNoise(rng, 3, cfg.hover_drift_m, (0.02, 0.15))
        self.aim1 = _SmoothNoise(rng, 3, cfg.aim_wobble_m, (0.02, 0.2))
        # UAV 2: starts 60-180 degrees around the circle from UAV 1.
        self.az2 = self.az1 + rng.choice([-1, 1]) * rng.uniform(np.pi / 3, np.pi)
        self.dir2 = float(rng.choice([-1, 1]))
        self.r_mid, self.r_amp = 0.5 * (d_lo + d_hi), 0.5 * (d_hi - d_lo)
        self.p_mid, self.p_amp = 0.5 * (p_lo + p_hi), 0.5 * (p_hi - p_lo)
        self.r_freq, self.r_phase = 1.0 / rng.uniform(15, 35), rng.uniform(0, 2 * np.pi)
        self.p_freq, self.p_phase = 1.0 / rng.uniform(20, 45), rng.uniform(0, 2 * np.pi)
        self.az_wobble = _SmoothNoise(rng, 1, 0.15, (0.03, 0.1))
        self.aim2 = _SmoothNoise(rng, 3, cfg.aim_wobble_m, (0.05, 0.3))

    def uav1(self, t: np.ndarray, pelvis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Eye (T, 3) and aim point (T, 3) of the hovering drone."""
        c = self.centre
        h = self.cfg.aim_height_m + self.d1 * math.sin(self.p1)
        horiz = self.d1 * math.cos(self.p1)
        base = np.array([c[0] + horiz * math.sin(self.az1), h, c[1] + horiz * math.cos(self.az1)])
        eye = base + self.drift(t)
        f = self.cfg.hover_follow
        target = np.stack([c[0] + f * (pelvis[:, 0] - c[0]),
                           np.full(len(t), self.cfg.aim_height_m) + f * (pelvis[:, 1] - self.cfg.aim_height_m),
                           c[1] + f * (pelvis[:, 2] - c[1])], -1)
        return eye, target + self.aim1(t)

    def uav2(self, t: np.ndarray, pelvis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Eye (T, 3) and aim point (T, 3) of the circling drone."""
        cfg = self.cfg
        az = (self.az2 + self.dir2 * 2 * np.pi * t / cfg.orbit_period_s + self.az_wobble(t)[:, 0])
        r = self.r_mid + self.r_amp * np.sin(2 * np.pi * self.r_freq * t + self.r_phase)
        pitch = self.p_mid + self.p_amp * np.sin(2 * np.pi * self.p_freq * t + self.p_phase)
        k = cfg.orbit_centre_follow
        cx = self.centre[0] + k * (pelvis[:, 0] - self.centre[0])
        cz = self.centre[1] + k * (pelvis[:, 2] - self.centre[1])
        # r and pitch refer to the person: the drone sits at distance r from the person's aim
        # point, in the direction of its (lagging) orbit position
        px, pz = pelvis[:, 0], pelvis[:, 2]
        horiz = r * np.cos(pitch)
        ex, ez = cx + horiz * np.sin(az), cz + horiz * np.cos(az)
        dx, dz = ex - px, ez - pz
        dist = np.hypot(dx, dz)
        ex, ez = px + dx * horiz / dist, pz + dz * horiz / dist
        eye = np.stack([ex, cfg.aim_height_m + r * np.sin(pitch), ez], -1)
        target = np.stack([px, pelvis[:, 1], pz], -1)
        return eye, target + self.aim2(t)


# ------------------------------------------------------------------------------------------
# Simulation (ground truth only, no pixels)

GROUND_TRUTH_KEYS: tuple[str, ...] = (
    "frame_index", "timestamps", "fps", "time_offsets", "K", "K_full", "image_size",
    "render_scale", "gender", "betas", "theta", "theta_view", "R_wb", "t_wb", "pelvis_world",
    "R_cw", "t_cw", "camera_center", "phi", "tau", "j3d_world", "j3d_cam", "j2d",
    "kp2d_body25", "kp2d_coco18", "kp_depth_body25", "kp_depth_coco18", "bbox",
    "person_size_px", "heading",
)


@dataclass
class SimulatedSequence:
    """A simulated recording before rendering.

    Attributes:
        config: the settings.
        script: the person's motion.
        gt: ground-truth arrays, keys :data:`GROUND_TRUTH_KEYS` (see :func:`simulate_sequence`).
    """

    config: SequenceConfig
    script: MotionScript
    gt: dict[str, np.ndarray]

    @property
    def num_frames(self) -> int:
        return int(self.gt["frame_index"].shape[0])

    @property
    def num_views(self) -> int:
        return int(self.gt["K"].shape[0])


_MODELS: dict[str, object] = {}


def _body_model(gender: str):
    """The open body model of a gender, float64, loaded once per process."""
    if gender not in _MODELS:
        import torch

        from airpose_lib.body import load_body_model

        _MODELS[gender] = load_body_model("open", gender, dtype=torch.float64)
    return _MODELS[gender]


def simulate_sequence(config: SequenceConfig, body_model=None) -> SimulatedSequence:
    """Simulate the motion, the flights and the cameras; compute all ground truth.

    Args:
        config: the recording's settings.
        body_model: the person's gendered ``smplx.SMPLX`` (default: the open model, float64).
    Returns:
        :class:`SimulatedSequence` whose ``gt`` holds (F frames, V views; 2D in pixels of the
        stored, scaled images):

        ==================== ============== =====================================================
        frame_index          (F,)           0..F-1
        timestamps           (F, V)         capture time of each view's frame, seconds
        fps, render_scale    ()
        time_offsets         (V,)           seconds
        K                    (V, 3, 3)      intrinsics of the stored images
        K_full               (V, 3, 3)      full-resolution intrinsics
        image_size           (V, 2)         stored (W, H)
        gender               ()  int64      0 neutral, 1 male, 2 female
        betas                (10,)
        theta                (F, 21, 3)     body pose at view 0's capture times
        theta_view           (F, V, 21, 3)  body pose at each view's capture time
        R_wb, t_wb           (F, V, 3, 3), (F, V, 3)   body in the world (model origin)
        pelvis_world         (F, V, 3)
        heading              (F, V)         the body's yaw, radians
        R_cw, t_cw           (F, V, 3, 3), (F, V, 3)   world -> camera extrinsics
        camera_center        (F, V, 3)      drone camera position in the world
        phi, tau             (F, V, 3, 3), (F, V, 3)   root rotation / translation per camera
        j3d_world, j3d_cam   (F, V, 22, 3)  the 22 body joints
        j2d                  (F, V, 22, 2)
        kp2d_body25          (F, V, 25, 2)  OpenPose BODY_25 keypoints projected
        kp2d_coco18          (F, V, 18, 2)  COCO-18 keypoints projected
        kp_depth_body25/coco18 (F, V, J)    keypoint depth along the optical axis, metres
        bbox                 (F, V, 4)      projected 76 joints +- margin, [x0, y0, x1, y1]
        person_size_px       (F, V)         larger side of the tight (margin-free) joint box
        ==================== ============== =====================================================
    """
    person = config.person_spec
    model = body_model if body_model is not None else _body_model(person.gender)
    ss = np.random.SeedSequence([config.seed, 7919])
    rng_motion, rng_flight = (np.random.default_rng(s) for s in ss.spawn(2))
    F, V = config.n_frames, config.num_views
    times = np.arange(F)[:, None] / config.fps + np.asarray(config.time_offsets)[None, :]  # (F, V)
    duration = float(times.max()) + 1.0
    script = sample_script(rng_motion, duration, person.style)
    state = evaluate_motion(script, times.reshape(-1))
    betas = np.asarray(person.betas, dtype=np.float64)
    R_wb, t_wb, pelvis = world_root_pose(state, model, betas)

    _, J0 = rest_body(model, np.broadcast_to(betas, (F * V, 10)), state.theta, mesh=False)
    Jw = np.einsum("tij,tkj->tki", R_wb, J0) + t_wb[:, None]  # (FV, 76, 3)

    flights = _Flights(rng_flight, config.flight, np.asarray(script.start_xz))
    pel = pelvis.reshape(F, V, 3)
    eyes, targets = np.zeros((F, V, 3)), np.zeros((F, V, 3))
    for v in range(V):
        fly = flights.uav1 if v == 0 else flights.uav2  # extra views circle too
        eyes[:, v], targets[:, v] = fly(times[:, v], pel[:, v])
    R_cw, t_cw = look_at_rotation(eyes.reshape(-1, 3), targets.reshape(-1, 3))

    Ks, sizes, Kf = [], [], []
    for cam in config.cameras:
        K, size = cam.scaled(config.render_scale)
        Ks.append(K)
        sizes.append(size)
        Kf.append(cam.K)
    K = np.stack(Ks)
    Kt = np.broadcast_to(K[None], (F, V, 3, 3)).reshape(-1, 3, 3)

    Jc = np.einsum("tij,tkj->tki", R_cw, Jw) + t_cw[:, None]  # (FV, 76, 3) camera frame
    uvw = np.einsum("tij,tkj->tki", Kt, Jc)
    uv = uvw[..., :2] / uvw[..., 2:3]
    scale = config.render_scale
    lo, hi = uv.min(1), uv.max(1)
    margin = config.bbox_margin_px * scale
    bbox = np.concatenate([lo - margin, hi + margin], -1)
    phi = R_cw @ R_wb
    tau = np.einsum("tij,tj->ti", R_cw, t_wb) + t_cw

    def fv(x):
        return x.reshape(F, V, *x.shape[1:])

    b25, c18 = list(BODY_25_FROM_SMPLX), list(COCO18_FROM_SMPLX)
    gt = {
        "frame_index": np.arange(F, dtype=np.int64),
        "timestamps": times,
        "fps": np.float64(config.fps),
        "time_offsets": np.asarray(config.time_offsets, dtype=np.float64),
        "K": K,
        "K_full": np.stack(Kf),
        "image_size": np.asarray(sizes, dtype=np.int64),
        "render_scale": np.float64(scale),
        "gender": np.int64(GENDER_CODES[person.gender]),
        "betas": betas,
        "theta": fv(state.theta)[:, 0].copy(),
        "theta_view": fv(state.theta),
        "R_wb": fv(R_wb),
        "t_wb": fv(t_wb),
        "pelvis_world": fv(pelvis),
        "heading": fv(state.heading),
        "R_cw": fv(R_cw),
        "t_cw": fv(t_cw),
        "camera_center": eyes,
        "phi": fv(phi),
        "tau": fv(tau),
        "j3d_world": fv(Jw[:, :22]),
        "j3d_cam": fv(Jc[:, :22]),
        "j2d": fv(uv[:, :22]),
        "kp2d_body25": fv(uv[:, b25]),
        "kp2d_coco18": fv(uv[:, c18]),
        "kp_depth_body25": fv(Jc[:, b25, 2]),
        "kp_depth_coco18": fv(Jc[:, c18, 2]),
        "bbox": fv(bbox),
        "person_size_px": fv(np.maximum(hi - lo, 0).max(-1)),
    }
    return SimulatedSequence(config, script, gt)


# ------------------------------------------------------------------------------------------
# Rendering

def _scene_renderer_class():
    # Imported lazily: VTK/pyvista start-up is only paid when frames are rendered.
    from .render import SceneRenderer

    class _Renderer(SceneRenderer):
        """SceneRenderer whose camera takes any pinhole K (fx != fy, off-centre principal point).

        The drones' calibrated cameras have non-square pixels, which a VTK view angle cannot
        express; the projection matrix is set explicitly instead (OpenGL clip space from K,
        the OpenCV pixel-centre convention and the near/far planes).
        """

        def _set_camera(self, K, R_cw, t_cw) -> None:
            W, H = self.image_size
            K = np.asarray(K, dtype=np.float64)
            if abs(K[0, 1]) > 1e-9:
                raise ValueError("skewed intrinsics (K[0, 1] != 0) are not supported")
            fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
            R = np.asarray(R_cw, dtype=np.float64)
            centre = -R.T @ np.asarray(t_cw, dtype=np.float64)
            cam = self._cam
            cam.SetPosition(*centre)
            cam.SetFocalPoint(*(centre + R[2]))
            cam.SetViewUp(*(-R[1]))
            n, f = self.near, self.far
            # View coordinates: x right, y up, camera looking down -z (VTK / OpenGL).
            # u = fx x/z + cx with OpenCV's x = x_v, y = -y_v, z = -z_v and NDC x = 2 (u + .5) / W - 1.
            P = np.array([
                [2 * fx / W, 0.0, 1.0 - 2.0 * (cx + 0.5) / W, 0.0],
                [0.0, 2 * fy / H, 2.0 * (cy + 0.5) / H - 1.0, 0.0],
                [0.0, 0.0, -(f + n) / (f - n), -2.0 * f * n / (f - n)],
                [0.0, 0.0, -1.0, 0.0],
            ])
            import vtk

            m = vtk.vtkMatrix4x4()
            for i in range(4):
                for j in range(4):
                    m.SetElement(i, j, float(P[i, j]))
            cam.SetExplicitProjectionTransformMatrix(m)
            cam.SetUseExplicitProjectionTransformMatrix(True)
            cam.SetClippingRange(n, f)
            self._pl.renderer.camera_set = True

    return _Renderer


class SequenceRenderer:
    """Renders a :class:`SimulatedSequence` frame by frame, one renderer per view size.

    Args:
        sim: the simulated sequence.
        body_model: the person's model (default: the open model of the person's gender).
        anti_aliasing: MSAA on edges (default: the sequence config's setting).
    """

    def __init__(self, sim: SimulatedSequence, body_model=None, anti_aliasing: bool | None = None) -> None:
        from .appearance import BodyPaint, sample_appearance
        from .scene import Distractor, EnvironmentSample

        self.sim = sim
        person = sim.config.person_spec
        self.model = body_model if body_model is not None else _body_model(person.gender)
        self.faces = np.asarray(self.model.faces, dtype=np.int64)
        self.colors = BodyPaint.from_model(self.model).colors(
            sample_appearance(np.random.default_rng(person.appearance_seed)))
        cls = _scene_renderer_class()
        if anti_aliasing is None:
            anti_aliasing = sim.config.anti_aliasing
        sizes = [tuple(int(x) for x in s) for s in sim.gt["image_size"]]
        self._renderers = {s: cls(s, anti_aliasing=anti_aliasing) for s in dict.fromkeys(sizes)}
        self._size_of_view = sizes
        # One fixed environment for the whole recording: a grass field, a clear sky, the sun,
        # and a few objects beyond the orbit (they never come between a drone and the person).
        rng = np.random.default_rng([sim.config.seed, 31337])
        first = next(iter(self._renderers.values()))
        tex = first.texture_names.index("grass") if "grass" in first.texture_names else 0
        centre = np.asarray(sim.script.start_xz)
        dist = []
        for _ in range(8):
            a, r = rng.uniform(-np.pi, np.pi), rng.uniform(16.0, 35.0)
            kind = "box" if rng.random() < 0.5 else "cylinder"
            size = np.array([rng.uniform(0.5, 3.0), rng.uniform(0.5, 3.0), rng.uniform(0.5, 3.0)])
            if kind == "cylinder":
                size[2] = size[0]
            dist.append(Distractor(kind, centre + r * np.array([np.sin(a), np.cos(a)]), size,
                                   float(rng.uniform(0, np.pi)), rng.uniform(0.2, 0.8, 3)))
        elev, az = np.deg2rad(rng.uniform(35, 65)), rng.uniform(-np.pi, np.pi)
        self.environment = EnvironmentSample(
            ground_texture=tex, ground_tile=3.0, ground_rotation=float(rng.uniform(0, np.pi)),
            ground_offset=rng.uniform(0, 1, 2), ground_tint=np.array([0.55, 0.72, 0.40]),
            sky_color=np.array([0.68, 0.80, 0.92]),
            light_dir=-np.array([np.cos(elev) * np.sin(az), np.sin(elev), np.cos(elev) * np.cos(az)]),
            light_intensity=0.9, ambient=0.35, distractors=dist)
        for r in self._renderers.values():
            r.set_environment(self.environment)

    def render_frames(self, frames=None, chunk: int = 32) -> Iterator[tuple[int, list[np.ndarray]]]:
        """Yield ``(frame_index, [image (H, W, 3) uint8 RGB per view])`` in order."""
        gt = self.sim.gt
        F, V = self.sim.num_frames, self.sim.num_views
        frames = np.arange(F) if frames is None else np.asarray(list(frames), dtype=np.int64)
        betas = gt["betas"]
        for a in range(0, len(frames), chunk):
            idx = frames[a:a + chunk]
            theta = gt["theta_view"][idx].reshape(-1, 21, 3)
            v0, _ = rest_body(self.model, np.broadcast_to(betas, (len(theta), 10)), theta)
            v0 = v0.reshape(len(idx), V, -1, 3)
            for k, i in enumerate(idx):
                images = []
                for v in range(V):
                    R_wb, t_wb = gt["R_wb"][i, v], gt["t_wb"][i, v]
                    r = self._renderers[self._size_of_view[v]]
                    r.set_body(v0[k, v] @ R_wb.T + t_wb, self.faces, self.colors)
                    images.append(r.render(gt["K"][v], gt["R_cw"][i, v], gt["t_cw"][i, v]))
                yield int(i), images

    def close(self) -> None:
        for r in self._renderers.values():
            r.close()

    def __enter__(self) -> SequenceRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def render_sequence(sim: SimulatedSequence, frames=None, body_model=None) -> list[list[np.ndarray]]:
    """All (or the given) frames in memory: ``[[image per view] per frame]``; for previews."""
    with SequenceRenderer(sim, body_model) as r:
        return [imgs for _, imgs in r.render_frames(frames)]


# ------------------------------------------------------------------------------------------
# Everything: simulate, detect, render, write the official layout

def generate_sequence(config: SequenceConfig, root: str | Path, *, progress: bool = False,
                      body_model=None) -> dict:
    """Simulate a recording, simulate both keypoint detectors, render the frames and store it in
    the official real-data layout (:mod:`airpose_lib.data.official_layout`) under ``root``.

    Returns:
        a summary dict: ``root``, ``num_frames``, ``render_seconds``, ``frames_per_second``
        (rendered images per second, all views counted), ``config``.
    """
    from .detections import DETECTOR_VERSION, detection_summary
    from .official_layout import OfficialLayoutWriter

    sim = simulate_sequence(config, body_model)
    detections = recording_detections(sim.gt, config)
    writer = OfficialLayoutWriter(root, sim.num_views, jpeg_quality=config.jpeg_quality)
    t0 = time.perf_counter()
    bar = None
    if progress:
        from airpose_lib.progress import progress_bar

        bar = progress_bar(total=sim.num_frames, desc=f"render {config.person_spec.name}", unit="frame")
    with SequenceRenderer(sim, body_model, anti_aliasing=config.anti_aliasing) as renderer:
        for i, images in renderer.render_frames():
            writer.write_frame(i, images)
            if bar is not None:
                bar.update(1)
    if bar is not None:
        bar.close()
    seconds = time.perf_counter() - t0
    writer.finish(K=sim.gt["K"], keypoints={k: d.keypoints for k, d in detections.items()},
                  timestamps=sim.gt["timestamps"], ground_truth=sim.gt,
                  meta={"generator_version": SEQUENCE_GENERATOR_VERSION, "config": config.to_dict(),
                        "script": [dataclasses.asdict(s) for s in sim.script.segments],
                        "render_seconds": seconds, "detector_version": DETECTOR_VERSION,
                        "detections": {k: detection_summary(d) for k, d in detections.items()}})
    n_img = sim.num_frames * sim.num_views
    return {"root": str(Path(root)), "num_frames": sim.num_frames, "render_seconds": seconds,
            "frames_per_second": n_img / max(seconds, 1e-9), "config": config.to_dict()}


def recording_detections(gt: Mapping[str, np.ndarray], config: SequenceConfig) -> dict:
    """Both simulated detectors on a recording's ground truth (``data.detections``): name ->
    :class:`~airpose_lib.data.detections.Detections`, seeded by ``config.detector_seed`` (default
    ``seed + 1``) and the detector's position."""
    from .detections import DEFAULT_DETECTORS, simulate_detections

    det_seed = config.detector_seed if config.detector_seed is not None else config.seed + 1
    return {name: simulate_detections(gt, det, seed=[det_seed, k])
            for k, (name, det) in enumerate(DEFAULT_DETECTORS.items())}


def refresh_detections(root: str | Path, config: SequenceConfig) -> dict:
    """Re-simulate the detector files of a rendered recording from its ``ground_truth.npz`` (the
    images stay): what :func:`ensure_sequences` does when only the detector model changed
    (:data:`~airpose_lib.data.detections.DETECTOR_VERSION`). Returns the new summaries."""
    import json

    from .detections import DETECTOR_VERSION, detection_summary
    from .official_layout import DETECTOR_FILES, OfficialLayoutWriter, load_sequence

    root = Path(root)
    with np.load(root / "ground_truth.npz") as z:
        gt = {k: z[k] for k in z.files}
    frames = [int(i) for i in load_sequence(root, detectors=(), ground_truth=False).frames]
    detections = recording_detections(gt, config)
    for name, det in detections.items():
        for v in range(config.num_views):
            path = root / f"machine_{v + 1}" / DETECTOR_FILES[name][0]
            w = OfficialLayoutWriter
            (w._write_openpose if name == "openpose" else w._write_alphapose)(path, frames, det.keypoints[:, v])
    meta_path = root / "sequence.json"
    meta = json.loads(meta_path.read_text())
    meta.update(detector_version=DETECTOR_VERSION,
                detections={k: detection_summary(d) for k, d in detections.items()})
    tmp = meta_path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(meta, indent=1))
    tmp.replace(meta_path)
    return meta["detections"]


def sequence_configs_from_profile(profile_section: Mapping) -> dict[str, SequenceConfig]:
    """Sequence configs from a profile's ``sequences:`` section.

    The section has shared settings at the top and one entry per recording under ``recordings``,
    e.g. ``{fps: 30, render_scale: 0.5, recordings: {person1: {n_frames: 90, seed: 1}, ...}}``;
    each recording's ``person`` defaults to its name.
    """
    section = dict(profile_section)
    recordings = section.pop("recordings", None)
    if not recordings:
        raise ValueError("a `sequences:` profile section needs a `recordings:` mapping")
    out = {}
    for name, rec in recordings.items():
        d = {**section, **(rec or {})}
        d.setdefault("person", name)
        out[name] = SequenceConfig.from_dict(d)
    return out


def profile_sequences(profile: str) -> dict[str, SequenceConfig]:
    """The recordings of a reproduction profile (its ``sequences:`` section, :mod:`airpose_lib.profiles`)."""
    return sequence_configs_from_profile(profile_section(profile, "sequences", required="the recordings' sizes"))


def default_sequence_root(profile: str) -> Path:
    """Where a profile's recordings live by default: ``<kit cache>/data/sequences_<profile>``."""
    from airpose_lib.body.cache import cache_dir

    return cache_dir() / "data" / f"sequences_{profile}"


def _detections_current(root: Path) -> bool:
    import json

    from .detections import DETECTOR_VERSION

    try:
        return json.loads((root / "sequence.json").read_text()).get("detector_version") == DETECTOR_VERSION
    except (OSError, json.JSONDecodeError):
        return False


def _is_complete(root: Path, config: SequenceConfig) -> bool:
    """The images and ground truth of ``config`` are all there (the detections may be outdated)."""
    import json

    meta_path = root / "sequence.json"
    if not meta_path.is_file() or not (root / "ground_truth.npz").is_file():
        return False
    try:
        meta = json.loads(meta_path.read_text())
    except json.JSONDecodeError:
        return False
    same = (meta.get("generator_version") == SEQUENCE_GENERATOR_VERSION
            and json.loads(json.dumps(config.to_dict())) == meta.get("config"))
    if not same:
        return False
    return all(len(list((root / f"machine_{v + 1}" / "images").glob("*.jpg"))) == config.n_frames
               for v in range(config.num_views))


def ensure_sequences(profile: str | None = None, root: str | Path | None = None, *,
                     configs: Mapping[str, SequenceConfig] | None = None, only=None,
                     force: bool = False, progress: bool = False) -> dict[str, Path]:
    """Generate a profile's recordings unless an identical complete copy exists.

    Args:
        profile: reproduction profile whose ``sequences:`` section lists the recordings.
        root: parent folder (default :func:`default_sequence_root`); recording ``name`` goes to
            ``root/name``.
        configs: recordings to make instead of a profile's.
        only: names to make (default: all).
        force: regenerate even if complete.
    Returns:
        name -> sequence folder (read it with
        :func:`airpose_lib.data.official_layout.load_sequence`).
    """
    import shutil

    if configs is None:
        if profile is None:
            raise ValueError("give a profile or configs")
        configs = profile_sequences(profile)
    if root is None:
        if profile is None:
            raise ValueError("give root when no profile is given")
        root = default_sequence_root(profile)
    root = Path(root)
    names = list(configs) if only is None else list(only)
    unknown = [n for n in names if n not in configs]
    if unknown:
        raise ValueError(f"unknown recording(s) {unknown}; available: {list(configs)}")
    out = {}
    for name in names:
        folder = root / name
        if force or not _is_complete(folder, configs[name]):
            partial = folder.with_name(folder.name + ".partial")
            if partial.exists():
                shutil.rmtree(partial)  # left by an interrupted run
            generate_sequence(configs[name], partial, progress=progress)
            if folder.exists():
                shutil.rmtree(folder)  # outdated
            partial.rename(folder)
        elif not _detections_current(folder):
            refresh_detections(folder, configs[name])  # a new detector model: no re-rendering
        out[name] = folder
    return out
