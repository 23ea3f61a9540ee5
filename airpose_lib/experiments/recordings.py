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

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from airpose_lib.assets import resolve_data_source
from airpose_lib.atomic import atomic_path
from airpose_lib.body import load_body_model
from airpose_lib.body.joint_sets import BODY_25_FROM_SMPLX
from airpose_lib.data.official.real import MARKER_POSES_FILE, load_marker_poses, load_official_real
from airpose_lib.data.sequences import ensure_sequences, profile_field_sequences
from airpose_lib.data.sequences.markers import marker_relative_cameras, sequence_marker_poses
from airpose_lib.data.sequences.reader import load_sequence, recording_fingerprint
from airpose_lib.engine.checkpoint import StaleRunError
from airpose_lib.errors import ConfigError
from airpose_lib.eval import metrics as M
from airpose_lib.eval.mean_body import NEUTRAL_LABEL, mean_body_recording_estimate
from airpose_lib.eval.recordings import (
    body_joints,
    per_view_params,
    recording_table,
)
from airpose_lib.finetune.config import finetune_config
from airpose_lib.finetune.keypoints import resolution_scales
from airpose_lib.finetune.network import load_sized_network
from airpose_lib.finetune.predict import (
    image_sizes,
    network_camera_of,
    predict_sequence,
    regress_features,
    sequence_features,
)
from airpose_lib.finetune.train import finetune
from airpose_lib.fitting import airpose_plus, fitting_profile
from airpose_lib.folder_lock import folder_lock
from airpose_lib.model import posed_joints_and_vertices, to_smplx_params
from airpose_lib.model.official import load_official_checkpoint
from airpose_lib.paths import profile_name, run_path
from airpose_lib.prior import load_prior
from airpose_lib.prior.build import ensure_prior
from airpose_lib.train.ablation import trained_checkpoint
from airpose_lib.train.config import load_train_config
from airpose_lib.train.official import find_official_checkpoint

from .shipped import shipped_networks

__all__ = ["METHODS", "RecordingExperiment", "default_experiment_dir", "run_recording_experiment", "runs_field",
           "body_vertices", "recording_prior", "ground_truth_diagnostic", "scored_frames",
           "CONTROL_LABEL", "official_recordings", "official_networks", "networks_for", "recordings_for",
           "marker_truth"]

#: Estimate names in plotting order.
METHODS = ("Baseline (pre-trained)", "AirPose (pre-trained)", "Baseline", "AirPose", "AirPose+")
_NETWORKS = {"Baseline (pre-trained)": ("baseline", False), "AirPose (pre-trained)": ("airpose", False),
             "Baseline": ("baseline", True), "AirPose": ("airpose", True)}
#: Crop size of the official networks.
OFFICIAL_INPUT_SIZE = 224
#: Folders of the official real-data (fine-tuned on person 1) checkpoints (data_manifests/official_checkpoints.yaml).
OFFICIAL_REAL_CHECKPOINTS = {"Baseline": "hmr_real_ckpt", "AirPose": "copenet_twoview_real_ckpt"}


def default_experiment_dir(profile: str, field: bool = False) -> Path:
    """``<runs>/recordings/<name>`` (:func:`airpose_lib.paths.runs_root`, like training runs;
    ``<name>``: :func:`~airpose_lib.paths.profile_name`); on the profile's field recordings
    ``<runs>/recordings/<name>_field``."""
    name = profile_name(profile)
    return run_path("recordings", f"{name}_field" if field else name)


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


def _stamp(path: Path) -> str:
    st = Path(path).stat()
    return f"{Path(path).resolve()}:{st.st_size}:{st.st_mtime_ns}"


def _key(*parts) -> str:
    return hashlib.sha256(json.dumps(parts, sort_keys=True, default=str).encode()).hexdigest()[:16]


def _slug(method: str) -> str:
    return "".join(c if c.isalnum() else "_" for c in method.lower()).strip("_").replace("__", "_")


