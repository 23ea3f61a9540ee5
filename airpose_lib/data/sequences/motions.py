"""Continuous human motion: scripted activities blended over time, root path, ground contact.

Stands in for the person in the paper's real recordings (two DJI drones around one person who
walks, turns, twists and moves the arms). A motion is a :class:`MotionScript`: a list of
:class:`Segment` activities (see :data:`ACTIVITIES`), each a closed-form function of its local
time that gives

* the pose parameters of :mod:`airpose_lib.data.still.poses` (composed to ``theta`` (21, 3)),
* a walking speed (m/s, along the body's facing direction), a turning rate (rad/s, about the
  world Y axis) and a forward tilt of the pelvis (rad; e.g. when bending). The tilt rotates the
  root; the hips flex by the same angle, so it inclines pelvis and trunk but not the legs.

Consecutive segments cross-fade over ``blend_s`` seconds (smoothstep weights that sum to one), so
every channel is continuous (C1) in time. The root path (heading and ground position of the
pelvis) integrates speed and turning rate on a fine time grid (``dt = 1 / 240`` s) and steers the
walker back when it leaves ``area_radius`` around the start, so the person stays in the region
the drones watch. :func:`evaluate_motion` samples everything at arbitrary times (each camera has
its own time stamps). :func:`world_root_pose` turns heading/tilt/pelvis position into the paper's
root convention ``V = R V0 + t`` (rotation about the model origin) and puts the lowest mesh
vertex on the ground plane ``y = 0``.

Simplifications (documented, not hidden): the feet are not pinned during stance (a little foot
sliding), and the arms do not react to contact with the ground or the body.
"""
from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from airpose_lib.body.forward import rest_body

from ..still.poses import PARAM_NAMES, compose_pose, walking_params

__all__ = [
    "ACTIVITIES",
    "Segment",
    "MotionScript",
    "MotionState",
    "PERSON_STYLES",
    "sample_script",
    "evaluate_motion",
    "world_root_pose",
]

ACTIVITIES: tuple[str, ...] = (
    "stand", "walk", "turn", "twist", "wave", "arms", "squat", "bend", "reach",
)
"""stand (idle sway, looking around), walk (path with a constant turning rate), turn (stepping in
place while turning), twist (upper body rotates against the lower body, as the paper's person 2),
wave (one arm up, forearm waving), arms (both arms raised and lowered, sideways or forwards),
squat (down and up), bend (forward bend at hips and spine, arms hanging), reach (alternating
reaches forwards/upwards)."""

_DEG = np.pi / 180.0


@dataclass(frozen=True)
class Segment:
    """One activity of a script.

    Attributes:
        activity: a name from :data:`ACTIVITIES`.
        duration: seconds (> 0).
        options: activity options (see :func:`_activity`); missing ones take defaults.
    """

    activity: str
    duration: float
    options: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.activity not in ACTIVITIES:
            raise ValueError(f"unknown activity {self.activity!r}; choose from {ACTIVITIES}")
        if not self.duration > 0:
            raise ValueError(f"segment duration must be > 0, got {self.duration}")


@dataclass(frozen=True)
class MotionScript:
    """A sequence of activities and the start of the root path.

    Attributes:
        segments: the activities in order; the last one lasts forever.
        start_xz: (2,) pelvis ground position (world x, z) at t = 0, metres.
        start_heading: yaw at t = 0, radians (0 = the person faces world +Z).
        blend_s: cross-fade time between segments, seconds.
        area_radius: the walker turns back towards ``start_xz`` beyond this radius (metres).
    """

    segments: tuple[Segment, ...]
    start_xz: tuple[float, float] = (0.0, 0.0)
    start_heading: float = 0.0
    blend_s: float = 0.8
    area_radius: float = 2.75

    def __post_init__(self) -> None:
        if len(self.segments) == 0:
            raise ValueError("a motion script needs at least one segment")

    @property
    def starts(self) -> np.ndarray:
        """(K,) start time of each segment, seconds."""
        return np.concatenate([[0.0], np.cumsum([s.duration for s in self.segments])[:-1]])

    @property
    def duration(self) -> float:
        return float(sum(s.duration for s in self.segments))


