"""Where the kit writes runs: one folder, whatever the current working directory.

Training runs, fine-tuning, the recordings experiment, the reproduction runner and notebooks run
by hand all put their outputs under :func:`runs_root`, so that a run made by one of them is found
by the others (``airpose train --profile cpu`` from the repository root and ``airpose reproduce
--profile cpu`` share checkpoints; so does a notebook opened in JupyterLab from ``notebooks/``).
This module imports nothing else of the kit.
"""
from __future__ import annotations

import os
from pathlib import Path

__all__ = ["RUNS_ENV", "repo_root", "runs_root", "run_path", "figures_root"]

#: Environment variable naming the runs folder (overrides the checkout's ``runs/``).
RUNS_ENV = "AIRPOSE_RUNS"


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
