"""Train the kit's prior for a profile and save it where :func:`~.checkpoint.load_prior` looks.

The corpus is the kit's own pose generators: still poses of :mod:`airpose_lib.data.still.poses` and
poses along the scripted motions of :mod:`airpose_lib.data.sequences.motions` (the same generators that
pose the people of the synthetic data), less the motion activities a profile holds out
(``prior: held_out_motions:``, the activities of its recordings: a prior that has not seen the
test motions, as the paper's VPoser had not).
"""
from __future__ import annotations

import copy
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from airpose_lib.body import BodyForward, load_body_model
from airpose_lib.data.sequences.motions import ACTIVITIES, evaluate_motion, sample_script
from airpose_lib.data.still.poses import sample_body_pose, within_limits
from airpose_lib.devices import resolve_device
from airpose_lib.errors import ConfigError
from airpose_lib.folder_lock import file_lock_for

from .checkpoint import load_prior, save_prior
from .train import CorpusConfig, PriorTrainConfig, evaluate_prior, train_prior

__all__ = ["PriorSetup", "check_held_out_motions", "motion_poses", "prior_corpus", "prior_is_current",
           "train_and_save_prior", "ensure_prior"]


@dataclass(frozen=True)
class PriorSetup:
    """A profile's kit prior, read once at the entry: its ``prior:`` section and where it lives.

    Attributes:
        train: the training settings.
        corpus: the corpus settings.
        where: how messages name the section (the file and the section).
        path: the prior's file (``RunFolders.prior``).
        label: how the prior's record names the profile.
    """

    train: PriorTrainConfig
    corpus: CorpusConfig
    where: str
    path: Path
    label: str


def check_held_out_motions(corpus: CorpusConfig, where: str = "the prior's corpus") -> None:
    """A :class:`ConfigError` (naming ``where``) when ``corpus.held_out_motions`` names an
    activity not in :data:`~airpose_lib.data.sequences.motions.ACTIVITIES` or holds out all of them while
    motion poses are asked for."""
    unknown = sorted(set(corpus.held_out_motions) - set(ACTIVITIES))
    if unknown:
        raise ConfigError(f"{where}: held_out_motions: unknown activities {unknown}; choose from {list(ACTIVITIES)}")
    if corpus.n_motion_poses and set(corpus.held_out_motions) >= set(ACTIVITIES):
        raise ConfigError(f"{where}: held_out_motions holds out every activity; set n_motion_poses: 0 "
                          "for a prior of still poses only")


def motion_poses(rng: np.random.Generator, n: int, fps: float,
                 exclude=()) -> tuple[np.ndarray, np.ndarray]:
    """``n`` poses sampled at ``fps`` along random 60 s scripts of :mod:`airpose_lib.data.sequences.motions`
    that never contain the activities ``exclude``, and how much of each activity every pose is.

    Returns:
        ``theta (n, 21, 3)`` axis-angle body poses and ``share (n, len(ACTIVITIES))``: the
        cross-fade weight of each activity in the pose (rows sum to 1; columns in the order of
        :data:`~airpose_lib.data.sequences.motions.ACTIVITIES`).
    """
    thetas, shares = [], []
    got = 0
    while got < n:
        script = sample_script(rng, 60.0, exclude=exclude)
        times = np.arange(0.0, script.duration, 1.0 / fps)
        state = evaluate_motion(script, times)
        onehot = np.array([[a == s.activity for a in ACTIVITIES] for s in script.segments], dtype=np.float64)
        thetas.append(state.theta[: n - got])
        shares.append((state.weights @ onehot)[: n - got])
        got += len(thetas[-1])
    if not thetas:
        return np.zeros((0, 21, 3)), np.zeros((0, len(ACTIVITIES)))
    return np.concatenate(thetas), np.concatenate(shares)


def prior_corpus(corpus: CorpusConfig, stream: int, n_still: int, n_motion: int) -> np.ndarray:
    """Poses of the kit's generators: ``n_still`` still poses and ``n_motion`` motion poses, the
    latter without the activities ``corpus.held_out_motions`` (:func:`motion_poses`).

    Returns:
        ``(n_still + n_motion, 21, 3)`` float32 axis-angle body poses.
    """
    check_held_out_motions(corpus)
    rng = np.random.default_rng([corpus.seed, stream])
    parts = [sample_body_pose(rng, n_still)] if n_still else []
    if n_motion:
        parts.append(motion_poses(rng, n_motion, corpus.motion_fps, corpus.held_out_motions)[0])
    return np.concatenate(parts).astype(np.float32)


def train_and_save_prior(setup: PriorSetup, out: str | Path | None = None, *, steps: int | None = None,
                         seed: int | None = None, device: str | None = None,
                         progress: bool = False) -> tuple[Path, dict]:
    """Train the prior with a profile's ``prior:`` section (``setup``), evaluate it on held-out
    poses, save it.

    ``steps``, ``seed``, ``device`` (``auto``, ``cpu``, ``cuda``, ``cuda:N``) replace the profile's
    (None: the profile's; the device's default is cpu).

    Returns:
        the checkpoint path (default ``setup.path``) and a report with
        ``steps, seconds, final_train_loss`` and the validation numbers of :func:`evaluate_prior`
        plus ``samples_within_joint_limits`` (share of N(0, I) samples within the joint limits +5 deg).
    """
    path = Path(out) if out is not None else setup.path
    with file_lock_for(path, "prior checkpoint"):  # one writer per output file
        return _train_and_save_prior(setup, path, steps, seed, device, progress)


def _train_and_save_prior(setup: PriorSetup, path: Path, steps: int | None, seed: int | None, device: str | None,
                          progress: bool) -> tuple[Path, dict]:
    cfg, corpus = copy.deepcopy(setup.train), copy.deepcopy(setup.corpus)  # changed below: the setup's stay
    if steps is not None:
        cfg.steps = steps
    if device is not None:
        cfg.device = device
    dev = resolve_device(cfg.device)  # a bad device fails before the corpus is drawn
    check_held_out_motions(corpus, setup.where)
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
    save_prior(model, path, {"profile": setup.label, "train": cfg.to_dict(), "corpus": corpus.to_dict(),
                             "train_seconds": hist["seconds"], "final_train_loss": hist["loss"][-1],
                             "validation": val})
    return path, report


def prior_is_current(path: str | Path, setup: PriorSetup) -> bool:
    """The kit prior at ``path`` exists and was trained on the corpus the profile's ``prior:``
    section asks for (its record's ``corpus``; e.g. the same ``held_out_motions``)."""
    path = Path(path)
    if not path.is_file():
        return False
    corpus = setup.corpus
    _, prov = load_prior("kit", path, return_provenance=True)
    return json.loads(json.dumps(prov.get("corpus"))) == json.loads(json.dumps(corpus.to_dict()))


def ensure_prior(setup: PriorSetup, progress: bool = False) -> Path:
    """The profile's kit prior, trained first if it is not cached yet or was trained on another
    corpus than the profile's (:func:`prior_is_current`)."""
    path = setup.path
    if not prior_is_current(path, setup):
        path, _ = train_and_save_prior(setup, progress=progress)
    return path
