"""A field camera pipeline for the rendered recordings: what a drone camera does to the light
that the renderer does not.

The renderer draws a clean pinhole image, the images the networks were trained on. A DJI
camera's frame differs: its exposure and white balance are the camera's guess, the sensor adds
signal-dependent noise, the person and the drone move while the shutter is open, the lens bends
straight lines, a tone curve maps light to pixel values, and the video is compressed. Each of
these is one small pure function below on an RGB frame (H, W, 3); :func:`field_frame` composes
them in the order the light meets them (:class:`FieldConfig` switches each, all off by default).

Linear light: the renders are taken as display-encoded with a power law of exponent
:data:`RENDER_GAMMA` (what sRGB approximates), so exposure, white balance, blur, resampling and
noise, all of which act on light, are applied after :func:`to_linear` and the frame is encoded
again with the camera's own exponent by :func:`from_linear`.

Order (:func:`field_frame`): motion blur and lens distortion (optics: the image that reaches the
sensor; the blur first, because its velocity is measured in the undistorted pinhole image), then
exposure and white balance (the gains of the sensor read-out), then sensor noise (it is added to
the gained signal and clipped by the sensor's range), then the tone curve (gamma), then
compression. Distortion comes before the noise because the lens acts before the sensor:
resampling noise after the fact would smooth it, which real noise is not.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from airpose_lib.config_fields import check_fields, require

__all__ = [
    "RENDER_GAMMA",
    "FieldConfig",
    "to_linear",
    "from_linear",
    "exposure_white_balance",
    "sensor_noise",
    "motion_blur_kernel",
    "motion_blur",
    "lens_distortion",
    "jpeg_compress",
    "field_frame",
    "field_rng",
    "person_image_velocity",
]

#: Power-law exponent the renderer's output is taken to be encoded with (sRGB ~ 2.2).
RENDER_GAMMA = 2.2

#: Salt of the field pipeline's random streams (distinct from the motion's and the flights').
_FIELD_SALT = 4711


@dataclass(frozen=True)
class FieldConfig:
    """The field camera pipeline of a recording; every part is off (identity) by default.

    With ``enabled=False`` nothing runs and the recording (frames and cache key) is exactly the
    clean one, whatever the other values.

    Attributes:
        enabled: apply the pipeline at all.
        exposure_ev: exposure error in stops (linear gain ``2 ** exposure_ev``); 0 = off.
        white_balance: (3,) linear R, G, B gains of a white-balance error; (1, 1, 1) = off.
        gamma: exponent of the camera's tone curve; :data:`RENDER_GAMMA` = off.
        shot_noise: ``a`` of the Poissonian-Gaussian model (variance per unit of linear signal,
            signal in [0, 1]); 0 = off.
        read_noise: ``sqrt(b)`` of the same model, standard deviation of the signal-independent
            part in linear units; 0 = off.
        shutter: exposure time as a share of the frame interval (motion blur length =
            ``shutter * |velocity|`` pixels); 0 = off.
        distortion: (k1, k2) radial lens distortion of the stored images (OpenCV model);
            (0, 0) = off. The recording's ground truth and calibration keep the undistorted K.
        jpeg_quality: quality of a compression pass standing in for the camera's video codec
            (the stored frames are written as JPEG afterwards as always); None = off.
    """

    enabled: bool = False
    exposure_ev: float = 0.0
    white_balance: tuple[float, float, float] = (1.0, 1.0, 1.0)
    gamma: float = RENDER_GAMMA
    shot_noise: float = 0.0
    read_noise: float = 0.0
    shutter: float = 0.0
    distortion: tuple[float, float] = (0.0, 0.0)
    jpeg_quality: int | None = None

    def __post_init__(self) -> None:
        check_fields(self)
        require(len(self.white_balance) == 3 and min(self.white_balance) > 0, "white_balance",
                "three positive gains", self.white_balance)
        require(self.gamma > 0, "gamma", "> 0", self.gamma)
        require(self.shot_noise >= 0, "shot_noise", ">= 0", self.shot_noise)
        require(self.read_noise >= 0, "read_noise", ">= 0", self.read_noise)
        require(0 <= self.shutter <= 1, "shutter", "in [0, 1]", self.shutter)
        require(len(self.distortion) == 2, "distortion", "(k1, k2)", self.distortion)
        require(self.jpeg_quality is None or 1 <= self.jpeg_quality <= 100, "jpeg_quality",
                "in [1, 100] or None", self.jpeg_quality)


# ------------------------------------------------------------------------------------------
# The parts

def to_linear(rgb: np.ndarray, gamma: float = RENDER_GAMMA) -> np.ndarray:
    """Display-encoded uint8 (H, W, 3) -> linear light float32 in [0, 1]: ``(x / 255) ** gamma``."""
    return (np.asarray(rgb, dtype=np.float32) / 255.0) ** np.float32(gamma)


def from_linear(lin: np.ndarray, gamma: float = RENDER_GAMMA) -> np.ndarray:
    """Linear light (H, W, 3) -> uint8 through the tone curve ``255 x ** (1 / gamma)``.

    The camera's tone curve: DJI cameras encode video in a gamma-like curve (Rec. 709 in their
    normal colour profile, a flatter log curve in D-Log), not the curve the renders assume, so a
    ``gamma`` other than :data:`RENDER_GAMMA` brightens or darkens the mid-tones. Values are
    clipped to [0, 1] first: the sensor's full well and black level bound what it records.
    """
    x = np.clip(lin, 0.0, 1.0) ** np.float32(1.0 / gamma)
    return np.rint(x * 255.0).astype(np.uint8)


def exposure_white_balance(lin: np.ndarray, exposure_ev: float = 0.0,
                           white_balance=(1.0, 1.0, 1.0)) -> np.ndarray:
    """Linear (H, W, 3) times ``2 ** exposure_ev`` and per-channel gains (R, G, B).

    Real footage: auto-exposure meters the whole frame (bright sky, dark grass), so the person
    is often a stop over or under; auto white balance under an overcast or low sun leaves a
    colour cast. Both are gains on the linear signal before the tone curve. No clipping here:
    the sensor's range clips the gained signal with its noise (:func:`from_linear`).
    """
    gains = np.float32(2.0 ** exposure_ev) * np.asarray(white_balance, dtype=np.float32)
    return lin * gains


def sensor_noise(lin: np.ndarray, shot_noise: float, read_noise: float,
                 rng: np.random.Generator) -> np.ndarray:
    """Linear (H, W, 3) plus Poissonian-Gaussian sensor noise.

    The model of Foi, Trimeche, Katkovnik and Egiazarian 2008 ("Practical Poissonian-Gaussian
    noise modeling and fitting for single-image raw-data", IEEE TIP 17(10)): the recorded value
    is ``z = y + sqrt(a y + b) * n``, ``n ~ N(0, 1)``, with ``a y`` the photon shot noise (its
    variance grows with the signal) and ``b`` the signal-independent read-out noise; the
    heteroscedastic Gaussian approximation of the Poisson part, as in the paper. ``a =
    shot_noise``, ``b = read_noise ** 2``, ``y`` in [0, 1]. Clipping happens at
    :func:`from_linear`, as a sensor clips.
    """
    var = np.maximum(np.float32(shot_noise) * lin + np.float32(read_noise) ** 2, 0.0)
    return lin + np.sqrt(var) * rng.standard_normal(lin.shape, dtype=np.float32)


def motion_blur_kernel(velocity_px, shutter: float) -> np.ndarray | None:
    """(n, n) float32 line kernel summing to 1, or None when the blur is under a pixel.

    The kernel is the path of a point during the exposure: a segment of length ``L = shutter *
    |velocity|`` along ``velocity_px`` (x right, y down, pixels per frame), centred on the
    frame's time (the shutter is open around the time stamp). Sampled densely along the
    segment and splatted bilinearly, so a fractional length keeps its length.
    """
    v = np.asarray(velocity_px, dtype=np.float64).reshape(2)
    length = float(shutter) * float(np.hypot(*v))
    if length < 1.0:
        return None
    half = int(np.ceil(length / 2)) + 1
    n = 2 * half + 1
    direction = v / np.hypot(*v)
    s = np.linspace(-length / 2, length / 2, max(int(np.ceil(length * 8)), 2))
    pts = s[:, None] * direction[None] + half  # (S, 2) x, y in kernel pixels
    k = np.zeros((n, n), dtype=np.float64)
    x0, y0 = np.floor(pts[:, 0]).astype(int), np.floor(pts[:, 1]).astype(int)
    fx, fy = pts[:, 0] - x0, pts[:, 1] - y0
    for dx, dy, w in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        np.add.at(k, (y0 + dy, x0 + dx), w)
    return (k / k.sum()).astype(np.float32)


def motion_blur(img: np.ndarray, velocity_px, shutter: float) -> np.ndarray:
    """(H, W, C) float image blurred along ``velocity_px`` (pixels per frame, x right, y down).

    Real footage: a DJI camera filming video at 30 fps in daylight exposes for a fraction of
    the 33 ms frame interval (often 1/60-1/120 s with the default 180-degree shutter rule, more
    in dull light); the circling drone, the gimbal and the person's limbs move several pixels in
    that time, which smears edges along their image motion. One global kernel: the velocity
    given is that of the person in the image (:func:`person_image_velocity`), the part of the
    frame the networks look at; the background's own motion differs. Borders reflect.
    """
    kernel = motion_blur_kernel(velocity_px, shutter)
    if kernel is None:
        return img
    return cv2.filter2D(img, -1, kernel, borderType=cv2.BORDER_REFLECT)


# Cached: a recording's camera is the same in every frame and the maps cost ~0.1 s at 960x540.
@lru_cache(maxsize=8)
def _distortion_maps(K_flat: tuple[float, ...], k1: float, k2: float, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) float32 x and y maps (read-only): for each pixel of the distorted image, where it
    lies in the pinhole image (the inverse of the distortion, OpenCV's iterative undistortion).
    ``K_flat``: the 9 entries of K (hashable, for the cache)."""
    K = np.asarray(K_flat, dtype=np.float64).reshape(3, 3)
    W, H = size
    xs, ys = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    pts = np.stack([xs.ravel(), ys.ravel()], -1)[:, None]
    dist = np.array([k1, k2, 0.0, 0.0], dtype=np.float64)
    # Many iterations: the default few leave a visible error at the corners for strong barrel.
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-6)
    if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4 (pyproject allows >= 4.8)
        und = cv2.undistortPointsIter(pts, K, dist, None, K, crit)[:, 0]
    else:  # OpenCV 5 took the criteria into undistortPoints
        und = cv2.undistortPoints(pts, K, dist, R=None, P=K, criteria=crit)[:, 0]
    mx, my = und[:, 0].reshape(H, W).astype(np.float32), und[:, 1].reshape(H, W).astype(np.float32)
    mx.flags.writeable = my.flags.writeable = False
    return mx, my


