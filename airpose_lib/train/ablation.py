"""Train and evaluate the four ablation variants of Table I with one profile's sizes."""
from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from airpose_lib.devices import worker_device
from airpose_lib.engine import StaleRunError
from airpose_lib.eval.ablation import VARIANT_LABELS
from airpose_lib.process_guard import die_with_parent

from .evaluate import evaluate_checkpoint
from .loop import TrainResult
from .pretrain import other_profile, own_backbone_keys, profile_backbone_keys
from .run import TrainInputs, prepare_data, train

__all__ = ["AblationRun", "run_ablation", "trained_checkpoint"]


@dataclass
class AblationRun:
    """One trained and evaluated variant: its checkpoint and test-split tables."""

    variant: str
    seed: int
    checkpoint: Path
    tables: dict[str, pd.DataFrame]


def run_ablation(inputs: TrainInputs, variants: Sequence[str] = tuple(VARIANT_LABELS), seeds: Sequence[int] = (123,),
                 out_root: str | Path | None = None, eval_max_samples: int | None = None,
                 progress: bool = False, workers: int = 1) -> dict[tuple[str, int], AblationRun]:
    """Train (or resume / reuse finished runs of) every variant for every seed, then evaluate.

    A run whose ``result.json`` shows it finished with the same configuration is reused as it is;
    an unfinished one resumes from ``last.pt``. Re-running a notebook therefore only evaluates.

    Args:
        inputs: the profile's trainings (:class:`~airpose_lib.train.run.TrainInputs`: its ``train:``
            section, still-frame dataset, backbone and folders).
        variants: kit variant names (``baseline``, ``multiview``, ``fullcam``, ``airpose``).
        seeds: training seeds.
        out_root: parent of the run folders (default ``runs/train/<profile>``).
        eval_max_samples: evaluate on at most this many test samples (None: all).
        progress: tqdm bars during training.
        workers: train this many runs at once, each in its own process on one thread (on a
            2-core CPU two single-thread runs do ~1.5x the steps of one two-thread run, whose
            threads also slow down several-fold when anything else runs). Same results as 1.
            With several GPUs and the device ``auto`` or ``cuda``, worker k trains on
            ``cuda:(k mod GPUs)`` (:func:`airpose_lib.devices.worker_device`).
    Returns:
        (variant, seed) -> :class:`AblationRun` (tables of :func:`airpose_lib.train.evaluate.evaluate`
        on the test split: ``per_view``, ``per_joint``, ``relative_camera``, and ``per_view_tight``
        on the tight-box test crops when the dataset has them).
    """
    if workers > 1:
        _train_parallel(inputs, variants, seeds, out_root, workers)
    results = {}
    # Seed-major: the first seed's four variants are ready first (the real-data notebooks need them).
    for seed in seeds:
        for variant in variants:
            checkpoint = trained_checkpoint(inputs, variant, seed, out_root, progress)
            label = VARIANT_LABELS[variant]
            tables = evaluate_checkpoint(checkpoint, split="test", method=label, max_samples=eval_max_samples)
            try:
                tight = evaluate_checkpoint(checkpoint, split="test", method=label, max_samples=eval_max_samples,
                                            crops="tight")
                tables["per_view_tight"] = tight["per_view"]
            except ValueError:  # a dataset without tight-box test crops (generator version 1)
                pass
            results[variant, seed] = AblationRun(variant, seed, checkpoint, tables)
    return results


def _run_dir(inputs: TrainInputs, variant: str, seed: int, out_root: str | Path | None) -> Path:
    return (Path(out_root) / variant / f"seed{seed}") if out_root is not None \
        else inputs.folders.train(variant, seed)


# This worker process's index k among the parallel workers (set by :func:`_init_worker`).
_WORKER_INDEX = 0


def _init_worker(parent_pid: int, indices) -> None:
    """Start of a worker of :func:`_train_parallel`: tied to the parent, takes its index k."""
    global _WORKER_INDEX
    die_with_parent(parent_pid)
    _WORKER_INDEX = indices.get()