@dataclass
class MotionState:
    """The motion sampled at ``T`` times.

    Attributes:
        times: (T,) seconds.
        theta: (T, 21, 3) body pose, axis-angle.
        heading: (T,) yaw about world Y, radians (0 = facing +Z).
        tilt: (T,) forward tilt of the pelvis, radians.
        pelvis_xz: (T, 2) pelvis ground position (world x, z), metres.
        speed: (T,) commanded walking speed, m/s.
        weights: (T, K) blend weight of each script segment.
    """

    times: np.ndarray
    theta: np.ndarray
    heading: np.ndarray
    tilt: np.ndarray
    pelvis_xz: np.ndarray
    speed: np.ndarray
    weights: np.ndarray

    @property
    def root_rotation(self) -> np.ndarray:
        """(T, 3, 3) world rotation of the body: heading about Y, then the forward tilt (about
        the body's x axis, which bends it towards its facing direction)."""
        return (Rotation.from_rotvec(np.stack([np.zeros_like(self.heading), self.heading,
                                               np.zeros_like(self.heading)], -1))
                * Rotation.from_rotvec(np.stack([self.tilt, np.zeros_like(self.tilt),
                                                 np.zeros_like(self.tilt)], -1))).as_matrix()


# ------------------------------------------------------------------------------------------
# Activities: local time tau (n,) -> parameters (degrees), speed, turn rate, tilt.

def _opt(options: Mapping[str, float], key: str, default: float) -> float:
    return float(options.get(key, default))


def _relaxed(n: int, o: Mapping[str, float]) -> dict[str, np.ndarray]:
    """Arms hanging loosely, legs straight (degrees)."""
    p: dict[str, np.ndarray] = {}
    for s in ("l", "r"):
        p[f"{s}_arm_abd"] = np.full(n, _opt(o, f"{s}_arm_abd", 12.0))
        p[f"{s}_arm_flex"] = np.full(n, _opt(o, f"{s}_arm_flex", 5.0))
        p[f"{s}_elbow"] = np.full(n, _opt(o, f"{s}_elbow", 15.0))
        p[f"{s}_hip_abd"] = np.full(n, 4.0)
        p[f"{s}_hip_twist"] = np.full(n, 6.0)
        p[f"{s}_knee"] = np.full(n, 4.0)
    return p


