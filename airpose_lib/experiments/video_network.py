"""The networks of ``airpose video``: a network over a recording and AirPose+ over it."""
from __future__ import annotations

from pathlib import Path

from airpose_lib.data.sequences.reader import load_sequence
from airpose_lib.finetune.network import load_sized_network
from airpose_lib.finetune.predict import predict_sequence, save_predictions
from airpose_lib.fitting.airpose_plus import AirPosePlusConfig, fit_sequence
from airpose_lib.fitting.recording import save_refinement
from airpose_lib.model.official import load_official_checkpoint
from airpose_lib.prior import load_prior

__all__ = ["predict", "refine"]


def predict(checkpoint: Path, root: Path, detector: str, out: Path, progress: bool) -> dict:
    """A network over a recording (``airpose predict``), written to ``out``; a kit ``.pt`` or the
    authors' ``.ckpt`` (ResNet-50 at 224 px)."""
    if Path(checkpoint).suffix == ".ckpt":
        model, size = load_official_checkpoint(checkpoint, backbone=None), 224
    else:
        model, _, size = load_sized_network(checkpoint, "cpu")
    seq = load_sequence(root, detectors=(detector,), ground_truth=False, missing_detections="zero")
    pred = predict_sequence(model, seq, input_size=size, detector=detector, progress=progress,
                            provenance={"checkpoint": str(checkpoint)})
    save_predictions(out, pred)
    return pred


def refine(sequence: Path, init: dict, prior_path: Path | None, config: AirPosePlusConfig, init_file: Path,
           out: Path, progress: bool) -> Path:
    """AirPose+ over the recording ``sequence`` from the network's estimates ``init``, to ``out``."""
    seq = load_sequence(sequence, detectors=("openpose",), ground_truth=False)
    prior, prior_prov = load_prior("kit", prior_path, return_provenance=True)
    res = fit_sequence(seq, init, prior=prior, config=config, progress=progress)
    return save_refinement(out, seq.frames, res, sequence=sequence, init=init_file, label="airpose video", prior=prior_prov)
