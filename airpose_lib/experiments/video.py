"""Two drone videos to SMPL-X per frame, UAV2's pose in UAV1's frame and overlays: the stages of
``airpose video`` (and notebook 08), each resumable in the output folder.

Stages, in order (``DIR`` the output folder):

1. ``frames``: each video decoded to ``DIR/frames/uav{1,2}/%06d.jpg`` (source frame numbers;
   undistorted when the intrinsics carry distortion).
2. ``keypoints``: the person's BODY_25 keypoints per decoded frame, from a file per video
   (:mod:`airpose_lib.data.video.keypoints`), in ``DIR/keypoints.npz``.
3. ``offset``: each view alone through the monocular Baseline network
   (``DIR/views/uav{k}``), and the offset that lines their body poses up
   (:mod:`airpose_lib.data.video.offset`), unless given; ``DIR/offset.json``.
4. ``network``: the two views, paired at the offset, as a recording (``DIR/sequence``) through the
   AirPose network (the exchange between the views): ``DIR/airpose.npz``.
5. ``fit``: AirPose+ over the whole sequence: ``DIR/airpose_plus.npz``.
6. ``outputs``: ``DIR/smplx.npz`` (:data:`SMPLX_KEYS`), ``DIR/uav2_in_uav1.csv``,
   ``DIR/overlay_uav{1,2}.mp4``, ``DIR/trajectory.png``, ``DIR/summary.json``.

A stage whose record in ``DIR/stages.json`` matches its inputs is skipped; a changed input redoes
it and every stage after it. One writer at a time holds the folder.
"""
from __future__ import annotations

import hashlib
import json
import os
import subprocess
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from airpose_lib.atomic import atomic_path
from airpose_lib.data.video import assemble, frames, intrinsics, keypoints, offset
from airpose_lib.errors import UserError
from airpose_lib.fitting.airpose_plus import AirPosePlusConfig
from airpose_lib.folder_lock import folder_lock
from airpose_lib.paths import RunFolders, repo_root
from airpose_lib.zoo import kit_checkpoint, read_manifest, verified, zoo_dir

from . import video_network, video_outputs

__all__ = ["VideoConfig", "VideoNetworks", "VideoError", "VideoRun", "SMPLX_KEYS", "run_video", "video_networks", "MIN_DETECTED"]

_DEFAULT_FOV = intrinsics.DEFAULT_FOV_Y_DEG  # the dataclass's field of that name hides the module there
#: The share of a video's frames that must show the person.
MIN_DETECTED = 0.5
#: ``smplx.npz``: arrays per method ``m`` in ``airpose`` (the network) and ``airpose_plus``.
SMPLX_KEYS = {
    "frames": "(F,) UAV1's source frame numbers of the paired frames",
    "frames_uav2": "(F,) UAV2's source frame numbers of the same instants (frames + offset)",
    "time_s": "(F,) seconds from UAV1's first frame",
    "K": "(2, 3, 3) the intrinsics used, pixels",
    "valid": "(F, 2) a view had a person box (else the previous box was used)",
    "m_phi": "(F, 2, 3, 3) root rotation, body -> camera, per view",
    "m_tau": "(F, 2, 3) translation per view, metres: vertices = phi @ V0(theta, beta) + tau, V0 the "
             "model's vertices with zero root rotation and zero translation",
    "m_theta": "(F, 2, 21, 3, 3) body joint rotations (AirPose+: one per frame, repeated for both views)",
    "m_body_pose": "(F, 2, 63) the same as SMPL-X axis-angle body_pose",
    "m_global_orient": "(F, 2, 3) phi as axis-angle",
    "m_betas": "(F, 2, 10) shape (AirPose+: one for the sequence, repeated)",
}


class VideoError(UserError, ValueError):
    """A video route input that does not fit (offset, coverage); the message names the file."""