def _activity(seg: Segment, tau: np.ndarray):
    """Closed-form activity at local times ``tau`` (n,) seconds.

    Returns (params in degrees name -> (n,), speed (n,) m/s, turn rate (n,) rad/s,
    tilt (n,) degrees).
    """
    o, n = seg.options, tau.shape[0]
    speed = np.zeros(n)
    turn = np.zeros(n)
    tilt = np.zeros(n)
    a = seg.activity
    phase0 = _opt(o, "phase", 0.0)
    if a == "stand":
        p = _relaxed(n, o)
        f = _opt(o, "freq", 0.15)
        p["spine_side"] = 2.0 * np.sin(2 * np.pi * f * tau + phase0)
        p["head_yaw"] = _opt(o, "look", 25.0) * np.sin(2 * np.pi * 0.6 * f * tau + 2 * phase0)
        p["head_pitch"] = np.full(n, _opt(o, "head_pitch", 5.0))
    elif a == "walk":
        v = _opt(o, "speed", 1.1)
        cycle = 1.0 + 0.3 * v  # metres per gait cycle (two steps)
        ph = 2 * np.pi * (v / cycle) * tau + phase0
        p = {k: np.rad2deg(x) for k, x in walking_params(ph, np.clip(v / 1.2, 0.5, 1.25)).items()}
        p["head_pitch"] = np.full(n, _opt(o, "head_pitch", 8.0))
        speed[:] = v
        turn[:] = _opt(o, "turn_rate", 0.0)
    elif a == "turn":
        rate = _opt(o, "turn_rate", 0.8)
        ph = 2 * np.pi * 1.6 * tau + phase0
        p = {k: np.rad2deg(x) for k, x in walking_params(ph, 0.35, 0.4).items()}
        turn[:] = rate
    elif a == "twist":
        p = _relaxed(n, o)
        amp, f = _opt(o, "amplitude", 60.0), _opt(o, "freq", 0.3)
        w = np.sin(2 * np.pi * f * tau + phase0)
        p["spine_twist"] = amp * w
        p["head_yaw"] = 0.4 * amp * w
        # the pelvis turns a little against the chest: the lower body rotates too
        turn[:] = -0.15 * amp * _DEG * 2 * np.pi * f * np.cos(2 * np.pi * f * tau + phase0)
        for s, sign in (("l", 1.0), ("r", -1.0)):
            p[f"{s}_arm_abd"] = np.full(n, _opt(o, "arm_abd", 45.0))
            p[f"{s}_arm_flex"] = np.full(n, 20.0) + 15 * sign * w
            p[f"{s}_elbow"] = np.full(n, _opt(o, "elbow", 70.0))
            p[f"{s}_hip_abd"] = np.full(n, 10.0)
            p[f"{s}_knee"] = np.full(n, 10.0)
    elif a == "wave":
        p = _relaxed(n, o)
        s = "l" if _opt(o, "side", 0.0) < 0.5 else "r"
        f = _opt(o, "freq", 1.2)
        p[f"{s}_arm_abd"] = np.full(n, _opt(o, "arm_abd", 140.0))
        p[f"{s}_arm_flex"] = np.full(n, 20.0)
        p[f"{s}_elbow"] = 45 + 25 * np.sin(2 * np.pi * f * tau + phase0)
        p["head_pitch"] = np.full(n, -10.0)
    elif a == "arms":
        p = _relaxed(n, o)
        f, top = _opt(o, "freq", 0.4), _opt(o, "top", 160.0)
        lift = 0.5 * (1 - np.cos(2 * np.pi * f * tau))
        forward = _opt(o, "forward", 0.0) >= 0.5
        for s in ("l", "r"):
            if forward:
                p[f"{s}_arm_flex"] = 5 + (top - 5) * lift
                p[f"{s}_arm_abd"] = np.full(n, 12.0)
            else:
                p[f"{s}_arm_abd"] = 12 + (top - 12) * lift
                p[f"{s}_arm_flex"] = np.full(n, 5.0)
            p[f"{s}_elbow"] = 15 + 10 * lift
        p["spine_bend"] = -8 * lift
        p["head_pitch"] = -15 * lift
    elif a == "squat":
        f, dmax = _opt(o, "freq", 0.3), _opt(o, "depth", 0.9)
        d = dmax * 0.5 * (1 - np.cos(2 * np.pi * f * tau))
        p = {}
        for s in ("l", "r"):
            p[f"{s}_hip_flex"] = 5 + 95 * d
            p[f"{s}_knee"] = 4 + 126 * d
            p[f"{s}_ankle"] = -25 * d
            p[f"{s}_hip_abd"] = 5 + 15 * d
            p[f"{s}_hip_twist"] = 6 + 12 * d
            p[f"{s}_arm_flex"] = 5 + 40 * d  # ~horizontal in the world: the trunk leans ~45 deg
            p[f"{s}_arm_abd"] = 12 + 10 * d
            p[f"{s}_elbow"] = 15 + 10 * d
        p["spine_bend"] = 5 + 20 * d
        p["head_pitch"] = -15 * d
        tilt = 20 * d
    elif a == "bend":
        f, bmax = _opt(o, "freq", 0.25), _opt(o, "depth", 85.0)
        b = bmax * 0.5 * (1 - np.cos(2 * np.pi * f * tau))
        p = _relaxed(n, o)
        tilt = 0.45 * b
        p["spine_bend"] = 0.55 * b
        p["head_pitch"] = -0.3 * b
        for s in ("l", "r"):
            p[f"{s}_arm_flex"] = 5 + 0.9 * b  # arms keep hanging towards the ground
            p[f"{s}_knee"] = 4 + 0.12 * b
    elif a == "reach":
        p = _relaxed(n, o)
        f, top = _opt(o, "freq", 0.35), _opt(o, "top", 130.0)
        w = np.sin(2 * np.pi * f * tau + phase0)
        left, right = np.clip(w, 0, None), np.clip(-w, 0, None)
        for s, amount in (("l", left), ("r", right)):
            p[f"{s}_arm_flex"] = 5 + (top - 5) * amount
            p[f"{s}_arm_abd"] = 12 + 20 * amount
            p[f"{s}_elbow"] = 15 - 10 * amount
        p["spine_twist"] = -20 * w  # the chest turns to bring the reaching shoulder forwards
        p["spine_bend"] = 8 * np.abs(w)
        p["head_pitch"] = -15 * np.abs(w)
    else:  # pragma: no cover - Segment validates the name
        raise ValueError(a)
    return p, speed, turn, tilt