def _cached_npz(path: Path, key: str):
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as d:
            if str(d["cache_key"]) != key:
                return None
            return {k: d[k] for k in d.files if k != "cache_key"}
    except (OSError, ValueError, KeyError):
        return None


def _save_npz(path: Path, key: str, arrays: dict) -> None:

    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, cache_key=np.array(key), **{k: np.asarray(v) for k, v in arrays.items()})


def _sequence_stamp(sequence) -> list[str]:
    """What a recording's estimates depend on besides the images: its detector files and metadata
    (re-simulated detections change the boxes)."""
    root = Path(sequence.root)
    files = sorted(root.glob("machine_*/*_res.*")) + sorted(root.glob("sequence.json"))
    return [_stamp(f) for f in files]


#: Bumped when the estimates of an unchanged network and recording change (e.g. the camera rule).
_ESTIMATE_VERSION = 3  # 3: the box margin of data.network_input.network_box_margin


def _network_estimate(checkpoint: Path, sequence, out: Path) -> dict:
    key = _key("predict", _ESTIMATE_VERSION, _stamp(checkpoint), str(sequence.root), sequence.frames.tolist(),
               _sequence_stamp(sequence))
    cached = _cached_npz(out, key)
    if cached is not None:
        return cached
    if Path(checkpoint).suffix == ".ckpt":  # an official Lightning checkpoint: ResNet-50 at 224 px
        model, size = load_official_checkpoint(checkpoint, backbone=None), OFFICIAL_INPUT_SIZE
    else:
        model, _, size = load_sized_network(checkpoint)
    pred = predict_sequence(model, sequence, input_size=size)
    arrays = {k: np.asarray(v) for k, v in pred.items() if k != "provenance"}
    _save_npz(out, key, arrays)
    return arrays


def marker_truth(sequence, out: Path) -> dict | None:
    """UAV 2 in UAV 1 from the ArUco markers on a recording's ground, or None without markers.

    The official release ships each drone's marker pose per frame (``data.official.real``, marker
    ``"0"`` as the world frame, as the official loader); a generated recording with the
    ``markers`` option is searched for its markers frame by frame (``cv2.aruco``,
    :func:`~airpose_lib.data.sequences.markers.sequence_marker_poses`; cached, about 10 ms an image).

    Returns:
        ``R_12 (F, 3, 3)``, ``t_12 (F, 3)``, ``valid (F,)`` (both drones posed), and for
        generated recordings ``count (F, V)`` markers detected and ``rms_px (F, V)`` reprojection
        error (NaN where not posed).
    """
    root = Path(sequence.root) if sequence.root is not None else None
    if root is not None and (root / "machine_1" / MARKER_POSES_FILE).is_file():
        poses = load_marker_poses(root, sequence.frames, num_views=sequence.num_views)
        R_12, t_12, valid = marker_relative_cameras(poses)
        return {"R_12": R_12, "t_12": t_12, "valid": valid}
    if ((sequence.meta or {}).get("config") or {}).get("markers") is None:
        return None
    key = _key("markers", _MARKER_VERSION, str(sequence.root), sequence.frames.tolist(), _sequence_stamp(sequence))
    cached = _cached_npz(out, key)
    if cached is not None:
        return cached
    poses, count, rms = sequence_marker_poses(sequence)
    R_12, t_12, valid = marker_relative_cameras(poses)
    arrays = {"R_12": R_12, "t_12": t_12, "valid": valid, "count": count, "rms_px": rms}
    _save_npz(out, key, arrays)
    return arrays


#: Bumped when the marker detection or pose of an unchanged recording changes.
_MARKER_VERSION = 1


