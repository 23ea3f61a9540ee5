"""Train the kit's prior for a profile and save it where :func:`~.checkpoint.load_prior` looks.

The corpus is the kit's own pose generators: still poses of :mod:`airpose_lib.data.still.poses` and
poses along the scripted motions of :mod:`airpose_lib.data.sequences.motions` (the same generators that
pose the people of the synthetic data).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from airpose_lib.body import BodyForward, load_body_model
from airpose_lib.data.sequences.motions import evaluate_motion, sample_script
from airpose_lib.data.still.poses import sample_body_pose, within_limits
from airpose_lib.devices import resolve_device
from airpose_lib.folder_lock import file_lock_for

from .checkpoint import kit_prior_path, save_prior
from .train import CorpusConfig, evaluate_prior, prior_profile, train_prior

__all__ = ["prior_corpus", "train_and_save_prior", "ensure_prior"]


def prior_corpus(corpus: CorpusConfig, stream: int, n_still: int, n_motion: int) -> np.ndarray:
    """Poses of the kit's generators: ``n_still`` still poses and ``n_motion`` motion poses.

    Returns:
        ``(n_still + n_motion, 21, 3)`` float32 axis-angle body poses.
    """
    rng = np.random.default_rng([corpus.seed, stream])
    parts = [sample_body_pose(rng, n_still)] if n_still else []
    got = 0
    while got < n_motion:
        script = sample_script(rng, 60.0)
        times = np.arange(0.0, script.duration, 1.0 / corpus.motion_fps)
        theta = evaluate_motion(script, times).theta[: n_motion - got]
        parts.append(theta)
        got += len(theta)
    return np.concatenate(parts).astype(np.float32)


def train_and_save_prior(profile: str, out: str | Path | None = None, *, steps: int | None = None,
                         seed: int | None = None, device: str | None = None,
                         progress: bool = False) -> tuple[Path, dict]:
    """Train the prior with a profile's ``prior:`` section, evaluate it on held-out poses, save it.

    ``steps``, ``seed``, ``device`` (``auto``, ``cpu``, ``cuda``, ``cuda:N``) replace the profile's
    (None: the profile's; the device's default is cpu).

    Returns:
        the checkpoint path (default :func:`kit_prior_path` of ``profile``) and a report with
        ``steps, seconds, final_train_loss`` and the validation numbers of :func:`evaluate_prior`
        plus ``samples_within_joint_limits`` (share of N(0, I) samples within the joint limits +5 deg).
    """
    path = Path(out) if out is not None else kit_prior_path(profile)
    with file_lock_for(path, "prior checkpoint"):  # one writer per output file
        return _train_and_save_prior(profile, path, steps, seed, device, progress)


def _train_and_save_prior(profile: str, path: Path, steps: int | None, seed: int | None, device: str | None,
                          progress: bool) -> tuple[Path, dict]:
    cfg, corpus = prior_profile(profile)
    if steps is not None:
        cfg.steps = steps
    if device is not None:
        cfg.device = device
    dev = resolve_device(cfg.device)  # a bad device fails before the corpus is drawn
    if seed is not None:
        cfg.seed = corpus.seed = seed
    share = corpus.n_poses / max(corpus.n_poses + corpus.n_motion_poses, 1)
    train_poses = prior_corpus(corpus, 0, corpus.n_poses, corpus.n_motion_poses)
    val_still = round(corpus.n_val * share)
    val_poses = prior_corpus(corpus, 1, val_still, corpus.n_val - val_still)
    joints_fn = None
    if cfg.w_joints > 0:
        body = BodyForward(load_body_model("open", "neutral"), range(22), vertices=None).to(dev)
        zero_beta = torch.zeros(1, body.num_betas, device=dev)

        def joints_fn(R):
            """22 body joints of the mean shape, on ``R``'s device (training: the run's device;
            the held-out evaluation: the CPU)."""
            return body(R.to(dev), zero_beta)[0].to(R.device)
    model, hist = train_prior(train_poses, cfg, joints_fn=joints_fn, progress=progress)
    val = evaluate_prior(model, val_poses, joints_fn=joints_fn, n_samples=1000, seed=cfg.seed)
    samples = val.pop("samples")
    val["samples_within_joint_limits"] = float(within_limits(samples, tol=np.deg2rad(5.0)).mean())
    report = {"steps": cfg.steps, "seconds": hist["seconds"], "final_train_loss": hist["loss"][-1],
              "train_poses": len(train_poses), "val_poses": len(val_poses), **val}
    save_prior(model, path, {"profile": profile, "train": cfg.to_dict(), "corpus": corpus.to_dict(),
                             "train_seconds": hist["seconds"], "final_train_loss": hist["loss"][-1],
                             "validation": val})
    return path, report


def ensure_prior(profile: str, progress: bool = False) -> Path:
    """The profile's kit prior, trained first if it is not cached yet."""
    path = kit_prior_path(profile)
    if not path.is_file():
        path, _ = train_and_save_prior(profile, progress=progress)
    return path
