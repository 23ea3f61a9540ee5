"""The video route checked on known truth: a kit recording exported as two videos
(:func:`airpose_lib.data.video.export.export_videos`), run through ``airpose video``, scored
against the recording's ground truth next to the same networks on the recording's own frames.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd

from airpose_lib.body import load_body_model
from airpose_lib.data.sequences import ensure_sequences
from airpose_lib.data.sequences.reader import load_sequence
from airpose_lib.eval.recordings import body_joints, recording_frame_table
from airpose_lib.finetune.network import load_sized_network
from airpose_lib.finetune.predict import predict_sequence
from airpose_lib.fitting.airpose_plus import AirPosePlusConfig, fit_sequence

from .configs import KitConfigs

__all__ = ["ROUTES", "known_truth_table", "route_agreement", "write_video_reference"]

ROUTES = ("video", "recording")
_METHODS = {"airpose": "AirPose", "airpose_plus": "AirPose+"}


def _scores(estimates: dict, gt: dict, body) -> pd.DataFrame:
    rows = []
    for key, est in estimates.items():
        t = recording_frame_table(est, gt, body_joints(est, body), _METHODS[key])
        first = t[t["view"] == 0]
        rows.append({"method": _METHODS[key], "frames": int(first["frame"].nunique()),
                     "mpjpe_median_m": float(t["mpjpe_m"].median()),
                     "uav2_in_uav1_position_median_m": float(first["rel_t_err_m"].median()),
                     "uav2_in_uav1_orientation_median_deg": float(first["rel_rot_deg"].median())})
    return pd.DataFrame(rows)


def known_truth_table(run_dir: str | Path, airpose_checkpoint: str | Path, *, prior=None,
                      fit_config: AirPosePlusConfig | None = None) -> pd.DataFrame:
    """Errors of ``airpose video``'s outputs in ``run_dir`` (made from videos that ``export_videos``
    wrote; its ``export.json`` sits beside the videos) and of the same network (and AirPose+) on the
    recording's frames, over the same frames, against the recording's ground truth.

    Returns:
        one row per route (``video``, ``recording``) and method: frames, median MPJPE, UAV2-in-UAV1
        position and orientation medians, and for the video route the offset found and the true one.
    """
    run_dir = Path(run_dir)
    summary = json.loads((run_dir / "summary.json").read_text())
    export = json.loads((Path(summary["videos"][0]).parent / "export.json").read_text())
    with np.load(run_dir / "smplx.npz") as z:
        arrays = {k: z[k] for k in z.files}
    # UAV1's video frame i is recording frame first_frame[0] + i
    rec_frames = arrays["frames"] + export["first_frame"][0]
    seq = load_sequence(export["recording"], frames=rec_frames, detectors=(export["detector"],))
    gt = seq.ground_truth
    body = load_body_model("open", "neutral")
    video = {m: {"phi": arrays[f"{m}_phi"], "tau": arrays[f"{m}_tau"], "theta": arrays[f"{m}_theta"],
                 "beta": arrays[f"{m}_betas"]} for m in _METHODS if f"{m}_phi" in arrays}
    model, _, size = load_sized_network(airpose_checkpoint, "cpu")
    pred = predict_sequence(model, seq, input_size=size, detector=export["detector"])
    recording = {"airpose": {k: pred[k] for k in ("phi", "tau", "theta", "beta")}}
    if "airpose_plus" in video:
        res = fit_sequence(seq, recording["airpose"], prior=prior, config=fit_config or AirPosePlusConfig(),
                           progress=False).to_numpy()
        recording["airpose_plus"] = {k: res[k] for k in ("phi", "tau", "theta", "beta")}
    out = []
    for route, est in (("video", video), ("recording", recording)):
        t = _scores(est, gt, body)
        t.insert(0, "route", route)
        out.append(t)
    table = pd.concat(out, ignore_index=True)
    off = summary["offset"]
    table["offset_frames"] = np.where(table["route"] == "video", off["frames"], export["true_offset_frames"])
    return table


def route_agreement(table: pd.DataFrame) -> pd.DataFrame:
    """Per method and metric: the video route's value over the recording route's (1.0: equal)."""
    metrics = ["mpjpe_median_m", "uav2_in_uav1_position_median_m", "uav2_in_uav1_orientation_median_deg"]
    v = table[table["route"] == "video"].set_index("method")[metrics]
    r = table[table["route"] == "recording"].set_index("method")[metrics]
    return (v / r).reset_index().melt(id_vars="method", var_name="metric", value_name="video / recording")


def write_video_reference(out_dir: str | Path, configs: KitConfigs, *, person: str = "person2", shift: int = 7,
                          networks: str = "cpu", command: str = "") -> Path:
    """The video route's reference on known truth into ``out_dir``: the profile's recording
    ``person`` and its field twin, each exported with UAV2 started ``shift`` frames late and run
    through ``airpose video`` with ``networks``' shipped set and the profile's AirPose+ settings
    (the offset estimated on the clean recording, given on the field one), then
    :func:`known_truth_table`. Writes ``known_truth.csv`` (a ``recordings`` column), the overlay
    stills of the first recording (``video_overlays.jpg``) and ``provenance.json`` (clean commit,
    seconds per stage and per 100 frames, machine, command).

    Raises:
        ProvenanceError: the checkout has uncommitted changes.
    """
    import matplotlib.pyplot as plt

    from airpose_lib.data.video.export import export_videos
    from airpose_lib.eval.reference import machine_description, require_clean_checkout
    from airpose_lib.prior import load_prior

    from .video import VideoConfig, run_video, video_networks
    from .video_outputs import overlay_stills

    git = require_clean_checkout()
    recordings = {kind: ensure_sequences(configs.recordings(field), configs.folders.sequences(field), only=[person],
                                         progress=True)[person] for kind, field in (("clean", False), ("field", True))}
    networks, fit_config = video_networks(networks), configs.fitting
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    work = out / ".work"
    tables, timing = [], {}
    prior = load_prior("kit", networks.prior)
    for n, (name, root) in enumerate(recordings.items()):
        paths = export_videos(root, work / name / "videos", shift=shift)
        cfg = VideoConfig(videos=(str(paths["uav1"]), str(paths["uav2"])), out=str(work / name / "run"),
                          intrinsics=tuple(str(Path(root) / f"machine_{v}" / "camera_calib.yml") for v in (1, 2)),
                          keypoints=(str(paths["uav1_keypoints"]), str(paths["uav2_keypoints"])),
                          offset=None if n == 0 else -shift, overlays=n == 0)
        run = run_video(cfg, networks, fit_config=fit_config, progress=False)
        timing[name] = {"frames": run.frames, "seconds": run.seconds,
                        "seconds_per_100_frames": 100 * sum(run.seconds.values()) / run.frames}
        table = known_truth_table(run.out, networks.airpose, prior=prior, fit_config=fit_config)
        table.insert(0, "recordings", name)
        tables.append(table)
        if n == 0:
            fig = overlay_stills(run, 3)
            fig.savefig(out / "video_overlays.jpg", dpi=110, pil_kwargs={"quality": 85})
            plt.close(fig)
    pd.concat(tables, ignore_index=True).to_csv(out / "known_truth.csv", index=False, float_format="%.5f")
    record = {"git": git, "profile": configs.label, "command": command, "shift": shift, "recordings": {k: Path(v).name for k, v in recordings.items()},
              "networks": {k: Path(v).name for k, v in (("airpose", networks.airpose), ("baseline", networks.baseline))},
              "timing": timing, "machine": machine_description(),
              "created_at": pd.Timestamp.now(tz="UTC").isoformat(timespec="seconds")}
    (out / "provenance.json").write_text(json.dumps(record, indent=1, default=str))
    shutil.rmtree(work, ignore_errors=True)
    return out