def lens_distortion(img: np.ndarray, K: np.ndarray, k1: float, k2: float) -> np.ndarray:
    """(H, W, C) pinhole image -> the image a lens with radial distortion (k1, k2) makes.

    OpenCV's radial model: a point at normalised pinhole coordinates ``x`` (``r^2 = |x|^2``)
    lands at ``x (1 + k1 r^2 + k2 r^4)``, then ``K``. Each output pixel samples the pinhole image
    where the inverse of that map sends it (``cv2.remap``, bilinear). A barrel distortion
    (k1 < 0) pulls in a rim the render never drew; it is mirrored from the edge (a replicated
    edge would streak).

    Real footage: the DJI Mavic's wide lens has a visible barrel distortion (calibrations of DJI
    Spark / Mavic cameras report k1 around -0.1 to +0.1 and |k2| up to ~0.3 at 1920x1080); the
    paper's calibrations give pinhole K only. The kit's ground truth keeps projecting with the
    undistorted K, so a non-zero distortion is a deliberate model error between the pixels and
    the geometry the networks assume, as in the authors' footage.
    """
    if k1 == 0 and k2 == 0:
        return img
    H, W = img.shape[:2]
    K_flat = tuple(float(x) for x in np.asarray(K, dtype=np.float64).ravel())
    mx, my = _distortion_maps(K_flat, float(k1), float(k2), (W, H))
    return cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT_101)