@dataclass(frozen=True)
class VideoConfig:
    """What ``airpose video`` was asked (plain values; the command builds it once).

    Attributes:
        videos: UAV1's and UAV2's video file or frame folder.
        out: the output folder.
        intrinsics: one file for both videos, or one per video (None: the default camera).
        fov_y_deg: the default camera's vertical field of view.
        keypoints: one keypoint file (or OpenPose JSON folder) per video (None: MediaPipe Pose in its
            own environment, :func:`mediapipe_python`).
        offset: frames, ``i`` of UAV1 = ``i + offset`` of UAV2 (None: estimated).
        max_offset_s: the largest offset the estimate tries, seconds.
        fps: the frame rate (None: the videos'; required for frame folders).
        start, end, every: the source frames of UAV1 used (``end`` exclusive; None: to the end);
            UAV2's follow them at the offset.
        fit: run AirPose+.
        overlays: write the overlay videos.
    """

    videos: tuple[str, str]
    out: str
    intrinsics: tuple[str | None, str | None] = (None, None)
    fov_y_deg: float = _DEFAULT_FOV
    keypoints: tuple[str, str] | None = None
    offset: int | None = None
    max_offset_s: float = 10.0
    fps: float | None = None
    start: int = 0
    end: int | None = None
    every: int = 1
    fit: bool = True
    overlays: bool = True


@dataclass(frozen=True)
class VideoNetworks:
    """The networks: ``airpose`` (two views, the exchange), ``baseline`` (one view, for the offset),
    ``prior`` (AirPose+'s pose prior; None: the kit's cached one), with the names they are reported by."""

    airpose: Path
    baseline: Path
    prior: Path | None = None
    about: dict = field(default_factory=dict)


@dataclass
class VideoRun:
    """What a run made: the folder, its files, the offset and the timings (seconds per stage)."""

    out: Path
    files: dict[str, Path]
    offset: dict
    frames: int
    seconds: dict[str, float]
    warnings: list[str]


def video_networks(shipped: str = "cpu", checkpoint: Path | None = None, baseline: Path | None = None,
                   prior: Path | None = None) -> VideoNetworks:
    """The networks of a run: a profile's shipped set, or the given checkpoints (a kit ``.pt`` or
    the authors' ``.ckpt``); the shipped set fills what is not given."""
    for flag, path in (("--checkpoint", checkpoint), ("--baseline-checkpoint", baseline), ("--prior-path", prior)):
        if path is not None and not Path(path).is_file():
            raise VideoError(f"{flag} {path}: no such file; give a checkpoint of `airpose train` or the authors' .ckpt")
    folder = zoo_dir(RunFolders(shipped))
    if not (folder / "manifest.yaml").is_file() and None in (checkpoint, baseline):
        raise VideoError(f"--networks {shipped}: {folder} holds no shipped networks; give --networks cpu, or "
                       "--checkpoint and --baseline-checkpoint")
    about = {}
    if None in (checkpoint, baseline, prior):
        read_manifest(folder)  # one line on a damaged manifest
        about["shipped"] = shipped

    def shipped_net(name: str) -> Path:
        return kit_checkpoint(verified(folder, name), verified(folder, "backbone"))

    return VideoNetworks(airpose=Path(checkpoint) if checkpoint else shipped_net("airpose"),
                         baseline=Path(baseline) if baseline else shipped_net("baseline"),
                         prior=Path(prior) if prior else verified(folder, "prior"), about=about)


# -- small pieces ---------------------------------------------------------------------------------
def _digest(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:16]


class _Stages:
    """``DIR/stages.json``: stage -> digest of its inputs; a stage reruns when its digest changes,
    and then every stage after it."""

    def __init__(self, out: Path) -> None:
        self.path = out / "stages.json"
        self.done = json.loads(self.path.read_text()) if self.path.is_file() else {}
        self.dirty = False

    def current(self, name: str, digest: str) -> bool:
        if not self.dirty and self.done.get(name) == digest:
            return True
        self.dirty = True
        return False

    def mark(self, name: str, digest: str) -> None:
        self.done[name] = digest
        with atomic_path(self.path) as tmp:
            tmp.write_text(json.dumps(self.done, indent=1))


