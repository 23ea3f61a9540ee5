"""Test helpers: tiny datasets in the official AirPose formats, made from the kit's own people and cameras.

They let the loaders of :mod:`~airpose_lib.data.official.synthetic` and
:mod:`~airpose_lib.data.official.real` be tested without the authors' data (the formats are
described there). Images are cheap: black frames with each of the 22 projected body joints drawn
as a filled disc of its own colour, so a test can check that a crop puts every disc where the
item's 2D joints say.

* :func:`write_official_synthetic_fixture`: subjects from :func:`airpose_lib.data.still.scene.sample_person`
  (one pose and shape per subject, as each official subject is one posed scan) placed at several
  positions, each seen by independently drawn drone cameras
  (:func:`~airpose_lib.data.still.scene.sample_cameras`, f = 1475 px, principal point at ``(W/2, H/2)``
  like the authors' AirSim intrinsics). Per-sample pkls hold the keys and shapes the authors'
  ``create_aerial_people_new.py`` writes; images are stored pre-cropped like the release
  (``cropped=True``) or as full frames; the list files hold absolute paths of a fictitious author
  machine, so path remapping is exercised.
* :func:`write_official_real_fixture`: a short two-drone recording with the release's dict-format
  detection files and ArUco marker poses (:class:`~airpose_lib.data.sequences.writer.OfficialLayoutWriter`
  writes only the kit's formats).

Every file is written atomically.
"""
from __future__ import annotations

import colorsys
import json
import math
import pickle
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from airpose_lib.atomic import atomic_path
from airpose_lib.body.forward import rest_body
from airpose_lib.data.official.synthetic import OFFICIAL_CROP_MARGIN, VAL_SUBJECTS, stored_image_box, subject_of
from airpose_lib.data.sequences.layout import write_camera_calib
from airpose_lib.data.sequences.writer import OfficialLayoutWriter
from airpose_lib.data.still.poses import sample_body_pose
from airpose_lib.data.still.scene import PersonSample, SceneConfig, body_world_pose, sample_cameras, sample_person

__all__ = [
    "AUTHOR_ROOT",
    "REAL_INTRINSICS",
    "joint_colors",
    "draw_discs",
    "write_official_synthetic_fixture",
    "write_official_real_fixture",
]

#: Fictitious data root of the authors' machine used in the fixture's list files.
AUTHOR_ROOT = "/home/author/Datasets/AerialPeople/agora_copenet_uniform_new_cropped"
#: The release's drone intrinsics (paper / facts): cam0 and cam1.
REAL_INTRINSICS = np.array([[[1537.83, 0.0, 1018.55], [0.0, 1517.66, 577.52], [0.0, 0.0, 1.0]],
                            [[1361.11, 0.0, 978.02], [0.0, 1378.80, 667.23], [0.0, 0.0, 1.0]]])


def _write_bytes(path: Path, data: bytes) -> None:
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def _write_png(path: Path, rgb: np.ndarray) -> None:
    import cv2

    ok, buf = cv2.imencode(".png", np.ascontiguousarray(rgb[..., ::-1]))
    if not ok:
        raise RuntimeError(f"PNG encoding failed for {path}")
    _write_bytes(path, buf.tobytes())


def joint_colors(n: int = 22) -> np.ndarray:
    """``(n, 3)`` uint8 RGB, fully saturated, hues evenly spaced (one colour per joint)."""
    return np.array([[round(255 * c) for c in colorsys.hsv_to_rgb(k / n, 1.0, 1.0)] for k in range(n)],
                    dtype=np.uint8)