# ------------------------------------------------------------------------------------------
# Scripts

PERSON_STYLES: dict[str, dict[str, float]] = {
    # person 1 (fine-tuning): mostly walking and varied whole-body actions
    "varied": {"stand": 1.0, "walk": 3.0, "turn": 1.0, "twist": 0.5, "wave": 1.0, "arms": 1.0,
               "squat": 1.0, "bend": 1.0, "reach": 1.0},
    # person 2 (test): many twisting poses, the hard case the paper reports
    "twisting": {"stand": 0.5, "walk": 2.0, "turn": 1.0, "twist": 3.0, "wave": 0.5,
                 "arms": 1.0, "squat": 0.5, "bend": 0.5, "reach": 1.5},
}
"""Activity weights of :func:`sample_script` per person style."""


def _sample_options(activity: str, rng: np.random.Generator) -> dict[str, float]:
    u = rng.uniform
    o = {"phase": u(0, 2 * np.pi)}
    if activity == "stand":
        o.update(look=u(10, 40), l_elbow=u(5, 40), r_elbow=u(5, 40))
    elif activity == "walk":
        o.update(speed=u(0.7, 1.4), turn_rate=u(-0.5, 0.5))
    elif activity == "turn":
        o.update(turn_rate=rng.choice([-1, 1]) * u(0.5, 1.2))
    elif activity == "twist":
        o.update(amplitude=u(40, 72), freq=u(0.2, 0.45), arm_abd=u(25, 70), elbow=u(40, 100))
    elif activity == "wave":
        o.update(side=float(rng.random() < 0.5), freq=u(0.8, 1.6), arm_abd=u(110, 165))
    elif activity == "arms":
        o.update(freq=u(0.25, 0.5), top=u(100, 170), forward=float(rng.random() < 0.5))
    elif activity == "squat":
        o.update(freq=u(0.2, 0.4), depth=u(0.5, 1.0))
    elif activity == "bend":
        o.update(freq=u(0.15, 0.3), depth=u(50, 100))
    elif activity == "reach":
        o.update(freq=u(0.2, 0.45), top=u(80, 150))
    return o