# -- the stages -----------------------------------------------------------------------------------
def _read_videos(cfg: VideoConfig, log: Callable[[str], None]) -> tuple[list, list, list[str]]:
    infos = [frames.video_info(v, cfg.fps) for v in cfg.videos]
    if abs(infos[0].fps - infos[1].fps) > 0.01 * infos[0].fps:
        raise VideoError(f"{cfg.videos[0]} runs at {infos[0].fps:g} fps and {cfg.videos[1]} at {infos[1].fps:g}; "
                         "re-encode one at the other's rate (ffmpeg -r) or give both as frame folders with --fps")
    cams, warns = [], []
    for v, info in enumerate(infos):
        source = cfg.intrinsics[v]
        if source is None:
            cam = intrinsics.default_intrinsics(info.width, info.height, cfg.fov_y_deg)
            warns.append(f"{cfg.videos[v]}: no intrinsics given; using {cam.source}: depths and the drones' distance "
                         "scale with the assumed focal length (give --intrinsics for metric results)")
        else:
            cam = intrinsics.read_intrinsics(source, v)
        warns += intrinsics.check_intrinsics(cam, info.width, info.height, str(cfg.videos[v]))
        cams.append(cam)
    for w in warns:
        log(f"warning: {w}")
    return infos, cams, warns


def _numbers(cfg: VideoConfig, infos, off: int | None) -> list[np.ndarray]:
    """Source frames to decode: UAV1's range; UAV2's the same instants at a known offset, or its
    whole range at the same step when the offset is still to be estimated."""
    n1 = frames.frame_numbers(infos[0], cfg.start, cfg.end, cfg.every)
    if off is None:
        reach = int(cfg.max_offset_s * infos[0].fps)
        lo = max(0, int(n1[0]) - reach)
        n2 = frames.frame_numbers(infos[1], lo, min(int(n1[-1]) + 1 + reach, infos[1].n_frames), cfg.every)
    else:
        n2 = n1 + off
        n2 = n2[(n2 >= 0) & (n2 < infos[1].n_frames)]
        if len(n2) == 0:
            raise VideoError(f"--offset {off} pairs none of {cfg.videos[0]}'s frames {int(n1[0])}..{int(n1[-1])} with "
                             f"{cfg.videos[1]}'s {infos[1].n_frames} frames; give an offset shorter than the videos")
    return [n1, n2]


def mediapipe_python() -> Path | None:
    """The MediaPipe environment's python (``$AIRPOSE_MEDIAPIPE_VENV``, else ``.venv-mediapipe`` at
    the checkout's root; ``scripts/setup_mediapipe.sh`` makes it), or None."""
    venv = os.environ.get("AIRPOSE_MEDIAPIPE_VENV")
    root = repo_root()
    for folder in ([Path(venv)] if venv else []) + ([root / ".venv-mediapipe"] if root else []):
        if (folder / "bin" / "python").is_file():
            return folder / "bin" / "python"
    return None


def _mediapipe(out: Path, infos, cams, numbers, log) -> list[Path]:
    """MediaPipe Pose over each video's decoded frames (``--crop track``), in its own environment."""
    python, root = mediapipe_python(), repo_root()
    if python is None or root is None or not (root / "scripts" / "mediapipe_detect.py").is_file():
        raise VideoError("no keypoints: give --keypoints UAV1_FILE UAV2_FILE (the kit's BODY_25 pickle or OpenPose's "
                         "JSON folder), or set up MediaPipe from a checkout with `bash scripts/setup_mediapipe.sh` "
                         "(docs/own_videos.md)")
    files = []
    for v in range(2):
        rec = out / "detect" / f"uav{v + 1}"
        result = rec / "machine_1" / "mediapipe_res.pkl"
        record = rec / "mediapipe_detect.json"
        # the decoded frames' record names the video file, its stamp and the frames: rerun when it changes
        stamp = _digest((out / "frames" / f"uav{v + 1}" / "frames.json").read_text())
        if not (result.is_file() and record.is_file() and json.loads(record.read_text()).get("stamp") == stamp):
            assemble.single_view(rec, out / "frames" / f"uav{v + 1}", numbers[v], cams[v].K,
                                 (infos[v].width, infos[v].height), None, "mediapipe", infos[v].fps)
            log(f"MediaPipe Pose over UAV{v + 1}'s {len(numbers[v])} frames ({python})")
            res = subprocess.run([str(python), str(root / "scripts" / "mediapipe_detect.py"), str(rec), "--crop", "track"],
                                 capture_output=True, text=True)
            if res.returncode != 0:
                raise RuntimeError(f"MediaPipe failed on {rec}:\n{res.stderr[-2000:]}")
            info = json.loads(record.read_text())
            with atomic_path(record) as tmp:
                tmp.write_text(json.dumps({**info, "stamp": stamp}, indent=1))
        files.append(result)
    return files