def draw_discs(image: np.ndarray, uv: np.ndarray, colors: np.ndarray, radius: float) -> np.ndarray:
    """Paint filled discs (in place; returns the image).

    Args:
        image: ``(H, W, 3)`` uint8.
        uv: ``(N, 2)`` centres in pixels (integer pixel centres), sub-pixel accurate.
        colors: ``(N, 3)`` uint8.
        radius: disc radius in pixels; a pixel is painted when its centre is within it.
    """
    H, W = image.shape[:2]
    r = int(math.ceil(radius)) + 1
    for (u, v), col in zip(np.asarray(uv, np.float64), colors):
        x0, x1 = max(int(math.floor(u)) - r, 0), min(int(math.ceil(u)) + r + 1, W)
        y0, y1 = max(int(math.floor(v)) - r, 0), min(int(math.ceil(v)) + r + 1, H)
        if x0 >= x1 or y0 >= y1:
            continue
        yy, xx = np.mgrid[y0:y1, x0:x1]
        inside = (xx - u) ** 2 + (yy - v) ** 2 <= radius ** 2
        image[y0:y1, x0:x1][inside] = col
    return image


def _project(K: np.ndarray, R: np.ndarray, t: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels ``(N, 2)`` and depths ``(N,)`` of world points ``X (N, 3)``."""
    xc = X @ R.T + t
    p = xc @ K.T
    return p[:, :2] / p[:, 2:], xc[:, 2]


def write_official_synthetic_fixture(root: Path | str, n_subjects: int = 3, n_positions: int = 2,
                                     n_cameras: int = 2, seed: int = 0,
                                     image_size: tuple[int, int] = (1920, 1080), *, cropped: bool = True,
                                     num_test_subjects: int = 1, write_lists: bool = True,
                                     body_source: str = "open", disc_radius: float = 8.0,
                                     store_vertices: bool = False, max_attempts: int = 50) -> dict:
    """Write a tiny synthetic dataset in the official layout under ``root``.

    Args:
        root: the data root (``dataset/`` and ``data/`` are created in it).
        n_subjects: subjects (folders ``rp_kit<iii>_posed_001``; subject id ``kit<iii>``).
        n_positions: positions (samples) per subject.
        n_cameras: cameras per sample (the release has 4; the loader reads 0 and 1).
        seed: everything follows from it.
        image_size: full frame ``(W, H)``.
        cropped: store images pre-cropped to the tight box + 200 px (the release) or full frames.
        num_test_subjects: the last subjects (sorted) listed in ``test_pkls.pkl``.
        write_lists: write ``train_pkls.pkl`` / ``test_pkls.pkl``.
        body_source: body model of the people (``open``: the kit's).
        disc_radius: radius of the joint discs, full-frame pixels.
        store_vertices: also store ``smpl_vertices_wrt_origin`` (as the release; large).
        max_attempts: redraws of a position whose 23 joints leave a frame (the authors dropped such
            samples).

    Returns:
        dict with ``root``, ``files`` (pkl paths in writing order), ``train`` / ``test`` (pkl
        paths), ``subjects``, ``colors`` ``(22, 3)`` uint8 RGB of the joint discs, ``disc_radius``.
    """
    import torch

    from airpose_lib.body import load_body_model


    root = Path(root)
    W, H = image_size
    cfg = SceneConfig(num_views=n_cameras, image_size=(W, H), principal_point=(W / 2.0, H / 2.0))
    colors = joint_colors(22)
    models: dict = {}
    files, subjects = [], []
    for s in range(n_subjects):
        subject = f"rp_kit{s:03d}_posed_001"
        subjects.append(subject)
        person = sample_person(np.random.default_rng([seed, s]), cfg, sample_body_pose)
        # Stored as float32, as the authors' pkls; the joints are made from the stored values.
        theta = person.theta.astype(np.float32).astype(np.float64)
        betas = person.betas.astype(np.float32).astype(np.float64)
        if person.gender not in models:
            models[person.gender] = load_body_model(body_source, person.gender, dtype=torch.float64)
        v0, j0 = (x[0] for x in rest_body(models[person.gender], betas[None], theta[None]))
        for pos in range(n_positions):
            for attempt in range(max_attempts):
                rng = np.random.default_rng([seed, s, pos, attempt])
                where = rng.uniform(-cfg.person_extent, cfg.person_extent, 2)
                placed = PersonSample(person.gender, betas, theta, where, float(rng.uniform(-math.pi, math.pi)))
                R_wb, t_wb = body_world_pose(placed, v0)
                cams = sample_cameras(rng, cfg)
                J = j0 @ R_wb.T + t_wb
                proj = [_project(c.K, c.R_cw, c.t_cw, J[:23]) for c in cams]
                if all((z > 0).all() and (uv >= 0).all() and (uv[:, 0] <= W).all() and (uv[:, 1] <= H).all()
                       for uv, z in proj):
                    break
            else:
                raise RuntimeError(f"fixture subject {s} position {pos}: no camera draw kept the person in frame")
            sample = {
                "smpl_joints_wrt_origin": J[None].astype(np.float32),
                "scanpose": np.concatenate([np.c_[R_wb, t_wb], [[0, 0, 0, 1]]])[None].astype(np.float32),
                "smpltrans": t_wb[None],
                "smplshape": betas[None].astype(np.float32),
                "smplpose": theta.reshape(1, 21, 3).astype(np.float32),
                "smplorient": np.array([[0.0, placed.heading, 0.0]], np.float32),
                "smplgender": person.gender,
                "smplorient_rotmat_wrt_origin": R_wb[None].astype(np.float32),
            }
            if store_vertices:
                sample["smpl_vertices_wrt_origin"] = (v0 @ R_wb.T + t_wb)[None].astype(np.float32)
            for c, cam in enumerate(cams):
                extr = np.eye(4)
                extr[:3, :3], extr[:3, 3] = cam.R_cw, cam.t_cw
                sample[f"cam{c}"] = {"extr": extr, "intr": cam.K.copy()}
                uv23 = proj[c][0]
                lo = np.array([max(uv23[:, 0].min() - 20, 0), max(uv23[:, 1].min() - 20, 0)]).astype(int)
                hi = np.array([min(uv23[:, 0].max() + 20, W), min(uv23[:, 1].max() + 20, H)]).astype(int)
                sample[f"j2d{c}"] = uv23
                sample[f"bb{c}"] = [lo, hi]
                rel = f"data/{subject}/MyCamera{c}_{pos}.png"
                sample[f"im{c}"] = rel
                frame = draw_discs(np.zeros((H, W, 3), np.uint8), uv23[:22], colors, disc_radius)
                if cropped:
                    x0, y0, x1, y1 = stored_image_box(np.r_[lo, hi], (W, H), OFFICIAL_CROP_MARGIN)
                    frame = frame[y0:y1, x0:x1]
                _write_png(root / rel, frame)
            pkl = root / "dataset" / "pkls" / subject / f"{subject}_{pos}.pkl"
            _write_bytes(pkl, pickle.dumps(sample, protocol=4))
            files.append(pkl)
    ids = sorted({subject_of(f) for f in files})
    test_ids = set(ids[-num_test_subjects:]) if num_test_subjects > 0 else set()
    train = [f for f in files if subject_of(f) not in test_ids]
    test = [f for f in files if subject_of(f) in test_ids]
    if write_lists:
        for name, part in (("train_pkls.pkl", train), ("test_pkls.pkl", test)):
            entries = [f"{AUTHOR_ROOT}/dataset/{f.relative_to(root / 'dataset').as_posix()}" for f in part]
            _write_bytes(root / "dataset" / name, pickle.dumps(entries, protocol=4))
    # The kit's validation split: the last VAL_SUBJECTS training subjects (the list files above
    # hold the authors' whole training split, as the release's do).
    train_ids = sorted({subject_of(f) for f in train})
    val_ids = set(train_ids[-VAL_SUBJECTS:]) if len(train_ids) > VAL_SUBJECTS else set()
    val = [f for f in train if subject_of(f) in val_ids]
    train = [f for f in train if subject_of(f) not in val_ids]
    return {"root": root, "files": files, "train": train, "val": val, "test": test, "subjects": subjects,
            "colors": colors, "disc_radius": disc_radius}


def write_official_real_fixture(root: Path | str, n_frames: int = 4, *, frames: Sequence[int] | None = None,
                                first_frame: int = 0, image_size: tuple[int, int] = (64, 36), seed: int = 0,
                                missing: dict | None = None, marker: str = "0") -> dict:
    """Write a short two-drone recording in the real-data release's formats.

    Args:
        root: the recording folder (``machine_1``, ``machine_2`` are created).
        n_frames: frames (numbered ``first_frame ..``) unless ``frames`` is given.
        frames: explicit frame numbers.
        image_size: ``(W, H)`` of the (black) JPEG frames.
        seed: keypoints, confidences and marker poses follow from it.
        missing: ``{"openpose" | "alphapose" | "marker": [(view, frame), ...]}`` entries left out
            of the files (not detected).
        marker: the marker id written.

    Returns:
        dict with ``frames (F,)``, ``K (2, 3, 3)``, ``openpose (F, 2, 25, 3)``,
        ``alphapose (F, 2, 18, 3)`` (zeros where left out), ``rvec``, ``tvec`` ``(F, 2, 3)`` and
        ``marker_valid (F, 2)``.
    """

    root = Path(root)
    frames = list(range(first_frame, first_frame + n_frames)) if frames is None else [int(i) for i in frames]
    F, W, H = len(frames), int(image_size[0]), int(image_size[1])
    missing = {k: {(int(v), int(i)) for v, i in pairs} for k, pairs in (missing or {}).items()}
    rng = np.random.default_rng(seed)
    op = np.concatenate([rng.uniform(0, [W, H], (F, 2, 25, 2)), rng.uniform(0.1, 1.0, (F, 2, 25, 1))], -1)
    ap = np.concatenate([rng.uniform(0, [W, H], (F, 2, 18, 2)), rng.uniform(0.1, 1.0, (F, 2, 18, 1))], -1)
    rvec = rng.normal(0.0, 0.5, (F, 2, 3))
    tvec = rng.uniform(-3.0, 3.0, (F, 2, 3)) + np.array([0.0, 0.0, 12.0])
    valid = np.ones((F, 2), bool)
    writer = OfficialLayoutWriter(root, num_views=2)
    black = np.zeros((H, W, 3), np.uint8)
    for i in frames:
        writer.write_frame(i, [black, black])
    for v in range(2):
        mdir = writer.machine(v)
        write_camera_calib(mdir / "camera_calib.yml", REAL_INTRINSICS[v], (W, H))
        op_file, ap_file, mk_file = {}, {}, {}
        for n, i in enumerate(frames):
            key = f"{i:06d}"
            if (v, i) in missing.get("openpose", ()):
                op[n, v] = 0.0
            else:
                op_file[key] = {"pose": op[n, v][None].astype(np.float32)}
            if (v, i) in missing.get("alphapose", ()):
                ap[n, v] = 0.0
            else:
                ap_file[key] = {"people": [{"pose_keypoints_2d": [float(x) for x in ap[n, v].reshape(-1)]}]}
            if (v, i) in missing.get("marker", ()):
                valid[n, v] = False
            else:
                mk_file[key] = {marker: {"rvec": rvec[n, v].copy(), "tvec": tvec[n, v].copy()}}
        _write_bytes(mdir / "openpose_res.pkl", pickle.dumps(op_file, protocol=4))
        _write_bytes(mdir / "alphapose_res.json", json.dumps(ap_file).encode())
        _write_bytes(mdir / "markerposes_corrected_all.pkl", pickle.dumps(mk_file, protocol=4))
    # float32 round trip of the OpenPose file
    op = op.astype(np.float32).astype(np.float64)
    return {"frames": np.asarray(frames), "K": REAL_INTRINSICS.copy(), "openpose": op, "alphapose": ap,
            "rvec": rvec, "tvec": tvec, "marker_valid": valid}