def sample_script(rng: np.random.Generator, duration_s: float, style: str = "varied",
                  segment_s: tuple[float, float] = (3.0, 7.0),
                  exclude: Collection[str] = ()) -> MotionScript:
    """A random script of at least ``duration_s`` seconds.

    Activities are drawn with the weights of ``PERSON_STYLES[style]`` (never the same one twice
    in a row, and the script starts with a short walk so that the root moves from the first
    frame); each lasts ``segment_s`` seconds (uniform; the first walk half of that). Periodic activities (squat, bend, arms) get a
    whole number of cycles so they end where they started.

    ``exclude`` names activities (:data:`ACTIVITIES`) the script never contains: their weight is
    zero, and when ``walk`` is one of them the first segment is drawn like the others (a
    corpus that must not see some families, e.g. the pose prior's held-out motions,
    :mod:`airpose_lib.prior.build`). Empty (default): the draws, and the script, are exactly
    those of a call without it.
    """
    if style not in PERSON_STYLES:
        raise ValueError(f"unknown style {style!r}; choose from {tuple(PERSON_STYLES)}")
    unknown = sorted(set(exclude) - set(ACTIVITIES))
    if unknown:
        raise ValueError(f"unknown activities {unknown} to exclude; choose from {ACTIVITIES}")
    names = tuple(PERSON_STYLES[style])
    w = np.array([0.0 if k in exclude else PERSON_STYLES[style][k] for k in names])
    if not w.sum() > 0:
        raise ValueError(f"excluding {sorted(exclude)} leaves no activity of style {style!r}")
    segments: list[Segment] = []
    total, last = 0.0, None
    while total < duration_s:
        if last is None and "walk" not in exclude:
            act = "walk"
        else:
            ww = np.where(np.array(names) == last, 0.0, w)
            if not ww.sum() > 0:  # one activity left: it repeats (one long segment)
                ww = w
            act = names[rng.choice(len(names), p=ww / ww.sum())]
        dur = float(rng.uniform(*segment_s))
        if last is None and act == "walk":
            dur = 0.5 * dur  # a short first walk: short recordings show more than walking
        opts = _sample_options(act, rng)
        if act in ("squat", "bend", "arms"):
            cycles = max(1, round(dur * opts["freq"]))
            dur = cycles / opts["freq"]
        segments.append(Segment(act, dur, opts))
        total += dur
        last = act
    return MotionScript(tuple(segments), start_xz=tuple(rng.uniform(-1.0, 1.0, 2)),
                        start_heading=float(rng.uniform(-np.pi, np.pi)))


# ------------------------------------------------------------------------------------------
# Evaluation

def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x)


def _segment_weights(script: MotionScript, t: np.ndarray) -> np.ndarray:
    """(T, K) cross-fade weights; rows sum to 1."""
    starts = script.starts
    b = max(script.blend_s, 1e-6)
    on = _smoothstep((t[:, None] - starts[None, :]) / b + 0.5)
    on[:, 0] = 1.0
    off = np.concatenate([on[:, 1:], np.zeros((t.shape[0], 1))], axis=1)
    return on - off


def _channels(script: MotionScript, t: np.ndarray):
    """Blended params (radians), speed, turn rate, tilt (radians) and weights at times t (T,)."""
    W = _segment_weights(script, t)
    params = {k: np.zeros(t.shape[0]) for k in PARAM_NAMES}
    speed, turn, tilt = (np.zeros(t.shape[0]) for _ in range(3))
    for k, (seg, t0) in enumerate(zip(script.segments, script.starts)):
        active = W[:, k] > 0
        if not active.any():
            continue
        wk = W[active, k]
        p, s, r, tl = _activity(seg, t[active] - t0)
        for name, val in p.items():
            params[name][active] += wk * np.deg2rad(val)
        speed[active] += wk * s
        turn[active] += wk * r
        tilt[active] += wk * np.deg2rad(tl)
    # The tilt inclines pelvis and trunk; the hips flex by as much so the legs keep their line.
    for side in ("l", "r"):
        params[f"{side}_hip_flex"] = params[f"{side}_hip_flex"] + tilt
    return params, speed, turn, tilt, W


