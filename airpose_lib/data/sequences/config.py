"""Settings of a simulated recording: the drone cameras, the persons, the flights, and the
recording as a whole (:class:`SequenceConfig`, also built from a profile's ``sequences:``
section)."""
from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from airpose_lib.body.genders import GENDER_CODES
from airpose_lib.config_fields import check_fields, config_from, ranged
from airpose_lib.errors import ConfigError, ProfileError, ProfileSettingError

from .field import FieldConfig
from .held_out import HeldOutConfig
from .markers import MarkerLayout, marker_layout

__all__ = [
    "CameraSpec",
    "PAPER_CAMERAS",
    "scale_intrinsics",
    "PersonSpec",
    "PERSONS",
    "FlightConfig",
    "SequenceConfig",
    "SEQUENCE_GENERATOR_VERSION",
    "sequence_configs_from_profile",
    ]

#: Bumped whenever the same settings would produce a different recording.
SEQUENCE_GENERATOR_VERSION = 1


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
        style: motion style (:data:`airpose_lib.data.sequences.motions.PERSON_STYLES`).
        appearance_seed: seed of the clothing colours.
    """

    name: str
    gender: str
    betas: tuple[float, ...]
    style: str = "varied"
    appearance_seed: int = 0

    def __post_init__(self) -> None:
        if self.gender not in GENDER_CODES:
            raise ConfigError(f"gender must be one of {tuple(GENDER_CODES)}, got {self.gender!r}")
        if len(self.betas) != 10:
            raise ConfigError(f"betas must have 10 values, got {len(self.betas)}")


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
        fps: frame rate of the recording: the frames kept, per camera and second.
        video_fps: the rate the cameras film at when the recording keeps fewer frames than they
            film (e.g. the paper's 7,000 frames of 30 fps video spanned at 6 fps: ``fps: 6,
            video_fps: 30``, every fifth frame); what happens within one video frame follows it,
            not ``fps``: the field pipeline's motion blur (the shutter is open for a share of a
            video frame) and the detectors' frame-to-frame correlation. None (default): ``fps``,
            every video frame kept; then absent from :meth:`to_dict` (the cache key).
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
        field: the field camera pipeline on the rendered frames (:mod:`.field`); off by default,
            and then absent from :meth:`to_dict` (the recordings' cache key), so the clean
            recordings keep their key and every byte.
        markers: ArUco markers printed on the ground (:class:`~airpose_lib.data.sequences.markers.MarkerLayout`,
            world coordinates), as in the paper's scene; None (default) = none, and then absent
            from :meth:`to_dict` like ``field``. A profile turns the default layout on with
            ``markers: {}`` (every recording) or ``field_markers: {}`` (the field twins only,
            :func:`~.presets.field_sequence_configs_from_profile`).
        held_out: appearance the networks never saw (:mod:`.held_out`: clothing colours, a
            ground photograph, a body shape outside the still frames' draw); off by default,
            and then absent from :meth:`to_dict` like ``field``.
    """

    person: str | PersonSpec = "person1"
    n_frames: int = ranged(120, ge=1)
    fps: float = ranged(30.0, gt=0)
    video_fps: float | None = None
    time_offsets: tuple[float, ...] = (0.0, 0.007)
    cameras: tuple[CameraSpec, ...] = PAPER_CAMERAS
    render_scale: float = ranged(0.5, gt=0, le=1)
    seed: int = 0
    flight: FlightConfig = dataclasses.field(default_factory=FlightConfig)
    jpeg_quality: int = ranged(92, ge=1, le=100)
    bbox_margin_px: float = ranged(20.0, ge=0)
    detector_seed: int | None = None
    anti_aliasing: bool = True
    field: FieldConfig = FieldConfig()
    markers: MarkerLayout | None = None
    held_out: HeldOutConfig = HeldOutConfig()

    def __post_init__(self) -> None:
        check_fields(self, convert=False)  # types and declared ranges (ints stay ints: the cache key)
        if self.video_fps is not None and not self.video_fps >= self.fps:
            raise ConfigError(f"video_fps must be null or >= fps ({self.fps}): the recording keeps some of the "
                              f"video's frames, got {self.video_fps}")
        if len(self.time_offsets) != len(self.cameras):
            raise ConfigError(f"{len(self.time_offsets)} time offsets for {len(self.cameras)} cameras")
        if min(self.time_offsets) < 0:
            raise ConfigError("time offsets must be >= 0")

    @property
    def person_spec(self) -> PersonSpec:
        if isinstance(self.person, PersonSpec):
            return self.person
        if self.person not in PERSONS:
            raise ConfigError(f"unknown person {self.person!r}; choose from {tuple(PERSONS)}")
        return PERSONS[self.person]

    @property
    def num_views(self) -> int:
        return len(self.cameras)

    def to_dict(self) -> dict:
        """Plain (JSON-able) settings, recorded with every generated sequence."""
        d = dataclasses.asdict(self)
        d["person"] = dataclasses.asdict(self.person_spec)
        # Options that are off leave the settings (and the cache key) as before they existed.
        if not self.field.enabled:
            del d["field"]
        if self.markers is None:
            del d["markers"]
        if not self.held_out.enabled:
            del d["held_out"]
        if self.video_fps is None:
            del d["video_fps"]
        return d

    @property
    def frame_step(self) -> float:
        """Video frames from one kept frame to the next: ``video_fps / fps`` (1: every frame kept)."""
        return 1.0 if self.video_fps is None else float(self.video_fps) / float(self.fps)

    @classmethod
    def from_dict(cls, d: Mapping) -> SequenceConfig:
        """Inverse of :meth:`to_dict`; also accepts a profile's YAML section (lists, names)."""
        d = dict(d)
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ProfileError(f"unknown sequence setting(s) {unknown}; known: {sorted(known)}")
        if isinstance(d.get("person"), Mapping):
            p = dict(d["person"])
            p["betas"] = tuple(p["betas"])
            d["person"] = PersonSpec(**p)
        if "cameras" in d:
            d["cameras"] = tuple(c if isinstance(c, CameraSpec) else CameraSpec(**c) for c in d["cameras"])
        if isinstance(d.get("flight"), Mapping):
            d["flight"] = config_from(FlightConfig, {k: tuple(v) if isinstance(v, list) else v
                                                     for k, v in d["flight"].items()}, "flight")
        if "time_offsets" in d:
            d["time_offsets"] = tuple(float(x) for x in d["time_offsets"])
        if isinstance(d.get("field"), Mapping):
            d["field"] = config_from(FieldConfig, d["field"], "field")
        if "markers" in d:
            d["markers"] = marker_layout(d["markers"], "markers:", ProfileSettingError)
        if isinstance(d.get("held_out"), Mapping):
            d["held_out"] = config_from(HeldOutConfig, d["held_out"], "held_out")
        return cls(**d)