def _keypoints(cfg: VideoConfig, out: Path, infos, cams, numbers: Sequence[np.ndarray], log) -> list[np.ndarray]:
    sources = cfg.keypoints if cfg.keypoints is not None else _mediapipe(out, infos, cams, numbers, log)
    kps = [keypoints.read_keypoints(sources[v], numbers[v]) for v in range(2)]
    for v, kp in enumerate(kps):
        share = keypoints.keypoint_fraction(kp)
        if share < MIN_DETECTED:
            raise VideoError(f"{sources[v]}: the person is found in {100 * share:.0f} % of {cfg.videos[v]}'s "
                             f"{len(kp)} frames used (at least {100 * MIN_DETECTED:.0f} % needed); check that the file "
                             "belongs to this video and is numbered by its frames, or cut the video with --start/--end")
    return kps


def _estimate_offset(cfg: VideoConfig, out: Path, infos, cams, numbers, kps, nets: VideoNetworks,
                     progress: bool, log) -> dict:
    theta, valid = [], []
    for v in range(2):
        root = out / "views" / f"uav{v + 1}"
        assemble.single_view(root, out / "frames" / f"uav{v + 1}", numbers[v], cams[v].K,
                             (infos[v].width, infos[v].height), kps[v], "openpose", infos[v].fps)
        pred = video_network.predict(nets.baseline, root, "openpose", out / "views" / f"uav{v + 1}_baseline.npz", progress)
        theta.append(pred["theta"][:, 0])
        valid.append(pred["valid"][:, 0])
    step = cfg.every
    # a lag k pairs UAV1's decoded frame i with UAV2's i + k: in source frames n2[0] - n1[0] + k * every
    base = int(numbers[1][0]) - int(numbers[0][0])
    reach = cfg.max_offset_s * infos[0].fps
    lag_range = (int(np.ceil((-reach - base) / step)), int(np.floor((reach - base) / step)))
    s1, s2 = (offset.pose_signal(t, ok) for t, ok in zip(theta, valid))
    est = offset.estimate_offset(s1, s2, lag_range, min_pairs=min(30, max(len(s1), len(s2)) // 3))
    if est is None:
        raise VideoError(f"{cfg.videos[0]} and {cfg.videos[1]} overlap too little to estimate their offset "
                         f"(within {cfg.max_offset_s:g} s); give --offset FRAMES")
    frames_off = base + est.frames * step
    result = {"frames": int(frames_off), "seconds": frames_off / infos[0].fps, "estimated": True,
              "correlation": est.correlation, "runner_up": est.runner_up,
              "runner_up_frames": base + est.runner_up_frames * step,
              "pairs": est.overlap, "confident": est.confident, "resolution_frames": step}
    return result


def run_video(cfg: VideoConfig, nets: VideoNetworks, *, fit_config: AirPosePlusConfig | None = None,
              progress: bool = True, log: Callable[[str], None] = print) -> VideoRun:
    """Run every stage (module docstring) into ``cfg.out``, skipping those already done.

    Raises:
        VideoError, and the readers' errors (:class:`airpose_lib.errors.UserError`): bad input,
        named in one line; FolderBusyError: another run writes ``cfg.out``.
    """
    out = Path(cfg.out)
    out.mkdir(parents=True, exist_ok=True)
    seconds: dict[str, float] = {}
    with folder_lock(out, "output folder"):
        stages = _Stages(out)
        t = time.perf_counter()
        infos, cams, warns = _read_videos(cfg, log)
        numbers = _numbers(cfg, infos, cfg.offset)
        for v in range(2):
            undistort = (cams[v].K, cams[v].dist) if cams[v].distorted else None
            frames.decode_frames(infos[v], numbers[v], out / "frames" / f"uav{v + 1}", undistort=undistort,
                                 progress=progress, desc=f"decode UAV{v + 1}")
        seconds["frames"] = time.perf_counter() - t

        t = time.perf_counter()
        kps = _keypoints(cfg, out, infos, cams, numbers, log)
        seconds["keypoints"] = time.perf_counter() - t

        t = time.perf_counter()
        key = _digest({"videos": [asdict(i) for i in infos], "stamps": [frames.file_stamp(v) for v in cfg.videos],
                       "numbers": [n.tolist() for n in numbers],
                       "keypoints": [hashlib.sha256(k.tobytes()).hexdigest() for k in kps],
                       "K": [c.K.tolist() for c in cams], "offset": cfg.offset, "baseline": str(nets.baseline),
                       "max_offset_s": cfg.max_offset_s})
        if cfg.offset is not None:
            off = {"frames": int(cfg.offset), "seconds": cfg.offset / infos[0].fps, "estimated": False}
        elif stages.current("offset", key) and (out / "offset.json").is_file():
            off = json.loads((out / "offset.json").read_text())
        else:
            off = _estimate_offset(cfg, out, infos, cams, numbers, kps, nets, progress, log)
        with atomic_path(out / "offset.json") as tmp:
            tmp.write_text(json.dumps(off, indent=1))
        stages.mark("offset", key)
        seconds["offset"] = time.perf_counter() - t
        if off["estimated"]:
            found = (f"UAV2 frame = UAV1 frame {off['frames']:+d} ({off['seconds']:+.3f} s), correlation "
                     f"{off['correlation']:.2f}, next best {off['runner_up']:.2f} at {off['runner_up_frames']:+d}")
            if not off["confident"]:
                raise VideoError(f"no clear offset between {cfg.videos[0]} and {cfg.videos[1]} (best: {found}); give "
                                 f"--offset FRAMES, e.g. from an event both cameras saw, or --offset {off['frames']} "
                                 "to take the best guess")
            log(f"offset: {found}")

        t = time.perf_counter()
        seq_frames = assemble.two_view(out / "sequence", [out / "frames" / "uav1", out / "frames" / "uav2"],
                                       numbers, off["frames"], [c.K for c in cams],
                                       [(i.width, i.height) for i in infos], kps, "openpose", infos[0].fps)
        if len(seq_frames) < 2:
            raise VideoError(f"at offset {off['frames']:+d} frames {cfg.videos[0]} and {cfg.videos[1]} share "
                             f"{len(seq_frames)} frames; check --offset, --start/--end and --every")
        key = _digest({"sequence": seq_frames.tolist(), "offset": off["frames"], "airpose": str(nets.airpose),
                       "prev": stages.done.get("offset")})
        if not (stages.current("network", key) and (out / "airpose.npz").is_file()):
            video_network.predict(nets.airpose, out / "sequence", "openpose", out / "airpose.npz", progress)
            stages.mark("network", key)
        seconds["network"] = time.perf_counter() - t
        with np.load(out / "airpose.npz") as z:
            estimates = {"airpose": {k: z[k] for k in ("phi", "tau", "theta", "beta")}, "valid": z["valid"]}

        if cfg.fit:
            t = time.perf_counter()
            fcfg = fit_config or AirPosePlusConfig()
            key = _digest({"prev": stages.done.get("network"), "fit": fcfg.to_dict(), "prior": str(nets.prior)})
            if not (stages.current("fit", key) and (out / "airpose_plus.npz").is_file()):
                video_network.refine(out / "sequence", estimates["airpose"], nets.prior, fcfg, out / "airpose.npz",
                                     out / "airpose_plus.npz", progress)
                stages.mark("fit", key)
            with np.load(out / "airpose_plus.npz") as z:
                estimates["airpose_plus"] = {k: z[k] for k in ("phi", "tau", "theta", "beta")}
            seconds["fit"] = time.perf_counter() - t

        t = time.perf_counter()
        files = video_outputs.write_outputs(out, infos, cams, seq_frames, off["frames"], estimates, overlays=cfg.overlays,
                                           every=cfg.every)
        seconds["outputs"] = time.perf_counter() - t
        summary = {"videos": list(cfg.videos), "frames": int(len(seq_frames)), "offset": off,
                   "intrinsics": [c.as_dict() for c in cams], "networks": {"airpose": str(nets.airpose),
                   "baseline": str(nets.baseline), "prior": str(nets.prior), **nets.about},
                   "seconds": seconds, "warnings": warns, "config": asdict(cfg)}
        with atomic_path(out / "summary.json") as tmp:
            tmp.write_text(json.dumps(summary, indent=1, default=str))
        files["summary"] = out / "summary.json"
    return VideoRun(out, files, off, int(len(seq_frames)), seconds, warns)

