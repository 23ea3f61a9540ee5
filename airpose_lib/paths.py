"""Where the kit writes runs (one folder, whatever the current working directory) and where it
caches what it builds.

Training runs, fine-tuning, the recordings experiment, the reproduction runner and notebooks run
by hand all put their outputs under :func:`runs_root`, so that a run made by one of them is found
by the others (``airpose train --profile cpu`` from the repository root and ``airpose reproduce
--profile cpu`` share checkpoints; so does a notebook opened in JupyterLab from ``notebooks/``).
:func:`cache_dir` (``$AIRPOSE_CACHE``, default ``~/.cache/airpose``) holds what the kit builds
once and reuses: the open body model (and anny's own build cache, ``<cache>/anny`` unless
``ANNY_CACHE_DIR`` is set), datasets, priors, backbones, ONNX exports, the assets' default folders.
This module imports nothing else of the kit.
"""
from __future__ import annotations

import os
from pathlib import Path

__all__ = ["CACHE_ENV", "RUNS_ENV", "cache_dir", "repo_root", "runs_root", "run_path", "figures_root", "profile_name"]

#: Environment variable naming the runs folder (overrides the checkout's ``runs/``).
RUNS_ENV = "AIRPOSE_RUNS"
#: Environment variable naming the cache folder (overrides ``~/.cache/airpose``).
CACHE_ENV = "AIRPOSE_CACHE"


def profile_name(profile: str | os.PathLike) -> str:
    """The name a profile's folders are made from: ``"cpu"`` for ``"cpu"``, and the file's stem
    for a profile given as a path (``results/x/cpu_more.yaml`` -> ``"cpu_more"``), so that its
    runs, caches and results are one folder each, as the kit's own profiles' are."""
    return Path(str(profile)).stem


def cache_dir() -> Path:
    """The kit's cache folder (``$AIRPOSE_CACHE`` or ``~/.cache/airpose``), created on demand."""
    root = Path(os.environ.get(CACHE_ENV, Path.home() / ".cache" / "airpose")).expanduser()
    root.mkdir(parents=True, exist_ok=True)
    return root


def repo_root() -> Path | None:
    """The checkout the kit is imported from (it has ``notebooks/`` and ``pyproject.toml``), or None
    for an installed copy."""
    root = Path(__file__).resolve().parents[1]
    if (root / "pyproject.toml").is_file() and (root / "notebooks").is_dir():
        return root
    return None


def runs_root() -> Path:
    """``$AIRPOSE_RUNS`` if set, else ``<checkout>/runs``, else (installed kit) ``./runs``; absolute."""
    env = os.environ.get(RUNS_ENV)
    if env:
        return Path(env).expanduser().resolve()
    root = repo_root()
    return (root / "runs") if root is not None else (Path.cwd() / "runs").resolve()


def run_path(*parts: str | os.PathLike) -> Path:
    """``runs_root() / parts...``, e.g. ``run_path("train", "cpu", "airpose", "seed123")``."""
    return runs_root().joinpath(*map(str, parts))


def figures_root() -> Path:
    """``<checkout>/figures`` (``./figures`` for an installed kit): where ``reproduce`` collects
    figures, one sub-folder per profile."""
    root = repo_root()
    return (root / "figures") if root is not None else (Path.cwd() / "figures").resolve()
