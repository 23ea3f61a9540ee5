"""The files ``airpose video`` writes: ``smplx.npz``, ``uav2_in_uav1.csv``, the plots and the
overlay videos (:mod:`airpose_lib.experiments.video` calls it last)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import torch

from airpose_lib.atomic import atomic_path
from airpose_lib.body import load_body_model
from airpose_lib.data.sequences.reader import load_sequence
from airpose_lib.eval.recordings import per_view_params, relative_camera_positions
from airpose_lib.geometry import matrix_to_axis_angle
from airpose_lib.model.smplx_params import posed_joints_and_vertices
from airpose_lib.viz.style import save_figure
from airpose_lib.viz.trajectories import plot_person_positions, plot_relative_camera
from airpose_lib.viz.video import plot_overlay_stills, write_overlay_video

__all__ = ["write_outputs", "overlay_stills"]


def _axis_angle(R: np.ndarray) -> np.ndarray:
    return matrix_to_axis_angle(torch.as_tensor(R, dtype=torch.float64)).numpy()


def write_outputs(out: Path, infos, cams, seq_frames: np.ndarray, off: int, estimates: dict, *, overlays: bool = True,
                  every: int = 1) -> dict[str, Path]:
    """``smplx.npz``, ``uav2_in_uav1.csv``, the plots and the overlay videos (module docstring of
    :mod:`airpose_lib.experiments.video`); returns name -> file."""
    files = {}
    fps = infos[0].fps
    time_s = (seq_frames - seq_frames[0]) / fps
    arrays = {"frames": seq_frames, "frames_uav2": seq_frames + off, "time_s": time_s,
              "K": np.stack([c.K for c in cams]), "valid": estimates["valid"]}
    params = {}
    for m, est in estimates.items():
        if m == "valid":
            continue
        p = per_view_params(est, 2)
        params[m] = p
        F = len(seq_frames)
        arrays.update({f"{m}_phi": p["phi"], f"{m}_tau": p["tau"], f"{m}_theta": p["theta"], f"{m}_betas": p["beta"],
                       f"{m}_global_orient": _axis_angle(p["phi"]),
                       f"{m}_body_pose": _axis_angle(p["theta"]).reshape(F, 2, 63)})
    files["smplx"] = out / "smplx.npz"
    with atomic_path(files["smplx"]) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **arrays)
    rows = []
    positions, rel = {}, {}
    for m, p in params.items():
        label = {"airpose": "AirPose", "airpose_plus": "AirPose+"}[m]
        R, t = relative_camera_positions(p)
        rel[label], positions[label] = t, p["tau"]
        aa = _axis_angle(R)
        rows.append(pd.DataFrame({"method": label, "frame_uav1": seq_frames, "frame_uav2": seq_frames + off,
                                  "time_s": time_s, "x_m": t[:, 0], "y_m": t[:, 1], "z_m": t[:, 2],
                                  "rx_rad": aa[:, 0], "ry_rad": aa[:, 1], "rz_rad": aa[:, 2]}))
    files["uav2_in_uav1"] = out / "uav2_in_uav1.csv"
    with atomic_path(files["uav2_in_uav1"]) as tmp:
        pd.concat(rows).to_csv(tmp, index=False, float_format="%.5f")
    fig_a = plot_person_positions(positions, time_s, title="the person in each UAV's camera frame")
    files["trajectory"] = out / "trajectory.png"
    save_figure(fig_a, files["trajectory"], show=False)
    files["uav2_in_uav1_plot"] = out / "uav2_in_uav1.png"
    save_figure(plot_relative_camera(rel, time_s, title="UAV2 in UAV1's camera frame"), files["uav2_in_uav1_plot"],
                show=False)
    if overlays:
        best = "airpose_plus" if "airpose_plus" in params else "airpose"
        body = load_body_model("open", "neutral")
        faces = np.asarray(body.faces, dtype=np.int64)
        p = params[best]
        seq = load_sequence(out / "sequence", detectors=(), ground_truth=False)

        def pairs(v):
            dtype = body.v_template.dtype
            for i in range(len(seq_frames)):
                part = {k: torch.as_tensor(np.ascontiguousarray(x[i:i + 1, v]), dtype=dtype) for k, x in p.items()}
                with torch.no_grad():
                    verts = posed_joints_and_vertices(body, part)["vertices"][0].double().numpy()
                yield seq.image(i, v), verts

        for v in range(2):
            files[f"overlay_uav{v + 1}"] = write_overlay_video(
                pairs(v), faces, cams[v].K, (infos[v].width, infos[v].height), fps / every,
                out / f"overlay_uav{v + 1}.mp4")
    return files


def overlay_stills(run, n: int = 3, title: str | None = None):
    """:func:`airpose_lib.viz.video.plot_overlay_stills` of a run's overlay videos (``run``: a
    :class:`~airpose_lib.experiments.video.VideoRun`), each still cut around the person's box."""
    with np.load(run.out / "airpose.npz") as z:
        boxes = [z["boxes"][:, 0], z["boxes"][:, 1]]
    return plot_overlay_stills([run.files["overlay_uav1"], run.files["overlay_uav2"]], n, title=title, boxes=boxes)
