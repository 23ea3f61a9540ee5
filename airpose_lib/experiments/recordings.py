"""The paper's real-data section on two-drone recordings, measured against ground truth.

Steps (each cached under ``out_dir``, so notebooks 03, 04 and 05 share one run):

1. the recordings: the profile's generated persons (``airpose data sequence``), or user-given
   folders in the official real-data layout;
2. Table I's Baseline and AirPose networks of the profile (:func:`~airpose_lib.train.ablation.trained_checkpoint`);
3. fine-tuning of both on person 1's 2D detections (:mod:`airpose_lib.finetune`), the model
   selected on person 1's held-out last 20 % of frames; the test persons' 2D and 3D errors per
   checkpoint are logged next to it as a diagnostic, never used for the choice; on generated
   recordings a control tunes AirPose on person 1's true 2D keypoints (:data:`CONTROL_LABEL`);
4. per-frame estimates on every person, before and after fine-tuning;
5. AirPose+ on every person, initialised from the fine-tuned AirPose;
6. camera-frame joints of every estimate and, where ground truth exists, the error tables.

This module runs the steps; each stage has its module: :mod:`.recording_inputs` (recordings,
given networks, pose prior), :mod:`.recording_finetune` (steps 2-3, with
:mod:`.recording_diagnostic`), :mod:`.recording_estimates` (steps 4-5, the markers, the vertices)
and :mod:`.recording_cache` (the cached arrays of every step).

The pose prior of fine-tuning and AirPose+ is VPoser V02_05 when it is installed
(``data_manifests/vposer_v02_05.yaml``), else the kit's (:func:`recording_prior`); every pixel
quantity (agreement threshold, 2D weight, AirPose+'s Geman-McClure scale) is the paper's
full-resolution value converted to each recording's resolution.

Methods (keys of :attr:`RecordingExperiment.estimates`):

- ``"Baseline (pre-trained)"``: the Baseline network trained on still frames only. It is the
  HMR/SPIN architecture (crop only, weak-perspective camera), so it also stands in for the
  paper's "vanilla SPIN" in the depth comparison (SPIN's weights cannot be used here).
- ``"AirPose (pre-trained)"``, ``"Baseline"``, ``"AirPose"`` (fine-tuned on person 1),
  ``"AirPose+"`` (AirPose's estimates refined offline).

The error tables also have a row :data:`~airpose_lib.eval.mean_body.NEUTRAL_LABEL` where ground
truth exists (:func:`airpose_lib.eval.mean_body.mean_body_recording_estimate`): the ground-truth
pose and 2D joints on the neutral mean body, what every position error, UAV2-in-UAV1 included,
comes to for an estimate that reads everything but the person's stature (a reference, not a
bound: a network may read stature from the body's proportions).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from airpose_lib.body import load_body_model
from airpose_lib.data.sequences import ensure_sequences
from airpose_lib.data.sequences.reader import load_sequence
from airpose_lib.eval.mean_body import NEUTRAL_LABEL, mean_body_recording_estimate
from airpose_lib.eval.recordings import body_joints, recording_table
from airpose_lib.folder_lock import folder_lock

from .configs import KitConfigs
from .recording_cache import method_slug
from .recording_estimates import airpose_plus_estimate, body_vertices, marker_truth, network_estimate
from .recording_finetune import CONTROL_LABEL, kit_networks
from .recording_inputs import (
    networks_for,
    official_networks,
    official_recordings,
    recording_prior,
    recordings_for,
    runs_field,
)

__all__ = ["METHODS", "RecordingExperiment", "run_recording_experiment", "runs_field",
           "body_vertices", "recording_prior", "scored_frames",
           "CONTROL_LABEL", "official_recordings", "official_networks", "networks_for", "recordings_for",
           "marker_truth"]

#: Estimate names in plotting order.
METHODS = ("Baseline (pre-trained)", "AirPose (pre-trained)", "Baseline", "AirPose", "AirPose+")
_NETWORKS = {"Baseline (pre-trained)": ("baseline", False), "AirPose (pre-trained)": ("airpose", False),
             "Baseline": ("baseline", True), "AirPose": ("airpose", True)}


@dataclass
class RecordingExperiment:
    """Everything the real-data notebooks plot and tabulate.

    Attributes:
        profile: the reproduction profile.
        out_dir: cache folder.
        sequences: person -> :class:`airpose_lib.data.sequences.reader.Sequence`.
        estimates: person -> method -> per-view parameters ``phi (F, V, 3, 3)``, ``tau (F, V, 3)``,
            ``theta (F, V, 21, 3, 3)``, ``beta (F, V, 10)`` (numpy), plus ``valid (F, V)``.
        joints: person -> method -> ``(F, V, 22, 3)`` camera-frame joints.
        tables: one row per (person, method) of :func:`airpose_lib.eval.recordings.recording_table`
            (empty without ground truth).
        checkpoints: method -> network checkpoint used.
        fit_info: person -> AirPose+ run summary (seconds, skipped frames, loss).
        finetune_info: variant -> fine-tuning summary (steps, selected step, agreement-filter
            counts, per-view threshold, the selection log).
        prior_info: the pose prior used (``source`` kit or vposer, ``file``, ``message``).
        markers: person -> UAV 2 in UAV 1 from the ArUco markers on the ground (``R_12``,
            ``t_12``, ``valid``; :func:`marker_truth`), for the recordings that have them.
    """

    profile: str
    out_dir: Path
    sequences: dict
    estimates: dict
    joints: dict
    tables: pd.DataFrame
    checkpoints: dict
    fit_info: dict = field(default_factory=dict)
    finetune_info: dict = field(default_factory=dict)
    prior_info: dict = field(default_factory=dict)
    markers: dict = field(default_factory=dict)

    @property
    def persons(self) -> list[str]:
        return list(self.sequences)

    def time_s(self, person: str) -> np.ndarray:
        """``(F,)`` seconds since the first frame (UAV1's timestamps, else frame / fps)."""
        seq = self.sequences[person]
        if seq.timestamps is not None:
            return seq.timestamps[:, 0] - seq.timestamps[0, 0]
        fps = float(seq.meta.get("fps", 30.0)) if seq.meta else 30.0
        return (seq.frames - seq.frames[0]) / fps

    def has_ground_truth(self, person: str) -> bool:
        return self.sequences[person].ground_truth is not None


def run_recording_experiment(configs: KitConfigs, out_dir: str | Path | None = None, *,
                             sequences: dict | None = None, seed: int | None = None,
                             fine_tune_on: str = "person1", networks: dict[str, str | Path] | None = None,
                             progress: bool = False, field: bool = False) -> RecordingExperiment:
    """Run (or load the cached steps of) the real-data experiment.

    Args:
        configs: the profile's configs (:func:`airpose_lib.reproduce.configs.kit_configs`): sizes of
            the recordings, networks, fine-tuning and AirPose+.
        out_dir: cache folder (default ``configs.folders.recordings(field)``: ``<runs>/recordings/<name>``,
            ``<name>_field`` on the field recordings).
        sequences: person -> recording folder in the official layout, or a loaded
            :class:`~airpose_lib.data.sequences.reader.Sequence` (default: the profile's generated
            recordings, made if missing).
        seed: training seed of the networks (default: the profile's).
        fine_tune_on: the person whose detections fine-tune the networks (paper: person 1).
        networks: method -> checkpoint for every network method (``Baseline (pre-trained)``,
            ``AirPose (pre-trained)``, ``Baseline``, ``AirPose``), kit ``.pt`` or official
            ``.ckpt`` (:func:`official_networks`); then nothing is trained or fine-tuned.
        field: on the profile's field recordings (``sequences: field_recordings:``)
            instead of the clean ones, cached in their own folder: the same pre-trained networks,
            fine-tuned again on the field person 1.
    """
    out = Path(out_dir) if out_dir is not None else configs.folders.recordings(field)
    with folder_lock(out, stale=(".*.tmp", "estimates/*/.*.tmp")):  # one writer of the cached steps
        return _run_recording_experiment(configs, out, sequences, seed, fine_tune_on, networks, progress, field)


def scored_frames(estimates: dict) -> np.ndarray:
    """``(F,)`` bool: the frames every network estimated in every view, those the errors are
    averaged over."""
    return np.all([np.all(e["valid"], axis=1) for m, e in estimates.items() if m in _NETWORKS], axis=0)


def _run_recording_experiment(configs: KitConfigs, out: Path, sequences: dict | None, seed: int | None,
                              fine_tune_on: str, networks: dict | None, progress: bool,
                              field: bool = False) -> RecordingExperiment:
    import torch

    if sequences is None:
        sequences = ensure_sequences(configs.recordings(field), configs.folders.sequences(field), progress=progress)
    seqs = {name: s if hasattr(s, "keypoints") else load_sequence(s) for name, s in sequences.items()}
    if fine_tune_on not in seqs:
        raise ValueError(f"fine_tune_on={fine_tune_on!r} is not one of the recordings {list(seqs)}")
    if seed is None:
        seed = configs.train.config("airpose").seed

    prior, prior_info = recording_prior(configs, progress)
    finetune_info = {}
    if networks is not None:
        missing = set(_NETWORKS) - set(networks)
        if missing:
            raise ValueError(f"networks lacks {sorted(missing)}")
        checkpoints = {m: Path(networks[m]) for m in _NETWORKS}
    else:
        tests = {n: s for n, s in seqs.items() if n != fine_tune_on and s.ground_truth is not None}
        checkpoints, finetune_info = kit_networks(configs, seed, seqs[fine_tune_on], tests, prior, prior_info, out,
                                                  progress)
    estimates, joints, fit_info, tables, markers = {}, {}, {}, [], {}
    body = load_body_model("open", "neutral", dtype=torch.float32)
    for person, seq in seqs.items():
        est = {}
        for method in _NETWORKS:
            est[method] = network_estimate(checkpoints[method], seq,
                                           out / "estimates" / person / f"{method_slug(method)}.npz")
        plus, info = airpose_plus_estimate(seq, est["AirPose"], configs.fitting, prior, prior_info,
                                           out / "estimates" / person / "airpose_plus.npz", progress)
        F, V = est["AirPose"]["phi"].shape[:2]
        plus = dict(plus)
        plus["theta"] = np.broadcast_to(plus["theta"][:, None], (F, V, 21, 3, 3))
        plus["beta"] = np.broadcast_to(plus["beta"], (F, V, plus["beta"].shape[-1]))
        plus["valid"] = np.broadcast_to(plus["kept"][:, None], (F, V))
        est["AirPose+"] = plus
        fit_info[person] = info
        estimates[person] = est
        if (truth := marker_truth(seq, out / "estimates" / person / "markers.npz")) is not None:
            markers[person] = truth
        joints[person] = {m: body_joints(e, body) for m, e in est.items()}
        if seq.ground_truth is not None:
            mask = scored_frames(est)
            fps = float(seq.ground_truth.get("fps", 30.0))
            t = recording_table(est, seq.ground_truth, joints[person], fps=fps, sequence=person, mask=mask)
            # the stature-blind reference: ground-truth pose and 2D joints, mean body (eval/mean_body.py)
            mean_body = mean_body_recording_estimate(seq.ground_truth, body)
            reference = recording_table({NEUTRAL_LABEL: mean_body}, seq.ground_truth,
                                        {NEUTRAL_LABEL: body_joints(mean_body, body)}, fps=fps, sequence=person,
                                        mask=mask)
            tables += [t, reference]
    table = pd.concat(tables, ignore_index=True) if tables else pd.DataFrame()
    return RecordingExperiment(profile=configs.label, out_dir=out, sequences=seqs, estimates=estimates, joints=joints,
                               tables=table, checkpoints=checkpoints, fit_info=fit_info,
                               finetune_info=finetune_info, prior_info=prior_info, markers=markers)
