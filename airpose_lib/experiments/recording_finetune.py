"""The real-data experiment's own networks: the profile's Table I Baseline and AirPose, fine-tuned
on one person's 2D detections (model selected on that person's held-out frames), with the test
persons' errors logged per checkpoint and, on generated recordings, a control tuned on the true
2D keypoints (:data:`CONTROL_LABEL`).
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

from airpose_lib.data.sequences.reader import recording_fingerprint
from airpose_lib.engine.checkpoint import StaleRunError
from airpose_lib.finetune.train import finetune
from airpose_lib.train.ablation import trained_checkpoint

from .configs import KitConfigs
from .recording_cache import cache_key
from .recording_diagnostic import ground_truth_diagnostic

__all__ = ["CONTROL_LABEL", "kit_networks"]

#: The control fine-tuning of :func:`kit_networks` (generated recordings only): AirPose tuned on
#: person 1's true 2D keypoints instead of the detections; never an estimate, only its log.
CONTROL_LABEL = "AirPose (control: true 2D targets)"


def _finetune_logged(pre: Path, tuning, tests: dict, ft_cfg, run_dir: Path, prior, progress: bool,
                     tests_key: str | None):
    """Fine-tune ``pre`` on ``tuning`` into ``run_dir`` (resumed, or afresh when its settings,
    network or recordings changed), the ``tests`` recordings' errors logged per checkpoint
    (``tests_key``: their fingerprint, :func:`_tests_key`); returns the result and the summary row
    of :attr:`~airpose_lib.experiments.recordings.RecordingExperiment.finetune_info`."""
    diagnostics: dict = {}

    def diagnostic(model, _d=diagnostics):
        if not _d:  # the frozen part's features, once, from the network being tuned: its BatchNorm
            for name, seq in tests.items():  # statistics may be the recording's (adapt_bn)
                _d[name] = ground_truth_diagnostic(model, seq, input_size=model.input_size, cut=ft_cfg.trainable_from)
        return {f"{name}_{k}": v for name, d in _d.items() for k, v in d(model).items()}

    kw = dict(progress=progress, prior=prior, diagnostic=diagnostic if tests else None, diagnostic_key=tests_key)
    try:
        res = finetune(pre, tuning.root, run_dir, ft_cfg, **kw)
    except StaleRunError:
        res = finetune(pre, tuning.root, run_dir, ft_cfg, resume=False, **kw)  # settings changed: afresh
    info = {"steps": res.step, "frames": res.num_frames, "heldout_frames": res.heldout_frames,
            "selected_step": res.best_step, "heldout_j2d": res.best_heldout_j2d,
            "selection_rule": res.config.get("selection"), "overfit_step": res.overfit_step,
            "overfit_terms": res.overfit_terms, "targets": res.config.get("targets", "detections"),
            "j2d_before": res.initial.get("j2d"), "j2d_after": (res.final or {}).get("j2d"),
            "threshold_px": res.pixels.get("threshold_px"), "keypoints": res.keypoints,
            "selection": res.selection}
    return res, info


def _tests_key(tests: dict) -> str | None:
    """The content of the recordings a fine-tuning's diagnostic measures (None without any)."""
    return cache_key(*((name, recording_fingerprint(seq)) for name, seq in sorted(tests.items()))) if tests else None


def kit_networks(configs: KitConfigs, seed: int, tuning, tests: dict, prior, prior_info: dict, out: Path,
                 progress: bool) -> tuple[dict, dict]:
    """Table I's Baseline and AirPose of the profile, their fine-tuning on ``tuning`` (model
    selected on its held-out frames) with the ``tests`` recordings' errors logged per checkpoint.

    On a generated ``tuning`` recording with test persons, AirPose is also fine-tuned on the true
    2D keypoints (:data:`CONTROL_LABEL`, ``FineTuneConfig.targets="ground_truth"``): if the test
    person's errors grow with perfect targets too, the cause is fitting one person, not the
    detectors.

    Returns:
        ``(checkpoints, finetune_info)``: method -> checkpoint (the pre-trained ones and the
        selected fine-tuned ones) and variant -> fine-tuning summary (the control's included).
    """
    checkpoints, finetune_info = {}, {}
    ft_cfg = configs.finetune
    if ft_cfg.frames is None and "person" in tuning.meta:  # an official split: fine-tune on its frames only
        ft_cfg = dataclasses.replace(ft_cfg, frames=[int(tuning.frames[0]), int(tuning.frames[-1]) + 1])
    ft_cfg = dataclasses.replace(ft_cfg, prior=prior_info["source"], prior_path=prior_info["file"])
    tests_key = _tests_key(tests)
    trainings = configs.train_inputs()
    for variant, label in (("baseline", "Baseline"), ("airpose", "AirPose")):
        pre = trained_checkpoint(trainings, variant, seed, progress=progress)
        checkpoints[f"{label} (pre-trained)"] = pre
        res, finetune_info[label] = _finetune_logged(pre, tuning, tests, ft_cfg, out / "finetune" / variant, prior,
                                                     progress, tests_key)
        checkpoints[label] = Path(res.best_checkpoint or res.checkpoint)
    if tests and tuning.ground_truth is not None and "kp2d_body25" in tuning.ground_truth:
        control = dataclasses.replace(ft_cfg, targets="ground_truth")
        _, finetune_info[CONTROL_LABEL] = _finetune_logged(checkpoints["AirPose (pre-trained)"], tuning, tests,
                                                           control, out / "finetune" / "airpose_true2d", prior,
                                                           progress, tests_key)
    return checkpoints, finetune_info
