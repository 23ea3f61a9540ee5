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
* **Person.** A :class:`~airpose_lib.data.sequences.motions.MotionScript` drawn for the person's style
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
  still-frame renderer :class:`airpose_lib.data.still.render.SceneRenderer` and appearance model.
* **Options, off by default** (off, they change neither a byte of a frame nor the settings that
  key the cache): ``field``, a camera pipeline that makes the frames behave like field footage
  (exposure, white balance, tone curve, sensor noise, motion blur, lens distortion,
  compression; :mod:`.field`); ``markers``, printed ArUco markers on the ground as in the
  paper's scene, from which each drone's pose and UAV 2 in UAV 1 can be measured
  (:mod:`airpose_lib.data.sequences.markers`; a profile's ``field_markers:`` puts them on its
  field recordings only, :mod:`.presets`).

Ground-truth arrays (:data:`GROUND_TRUTH_KEYS`; F frames, V views; the paper's root convention
``V_world = R_wb V0 + t_wb`` about the model origin, cameras OpenCV ``x_cam = R_cw x_world +
t_cw``) are documented in :func:`simulate_sequence`.

Modules: ``config`` (cameras, persons, flights, :class:`SequenceConfig`, a profile's recordings),
``motions`` (the person's motion scripts), ``flight`` (the drones' paths and camera poses),
``simulate`` (ground truth without pixels), ``detections`` (the simulated keypoint detectors),
``renderer`` (the frames), ``field`` (the opt-in field camera pipeline on them), ``markers``
(ArUco markers on the ground: detection, camera poses, UAV 2 in UAV 1), ``held_out``
(opt-in appearance the networks never saw: clothing colours, ground photograph, body shape),
``presets`` (named field presets and a profile's field recordings), ``recording`` (one
recording on disk, detector files), ``cache`` (a profile's recordings, made only when missing or
outdated). Every recording, kit or real, is in one folder layout: ``layout`` (its files and
names, the calibration), ``writer`` (:class:`~.writer.OfficialLayoutWriter`), ``reader``
(``load_sequence``), ``detector_files`` (the detector files' formats, one reader per format), ``mediapipe_pose``
(a real detector's landmarks as BODY_25 keypoints: MediaPipe Pose, run by
``scripts/mediapipe_detect.py`` in its own environment).

The names below are imported from their module on first use (``import
airpose_lib.data.sequences.reader`` stays light: no torch, no VTK).
"""
from __future__ import annotations

from airpose_lib._lazy import lazy_namespace

# name -> module, each name written once (a module's other names: import them from the module)
_EXPORTS = {
    "ensure_sequences": "cache",
    **dict.fromkeys(("PAPER_CAMERAS", "PERSONS", "SEQUENCE_GENERATOR_VERSION", "CameraSpec", "FlightConfig",
                     "PersonSpec", "SequenceConfig", "scale_intrinsics",
                     "sequence_configs_from_profile"), "config"),
    "FieldConfig": "field",
    "HeldOutConfig": "held_out",
    **dict.fromkeys(("FIELD_PRESETS", "field_variant", "field_sequence_configs_from_profile"), "presets"),
    "look_at_rotation": "flight",
    **dict.fromkeys(("generate_sequence", "recording_detections", "refresh_detections"), "recording"),
    **dict.fromkeys(("SequenceRenderer", "render_sequence"), "renderer"),
    **dict.fromkeys(("GROUND_TRUTH_KEYS", "SimulatedSequence", "simulate_sequence"), "simulate"),
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_namespace(__name__, globals(), (), _EXPORTS)