def _airpose_plus(sequence, init: dict, profile: str, prior, prior_info: dict, out: Path,
                  progress: bool) -> tuple[dict, dict]:
    import dataclasses

    cfg = fitting_profile(profile)
    # The Geman-McClure scale (30 px) is a full-resolution value: rho is a function of residual / sigma.
    scale = float(np.mean(resolution_scales(image_sizes(sequence))))
    cfg = dataclasses.replace(cfg, sigma=cfg.sigma * scale)
    start = {k: init[k] for k in ("phi", "tau", "theta", "beta")}
    digest = hashlib.sha256()
    for k in start:  # the whole initialisation, not just one of its arrays
        digest.update(np.ascontiguousarray(start[k]).tobytes())
    # The device (the profile's `fitting: device`) is in the key only when it is not the default
    # CPU, so that the caches written before the option existed stay valid.
    fit_key = {k: v for k, v in cfg.to_dict().items() if k != "device" or v != "cpu"}
    key = _key("airpose+", fit_key, prior_info.get("stamp"), str(sequence.root), sequence.frames.tolist(),
               digest.hexdigest(), _sequence_stamp(sequence))
    cached = _cached_npz(out, key)
    if cached is not None:
        info = json.loads(str(cached.pop("info")))
        return cached, info
    res = airpose_plus(sequence.keypoints, sequence.K, start, prior=prior, config=cfg, progress=progress)
    arrays = res.to_numpy()
    info = {"seconds": res.seconds, "iterations": cfg.iterations, "frames": int(len(arrays["kept"])),
            "skipped_frames": len(res.skipped_frames), "final_loss": float(res.history["loss"][-1]),
            "sigma_px": cfg.sigma, "prior": prior_info.get("source")}
    _save_npz(out, key, {**arrays, "info": np.array(json.dumps(info))})
    return arrays, info


def recording_prior(profile: str, progress: bool = False):
    """The pose prior of the experiment: VPoser V02_05 when it is installed (``vposer_v02_05``
    asset, e.g. ``$AIRPOSE_VPOSER_DIR``), else the profile's kit prior (trained on first use).

    Returns:
        ``(prior, info)``: the :class:`~airpose_lib.prior.VPoser` and ``{"source": "vposer" | "kit",
        "file", "stamp", "message"}`` (the message says which prior and why).
    """
    found = resolve_data_source("official", needs=["vposer_v02_05"])
    if found.source == "official":
        prior, prov = load_prior("vposer", found.roots["vposer_v02_05"], return_provenance=True)
        file = Path(prov["file"])
        msg = f"Pose prior: VPoser V02_05 ({file}), as the paper."
        source = "vposer"
    else:
        shipped = shipped_networks(profile)
        file = shipped.prior if shipped is not None else ensure_prior(profile, progress=progress)
        prior = load_prior("kit", file)
        msg = (f"Pose prior: the kit's VPoser-architecture prior ({file}); VPoser V02_05 is not installed "
               "(data_manifests/vposer_v02_05.yaml says how to get it; it is then used automatically).")
        source = "kit"
    return prior, {"source": source, "file": str(file), "stamp": _stamp(file), "message": msg}