# ------------------------------------------------------------------------------------------
# From a reproduction profile

def sequence_configs_from_profile(profile_section: Mapping,
                                  where: str = "a `sequences:` profile section") -> dict[str, SequenceConfig]:
    """Sequence configs from a profile's ``sequences:`` section.

    The section has shared settings at the top and one entry per recording under ``recordings``,
    e.g. ``{fps: 30, render_scale: 0.5, recordings: {person1: {n_frames: 90, seed: 1}, ...}}``;
    each recording's ``person`` defaults to its name. Each recording's settings go through
    ``config_fields.config_from`` (unknown keys with the closest one, named with ``where``), as
    every profile section does (``profiles.section_config``).
    """
    section = dict(profile_section)
    recordings = section.pop("recordings", None)
    section.pop("field_recordings", None)  # the field twins' preset (.presets.field_sequence_configs_from_profile)
    section.pop("field_markers", None)  # the field twins' markers (the same)
    if not recordings:
        raise ProfileError(f"{where} needs a `recordings:` mapping")
    out = {}
    for name, rec in recordings.items():
        d = {**section, **(rec or {})}
        d.setdefault("person", name)
        out[name] = config_from(SequenceConfig, d, f"{where} `recordings: {name}:`", build=SequenceConfig.from_dict,
                                error=ProfileSettingError)
    return out