def _train_single_thread(job: tuple) -> str:
    """Worker of :func:`_train_parallel` (module level: it is pickled into spawned processes).

    ``job``: ``(inputs, variant, seed, out_root)`` (the inputs pickled whole: a worker reads no
    profile); the run's device is spread over the visible
    GPUs by the worker's index (:func:`airpose_lib.devices.worker_device`; unchanged on the CPU).
    """
    import torch

    torch.set_num_threads(1)
    inputs, variant, seed, out_root = job
    asked = inputs.section.config(variant, seed).device
    gpus = torch.cuda.device_count() if torch.cuda.is_available() else 0
    device = worker_device(_WORKER_INDEX, gpus, asked)
    return str(trained_checkpoint(inputs, variant, seed, out_root, device=None if device == asked else device))


def _train_parallel(inputs: TrainInputs, variants: Sequence[str], seeds: Sequence[int],
                    out_root: str | Path | None, workers: int) -> None:
    """Train the unfinished runs in ``workers`` spawned single-thread processes."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    todo = [(inputs, v, s, out_root) for s in seeds for v in variants
            if _finished_run(_run_dir(inputs, v, s, out_root), inputs, v, s) is None]
    if not todo:
        return
    prepare_data(inputs.section.config(todo[0][1], todo[0][2]), inputs)  # generate the data once, here
    ctx, n = mp.get_context("spawn"), min(workers, len(todo))
    indices = ctx.Queue()  # each worker takes one k = 0 .. n-1 at its start (its GPU, see above)
    for k in range(n):
        indices.put(k)
    # die_with_parent: a worker trains for minutes to hours; it must not outlive a killed parent
    with ProcessPoolExecutor(n, mp_context=ctx, initializer=_init_worker, initargs=(os.getpid(), indices)) as pool:
        for _ in pool.map(_train_single_thread, todo):
            pass


def trained_checkpoint(inputs: TrainInputs, variant: str, seed: int, out_root: str | Path | None = None,
                       progress: bool = False, device: str | None = None) -> Path:
    """The final checkpoint of a profile's run of ``variant`` (trained, or resumed, first if needed).

    Same run folders as :func:`run_ablation`, so the real-data notebooks reuse Table I's networks.
    A run left there with other settings (e.g. from the backbone the profile asked for before a
    new one was committed) is stale: it is trained afresh, with a line saying so, instead of
    stopping the reproduction. ``device`` replaces the profile's (None: the profile's).
    """
    out = _run_dir(inputs, variant, seed, out_root)
    run = _finished_run(out, inputs, variant, seed)
    if run is None:
        kw = dict(seed=seed, out_dir=out, overrides={"progress": progress, **({"device": device} if device else {})})
        try:
            run = train(variant, inputs, resume=True, **kw)
        except StaleRunError as e:
            print(f"{out}: trained with other {', '.join(e.fields)} than the profile asks for now; training it afresh")
            run = train(variant, inputs, resume=False, **kw)
    if run.checkpoint is None:
        raise RuntimeError(f"training {variant} (seed {seed}) wrote no checkpoint in {out}")
    return Path(run.checkpoint)


def _finished_run(out: Path, inputs: TrainInputs, variant: str, seed: int) -> TrainResult | None:
    """The run in ``out`` if it completed with the configuration the profile asks for now."""
    import json

    try:
        done = TrainResult.from_json(json.loads((Path(out) / "result.json").read_text()))
    except (OSError, ValueError, KeyError):
        return None
    wanted = inputs.section.config(variant, seed).to_dict()
    # training fills in the resolved dataset folder when the profile names none, and the
    # profile's backbone file for `pretrained: profile` (named by its key: it must be the key the
    # profile's `pretrain:` settings give now); the device may be a parallel worker's own GPU
    # (_train_single_thread) and changes the rounding only
    ignore = {"progress", "device"} | ({"data"} if not wanted["data"] else set())
    if wanted.get("pretrained") == "profile":
        ignore.add("pretrained")
        used = Path(str(done.config.get("pretrained")))
        root = (done.config.get("data") or {}).get("root")
        if root is None or not used.is_file() or inputs.pretrain is None \
                or used.stem not in profile_backbone_keys(inputs.pretrain, root):
            return None
    elif (other := other_profile(wanted.get("pretrained"))) is not None:  # another profile's backbone
        ignore.add("pretrained")
        used = Path(str(done.config.get("pretrained")))
        if not used.is_file() or other not in inputs.others or used.stem not in own_backbone_keys(inputs.others[other]):
            return None
    same = all(done.config.get(k) == wanted[k] for k in wanted.keys() - ignore)
    if same and done.step >= wanted["steps"] and done.checkpoint is not None and Path(done.checkpoint).is_file():
        return done
    return None