def ground_truth_diagnostic(model, sequence, *, input_size: int, features: dict | None = None,
                            cut: str | None = None):
    """A fine-tuning diagnostic on a recording with ground truth (the test person): ``f(model) ->
    {"mpjpe_m", "mpe_m", "j2d_px"}`` for ``finetune(..., diagnostic=f)``.

    The backbone is frozen during fine-tuning up to block ``cut`` (``FineTuneConfig.trainable_from``;
    None: all of it), so the recording's features up to there are computed once here (with
    ``model``'s backbone) and every call runs only the rest: the trainable blocks and the regressor. ``j2d_px`` is the mean
    distance of the predicted BODY_25 keypoints to the true ones, in pixels at the reference
    width (1920); ``mpjpe_m`` pelvis-aligned, 22 joints; ``mpe_m`` the position error.

    Args:
        features: precomputed :func:`~airpose_lib.finetune.predict.sequence_features` output
            (with the same ``cut``).
    """
    import torch

    gt = sequence.ground_truth
    if gt is None:
        raise ValueError(f"{sequence.root}: no ground truth for a diagnostic")
    feats = features if features is not None else sequence_features(model, sequence, input_size=input_size, cut=cut)
    K_net = network_camera_of(model)
    body = load_body_model("open", "neutral", dtype=torch.float32)
    f = torch.as_tensor(np.asarray(feats["features"]), dtype=torch.float32)
    P = torch.as_tensor(np.asarray(feats["P"]), dtype=torch.float32)
    pos = np.asarray(feats["positions"])
    F, V = P.shape[:2]
    K = torch.as_tensor(np.asarray(sequence.K), dtype=torch.float32)
    K_p = torch.as_tensor(K_net, dtype=torch.float32).expand(F, V, 3, 3)
    j3d = torch.as_tensor(np.asarray(gt["j3d_cam"])[pos], dtype=torch.float32)
    tau_gt = torch.as_tensor(np.asarray(gt["tau"])[pos], dtype=torch.float32)
    kp_gt = torch.as_tensor(np.asarray(gt["kp2d_body25"])[pos], dtype=torch.float32)
    r = torch.as_tensor(resolution_scales(image_sizes(sequence)), dtype=torch.float32).reshape(1, V, 1)
    idx = torch.as_tensor(BODY_25_FROM_SMPLX)

    def diagnostic(net) -> dict[str, float]:
        out = regress_features(net, f.to(net.init_beta.dtype), P.to(net.init_beta.dtype), input_size, cut=cut)
        pred = {k: v.float() for k, v in to_smplx_params(out, P, K_p, input_size).items()}
        flat = {k: v.reshape(F * V, *v.shape[2:]) for k, v in pred.items()}
        joints = posed_joints_and_vertices(body, flat, joints_only=True)["joints"].reshape(F, V, -1, 3)
        uv = (joints[:, :, idx] @ K.transpose(-1, -2)[None])
        uv = uv[..., :2] / uv[..., 2:].clamp_min(0.05)
        err2d = torch.linalg.norm(uv - kp_gt, dim=-1) / r
        return {"mpjpe_m": float(M.mpjpe(joints[:, :, :22], j3d).mean()),
                "mpe_m": float(M.translation_error(pred["tau"], tau_gt).mean()),
                "j2d_px": float(torch.nanmean(err2d))}

    return diagnostic


def body_vertices(params: dict, body_model, index, view: int) -> np.ndarray:
    """Camera-frame vertices of an estimate at some frames of one view.

    Args:
        params: per-view parameters (see :class:`RecordingExperiment`).
        body_model: a neutral ``smplx.SMPLX``.
        index: frame positions (n,).
        view: the view.

    Returns:
        ``(n, N, 3)`` vertices, ``V = phi V0(theta, beta) + tau``.
    """
    import torch

    p = per_view_params(params)
    idx = np.asarray(index)
    part = {k: torch.as_tensor(np.ascontiguousarray(v[idx, view]), dtype=body_model.v_template.dtype)
            for k, v in p.items()}
    with torch.no_grad():
        return posed_joints_and_vertices(body_model, part)["vertices"].double().numpy()


def official_recordings(root: str | Path) -> dict:
    """The official real-data release as the experiment's recordings: person 1 (frames 0-6999,
    fine-tuning) and person 2 (frames 8000-14999, test), without ground truth."""
    return {"person1": load_official_real(root, person=1), "person2": load_official_real(root, person=2)}


def official_networks(checkpoints_root: str | Path) -> dict[str, Path]:
    """The authors' networks for the experiment's methods: the synthetic-data checkpoints of
    Baseline and AirPose (pre-trained) and their real-data fine-tuned ones (``hmr_real_ckpt``,
    ``copenet_twoview_real_ckpt``)."""
    root = Path(checkpoints_root)
    nets = {"Baseline (pre-trained)": find_official_checkpoint(root, "baseline"),
            "AirPose (pre-trained)": find_official_checkpoint(root, "airpose")}
    for method, folder in OFFICIAL_REAL_CHECKPOINTS.items():
        found = sorted((root / folder).glob("**/*.ckpt"))
        if not found:
            raise FileNotFoundError(f"no .ckpt under {root / folder}; unpack {folder}.zip of the official release "
                                    "there (data_manifests/official_checkpoints.yaml)")
        nets[method] = found[-1]
    return nets