def _integrate_path(script: MotionScript, t_end: float, dt: float):
    """Heading and pelvis ground position on a uniform grid from 0 to t_end."""
    grid = np.arange(0.0, t_end + 2 * dt, dt)
    _, speed, turn, _, _ = _channels(script, grid)
    heading = np.empty_like(grid)
    xz = np.empty((grid.shape[0], 2))
    h, pos = script.start_heading, np.asarray(script.start_xz, dtype=np.float64)
    centre = pos.copy()
    for i in range(grid.shape[0]):
        heading[i], xz[i] = h, pos
        fwd = np.array([np.sin(h), np.cos(h)])
        rate = turn[i]
        off = pos - centre
        dist = np.hypot(*off)
        if speed[i] > 0.05 and dist > 0.6 * script.area_radius:
            # steer towards the centre, harder the further out (stays inside the area)
            to_centre = np.arctan2(-off[0], -off[1])
            err = (to_centre - h + np.pi) % (2 * np.pi) - np.pi
            gain = 1.5 * min(1.0, (dist - 0.6 * script.area_radius) / (0.4 * script.area_radius))
            rate = (1 - gain / 1.5) * rate + gain * err
        h = h + rate * dt
        pos = pos + speed[i] * fwd * dt
    return grid, heading, xz


def evaluate_motion(script: MotionScript, times: np.ndarray | Sequence[float],
                    dt: float = 1.0 / 240.0) -> MotionState:
    """Sample a script at arbitrary times.

    Args:
        script: the motion.
        times: (T,) seconds, >= 0, any order.
        dt: integration step of the root path, seconds.
    Returns:
        :class:`MotionState` at ``times``.
    """
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    if t.size and t.min() < 0:
        raise ValueError("motion times must be >= 0")
    params, speed, _, tilt, W = _channels(script, t)
    theta = compose_pose(params, n=t.shape[0])
    grid, heading_g, xz_g = _integrate_path(script, float(t.max(initial=0.0)), dt)
    heading = np.interp(t, grid, heading_g)
    xz = np.stack([np.interp(t, grid, xz_g[:, 0]), np.interp(t, grid, xz_g[:, 1])], -1)
    return MotionState(t, theta, heading, tilt, xz, speed, W)


def world_root_pose(state: MotionState, body_model, betas: np.ndarray, chunk: int = 64
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World root pose in the paper's convention with the feet on the ground.

    The pelvis is placed at ``state.pelvis_xz`` on the ground-plane axes and the body is lifted
    so that its lowest vertex touches ``y = 0``.

    Args:
        state: the motion at T times.
        body_model: an ``smplx.SMPLX`` (the person's gendered model).
        betas: (10,) shape.
        chunk: frames per forward pass.
    Returns:
        R_wb (T, 3, 3), t_wb (T, 3) with ``V_world = R_wb @ V0 + t_wb`` about the model origin,
        and the pelvis world position (T, 3).
    """
    R = state.root_rotation
    T = R.shape[0]
    t_wb = np.zeros((T, 3))
    pelvis = np.zeros((T, 3))
    for a in range(0, T, chunk):
        b = min(T, a + chunk)
        n = b - a
        v0, j0 = rest_body(body_model, np.broadcast_to(betas, (n, len(betas))), state.theta[a:b])
        j0 = j0[:, 0]  # pelvis in V0 (depends on betas only)
        Rn = R[a:b]
        # horizontal placement: the pelvis at the path position
        t_xz = np.stack([state.pelvis_xz[a:b, 0], np.zeros(n), state.pelvis_xz[a:b, 1]], -1)
        t = t_xz - np.einsum("nij,nj->ni", Rn, j0)
        t[:, 1] = 0.0
        low = np.einsum("nij,nvj->nvi", Rn[:, 1:2], v0)[..., 0].min(-1)  # lowest world y
        t[:, 1] = -low
        t_wb[a:b] = t
        pelvis[a:b] = np.einsum("nij,nj->ni", Rn, j0) + t
    return R, t_wb, pelvis
