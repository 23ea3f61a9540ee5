"""One process's still-frame generator: draw a subject and its drone cameras, pose the body,
render the person crops and collect one shard's arrays (:class:`StillFrameGenerator`).

Shard ``k`` draws its sample attempts from generators seeded with ``(seed, k, attempt)``, so a
shard depends only on the configuration and its index (see :mod:`airpose_lib.data.still.generate`).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from airpose_lib.body.forward import rest_body
from airpose_lib.body.genders import GENDER_CODES
from airpose_lib.geometry import body_in_camera, crop_intrinsics, crop_vector, pad_outside_box, project_points

from .appearance import sample_appearance
from .config import GENERATOR_VERSION, GenerationConfig
from .manifest import DATASET_KIND
from .scene import (
    body_world_pose,
    jitter_bbox,
    points_in_frame,
    sample_cameras,
    sample_environment,
    sample_person,
    tight_bbox,
)
from .shards import shard_name, write_shard

__all__ = ["StillFrameGenerator"]

_ATTEMPT_BATCH = 16  # body forwards are batched over this many attempts


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
            :func:`airpose_lib.data.still.poses.sample_body_pose`.
    """

    def __init__(self, config: GenerationConfig, pose_sampler=None) -> None:
        # Imported when a generator is built (once per rendering process): the renderer starts
        # VTK/pyvista (optional GL).
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
            v, j = rest_body(self.models[g], np.stack([people[i].betas for i in idx]),
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


def _limit_threads() -> None:
    """One thread per process: workers run side by side, and fixed threading keeps results equal."""
    import torch

    torch.set_num_threads(1)
