"""Training the kit's pose prior on a corpus of body poses, and measuring it.

The loss follows VPoser v2's trainer (``human_body_prior``, release V02_05), without its mesh term
(the kit's corpus has no mesh-level data and the joints carry the skeleton's geometry):

    L = w_rot * mean geodesic(R_rec, R)                                   (radians, per joint)
      + w_joints * mean |J(R_rec) - J(R)|_1     (optional, metres, through a body model)
      + w_kl(step) * mean_batch sum_latent KL(q(z | theta) || N(0, I))

``w_kl`` rises linearly from 0 to its value over ``kl_anneal_steps`` (KL annealing: the decoder
learns to reconstruct before the posterior is pulled to the prior). Adam with weight decay
(the release's optimiser settings) and a cosine learning-rate decay; batches are drawn by a
seeded generator, so the same corpus, config and seed give the same weights.

The corpus is any ``(N, 21, 3)`` axis-angle array; the kit trains on
:func:`airpose_lib.data.still.poses.sample_body_pose` and poses of :mod:`airpose_lib.data.sequences.motions`
(assembled by ``airpose prior train``; this package does not import ``data``).
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np
import torch
from torch import Tensor

from airpose_lib.config_fields import ranged
from airpose_lib.devices import resolve_device
from airpose_lib.engine import Schedule, TrainingTask, run_engine
from airpose_lib.geometry import axis_angle_to_matrix, geodesic_angle

from .vposer import LATENT_DIM, NUM_JOINTS, NUM_NEURONS, VPoser

__all__ = ["PriorTrainConfig", "CorpusConfig", "train_prior", "evaluate_prior",
           "rotation_geodesic"]


JointsFn = Callable[[Tensor], Tensor]
"""Body rotations ``(B, 21, 3, 3)`` -> joint positions ``(B, J, 3)`` metres (e.g. the open model)."""


@dataclass
class PriorTrainConfig:
    """Sizes and weights of prior training (defaults: the ``cpu`` profile's, a few minutes)."""

    steps: int = ranged(6000, ge=1)
    batch_size: int = ranged(256, ge=1)
    lr: float = ranged(1e-3, gt=0)
    lr_final_fraction: float = ranged(0.05, ge=0, le=1)  # cosine decay to lr * this at the last step
    weight_decay: float = ranged(1e-5, ge=0)  # the release's Adam setting
    w_rot: float = ranged(2.0, ge=0)  # the release's loss_matrot_wt (geodesic, radians)
    w_joints: float = ranged(2.0, ge=0)  # the release's loss_jtr_wt (L1, metres); used only with joints_fn
    w_kl: float = ranged(5e-3, ge=0)  # the release's loss_kl_wt
    kl_anneal_steps: int = ranged(1000, ge=0)
    num_neurons: int = ranged(NUM_NEURONS, ge=1)
    latent_dim: int = ranged(LATENT_DIM, ge=1)
    seed: int = 0
    log_every: int = ranged(250, ge=1)
    device: str = "cpu"  # auto, cpu, cuda, cuda:N (airpose_lib.devices); the model comes back on the CPU

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class CorpusConfig:
    """The training corpus drawn from the kit's pose generators (``airpose prior train``).

    ``n_poses`` still poses of :func:`airpose_lib.data.still.poses.sample_body_pose` plus about
    ``n_motion_poses`` poses sampled at ``motion_fps`` from random scripts of
    :mod:`airpose_lib.data.sequences.motions` (transitions and blends the still sampler does not make);
    ``n_val`` held-out poses from a separate stream with the same mixture.

    ``held_out_motions`` names motion activities (``data.sequences.motions.ACTIVITIES``) whose poses the
    corpus never contains: the scripts are drawn without them (the paper's
    VPoser was trained on AMASS, not on its test motions, so the kit's prior must not have seen
    the recordings' activities either). Empty (default): all activities, and the setting is
    absent from :meth:`to_dict` (the record of earlier priors stays as it was).
    """

    n_poses: int = ranged(100_000, ge=1)
    n_motion_poses: int = ranged(20_000, ge=0)
    motion_fps: float = ranged(5.0, gt=0)
    n_val: int = ranged(2000, ge=1)
    seed: int = 0
    held_out_motions: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        d = asdict(self)
        if self.held_out_motions:
            d["held_out_motions"] = list(self.held_out_motions)
        else:
            del d["held_out_motions"]
        return d


def rotation_geodesic(R1: Tensor, R2: Tensor, eps: float = 1e-7) -> Tensor:
    """Geodesic angle (radians) with a finite gradient at zero, for losses.

    ``||R1 - R2||_F = 2 sqrt(2) sin(angle / 2)``; the square root gets ``eps`` added inside so
    that identical rotations (angle 0, where the exact angle is not differentiable) give a zero
    gradient instead of NaN. Error ``< sqrt(eps)``.

    Args:
        R1, R2: ``(..., 3, 3)``.
    Returns:
        ``(...)`` angles.
    """
    chord = ((R1 - R2).square().sum(dim=(-1, -2)) + eps).sqrt()
    return 2.0 * torch.asin((chord / (2.0 * math.sqrt(2.0))).clamp(max=1.0 - 1e-7))


def _as_poses(poses) -> Tensor:
    t = torch.as_tensor(np.asarray(poses), dtype=torch.float32)
    if t.ndim == 2 and t.shape[1] == NUM_JOINTS * 3:
        t = t.reshape(-1, NUM_JOINTS, 3)
    if t.ndim != 3 or tuple(t.shape[1:]) != (NUM_JOINTS, 3):
        raise ValueError(f"poses must be (N, 21, 3) axis-angle, got {tuple(t.shape)}")
    if not torch.isfinite(t).all():
        raise ValueError("poses contain NaN or inf")
    return t


def train_prior(
    poses,
    config: PriorTrainConfig | None = None,
    *,
    joints_fn: JointsFn | None = None,
    val_poses=None,
    progress: bool = False,
    log: Callable[[str], None] | None = None,
) -> tuple[VPoser, dict]:
    """Train a VPoser-architecture prior.

    Args:
        poses: ``(N, 21, 3)`` (or ``(N, 63)``) axis-angle training poses, N >= 2.
        config: sizes and weights (default :class:`PriorTrainConfig`).
        joints_fn: optional body-model joints for the joint term (``w_joints``); it is called
            with rotations on ``config.device`` and must answer on the same device.
        val_poses: optional held-out poses, evaluated at the end (:func:`evaluate_prior`, on the CPU).
        progress: tqdm bar.
        log: called with a line every ``config.log_every`` steps.
    Returns:
        the trained model (eval mode, on the CPU whatever ``config.device``) and a history dict: ``config``, ``steps``, per-log-step
        ``loss``/``rot_deg``/``kl``, ``seconds``, and ``val`` metrics if ``val_poses`` was given.
    """
    cfg = config or PriorTrainConfig()
    data = _as_poses(poses)  # (N, 21, 3)
    if data.shape[0] < 2:
        raise ValueError("need at least 2 training poses (batch norm)")
    dev = resolve_device(cfg.device)
    torch.manual_seed(cfg.seed)  # weight initialisation (on the CPU: the same weights on every device)
    model = VPoser(cfg.num_neurons, cfg.latent_dim).to(dev)
    model.train()
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    gen = torch.Generator().manual_seed(cfg.seed + 1)  # the batch order, drawn on the CPU
    data = data.to(dev)
    R_all = axis_angle_to_matrix(data)  # (N, 21, 3, 3), computed once
    J_all = None
    if joints_fn is not None and cfg.w_joints > 0:
        with torch.no_grad():
            J_all = torch.cat([joints_fn(R_all[i:i + 4096]) for i in range(0, len(R_all), 4096)])
    hist: dict = {"config": cfg.to_dict(), "step": [], "loss": [], "rot_deg": [], "kl": []}
    task = _PriorTask(model, opt, cfg, data, R_all, J_all, joints_fn, gen, hist, log)
    # In memory (the result is one saved model): no run folder, so no checkpoints or CSV; rows at
    # the 0-based steps 0, log_every, ... as the history always had them.
    schedule = Schedule(steps=cfg.steps, log_every=cfg.log_every, log_offset=1, check_finite=False, what="prior",
                        progress=progress, progress_kwargs={"unit": "step"})
    t0 = time.perf_counter()
    run_engine(task, schedule)
    hist["seconds"] = time.perf_counter() - t0
    hist["steps"] = cfg.steps
    model.eval().cpu()
    if val_poses is not None:
        hist["val"] = evaluate_prior(model, val_poses, joints_fn=joints_fn)
    return model, hist


def _cosine_lr(cfg: PriorTrainConfig, step: int) -> float:
    """Learning rate of 0-based ``step``: cosine decay from ``lr`` to ``lr * lr_final_fraction``."""
    final = cfg.lr_final_fraction
    frac = step / max(cfg.steps - 1, 1)
    return cfg.lr * (final + (1 - final) * 0.5 * (1 + math.cos(math.pi * frac)))


class _PriorTask(TrainingTask):
    """The engine's task for the prior: VAE steps on random batches of the corpus.

    Each epoch is a permutation of the corpus drawn from the seeded generator ``gen``, cut into
    ``N // B`` batches (``B = min(batch_size, N)``); dropout and the posterior sample use torch's
    global RNG, seeded with the weights.
    """

    def __init__(self, model: VPoser, optimizer, cfg: PriorTrainConfig, data: Tensor, R_all: Tensor,
                 J_all: Tensor | None, joints_fn: JointsFn | None, gen: torch.Generator, hist: dict,
                 log: Callable[[str], None] | None) -> None:
        self.model, self.optimizer, self.cfg = model, optimizer, cfg
        self.data, self.R_all, self.J_all, self.joints_fn = data, R_all, J_all, joints_fn
        self.gen, self.hist, self.log = gen, hist, log
        self.batch = min(cfg.batch_size, data.shape[0])

    def batches(self, epoch: int, start: int):
        # The generator is consumed epoch after epoch (no resume: the prior trains in memory).
        n, B = self.data.shape[0], self.batch
        order = torch.randperm(n, generator=self.gen)
        for b in range(start, n // B):
            yield order[b * B:(b + 1) * B]

    def train_step(self, idx: Tensor, step: int) -> dict[str, Tensor]:
        """Loss of the batch ``idx (B,)``: ``total``, ``rot`` (mean geodesic, radians), ``kl``."""
        cfg = self.cfg
        for g in self.optimizer.param_groups:
            g["lr"] = _cosine_lr(cfg, step)
        idx = idx.to(self.data.device)  # drawn by the CPU generator
        out = self.model(self.data[idx])
        R_rec = out["pose_body_matrot"]
        rot = rotation_geodesic(R_rec, self.R_all[idx]).mean()
        kl = torch.distributions.kl_divergence(out["q_z"], torch.distributions.Normal(0.0, 1.0)).sum(-1).mean()
        w_kl = cfg.w_kl * min(1.0, (step + 1) / max(cfg.kl_anneal_steps, 1))  # KL annealing
        loss = cfg.w_rot * rot + w_kl * kl
        if self.J_all is not None:
            loss = loss + cfg.w_joints * (self.joints_fn(R_rec) - self.J_all[idx]).abs().mean()
        return {"total": loss, "rot": rot, "kl": kl}

    def on_log(self, step: int, values) -> None:
        rot_deg = math.degrees(values["rot"])
        self.hist["step"].append(step - 1)  # the history counts steps from 0
        self.hist["loss"].append(values["total"])
        self.hist["rot_deg"].append(rot_deg)
        self.hist["kl"].append(values["kl"])
        if self.log is not None:
            self.log(f"step {step - 1:6d}  loss {values['total']:.4f}  rot {rot_deg:.2f} deg  kl {values['kl']:.1f}")


@torch.no_grad()
def evaluate_prior(model: VPoser, poses, *, joints_fn: JointsFn | None = None,
                   n_samples: int = 0, seed: int = 0) -> dict:
    """Reconstruction error of held-out poses through the posterior mean.

    Args:
        model: the prior (evaluated in eval mode; its mode is restored).
        poses: ``(N, 21, 3)`` axis-angle.
        joints_fn: optional, adds the joint position error.
        n_samples: also decode this many ``N(0, I)`` samples and report them (``samples``,
            ``(n, 21, 3)`` axis-angle numpy) for plausibility checks.
        seed: of those samples.
    Returns:
        ``rot_err_deg`` (mean over poses and joints of the geodesic error), ``rot_err_deg_median``,
        ``rot_err_deg_p95``, ``per_joint_rot_err_deg`` (21,), ``n``; with ``joints_fn``:
        ``joint_err_mm`` (mean per-joint position error of the returned joints, model frame).
    """
    data = _as_poses(poses)
    was_training = model.training
    model.eval()
    try:
        R = axis_angle_to_matrix(data)
        R_rec = model.decode_matrot(model.encode(data).loc)
        err = torch.rad2deg(geodesic_angle(R, R_rec))  # (N, 21)
        out = {
            "n": int(data.shape[0]),
            "rot_err_deg": err.mean().item(),
            "rot_err_deg_median": err.median().item(),
            "rot_err_deg_p95": torch.quantile(err.flatten().double(), 0.95).item(),
            "per_joint_rot_err_deg": err.mean(0).tolist(),
        }
        if joints_fn is not None:
            d = (joints_fn(R_rec) - joints_fn(R)).norm(dim=-1)
            out["joint_err_mm"] = 1000.0 * d.mean().item()
        if n_samples:
            out["samples"] = model.sample(n_samples, seed=seed)["pose_body"].numpy()
    finally:
        model.train(was_training)
    return out
