"""Plausible SMPL-X body poses: motion primitives, anatomical joint limits, small perturbations.

A body pose ``theta`` is (21, 3) axis-angle for the SMPL-X joints 1..21 (left_hip ...
right_wrist, :data:`airpose_lib.body.SMPLX_JOINT_NAMES`), each rotation relative to the parent
and expressed in the rest-pose (T-pose) axes of the model: x = the subject's left, y = up,
z = forward. With these axes

* knee flexion (foot goes backwards) is ``+x``; hip flexion (thigh forwards) is ``-x``;
* spine / neck forward bend is ``+x``, twist is ``y``, lateral bend is ``z``;
* ankle plantar flexion (toes down) is ``+x``;
* left elbow flexion is ``-y``, right elbow flexion ``+y`` (the forearm comes forwards from the
  T-pose); the left arm is lowered with ``-z``, the right one with ``+z``.

Poses are built from a small set of interpretable *pose parameters* (spine bend, arm flexion /
abduction, knee flexion, ...; see :data:`PARAM_NAMES` and :func:`compose_pose`) so that the same
builder serves still frames (parameters drawn per motion primitive, :func:`sample_body_pose`) and
continuous motions (parameters varied smoothly over time, :mod:`airpose_lib.data.sequences.motions`).
Every pose is finally clipped to :data:`joint_limits`, a box on the axis-angle components per
joint (:data:`JOINT_LIMITS_DEG`, degrees), so that no sample leaves the anatomical ranges.

Arm directions use two angles relative to the torso: ``flex`` swings the arm forwards in the
sagittal plane (0 = hanging, 90 deg = pointing forwards, 180 deg = overhead) and ``abd`` raises
it sideways in the coronal plane (90 deg = T-pose). The shoulder gets the shortest rotation from
the T-pose direction to that direction, then a twist about the arm; above the horizontal the
collar bone takes a share (a shrug).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from airpose_lib.body.joint_sets import SMPLX_JOINT_NAMES

__all__ = [
    "POSE_JOINT_NAMES",
    "PRIMITIVES",
    "PARAM_NAMES",
    "JOINT_LIMITS_DEG",
    "joint_limits",
    "clip_to_limits",
    "within_limits",
    "compose_pose",
    "neutral_params",
    "primitive_params",
    "walking_params",
    "sample_body_pose",
]

POSE_JOINT_NAMES: tuple[str, ...] = SMPLX_JOINT_NAMES[1:22]
"""The 21 joints of ``theta`` in order (joint 0, the pelvis, is the root and not part of it)."""
_J = {name: i for i, name in enumerate(POSE_JOINT_NAMES)}

# Per-joint limits on the axis-angle components (x, y, z) in degrees: (low, high). Ranges follow
# textbook active ranges of motion, narrowed where the SMPL-X joint only carries part of a
# movement (the spine's bend is shared by three joints, the neck's by neck and head). Single-axis
# joints (knee, elbow) are exactly their flexion angle in one component.
JOINT_LIMITS_DEG: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = {
    # hips: flexion -x up to 125, extension 35; twist +-40; abduction 50 / adduction 25
    "left_hip": ((-125.0, -40.0, -25.0), (35.0, 40.0, 50.0)),
    "right_hip": ((-125.0, -40.0, -50.0), (35.0, 40.0, 25.0)),
    # lumbar spine: forward 45 / back 20, twist 25, lateral 20
    "spine1": ((-20.0, -25.0, -20.0), (45.0, 25.0, 20.0)),
    # knees: flexion 0..150 only, a little play about the other axes
    "left_knee": ((0.0, -10.0, -8.0), (150.0, 10.0, 8.0)),
    "right_knee": ((0.0, -10.0, -8.0), (150.0, 10.0, 8.0)),
    "spine2": ((-15.0, -25.0, -20.0), (35.0, 25.0, 20.0)),
    # ankles: dorsiflexion 30 (-x), plantar flexion 50 (+x), inversion/eversion and twist 25
    "left_ankle": ((-30.0, -25.0, -25.0), (50.0, 25.0, 25.0)),
    "right_ankle": ((-30.0, -25.0, -25.0), (50.0, 25.0, 25.0)),
    "spine3": ((-15.0, -25.0, -20.0), (35.0, 25.0, 20.0)),
    # toes (SMPL-X "foot" joints): bend only
    "left_foot": ((-40.0, -10.0, -10.0), (25.0, 10.0, 10.0)),
    "right_foot": ((-40.0, -10.0, -10.0), (25.0, 10.0, 10.0)),
    "neck": ((-30.0, -40.0, -25.0), (40.0, 40.0, 25.0)),
    # collar bones: a shrug (elevation) of ~30 and some protraction
    "left_collar": ((-15.0, -25.0, -15.0), (15.0, 20.0, 30.0)),
    "right_collar": ((-15.0, -20.0, -30.0), (15.0, 25.0, 15.0)),
    "head": ((-30.0, -40.0, -25.0), (35.0, 40.0, 25.0)),
    # shoulders: the ball joint covers hanging (z = -+90) to overhead with the collar's share
    "left_shoulder": ((-100.0, -110.0, -100.0), (100.0, 60.0, 95.0)),
    "right_shoulder": ((-100.0, -60.0, -95.0), (100.0, 110.0, 100.0)),
    # elbows: flexion 0..150 only (-y left, +y right), forearm roll +-40 about the arm (x)
    "left_elbow": ((-40.0, -150.0, -15.0), (40.0, 0.0, 15.0)),
    "right_elbow": ((-40.0, 0.0, -15.0), (40.0, 150.0, 15.0)),
    # wrists: flexion/extension 70 (z), deviation 35 (y), roll 50 (x)
    "left_wrist": ((-50.0, -35.0, -70.0), (50.0, 35.0, 70.0)),
    "right_wrist": ((-50.0, -35.0, -70.0), (50.0, 35.0, 70.0)),
}

joint_limits: np.ndarray = np.deg2rad(
    np.array([JOINT_LIMITS_DEG[name] for name in POSE_JOINT_NAMES], dtype=np.float64)
)
"""(21, 2, 3) radians: ``joint_limits[j, 0]`` the lower and ``joint_limits[j, 1]`` the upper bound
of the axis-angle components of joint ``POSE_JOINT_NAMES[j]``."""
joint_limits.setflags(write=False)

PRIMITIVES: tuple[str, ...] = (
    "standing", "walking", "reaching", "squatting", "twisting", "arms_raised", "bending",
    "crouching",
)
"""Motion primitives :func:`sample_body_pose` mixes (``crouching`` is the sitting-like one)."""

_SIDE_PARAMS = (
    "arm_flex", "arm_abd", "arm_twist", "elbow", "forearm_roll", "wrist_flex", "wrist_dev",
    "hip_flex", "hip_abd", "hip_twist", "knee", "ankle", "toe",
)
PARAM_NAMES: tuple[str, ...] = (
    "spine_bend", "spine_twist", "spine_side", "head_pitch", "head_yaw", "head_roll",
    *(f"{s}_{p}" for s in ("l", "r") for p in _SIDE_PARAMS),
)
"""Pose parameters of :func:`compose_pose`, all in radians. ``l_``/``r_`` = subject's left/right.