def jpeg_compress(rgb: np.ndarray, quality: int) -> np.ndarray:
    """uint8 RGB (H, W, 3) after a JPEG encode / decode at ``quality`` (1-100).

    Real footage: DJI drones record H.264 / H.265 video at a bit rate that leaves 8x8 / 16x16
    block artefacts, ringing at edges and smeared colour (4:2:0 chroma subsampling); the
    authors' frames are JPEGs extracted from such video. One JPEG pass at a low quality makes
    the same kinds of artefacts (block DCT quantisation, chroma subsampling) without a codec.
    """
    ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(rgb[..., ::-1]), [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("JPEG encoding failed")
    return cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1].copy()


# ------------------------------------------------------------------------------------------
# The pipeline

def field_frame(rgb: np.ndarray, cfg: FieldConfig, rng: np.random.Generator, *, K: np.ndarray | None = None,
                velocity_px=(0.0, 0.0)) -> np.ndarray:
    """One rendered frame (H, W, 3) uint8 RGB through the field camera pipeline.

    Args:
        rgb: the rendered frame.
        cfg: the pipeline's settings; ``enabled=False`` returns ``rgb`` itself.
        rng: this frame's and this drone's random stream (:func:`field_rng`).
        K: (3, 3) intrinsics of the frame (needed for a lens distortion).
        velocity_px: (2,) image velocity of the person, pixels per frame (the motion blur).
    Returns:
        the field frame, (H, W, 3) uint8; the input itself where every part is identity.
    """
    if not cfg.enabled:
        return rgb
    k1, k2 = cfg.distortion
    optics = cfg.shutter > 0 or k1 != 0 or k2 != 0
    sensor = cfg.exposure_ev != 0 or tuple(cfg.white_balance) != (1.0, 1.0, 1.0) \
        or cfg.shot_noise > 0 or cfg.read_noise > 0 or cfg.gamma != RENDER_GAMMA
    out = rgb
    if optics or sensor:  # skipped otherwise, so an identity pipeline keeps every byte
        lin = to_linear(rgb)
        lin = motion_blur(lin, velocity_px, cfg.shutter)
        if k1 != 0 or k2 != 0:
            if K is None:
                raise ValueError("a lens distortion needs the frame's intrinsics K")
            lin = lens_distortion(lin, K, k1, k2)
        lin = exposure_white_balance(lin, cfg.exposure_ev, cfg.white_balance)
        if cfg.shot_noise > 0 or cfg.read_noise > 0:
            lin = sensor_noise(lin, cfg.shot_noise, cfg.read_noise, rng)
        out = from_linear(lin, cfg.gamma)
    if cfg.jpeg_quality is not None:
        out = jpeg_compress(out, cfg.jpeg_quality)
    return out


def field_rng(seed: int, frame: int, view: int) -> np.random.Generator:
    """The random stream of one frame of one drone: independent of the rendering order, so a
    frame re-rendered alone gets the same noise."""
    return np.random.default_rng([int(seed), _FIELD_SALT, int(frame), int(view)])


def person_image_velocity(j2d: np.ndarray) -> np.ndarray:
    """(F, V, 2) image velocity of the person (mean of the joints), pixels per frame.

    Args:
        j2d: (F, V, J, 2) the joints in each view's image, consecutive frames.
    It is the motion the camera sees, the person's own and the drone's together (central
    differences; one-sided at the ends; zero for a single frame).
    """
    c = np.asarray(j2d, dtype=np.float64).mean(axis=2)  # (F, V, 2)
    if c.shape[0] < 2:
        return np.zeros_like(c)
    return np.gradient(c, axis=0)
