"""Generator of the synthetic two-drone still-frame dataset (the paper's ~30,000 AGORA frames,
here the open body model rendered off-screen).

One sample = one subject (gender, betas, pose, place and heading on the ground) seen by
``num_views`` independently placed drone cameras; per view the person crop is rendered directly
at the network input size with the crop's intrinsics, and the full-frame ground truth is stored
(see :class:`airpose_lib.data.dataset.StillFrameDataset` for the sample dict).

Reproducibility: shard ``k`` draws its sample attempts from ``numpy`` generators seeded with
``(seed, k, attempt)`` and keeps the first ``shard_size`` attempts whose person stays inside every
frame (the others are dropped and counted). A shard therefore depends only on the configuration
and its index: the same seed gives byte-identical shards whatever the number of workers, and an
interrupted run resumes by skipping the shards the manifest lists (after re-checking their
SHA-256) and rebuilding the rest.

Command line: ``airpose data generate --profile smoke|cpu|paper [--out DIR] [--workers N]``;
sizes come from the ``data: still:`` section of ``airpose_lib/profiles/<profile>.yaml``.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import multiprocessing as mp
import os
import queue as queue_mod
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from airpose_lib.body.cache import cache_dir
from airpose_lib.body.genders import GENDER_CODES
from airpose_lib.folder_lock import locks_folder
from airpose_lib.process_guard import die_with_parent
from airpose_lib.profiles import ProfileError, profile_path, profile_section

from .appearance import AppearanceConfig, sample_appearance
from .manifest import (
    DATASET_KIND,
    DatasetError,
    load_manifest,
    record_manifest,
    regenerate_command,
    write_manifest,
)
from .scene import (
    SceneConfig,
    body_world_pose,
    jitter_bbox,
    points_in_frame,
    sample_cameras,
    sample_environment,
    sample_person,
    tight_bbox,
)
from .shards import sha256_file, shard_name, write_shard

__all__ = [
    "GENERATOR_VERSION",
    "GenerationConfig",
    "StillFrameGenerator",
    "generate_still_dataset",
    "ensure_still_dataset",
    "profile_config",
    "default_root",
]

#: Bumped whenever the same configuration would produce different shards.
#: 2: test crops are jittered like training crops; test shards also hold the tight-box crops.
GENERATOR_VERSION = 2

_ATTEMPT_BATCH = 16  # body forwards are batched over this many attempts


# -- configuration --------------------------------------------------------------------------------
@dataclass(frozen=True)
class GenerationConfig:
    """Everything that determines a still-frame dataset.

    Attributes:
        num_samples: accepted multi-view samples (pairs for two views).
        shard_size: samples per shard file (the unit of resumption and verification).
        seed: master seed.
        crop_size: side S of the rendered crops (the network input; 224 in the paper).
        test_fraction: share of shards (the last ones, hence distinct subjects) in the test split;
            at least one test shard.
        image_format: ``"jpg"`` or ``"png"`` (lossless, ~3x larger).
        jpeg_quality: JPEG quality 1-100.
        anti_aliasing: MSAA on the rendered crops (slow in software rendering).
        blur_sigma: Gaussian blur (pixels) of the rendered crop before padding: softens
            aliased edges and textures like a real lens and downscaling do (0 = none).
        test_crops: how the test split's crops are drawn. ``"jittered"`` (default, the official
            code: ``copenet/dsets/aerialpeople.py`` enlarges every box, test split included, by a
            random 0-200 px, so test crops come from the training distribution; deterministic per
            sample, since each sample has its own generator) or ``"tight"`` (the box + 20 px of
            the paper's text, outside the training range of the crop scale s).
        tight_test_crops: test shards also store the tight-box crops (``images_tight``,
            ``P_tight``) so that both protocols are evaluated on the same samples.
        body_source: ``"open"`` or ``"smplx"`` (:func:`airpose_lib.body.load_body_model`).
        max_attempts_per_sample: a shard gives up (error) after this many attempts per sample.
        scene: person / camera / crop / environment sampling.
        appearance: skin, hair and clothing sampling.
    """

    num_samples: int = 300
    shard_size: int = 50
    seed: int = 0
    crop_size: int = 224
    test_fraction: float = 0.1
    image_format: str = "jpg"
    jpeg_quality: int = 95
    anti_aliasing: bool = False
    blur_sigma: float = 0.5
    test_crops: str = "jittered"
    tight_test_crops: bool = True
    body_source: str = "open"
    max_attempts_per_sample: int = 20
    scene: SceneConfig = field(default_factory=SceneConfig)
    appearance: AppearanceConfig = field(default_factory=AppearanceConfig)

    def __post_init__(self) -> None:
        if self.num_samples < 1 or self.shard_size < 1:
            raise ValueError("num_samples and shard_size must be positive")
        if self.test_crops not in ("jittered", "tight"):
            raise ValueError(f"test_crops must be 'jittered' or 'tight', got {self.test_crops!r}")
        if self.image_format not in ("jpg", "png"):
            raise ValueError(f"image_format must be 'jpg' or 'png', got {self.image_format!r}")
        if not 0.0 <= self.test_fraction < 1.0:
            raise ValueError(f"test_fraction must be in [0, 1), got {self.test_fraction}")
        if self.crop_size < 8:
            raise ValueError(f"crop_size too small: {self.crop_size}")

    # -- shards -----------------------------------------------------------------------------------
    @property
    def num_shards(self) -> int:
        return math.ceil(self.num_samples / self.shard_size)

    @property
    def num_test_shards(self) -> int:
        if self.num_shards < 2:
            return 0  # a one-shard dataset is all training data
        return min(self.num_shards - 1, max(1, round(self.test_fraction * self.num_shards)))

    def shard_samples(self, k: int) -> int:
        """Samples in shard ``k`` (the last one may be smaller)."""
        return min(self.shard_size, self.num_samples - k * self.shard_size)

    def shard_split(self, k: int) -> str:
        """``"train"`` or ``"test"``: the last shards (new subjects) are the test split."""
        return "test" if k >= self.num_shards - self.num_test_shards else "train"

    # -- (de)serialisation ------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """Plain dict (lists for tuples) for YAML/JSON."""
        return _plain(dataclasses.asdict(self))

    @classmethod
    def from_dict(cls, d: dict) -> GenerationConfig:
        """Inverse of :meth:`to_dict`; missing keys take the defaults, unknown keys raise."""
        d = dict(d or {})
        scene = _build(SceneConfig, d.pop("scene", None) or {}, "scene")
        appearance = _build(AppearanceConfig, d.pop("appearance", None) or {}, "appearance")
        return _build(cls, d, "data", scene=scene, appearance=appearance)

    def replace(self, **changes) -> GenerationConfig:
        return dataclasses.replace(self, **changes)

    def fingerprint(self) -> str:
        """SHA-256 of the configuration and generator version (what a dataset must match)."""
        blob = json.dumps({"generator_version": GENERATOR_VERSION, "config": self.to_dict()},
                          sort_keys=True)
        return hashlib.sha256(blob.encode()).hexdigest()


def _plain(x):
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    return x


def _build(cls, d: dict, where: str, **extra):
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(d) - names)
    if unknown:
        raise ValueError(f"unknown {where} setting(s) {unknown}; known: {sorted(names)}")
    return cls(**{k: _tuplify(v) for k, v in d.items()}, **extra)


def _tuplify(x):
    """YAML lists -> tuples (every sequence setting is a tuple), recursively."""
    return tuple(_tuplify(v) for v in x) if isinstance(x, list) else x


def profile_config(profile: str) -> GenerationConfig:
    """The still-frame dataset settings of a reproduction profile.

    Reads the ``data: still:`` section of the profile (:mod:`airpose_lib.profiles`; keys are
    :class:`GenerationConfig` fields, ``scene:`` / ``appearance:`` sub-dicts allowed).
    """
    try:  # the data commands report every unusable input as a DatasetError
        path = profile_path(profile)
        return GenerationConfig.from_dict(profile_section(path, "data.still",
                                                          required="the still-frame dataset sizes"))
    except ProfileError as e:  # before ValueError: it is one
        raise DatasetError(str(e)) from None
    except (TypeError, ValueError) as e:
        raise DatasetError(f"{path}, `data: still:` section: {e}") from None


def default_root(profile: str) -> Path:
    """Where a profile's dataset lives by default: ``<kit cache>/data/still_<profile>``."""
    return cache_dir() / "data" / f"still_{profile}"


# -- one process's generator ----------------------------------------------------------------------
def _body_forward(model, betas: np.ndarray, theta: np.ndarray):
    """Vertices ``(B, V, 3)`` and joints ``(B, J, 3)`` (float64) with identity root, zero translation.

    ``betas (B, 10)``, ``theta (B, 21, 3)`` axis-angle.
    """
    import torch

    B = len(betas)
    dt = model.shapedirs.dtype
    z = lambda n: torch.zeros(B, n, dtype=dt)  # noqa: E731
    with torch.no_grad():
        out = model(betas=torch.as_tensor(betas, dtype=dt), body_pose=torch.as_tensor(theta, dtype=dt).reshape(B, 63),
                    global_orient=z(3), transl=z(3), jaw_pose=z(3), leye_pose=z(3), reye_pose=z(3),
                    left_hand_pose=z(45), right_hand_pose=z(45),
                    expression=z(model.num_expression_coeffs))
    return out.vertices.double().numpy(), out.joints.double().numpy()


def _blur(img: np.ndarray, sigma: float) -> np.ndarray:
    import cv2

    return cv2.GaussianBlur(img, (0, 0), sigmaX=sigma, sigmaY=sigma, borderType=cv2.BORDER_REFLECT)


def _encode(img: np.ndarray, fmt: str, quality: int) -> bytes:
    import cv2

    bgr = np.ascontiguousarray(img[..., ::-1])
    if fmt == "jpg":
        ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    else:
        ok, buf = cv2.imencode(".png", bgr, [cv2.IMWRITE_PNG_COMPRESSION, 3])
    if not ok:
        raise RuntimeError("image encoding failed")
    return buf.tobytes()


class StillFrameGenerator:
    """Makes shards: holds the body models, the body paint and one off-screen renderer.

    One instance per process (each worker has its own renderer).

    Args:
        config: the dataset configuration.
        pose_sampler: ``f(rng, n) -> (n, 21, 3)``; default
            :func:`airpose_lib.data.poses.sample_body_pose`.
    """

    def __init__(self, config: GenerationConfig, pose_sampler=None) -> None:
        import torch

        from airpose_lib.body import BODY_25_FROM_SMPLX, load_body_model

        from .appearance import BodyPaint
        from .render import SceneRenderer

        if pose_sampler is None:
            from .poses import sample_body_pose as pose_sampler
        self.config = config
        self.pose_sampler = pose_sampler
        self.models, self.paint, self.faces = {}, {}, {}
        for g in config.scene.genders:
            m = load_body_model(config.body_source, g, dtype=torch.float32)
            self.models[g] = m
            self.paint[g] = BodyPaint.from_model(m)
            self.faces[g] = np.asarray(m.faces, dtype=np.int64)
        self.body25 = np.asarray(BODY_25_FROM_SMPLX)
        self.renderer = SceneRenderer(config.crop_size, anti_aliasing=config.anti_aliasing)
        self.num_textures = len(self.renderer.texture_names)

    def close(self) -> None:
        self.renderer.close()

    # -- attempts ---------------------------------------------------------------------------------
    def attempt_rng(self, shard: int, attempt: int) -> np.random.Generator:
        """The generator of one sample attempt: depends on (seed, shard, attempt) only."""
        return np.random.default_rng(np.random.SeedSequence([self.config.seed, shard, attempt]))

    def _people(self, shard: int, first: int, n: int):
        """Draw ``n`` attempts' subjects and pose their bodies (batched per gender)."""
        rngs = [self.attempt_rng(shard, a) for a in range(first, first + n)]
        people = [sample_person(r, self.config.scene, self.pose_sampler) for r in rngs]
        verts: list = [None] * n
        joints: list = [None] * n
        for g in self.config.scene.genders:
            idx = [i for i, p in enumerate(people) if p.gender == g]
            if not idx:
                continue
            v, j = _body_forward(self.models[g], np.stack([people[i].betas for i in idx]),
                                 np.stack([people[i].theta for i in idx]))
            for k, i in enumerate(idx):
                verts[i], joints[i] = v[k], j[k]
        return rngs, people, verts, joints

    def _sample(self, rng, person, v0, j0, train: bool) -> dict | None:
        """Finish one attempt: cameras, visibility, appearance, environment, crops, renders.

        Returns the sample's arrays (with encoded images under ``"images"``) or None if the
        person leaves a frame.
        """
        import torch

        from airpose_lib.geometry import body_in_camera, crop_vector, project_points

        cfg, sc = self.config, self.config.scene
        R_wb, t_wb = body_world_pose(person, v0)
        cams = sample_cameras(rng, sc)
        V = len(cams)
        K = np.stack([c.K for c in cams])
        R_cw = np.stack([c.R_cw for c in cams])
        t_cw = np.stack([c.t_cw for c in cams])
        T = lambda a: torch.as_tensor(a, dtype=torch.float64)  # noqa: E731
        phi, tau = (x.numpy() for x in body_in_camera(T(R_wb), T(t_wb), T(R_cw), T(t_cw)))

        # Everything in a camera follows from the model-frame points: X_c = phi X_0 + tau.
        vc = v0 @ phi.transpose(0, 2, 1) + tau[:, None]  # (V, N, 3)
        uv_v = project_points(T(vc), T(K)).numpy()
        if not points_in_frame(uv_v, vc[..., 2], sc.image_size, sc.frame_margin_px).all():
            return None
        jc = j0 @ phi.transpose(0, 2, 1) + tau[:, None]
        uv_j = project_points(T(jc), T(K)).numpy()

        appearance = sample_appearance(rng, cfg.appearance)
        colors = self.paint[person.gender].colors(appearance, cfg.appearance.shading_strength)
        env = sample_environment(rng, sc, self.num_textures, person.position,
                                 np.stack([c.centre for c in cams]))
        box_pts = uv_j if sc.bbox_from == "joints" else uv_v
        tight = np.stack([tight_bbox(box_pts[c], sc.bbox_margin_px) for c in range(V)])
        margin = sc.bbox_jitter_px if (train or cfg.test_crops == "jittered") else 0.0
        bbox = np.stack([jitter_bbox(tight[c], rng, margin, sc.image_size) for c in range(V)])
        P = crop_vector(T(bbox), T(K), cfg.crop_size).numpy()

        self.renderer.set_environment(env)
        self.renderer.set_body(v0 @ R_wb.T + t_wb, self.faces[person.gender], colors)
        images = self._render_crops(bbox, K, R_cw, t_cw)
        extra = {}
        if not train and cfg.tight_test_crops:
            # the same box before enlargement, clipped to the frame like every crop
            tight_clipped = np.stack([jitter_bbox(tight[c], rng, 0.0, sc.image_size) for c in range(V)])
            extra = {"images_tight": self._render_crops(tight_clipped, K, R_cw, t_cw),
                     "P_tight": crop_vector(T(tight_clipped), T(K), cfg.crop_size).numpy(),
                     "bbox_tight_crop": tight_clipped}

        kp_idx = self.body25
        kp2d = np.where((kp_idx >= 0)[None, :, None], uv_j[:, np.maximum(kp_idx, 0)], np.nan)
        kp_z = np.where(kp_idx >= 0, jc[:, np.maximum(kp_idx, 0), 2], -1.0)
        kp_visible = (kp_idx >= 0)[None] & points_in_frame(kp2d, kp_z, sc.image_size)
        return {
            "images": images,
            "gender": GENDER_CODES[person.gender],
            "beta": person.betas, "theta": person.theta,
            "R_wb": R_wb, "t_wb": t_wb, "heading": person.heading,
            "K": K, "R_cw": R_cw, "t_cw": t_cw, "phi": phi, "tau": tau,
            "bbox": bbox, "bbox_tight": tight, "P": P,
            "j2d": uv_j[:, :22], "kp2d": kp2d, "kp_visible": kp_visible, "j3d_cam": jc[:, :22],
            "cam_centre": np.stack([c.centre for c in cams]),
            "cam_distance": np.array([c.distance for c in cams]),
            "cam_pitch": np.array([c.pitch for c in cams]),
            "cam_azimuth": np.array([c.azimuth for c in cams]),
            "env_texture": env.ground_texture, "env_light_dir": env.light_dir,
            "env_light_intensity": env.light_intensity, "env_num_distractors": len(env.distractors),
            "skin_color": appearance.region_colors[0],
            **extra,
        }

    def _render_crops(self, bbox: np.ndarray, K: np.ndarray, R_cw: np.ndarray, t_cw: np.ndarray) -> list[bytes]:
        """Encoded crops ``[V]`` of the scene set on the renderer, one per box ``bbox (V, 4)``."""
        import torch

        from airpose_lib.geometry import crop_intrinsics, pad_outside_box

        cfg = self.config
        T = lambda a: torch.as_tensor(a, dtype=torch.float64)  # noqa: E731
        K_crop = crop_intrinsics(T(K), T(bbox), cfg.crop_size).numpy()
        out = []
        for c in range(len(bbox)):
            img = self.renderer.render(K_crop[c], R_cw[c], t_cw[c])
            if cfg.blur_sigma > 0:
                img = _blur(img, cfg.blur_sigma)
            out.append(_encode(pad_outside_box(img, bbox[c]), cfg.image_format, cfg.jpeg_quality))
        return out

    def make_shard(self, k: int, progress=None) -> tuple[dict, dict]:
        """Generate shard ``k``: ``(arrays, stats)``; ``progress(n)`` is called per accepted sample."""
        cfg = self.config
        want = cfg.shard_samples(k)
        train = cfg.shard_split(k) == "train"
        max_attempts = cfg.max_attempts_per_sample * want
        samples, attempts, dropped = [], [], 0
        first = 0
        while len(samples) < want:
            if first >= max_attempts:
                raise RuntimeError(
                    f"shard {k}: only {len(samples)} of {want} samples after {first} attempts; the "
                    "person leaves the frame too often (check the scene settings)")
            n = min(_ATTEMPT_BATCH, max_attempts - first)
            rngs, people, verts, joints = self._people(k, first, n)
            for i in range(n):
                if len(samples) == want:
                    break
                s = self._sample(rngs[i], people[i], verts[i], joints[i], train)
                if s is None:
                    dropped += 1
                    continue
                samples.append(s)
                attempts.append(first + i)
                if progress is not None:
                    progress(1)
            first += n
        arrays = _stack_samples(samples, k * cfg.shard_size, attempts)
        stats = {"samples": len(samples), "attempts": attempts[-1] + 1, "dropped": dropped}
        return arrays, stats

    def write_shard(self, k: int, root: Path, progress=None) -> dict:
        """Generate shard ``k`` into ``root`` (atomically); returns its manifest record."""
        arrays, stats = self.make_shard(k, progress)
        cfg = self.config
        meta = {"kind": DATASET_KIND, "generator_version": GENERATOR_VERSION, "shard": k,
                "split": cfg.shard_split(k), "fingerprint": cfg.fingerprint(),
                "crop_size": cfg.crop_size, "num_views": cfg.scene.num_views,
                "image_format": cfg.image_format, **stats}
        name = shard_name(k)
        digest, size = write_shard(Path(root) / name, arrays, meta)
        return {"index": k, "file": name, "split": cfg.shard_split(k), **stats,
                "bytes": size, "sha256": digest}


def _stack_samples(samples: list[dict], first_index: int, attempts: list[int]) -> dict[str, np.ndarray]:
    """Turn per-sample dicts into the shard's arrays (one row per sample)."""
    out: dict[str, np.ndarray] = {}
    for key, offsets in (("images", "image_offsets"), ("images_tight", "image_offsets_tight")):
        if key not in samples[0]:
            continue
        images = [b for s in samples for b in s[key]]
        lengths = np.array([len(b) for b in images], dtype=np.int64)
        out[offsets] = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
        out[key] = np.frombuffer(b"".join(images), dtype=np.uint8)
    out["index"] = first_index + np.arange(len(samples), dtype=np.int64)
    out["attempt"] = np.asarray(attempts, dtype=np.int64)
    for key in samples[0]:
        if key in ("images", "images_tight"):
            continue
        vals = [s[key] for s in samples]
        if key in ("gender", "env_texture", "env_num_distractors"):
            out[key] = np.asarray(vals, dtype=np.int64)
        elif key == "kp_visible":
            out[key] = np.stack(vals).astype(bool)
        else:
            out[key] = np.stack([np.asarray(v, dtype=np.float64) for v in vals])
    return out


# -- parallel driver ------------------------------------------------------------------------------
_WORKER: dict = {}


def _limit_threads() -> None:
    """One thread per process: workers run side by side, and fixed threading keeps results equal."""
    import torch

    torch.set_num_threads(1)


def _worker_init(config_dict: dict, progress_queue, parent: int | None = None) -> None:
    die_with_parent(parent)  # no orphaned renderers if the parent is killed (even before this runs)
    os.environ.setdefault("LP_NUM_THREADS", "1")  # Mesa llvmpipe: one raster thread per worker
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    _limit_threads()
    _WORKER["gen"] = StillFrameGenerator(GenerationConfig.from_dict(config_dict))
    _WORKER["queue"] = progress_queue


def _worker_shard(args: tuple[int, str]) -> dict:
    k, root = args
    q = _WORKER["queue"]
    return _WORKER["gen"].write_shard(k, Path(root), progress=lambda n: q.put(n))


def _body_model_hashes(config: GenerationConfig) -> dict[str, str]:
    """SHA-256 of the body-model file of each ground-truth gender (the data depend on it)."""
    from airpose_lib.body import check_model_file, resolve_model_file

    return {g: sha256_file(check_model_file(resolve_model_file(config.body_source, g)))  # a damaged file
            for g in config.scene.genders}                                            # is named as such


def _new_manifest(config: GenerationConfig, profile: str | None, body_models: dict) -> dict:
    from airpose_lib import __version__

    return {
        "kind": DATASET_KIND,
        "generator_version": GENERATOR_VERSION,
        "kit_version": __version__,
        "profile": profile,
        "seed": config.seed,
        "fingerprint": config.fingerprint(),
        "status": "incomplete",
        "num_samples": config.num_samples,
        "num_shards": config.num_shards,
        "shard_size": config.shard_size,
        "crop_size": config.crop_size,
        "num_views": config.scene.num_views,
        "image_format": config.image_format,
        "body_models": {"source": config.body_source, "sha256": body_models},
        "splits": {"train": [k for k in range(config.num_shards) if config.shard_split(k) == "train"],
                   "test": [k for k in range(config.num_shards) if config.shard_split(k) == "test"]},
        "totals": {},
        "config": config.to_dict(),
        "shards": [],
    }


def _finish_manifest(manifest: dict, config: GenerationConfig) -> None:
    shards = sorted(manifest["shards"], key=lambda r: r["index"])
    manifest["shards"] = shards
    samples = {s: sum(r["samples"] for r in shards if r["split"] == s) for s in ("train", "test")}
    attempts = sum(r["attempts"] for r in shards)
    dropped = sum(r["dropped"] for r in shards)
    manifest["totals"] = {
        "samples": samples["train"] + samples["test"], "train_samples": samples["train"],
        "test_samples": samples["test"], "attempts": attempts, "dropped": dropped,
        "drop_rate": round(dropped / attempts, 4) if attempts else 0.0,
        "bytes": sum(r["bytes"] for r in shards),
    }
    done = {r["index"] for r in shards}
    manifest["status"] = "complete" if done == set(range(config.num_shards)) else "incomplete"


@locks_folder("root", "dataset folder")  # one writer; removes a dead writer's .shard_*.tmp
def generate_still_dataset(
    config: GenerationConfig,
    root: Path | str,
    *,
    workers: int = 1,
    profile: str | None = None,
    progress: bool = True,
    record: bool | Path = False,
    stop_after_shards: int | None = None,
) -> dict:
    """Generate (or resume, or just verify) a still-frame dataset in ``root``.

    Shards listed in ``root/manifest.yaml`` whose size and SHA-256 still match are kept; every
    other shard is (re)built. The manifest is rewritten after each finished shard.

    Args:
        config: what to generate.
        root: dataset folder (created if needed).
        workers: processes rendering shards in parallel, each with its own renderer (1 = in
            this process). The result does not depend on it.
        profile: profile name recorded in the manifest (and used for the repair hint).
        progress: show a tqdm bar over samples.
        record: when the dataset is complete, copy the manifest to the checkout's
            ``data_manifests/generated_<profile>.yaml`` (True) or into the given folder.
        stop_after_shards: stop after building this many shards (simulates an interruption).

    Returns:
        The manifest dict (``status`` is ``complete`` unless stopped early).

    Raises:
        DatasetError: ``root`` holds a dataset made with other settings.
    """
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    manifest = load_manifest(root)
    if manifest is not None and manifest.get("fingerprint") != config.fingerprint():
        raise DatasetError(
            f"{root} holds a dataset made with other settings (profile {manifest.get('profile')!r}, "
            f"generator {manifest.get('generator_version')}); delete the folder or choose another "
            f"--out to generate this one")
    body_models = _body_model_hashes(config)
    if manifest is not None and (manifest.get("body_models") or {}).get("sha256") != body_models:
        raise DatasetError(
            f"{root} was generated with other body-model files than the ones in the cache now "
            f"(see body_models in {root / 'manifest.yaml'}); delete the folder or choose another "
            f"--out to generate the dataset again with the current model")
    if manifest is None:
        manifest = _new_manifest(config, profile, body_models)
    if profile is not None:
        manifest["profile"] = profile

    kept, todo = [], []
    records = {r["index"]: r for r in manifest.get("shards") or []}
    for k in range(config.num_shards):
        r = records.get(k)
        path = root / shard_name(k)
        if r is not None and path.is_file() and path.stat().st_size == r["bytes"] \
                and sha256_file(path) == r["sha256"]:
            kept.append(r)
        else:
            todo.append(k)
    manifest["shards"] = kept
    _finish_manifest(manifest, config)
    write_manifest(root, manifest)
    if todo and stop_after_shards is not None:
        todo = todo[:stop_after_shards]

    bar = None
    if progress and todo:
        from airpose_lib.progress import progress_bar

        bar = progress_bar(total=config.num_samples, initial=manifest["totals"]["samples"], unit="sample",
                   desc=f"still frames -> {root.name}", smoothing=0.1)

    def finished(rec: dict) -> None:
        manifest["shards"].append(rec)
        _finish_manifest(manifest, config)
        write_manifest(root, manifest)

    try:
        if todo and workers <= 1:
            _run_inprocess(config, root, todo, bar, finished)
        elif todo:
            _run_pool(config, root, todo, min(workers, len(todo)), bar, finished)
    finally:
        if bar is not None:
            bar.close()
    if manifest["status"] == "complete" and record:
        record_manifest(manifest, None if record is True else Path(record))
    return manifest


def _run_inprocess(config, root, todo, bar, finished) -> None:
    import torch

    threads = torch.get_num_threads()
    _limit_threads()
    gen = StillFrameGenerator(config)
    try:
        for k in todo:
            finished(gen.write_shard(k, root, progress=bar.update if bar is not None else None))
    finally:
        gen.close()
        torch.set_num_threads(threads)


def _run_pool(config, root, todo, workers, bar, finished) -> None:
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    # spawn: a fresh interpreter per worker, so no GL context or torch thread pool is inherited.
    # ProcessPoolExecutor (not multiprocessing.Pool): a worker that dies raises BrokenProcessPool
    # here instead of leaving its shard pending forever.
    ctx = mp.get_context("spawn")
    q = ctx.Queue()

    def drain() -> None:
        while True:
            try:
                n = q.get_nowait()
            except queue_mod.Empty:
                return
            if bar is not None:
                bar.update(n)

    ex = ProcessPoolExecutor(workers, mp_context=ctx, initializer=_worker_init,
                             initargs=(config.to_dict(), q, os.getpid()))
    try:
        pending = {ex.submit(_worker_shard, (k, str(root))) for k in todo}
        while pending:
            done, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
            drain()
            for f in done:
                finished(f.result())  # re-raises a worker's exception here
        drain()
    except BaseException:
        # Interrupted or failed: stop the other workers now; their unfinished shards leave only
        # temporary files, which the next run deletes.
        for p in list(getattr(ex, "_processes", {}).values()):
            p.terminate()
        ex.shutdown(wait=False, cancel_futures=True)
        raise
    ex.shutdown(wait=True)


def ensure_still_dataset(profile: str | None = None, *, config: GenerationConfig | None = None,
                         root: Path | str | None = None, workers: int | None = None,
                         progress: bool = True, record: bool | Path = False) -> Path:
    """Make sure a complete, verified dataset exists and return its folder.

    Either ``profile`` (settings from the profile file, default folder
    :func:`default_root`) or an explicit ``config`` and ``root``. Existing shards are verified
    and kept, so on a finished dataset this only checks checksums.
    """
    if config is None:
        if profile is None:
            raise ValueError("give a profile or a config")
        config = profile_config(profile)
    if root is None:
        if profile is None:
            raise ValueError("give a root folder for an explicit config")
        root = default_root(profile)
    done = load_manifest(Path(root))
    if done is not None and done.get("status") == "complete" and done.get("fingerprint") == config.fingerprint() \
            and not record:
        # Finished: readers take no writer's lock (parallel trainings open it at once); the
        # datasets verify every shard's checksum when they open it.
        return Path(root)
    workers = workers if workers is not None else max(1, min(os.cpu_count() or 1, 4))
    manifest = generate_still_dataset(config, root, workers=workers, profile=profile,
                                      progress=progress, record=record)
    if manifest["status"] != "complete":
        raise DatasetError(f"dataset in {root} is incomplete; resume with "
                           f"`{regenerate_command(manifest, Path(root))}`")
    return Path(root)