spine_bend (+ forwards), spine_twist (+ turns the chest to the subject's left), spine_side
(+ leans to the subject's right), head_pitch (+ looks down), head_yaw (+ left), head_roll
(+ tilts to the right);
per side: arm_flex, arm_abd (see module doc), arm_twist (about the upper arm), elbow (flexion
>= 0), forearm_roll, wrist_flex, wrist_dev, hip_flex (+ thigh forwards), hip_abd (+ outwards),
hip_twist (+ outwards), knee (flexion >= 0), ankle (+ toes down), toe (+ toes up).
"""

# Share of the trunk movement carried by spine1, spine2, spine3 and of the head's by neck, head.
_SPINE_SHARE = np.array([0.4, 0.3, 0.3])
_NECK_SHARE = np.array([0.5, 0.5])


def clip_to_limits(theta: np.ndarray) -> np.ndarray:
    """Clip axis-angle poses (..., 21, 3) component-wise into :data:`joint_limits`."""
    return np.clip(theta, joint_limits[:, 0], joint_limits[:, 1])


def within_limits(theta: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """(...,) bool: every component of the pose (..., 21, 3) lies inside :data:`joint_limits`."""
    lo, hi = joint_limits[:, 0], joint_limits[:, 1]
    return np.all((theta >= lo - tol) & (theta <= hi + tol), axis=(-2, -1))


def neutral_params(n: int) -> dict[str, np.ndarray]:
    """All pose parameters zero (upright, arms hanging, legs straight): name -> (n,) float64."""
    return {name: np.zeros(n) for name in PARAM_NAMES}


def _arm_rotations(flex, abd, twist, side: float) -> tuple[np.ndarray, np.ndarray]:
    """Collar and shoulder axis-angle (n, 3) for arm directions given by flex/abd (n,) radians."""
    n = flex.shape[0]
    d = np.stack([side * np.sin(abd), -np.cos(abd) * np.cos(flex), np.cos(abd) * np.sin(flex)], -1)
    rest = np.array([side, 0.0, 0.0])
    axis = np.cross(np.broadcast_to(rest, d.shape), d)
    s = np.linalg.norm(axis, axis=-1, keepdims=True)
    c = d @ rest
    angle = np.arctan2(s[:, 0], c)
    # Straight-across directions (s == 0, c < 0) never occur for abd in (-90, 270); guard anyway.
    unit = np.where(s > 1e-12, axis / np.maximum(s, 1e-12), np.array([0.0, 0.0, 1.0]))
    swing = Rotation.from_rotvec(unit * angle[:, None])
    total = Rotation.from_rotvec(d * twist[:, None]) * swing
    # Above the horizontal the shoulder girdle elevates (shrug) by a quarter of the excess.
    elevation = np.arccos(np.clip(-d[:, 1], -1.0, 1.0))  # 0 hanging .. pi overhead
    shrug = 0.25 * np.maximum(elevation - np.pi / 2, 0.0)
    collar_vec = np.zeros((n, 3))
    collar_vec[:, 2] = side * shrug
    collar = Rotation.from_rotvec(collar_vec)
    shoulder = collar.inv() * total
    return collar_vec, shoulder.as_rotvec()


def compose_pose(params: Mapping[str, np.ndarray | float], n: int | None = None) -> np.ndarray:
    """Body pose from pose parameters.

    Args:
        params: name -> (n,) array or scalar, radians; names from :data:`PARAM_NAMES`, missing
            ones are zero.
        n: number of poses; inferred from the array parameters when omitted.
    Returns:
        (n, 21, 3) axis-angle ``theta``, clipped to :data:`joint_limits`.
    """
    unknown = set(params) - set(PARAM_NAMES)
    if unknown:
        raise KeyError(f"unknown pose parameters {sorted(unknown)}; see PARAM_NAMES")
    if n is None:
        sizes = {np.size(v) for v in params.values() if np.ndim(v) > 0}
        n = sizes.pop() if len(sizes) == 1 else 1
    p = {k: np.broadcast_to(np.asarray(params.get(k, 0.0), dtype=np.float64), (n,)) for k in PARAM_NAMES}
    theta = np.zeros((n, 21, 3))
    trunk = np.stack([p["spine_bend"], p["spine_twist"], p["spine_side"]], -1)  # lean right = +z
    for share, name in zip(_SPINE_SHARE, ("spine1", "spine2", "spine3")):
        theta[:, _J[name]] = share * trunk
    head = np.stack([p["head_pitch"], p["head_yaw"], p["head_roll"]], -1)
    for share, name in zip(_NECK_SHARE, ("neck", "head")):
        theta[:, _J[name]] = share * head
    for s, side, sign in (("l", "left", 1.0), ("r", "right", -1.0)):
        q = {k: p[f"{s}_{k}"] for k in _SIDE_PARAMS}
        collar, shoulder = _arm_rotations(q["arm_flex"], q["arm_abd"], q["arm_twist"], sign)
        theta[:, _J[f"{side}_collar"]] = collar
        theta[:, _J[f"{side}_shoulder"]] = shoulder
        theta[:, _J[f"{side}_elbow"]] = np.stack(
            [q["forearm_roll"], -sign * q["elbow"], np.zeros(n)], -1)
        theta[:, _J[f"{side}_wrist"]] = np.stack(
            [np.zeros(n), q["wrist_dev"], sign * q["wrist_flex"]], -1)
        # Hip: flex forwards (-x) after abduction (+-z) and twist (+-y), intrinsic order.
        hip = Rotation.from_euler(
            "XZY", np.stack([-q["hip_flex"], sign * q["hip_abd"], sign * q["hip_twist"]], -1))
        theta[:, _J[f"{side}_hip"]] = hip.as_rotvec()
        theta[:, _J[f"{side}_knee"], 0] = q["knee"]
        theta[:, _J[f"{side}_ankle"], 0] = q["ankle"]
        theta[:, _J[f"{side}_foot"], 0] = -q["toe"]
    return clip_to_limits(theta)


# ------------------------------------------------------------------------------------------
# Primitives: distributions over pose parameters (degrees in the code, radians returned).

def _u(rng: np.random.Generator, lo: float, hi: float, n: int) -> np.ndarray:
    return rng.uniform(lo, hi, n)


def _relaxed_arms(rng, n, p, sides=("l", "r")) -> None:
    for s in sides:
        p[f"{s}_arm_flex"] = _u(rng, -15, 25, n)
        p[f"{s}_arm_abd"] = _u(rng, 10, 30, n)
        p[f"{s}_arm_twist"] = _u(rng, -20, 20, n)
        p[f"{s}_elbow"] = _u(rng, 5, 45, n)
        p[f"{s}_forearm_roll"] = _u(rng, -20, 20, n)
        p[f"{s}_wrist_flex"] = _u(rng, -20, 20, n)
        p[f"{s}_wrist_dev"] = _u(rng, -10, 10, n)


def _standing_legs(rng, n, p) -> None:
    for s in ("l", "r"):
        p[f"{s}_hip_flex"] = _u(rng, -5, 12, n)
        p[f"{s}_hip_abd"] = _u(rng, 0, 10, n)
        p[f"{s}_hip_twist"] = _u(rng, -5, 15, n)
        p[f"{s}_knee"] = _u(rng, 0, 15, n)
        p[f"{s}_ankle"] = _u(rng, -5, 8, n)


def _head(rng, n, p, pitch=(-15, 20), yaw=(-30, 30)) -> None:
    p["head_pitch"] = _u(rng, *pitch, n)
    p["head_yaw"] = _u(rng, *yaw, n)
    p["head_roll"] = _u(rng, -8, 8, n)


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def _bump(phase: np.ndarray, centre: float, width: float) -> np.ndarray:
    return np.exp(-0.5 * (_wrap(phase - centre) / width) ** 2)


def walking_params(phase: np.ndarray | float, amplitude: np.ndarray | float = 1.0,
                   arm_swing: np.ndarray | float = 1.0) -> dict[str, np.ndarray]:
    """Pose parameters of a walking gait at the given phase.

    One gait cycle is ``phase`` in [0, 2 pi): the left hip swings forwards through neutral at 0
    and is most flexed at pi/2; the right leg runs half a cycle behind; each arm swings against
    the leg of its side. Shapes follow the textbook gait curves: hip -10..+25 deg, knee ~5 deg in
    stance with ~15 deg at loading and ~60 deg in swing, plantar flexion at push-off.

    Args:
        phase: (n,) or scalar radians. amplitude: stride scale (1 = normal walk).
        arm_swing: arm swing scale.
    Returns:
        name -> (n,) radians (angles in degrees internally); body-only, no trunk/head noise.
    """
    phase = np.atleast_1d(np.asarray(phase, dtype=np.float64))
    n = phase.shape[0]
    amp = np.broadcast_to(np.asarray(amplitude, dtype=np.float64), (n,))
    swing = np.broadcast_to(np.asarray(arm_swing, dtype=np.float64), (n,))
    p: dict[str, np.ndarray] = {}
    for s, off in (("l", 0.0), ("r", np.pi)):
        ph = phase + off
        hip = 7.5 + 17.5 * np.sin(ph)
        p[f"{s}_hip_flex"] = amp * hip
        p[f"{s}_knee"] = amp * (5 + 55 * _bump(ph, -0.25, 0.6) + 12 * _bump(ph, 2.0, 0.45))
        p[f"{s}_ankle"] = amp * (15 * _bump(ph, -0.9, 0.4) - 6 * _bump(ph, 1.6, 0.6))
        p[f"{s}_hip_abd"] = np.full(n, 3.0)
        p[f"{s}_hip_twist"] = np.full(n, 5.0)
        p[f"{s}_toe"] = 15 * _bump(ph, -1.0, 0.4)
        # arm of the same side swings against its leg
        p[f"{s}_arm_flex"] = -swing * amp * 1.0 * (hip - 7.5) + 3
        p[f"{s}_arm_abd"] = np.full(n, 12.0)
        p[f"{s}_elbow"] = 15 + 15 * swing * np.clip(-np.sin(ph), 0, None)
    p["spine_twist"] = -5 * amp * np.sin(phase)  # the chest counter-rotates against the pelvis
    p["spine_bend"] = np.full(n, 4.0)
    return {k: np.deg2rad(v) for k, v in p.items()}


def _primitive_deg(name: str, rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    p: dict[str, np.ndarray] = {}
    if name == "standing":
        _relaxed_arms(rng, n, p)
        _standing_legs(rng, n, p)
        _head(rng, n, p)
        p["spine_bend"] = _u(rng, -5, 10, n)
        p["spine_twist"] = _u(rng, -10, 10, n)
        p["spine_side"] = _u(rng, -6, 6, n)
    elif name == "walking":
        w = walking_params(_u(rng, 0, 2 * np.pi, n), _u(rng, 0.7, 1.25, n), _u(rng, 0.6, 1.4, n))
        p = {k: np.rad2deg(v) for k, v in w.items()}
        _head(rng, n, p, pitch=(-10, 20), yaw=(-20, 20))
    elif name == "reaching":
        _relaxed_arms(rng, n, p)
        _standing_legs(rng, n, p)
        _head(rng, n, p, pitch=(-25, 20))
        both = rng.random(n) < 0.3
        left = rng.random(n) < 0.5
        for s, mask in (("l", both | left), ("r", both | ~left)):
            p[f"{s}_arm_flex"] = np.where(mask, _u(rng, 40, 150, n), p[f"{s}_arm_flex"])
            p[f"{s}_arm_abd"] = np.where(mask, _u(rng, 5, 60, n), p[f"{s}_arm_abd"])
            p[f"{s}_elbow"] = np.where(mask, _u(rng, 0, 40, n), p[f"{s}_elbow"])
            p[f"{s}_arm_twist"] = np.where(mask, _u(rng, -30, 30, n), p[f"{s}_arm_twist"])
        toward = np.where(both, 0.0, np.where(left, -1.0, 1.0))  # reach left -> chest turns right
        p["spine_bend"] = _u(rng, 0, 25, n)
        p["spine_twist"] = toward * _u(rng, 0, 25, n)
        p["spine_side"] = -toward * _u(rng, 0, 10, n)
        step = rng.random(n) < 0.4  # a step towards the target with one leg
        leg = np.where(rng.random(n) < 0.5, "l", "r")
        for s in ("l", "r"):
            m = step & (leg == s)
            p[f"{s}_hip_flex"] = np.where(m, _u(rng, 10, 35, n), p[f"{s}_hip_flex"])
            p[f"{s}_knee"] = np.where(m, _u(rng, 10, 40, n), p[f"{s}_knee"])
    elif name == "squatting":
        depth = _u(rng, 0.3, 1.0, n)
        _head(rng, n, p, pitch=(-30, 10))
        for s in ("l", "r"):
            p[f"{s}_hip_flex"] = 50 + 65 * depth + _u(rng, -5, 5, n)
            p[f"{s}_knee"] = 55 + 85 * depth + _u(rng, -5, 5, n)
            p[f"{s}_ankle"] = -(8 + 20 * depth)
            p[f"{s}_hip_abd"] = _u(rng, 8, 28, n)
            p[f"{s}_hip_twist"] = _u(rng, 0, 25, n)
            p[f"{s}_arm_flex"] = _u(rng, 30, 100, n)
            p[f"{s}_arm_abd"] = _u(rng, 10, 35, n)
            p[f"{s}_elbow"] = _u(rng, 0, 70, n)
            p[f"{s}_arm_twist"] = _u(rng, -20, 20, n)
        p["spine_bend"] = 10 + 25 * depth + _u(rng, -5, 5, n)
        p["spine_twist"] = _u(rng, -8, 8, n)
    elif name == "twisting":
        _relaxed_arms(rng, n, p)
        _standing_legs(rng, n, p)
        sign = np.where(rng.random(n) < 0.5, -1.0, 1.0)
        p["spine_twist"] = sign * _u(rng, 25, 70, n)
        p["spine_bend"] = _u(rng, -5, 15, n)
        _head(rng, n, p, yaw=(0, 0))
        p["head_yaw"] = sign * _u(rng, 0, 35, n)
        for s in ("l", "r"):
            p[f"{s}_arm_abd"] = _u(rng, 15, 80, n)
            p[f"{s}_elbow"] = _u(rng, 20, 100, n)
            p[f"{s}_arm_flex"] = _u(rng, -10, 60, n)
    elif name == "arms_raised":
        _standing_legs(rng, n, p)
        _relaxed_arms(rng, n, p)
        _head(rng, n, p, pitch=(-30, 5))
        sideways = rng.random(n) < 0.5
        for s in ("l", "r"):
            one = rng.random(n) < 0.85  # occasionally only one arm up
            up_abd = np.where(sideways, _u(rng, 100, 175, n), _u(rng, 5, 40, n))
            up_flex = np.where(sideways, _u(rng, -10, 30, n), _u(rng, 100, 175, n))
            p[f"{s}_arm_abd"] = np.where(one, up_abd, p[f"{s}_arm_abd"])
            p[f"{s}_arm_flex"] = np.where(one, up_flex, p[f"{s}_arm_flex"])
            p[f"{s}_elbow"] = np.where(one, _u(rng, 0, 50, n), p[f"{s}_elbow"])
        p["spine_bend"] = _u(rng, -15, 5, n)
        p["spine_side"] = _u(rng, -8, 8, n)
    elif name == "bending":
        bend = _u(rng, 40, 100, n)
        _head(rng, n, p, pitch=(-35, 10))
        p["spine_bend"] = bend
        p["spine_twist"] = _u(rng, -15, 15, n)
        p["spine_side"] = _u(rng, -8, 8, n)
        for s in ("l", "r"):
            # arms hang towards the ground: relative to the torso they swing forwards by ~bend
            p[f"{s}_arm_flex"] = 0.85 * bend + _u(rng, -15, 25, n)
            p[f"{s}_arm_abd"] = _u(rng, 8, 25, n)
            p[f"{s}_elbow"] = _u(rng, 0, 50, n)
            p[f"{s}_hip_flex"] = _u(rng, 0, 20, n)
            p[f"{s}_knee"] = _u(rng, 0, 30, n)
            p[f"{s}_hip_abd"] = _u(rng, 0, 12, n)
    elif name == "crouching":
        _head(rng, n, p, pitch=(-20, 20))
        for s in ("l", "r"):
            p[f"{s}_hip_flex"] = _u(rng, 75, 112, n)
            p[f"{s}_knee"] = _u(rng, 65, 115, n)
            p[f"{s}_ankle"] = _u(rng, -15, 10, n)
            p[f"{s}_hip_abd"] = _u(rng, 3, 22, n)
            p[f"{s}_hip_twist"] = _u(rng, -5, 15, n)
            p[f"{s}_arm_flex"] = _u(rng, 20, 75, n)
            p[f"{s}_arm_abd"] = _u(rng, 8, 30, n)
            p[f"{s}_elbow"] = _u(rng, 20, 90, n)
            p[f"{s}_wrist_flex"] = _u(rng, -20, 30, n)
        p["spine_bend"] = _u(rng, 0, 30, n)
        p["spine_twist"] = _u(rng, -10, 10, n)
    else:
        raise ValueError(f"unknown primitive {name!r}; choose from {PRIMITIVES}")
    return p


def primitive_params(name: str, rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    """Draw ``n`` parameter sets of one primitive: name -> (n,) radians (see :data:`PARAM_NAMES`)."""
    return {k: np.deg2rad(np.asarray(v, dtype=np.float64) * np.ones(n))
            for k, v in _primitive_deg(name, rng, n).items()}


# Perturbation std (degrees) added to every component after composing a primitive: small for
# the spine segments (they add up), larger for the free ball joints.
_NOISE_DEG = np.full(21, 4.0)
for _name, _sd in (("spine1", 2.5), ("spine2", 2.5), ("spine3", 2.5), ("left_shoulder", 6.0),
                   ("right_shoulder", 6.0), ("left_wrist", 8.0), ("right_wrist", 8.0),
                   ("left_foot", 3.0), ("right_foot", 3.0)):
    _NOISE_DEG[_J[_name]] = _sd


def _primitive_weights(primitives) -> tuple[tuple[str, ...], np.ndarray]:
    if primitives is None:
        names, w = PRIMITIVES, np.ones(len(PRIMITIVES))
    elif isinstance(primitives, str):
        names, w = (primitives,), np.ones(1)
    elif isinstance(primitives, Mapping):
        names = tuple(primitives)
        w = np.array([float(primitives[k]) for k in names])
    else:
        names = tuple(primitives)
        w = np.ones(len(names))
    for k in names:
        if k not in PRIMITIVES:
            raise ValueError(f"unknown primitive {k!r}; choose from {PRIMITIVES}")
    if len(names) == 0 or np.any(w < 0) or w.sum() <= 0:
        raise ValueError("primitives need at least one name with a positive weight")
    return names, w / w.sum()


def sample_body_pose(
    rng: np.random.Generator,
    n: int,
    primitives: Sequence[str] | Mapping[str, float] | str | None = None,
    *,
    noise_scale: float = 1.0,
    return_primitives: bool = False,
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Sample ``n`` plausible, varied SMPL-X body poses.

    Each sample picks a motion primitive (uniformly, or by the given weights), draws that
    primitive's pose parameters, composes the pose, adds Gaussian perturbations per joint
    (2.5-8 deg std times ``noise_scale``) and clips to :data:`joint_limits`.

    Args:
        rng: the random generator (the only source of randomness: same seed, same poses).
        n: number of poses.
        primitives: None (all of :data:`PRIMITIVES`, equal weights), a name, a list of names, or
            a mapping name -> weight.
        noise_scale: multiplies the perturbation std (0 = the bare primitives).
        return_primitives: also return the (n,) index into :data:`PRIMITIVES` of each sample.
    Returns:
        (n, 21, 3) float64 axis-angle ``theta`` (joints 1..21), and optionally the (n,) int64
        primitive indices.
    """
    names, w = _primitive_weights(primitives)
    choice = rng.choice(len(names), size=n, p=w)
    theta = np.zeros((n, 21, 3))
    for k, name in enumerate(names):  # fixed order keeps the stream deterministic
        idx = np.flatnonzero(choice == k)
        if idx.size:
            theta[idx] = compose_pose(primitive_params(name, rng, idx.size), n=idx.size)
    noise = rng.standard_normal((n, 21, 3)) * np.deg2rad(_NOISE_DEG)[:, None] * noise_scale
    theta = clip_to_limits(theta + noise)
    if return_primitives:
        labels = np.array([PRIMITIVES.index(names[c]) for c in choice], dtype=np.int64)
        return theta, labels
    return theta