def networks_for(source, profile: str | None = None, field: bool = False) -> dict[str, Path] | None:
    """The networks the experiment runs instead of training its own: the official ones when the
    data source is official and ``official_checkpoints`` is present (see :func:`official_networks`),
    the shipped set of a profile on shipped networks (``field``: those fine-tuned on the field
    recordings), else None (the kit trains and fine-tunes its own)."""
    if getattr(source, "source", "generated") != "official":
        shipped = shipped_networks(profile) if profile is not None else None
        return None if shipped is None else shipped.recordings(field)

    ckpts = resolve_data_source("official", needs=["official_checkpoints"])
    if ckpts.source != "official":
        print(ckpts.message.replace("the kit's generated data", "the kit's own networks, fine-tuned here"))
        return None
    return official_networks(ckpts.roots["official_checkpoints"])


def recordings_for(source, profile: str) -> dict | None:
    """Recordings for a resolved data source (:func:`airpose_lib.assets.resolve_data_source`):
    None (the profile's generated recordings) or the official release's two persons."""
    if getattr(source, "source", "generated") != "official":
        return None
    return official_recordings(source.roots["official_real"])


def runs_field(source, profile: str, field: bool | None = None) -> bool:
    """Whether the real-data notebooks also run the profile's field recordings.

    Args:
        source: the resolved data source (:func:`recordings_for`'s).
        field: the notebook's parameter; None: when the recordings are generated and the profile
            has field recordings (``sequences: field_recordings:``).
    Raises:
        ConfigError: ``field`` is true with the official recordings (they are field footage) or
            with a profile without field recordings.
    """
    generated = getattr(source, "source", "generated") != "official"
    has = bool(profile_field_sequences(profile))
    if field is None:
        return generated and has
    if field and not (generated and has):
        raise ConfigError(f"field=True needs the generated recordings of a profile with `sequences: field_recordings:` "
                          f"({'the official recordings are field footage' if not generated else profile + ' has none'}); "
                          "set field to None or False")
    return bool(field)


#: The control fine-tuning of :func:`_kit_networks` (generated recordings only): AirPose tuned on
#: person 1's true 2D keypoints instead of the detections; never an estimate, only its log.
CONTROL_LABEL = "AirPose (control: true 2D targets)"


def _finetune_logged(pre: Path, tuning, tests: dict, ft_cfg, run_dir: Path, prior, progress: bool,
                     tests_key: str | None):
    """Fine-tune ``pre`` on ``tuning`` into ``run_dir`` (resumed, or afresh when its settings,
    network or recordings changed), the ``tests`` recordings' errors logged per checkpoint
    (``tests_key``: their fingerprint, :func:`_tests_key`); returns the result and the summary row
    of :attr:`RecordingExperiment.finetune_info`."""
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
    return _key(*((name, recording_fingerprint(seq)) for name, seq in sorted(tests.items()))) if tests else None


def _kit_networks(profile: str, seed: int, tuning, tests: dict, prior, prior_info: dict, out: Path,
                  progress: bool) -> tuple[dict, dict]:
    """Table I's Baseline and AirPose of the profile, their fine-tuning on ``tuning`` (model
    selected on its held-out frames) with the ``tests`` recordings' errors logged per checkpoint.

    On a generated ``tuning`` recording with test persons, AirPose is also fine-tuned on the true
    2D keypoints (:data:`CONTROL_LABEL`, ``FineTuneConfig.targets="ground_truth"``): if the test
    person's errors grow with perfect targets too, the cause is fitting one person, not the
    detectors."""
    import dataclasses

    checkpoints, finetune_info = {}, {}
    ft_cfg = finetune_config(profile)
    if ft_cfg.frames is None and "person" in tuning.meta:  # an official split: fine-tune on its frames only
        ft_cfg = dataclasses.replace(ft_cfg, frames=[int(tuning.frames[0]), int(tuning.frames[-1]) + 1])
    ft_cfg = dataclasses.replace(ft_cfg, prior=prior_info["source"], prior_path=prior_info["file"])
    tests_key = _tests_key(tests)
    for variant, label in (("baseline", "Baseline"), ("airpose", "AirPose")):
        pre = trained_checkpoint(profile, variant, seed, progress=progress)
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


