"""Simulation of a recording without pixels: the person's motion, the drones' flights and
cameras, and every ground-truth array of every frame and view (:func:`simulate_sequence`)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from airpose_lib.body import load_body_model
from airpose_lib.body.forward import rest_body
from airpose_lib.body.genders import GENDER_CODES
from airpose_lib.body.joint_sets import BODY_25_FROM_SMPLX, COCO18_FROM_SMPLX

from .config import SequenceConfig
from .flight import Flights, look_at_rotation
from .held_out import held_out_betas
from .motions import MotionScript, evaluate_motion, sample_script, world_root_pose

__all__ = ["GROUND_TRUTH_KEYS", "SimulatedSequence", "person_body_model", "recording_script", "simulate_sequence"]


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


def person_body_model(gender: str):
    """The open body model of a gender, float64, loaded once per process (simulation and
    rendering share it)."""
    if gender not in _MODELS:
        _MODELS[gender] = load_body_model("open", gender, dtype=torch.float64)
    return _MODELS[gender]


def _streams(config: SequenceConfig) -> tuple[np.random.Generator, np.random.Generator]:
    """The recording's motion and flight random streams (independent children of its seed)."""
    ss = np.random.SeedSequence([config.seed, 7919])
    rng_motion, rng_flight = (np.random.default_rng(s) for s in ss.spawn(2))
    return rng_motion, rng_flight


def _frame_times(config: SequenceConfig) -> np.ndarray:
    """(F, V) capture time of every frame of every camera, seconds."""
    return np.arange(config.n_frames)[:, None] / config.fps + np.asarray(config.time_offsets)[None, :]


def recording_script(config: SequenceConfig) -> MotionScript:
    """The motion script of a recording, as :func:`simulate_sequence` draws it (no body model,
    no rendering): e.g. which activities a recording shows (``prior: held_out_motions:``)."""
    return sample_script(_streams(config)[0], float(_frame_times(config).max()) + 1.0,
                         config.person_spec.style)


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
    model = body_model if body_model is not None else person_body_model(person.gender)
    _, rng_flight = _streams(config)
    F, V = config.n_frames, config.num_views
    times = _frame_times(config)
    script = recording_script(config)
    state = evaluate_motion(script, times.reshape(-1))
    betas = held_out_betas(person.betas, config.held_out)  # the person's own unless held_out says
    R_wb, t_wb, pelvis = world_root_pose(state, model, betas)

    _, J0 = rest_body(model, np.broadcast_to(betas, (F * V, 10)), state.theta, mesh=False)
    Jw = np.einsum("tij,tkj->tki", R_wb, J0) + t_wb[:, None]  # (FV, 76, 3)

    flights = Flights(rng_flight, config.flight, np.asarray(script.start_xz))
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

