"""The two drones' flights and camera poses, in closed form in time (so any camera time stamps
can be evaluated): UAV 1 hovers with a slow drift and a gimbal that partly follows the person,
UAV 2 circles the person with a varying radius and pitch; both aim with a small smooth wobble."""
from __future__ import annotations

import math

import numpy as np

from .config import FlightConfig

__all__ = ["SmoothNoise", "look_at_rotation", "Flights"]


class SmoothNoise:
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


class Flights:
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
        self.drift = SmoothNoise(rng, 3, cfg.hover_drift_m, (0.02, 0.15))
        self.aim1 = SmoothNoise(rng, 3, cfg.aim_wobble_m, (0.02, 0.2))
        # UAV 2: starts 60-180 degrees around the circle from UAV 1.
        self.az2 = self.az1 + rng.choice([-1, 1]) * rng.uniform(np.pi / 3, np.pi)
        self.dir2 = float(rng.choice([-1, 1]))
        self.r_mid, self.r_amp = 0.5 * (d_lo + d_hi), 0.5 * (d_hi - d_lo)
        self.p_mid, self.p_amp = 0.5 * (p_lo + p_hi), 0.5 * (p_hi - p_lo)
        self.r_freq, self.r_phase = 1.0 / rng.uniform(15, 35), rng.uniform(0, 2 * np.pi)
        self.p_freq, self.p_phase = 1.0 / rng.uniform(20, 45), rng.uniform(0, 2 * np.pi)
        self.az_wobble = SmoothNoise(rng, 1, 0.15, (0.03, 0.1))
        self.aim2 = SmoothNoise(rng, 3, cfg.aim_wobble_m, (0.05, 0.3))

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