def run_recording_experiment(profile: str = "smoke", out_dir: str | Path | None = None, *,
                             sequences: dict | None = None, seed: int | None = None,
                             fine_tune_on: str = "person1", networks: dict[str, str | Path] | None = None,
                             progress: bool = False, field: bool = False) -> RecordingExperiment:
    """Run (or load the cached steps of) the real-data experiment.

    Args:
        profile: sizes of the recordings, networks, fine-tuning and AirPose+ (profile YAML).
        out_dir: cache folder (default :func:`default_experiment_dir`).
        sequences: person -> recording folder in the official layout, or a loaded
            :class:`~airpose_lib.data.sequences.reader.Sequence` (default: the profile's generated
            recordings, made if missing).
        seed: training seed of the networks (default: the profile's).
        fine_tune_on: the person whose detections fine-tune the networks (paper: person 1).
        networks: method -> checkpoint for every network method (``Baseline (pre-trained)``,
            ``AirPose (pre-trained)``, ``Baseline``, ``AirPose``), kit ``.pt`` or official
            ``.ckpt`` (:func:`official_networks`); then nothing is trained or fine-tuned.
        field: on the profile's field recordings (``sequences: field_recordings:``)
            instead of the clean ones, cached in :func:`default_experiment_dir` ``(profile,
            field=True)``: the same pre-trained networks, fine-tuned again on the field person 1.
    """
    out = Path(out_dir) if out_dir is not None else default_experiment_dir(profile, field)
    with folder_lock(out, stale=(".*.tmp", "estimates/*/.*.tmp")):  # one writer of the cached steps
        return _run_recording_experiment(profile, out, sequences, seed, fine_tune_on, networks, progress, field)


def scored_frames(estimates: dict) -> np.ndarray:
    """``(F,)`` bool: the frames every network estimated in every view, those the errors are
    averaged over."""
    return np.all([np.all(e["valid"], axis=1) for m, e in estimates.items() if m in _NETWORKS], axis=0)


def _run_recording_experiment(profile: str, out: Path, sequences: dict | None, seed: int | None,
                              fine_tune_on: str, networks: dict | None, progress: bool,
                              field: bool = False) -> RecordingExperiment:
    import torch

    if sequences is None:
        sequences = ensure_sequences(profile, progress=progress, field=field)
    seqs = {name: s if hasattr(s, "keypoints") else load_sequence(s) for name, s in sequences.items()}
    if fine_tune_on not in seqs:
        raise ValueError(f"fine_tune_on={fine_tune_on!r} is not one of the recordings {list(seqs)}")
    if seed is None:
        seed = load_train_config(profile, "airpose").seed

    prior, prior_info = recording_prior(profile, progress)
    finetune_info = {}
    if networks is not None:
        missing = set(_NETWORKS) - set(networks)
        if missing:
            raise ValueError(f"networks lacks {sorted(missing)}")
        checkpoints = {m: Path(networks[m]) for m in _NETWORKS}
    else:
        tests = {n: s for n, s in seqs.items() if n != fine_tune_on and s.ground_truth is not None}
        checkpoints, finetune_info = _kit_networks(profile, seed, seqs[fine_tune_on], tests, prior, prior_info, out,
                                                   progress)
    estimates, joints, fit_info, tables, markers = {}, {}, {}, [], {}
    body = load_body_model("open", "neutral", dtype=torch.float32)
    for person, seq in seqs.items():
        est = {}
        for method in _NETWORKS:
            est[method] = _network_estimate(checkpoints[method], seq,
                                            out / "estimates" / person / f"{_slug(method)}.npz")
        plus, info = _airpose_plus(seq, est["AirPose"], profile, prior, prior_info,
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
    return RecordingExperiment(profile=profile, out_dir=out, sequences=seqs, estimates=estimates, joints=joints,
                               tables=table, checkpoints=checkpoints, fit_info=fit_info,
                               finetune_info=finetune_info, prior_info=prior_info, markers=markers)
