"""One recording on disk: simulate it, simulate both keypoint detectors, render the frames and
write the official real-data layout (:func:`generate_sequence`); re-simulate only the detector
files of a rendered recording (:func:`refresh_detections`)."""
from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from airpose_lib.progress import progress_bar

from .config import SEQUENCE_GENERATOR_VERSION, SequenceConfig
from .detections import DEFAULT_DETECTORS, DETECTOR_VERSION, detection_summary, simulate_detections
from .detector_files import write_detector_file
from .layout import DETECTOR_FILES
from .reader import load_sequence
from .renderer import SequenceRenderer
from .simulate import simulate_sequence
from .writer import OfficialLayoutWriter

__all__ = ["generate_sequence", "recording_detections", "refresh_detections"]


def generate_sequence(config: SequenceConfig, root: str | Path, *, progress: bool = False,
                      body_model=None) -> dict:
    """Simulate a recording, simulate both keypoint detectors, render the frames and store it in
    the official real-data layout (:mod:`airpose_lib.data.sequences.layout`) under ``root``.

    Returns:
        a summary dict: ``root``, ``num_frames``, ``render_seconds``, ``frames_per_second``
        (rendered images per second, all views counted), ``config``.
    """
    sim = simulate_sequence(config, body_model)
    detections = recording_detections(sim.gt, config)
    writer = OfficialLayoutWriter(root, sim.num_views, jpeg_quality=config.jpeg_quality)
    t0 = time.perf_counter()
    bar = None
    if progress:
        bar = progress_bar(total=sim.num_frames, desc=f"render {config.person_spec.name}", unit="frame")
    with SequenceRenderer(sim, body_model, anti_aliasing=config.anti_aliasing) as renderer:
        for i, images in renderer.render_frames():
            writer.write_frame(i, images)
            if bar is not None:
                bar.update(1)
    if bar is not None:
        bar.close()
    seconds = time.perf_counter() - t0
    writer.finish(K=sim.gt["K"], keypoints={k: d.keypoints for k, d in detections.items()},
                  timestamps=sim.gt["timestamps"], ground_truth=sim.gt,
                  meta={"generator_version": SEQUENCE_GENERATOR_VERSION, "config": config.to_dict(),
                        "script": [dataclasses.asdict(s) for s in sim.script.segments],
                        "render_seconds": seconds, "detector_version": DETECTOR_VERSION,
                        "detections": {k: detection_summary(d) for k, d in detections.items()}})
    n_img = sim.num_frames * sim.num_views
    return {"root": str(Path(root)), "num_frames": sim.num_frames, "render_seconds": seconds,
            "frames_per_second": n_img / max(seconds, 1e-9), "config": config.to_dict()}


def recording_detections(gt: Mapping[str, np.ndarray], config: SequenceConfig) -> dict:
    """Both simulated detectors on a recording's ground truth (``data.sequences.detections``): name ->
    :class:`~airpose_lib.data.sequences.detections.Detections`, seeded by ``config.detector_seed`` (default
    ``seed + 1``) and the detector's position."""
    det_seed = config.detector_seed if config.detector_seed is not None else config.seed + 1
    return {name: simulate_detections(gt, det, seed=[det_seed, k], frame_step=config.frame_step)
            for k, (name, det) in enumerate(DEFAULT_DETECTORS.items())}


def refresh_detections(root: str | Path, config: SequenceConfig) -> dict:
    """Re-simulate the detector files of a rendered recording from its ``ground_truth.npz`` (the
    images stay): what :func:`ensure_sequences` does when only the detector model changed
    (:data:`~airpose_lib.data.sequences.detections.DETECTOR_VERSION`). Returns the new summaries."""
    root = Path(root)
    with np.load(root / "ground_truth.npz") as z:
        gt = {k: z[k] for k in z.files}
    frames = [int(i) for i in load_sequence(root, detectors=(), ground_truth=False).frames]
    detections = recording_detections(gt, config)
    for name, det in detections.items():
        for v in range(config.num_views):
            path = root / f"machine_{v + 1}" / DETECTOR_FILES[name][0]
            write_detector_file(name, path, frames, det.keypoints[:, v])
    meta_path = root / "sequence.json"
    meta = json.loads(meta_path.read_text())
    meta.update(detector_version=DETECTOR_VERSION,
                detections={k: detection_summary(d) for k, d in detections.items()})
    tmp = meta_path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(meta, indent=1))
    tmp.replace(meta_path)
    return meta["detections"]

