"""AirPose+ over a recording: the run's configuration, the network outputs it starts from (an
``.npz`` of ``airpose predict``) and the ``.npz`` of refined parameters it writes.

:func:`airpose_plus` works on arrays; this module is what ``airpose fit`` (and a notebook) adds
around it to go from files to files.
"""
from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import numpy as np

from airpose_lib.atomic import atomic_path
from airpose_lib.errors import ConfigError, DamagedFileError, reading

from .airpose_plus import AirPosePlusConfig, AirPosePlusResult

__all__ = ["INIT_ARRAYS", "fit_config", "initialisation_for", "open_initialisation", "refined_path",
           "save_refinement"]

INIT_ARRAYS = ("phi", "tau", "theta", "beta")
_TEMPORAL = ("temp_pose", "temp_root", "temp_transl")
_WHAT = "an .npz of network outputs"
_FIX = "write it again with `airpose predict`"


def fit_config(base: AirPosePlusConfig, *, official_temporal: bool = False, iterations: int | None = None,
               threads: int | None = None, device: str | None = None) -> AirPosePlusConfig:
    """The profile's ``fitting:`` configuration (``base``, as the entry read it) with the
    command's overrides (on a copy).

    Args:
        official_temporal: the official code's relative temporal weights
            (:meth:`AirPosePlusConfig.official_code`) in place of the profile's.
        iterations: Adam iterations (None: the profile's).
        threads: torch threads during the fit (None or 0: unchanged).
        device: ``auto``, ``cpu``, ``cuda`` or ``cuda:N`` (None: the profile's, default cpu).
    """
    cfg = dataclasses.replace(base)
    if official_temporal:
        cfg = AirPosePlusConfig.official_code(**{k: v for k, v in cfg.to_dict().items() if k not in _TEMPORAL})
    if iterations is not None:
        cfg.iterations = iterations
    if threads:
        cfg.num_threads = threads
    if device is not None:
        cfg.device = device
    return cfg


def open_initialisation(path: str | os.PathLike) -> np.lib.npyio.NpzFile:
    """The network outputs ``path`` opened (arrays are read by :func:`initialisation_for`).

    Raises:
        FileNotFoundError: no such file.
        DamagedFileError: not a readable ``.npz``.
    """
    with reading(path, _WHAT, _FIX):
        pred = np.load(path)
        _ = pred.files
    return pred


def initialisation_for(pred: np.lib.npyio.NpzFile, path: str | os.PathLike,
                       frames: np.ndarray) -> dict[str, np.ndarray]:
    """The starting point of :func:`airpose_plus` for a recording's frames.

    Args:
        pred: the file of :func:`open_initialisation` with ``phi`` (F', V, 3, 3), ``tau`` (F', V, 3),
            ``theta`` (F', V, 21, 3, 3) or axis-angle (F', V, 21, 3), ``beta`` (F', V, 10) and
            optionally ``frames`` (F',) image numbers (sorted).
        path: its file name, for the messages.
        frames: (F,) image numbers of the recording's frames to fit.
    Returns:
        ``phi, tau, theta, beta`` at ``frames`` (all F' rows when the file has no ``frames``).
    Raises:
        DamagedFileError: an array is missing.
        ConfigError: the file's ``frames`` do not include every one of ``frames``.
    """
    files = set(pred.files)
    missing = set(INIT_ARRAYS) - files
    if missing:
        detail = ValueError(f"missing arrays {sorted(missing)}; need phi, tau, theta, beta")
        raise DamagedFileError(path, _WHAT, _FIX, detail)
    with reading(path, _WHAT, _FIX):
        init = {k: pred[k] for k in INIT_ARRAYS}
        pf = np.asarray(pred["frames"]) if "frames" in files else None
    if pf is None:
        return init
    sel = np.searchsorted(pf, frames)
    if np.any(sel >= len(pf)) or np.any(pf[np.minimum(sel, len(pf) - 1)] != frames):
        raise ConfigError(f"{path}: its `frames` do not cover the sequence's frames; give the .npz that "
                          "`airpose predict` wrote for this recording, or --frames within its frames")
    return {k: v[sel] if v.ndim and v.shape[0] == len(pf) else v for k, v in init.items()}


def refined_path(init: str | os.PathLike) -> Path:
    """Default output next to the network outputs: ``<init stem>_airpose_plus.npz``."""
    return Path(init).with_name(Path(init).stem + "_airpose_plus.npz")


def save_refinement(out: str | os.PathLike, frames: np.ndarray, result: AirPosePlusResult, *,
                    sequence: str | os.PathLike, init: str | os.PathLike, label: str,
                    prior: dict) -> Path:
    """Write ``result`` (:meth:`AirPosePlusResult.to_numpy`), ``frames`` (F,) and a JSON
    ``provenance`` (recording, initialisation, profile (``label``), configuration, prior, seconds, final loss,
    skipped frames) to ``out`` atomically."""
    cfg = result.config
    provenance = {"sequence": str(sequence), "init": str(init), "profile": label, "config": cfg.to_dict(),
                  "prior": prior, "seconds": result.seconds, "final_loss": result.history["loss"][-1],
                  "skipped_frames": result.skipped_frames}
    with atomic_path(Path(out)) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, frames=frames, provenance=np.array(json.dumps(provenance, default=str)),
                     **result.to_numpy())
    return Path(out)
