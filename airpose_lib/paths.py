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
from dataclasses import dataclass
from pathlib import Path

__all__ = ["CACHE_ENV", "RUNS_ENV", "RunFolders", "cache_dir", "repo_root", "runs_root", "run_path", "figures_root",
           "profile_name"]

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
    root = _cache_root()
    root.mkdir(parents=True, exist_ok=True)
    return root


def _cache_root() -> Path:
    """The kit's cache folder, not created (a folder named is not a folder made)."""
    return Path(os.environ.get(CACHE_ENV, Path.home() / ".cache" / "airpose")).expanduser()


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


@dataclass(frozen=True)
class RunFolders:
    """The folders of one profile's runs, caches and results, named once at the entry.

    Built from the profile by the command, ``airpose reproduce`` or a notebook's set-up
    (:meth:`of`) and passed down, so that the code below names no folder from a profile: a
    training takes ``folders.train(variant, seed)``, a dataset ``folders.still``. The folders are
    not created (not even the cache), and each is resolved when asked for (``$AIRPOSE_RUNS`` and ``$AIRPOSE_CACHE`` as
    they are then).

    Attributes:
        name: what the folders are named after (:func:`profile_name`: ``"cpu"``; a profile file of
            one's own, its stem).
    """

    name: str

    @classmethod
    def of(cls, profile: str | os.PathLike) -> RunFolders:
        """The folders of a profile (a name or the path of a profile file)."""
        return cls(profile_name(profile))

    @property
    def runs(self) -> Path:
        """``<runs>/<name>``: the notebooks' outputs and the reproduction's report."""
        return runs_root() / self.name

    def train(self, variant: str, seed: int) -> Path:
        """``<runs>/train/<name>/<variant>/seed<seed>``: one training run."""
        return run_path("train", self.name, variant, f"seed{seed}")

    @property
    def pretrain(self) -> Path:
        """``<runs>/pretrain/<name>``: the backbone's pretraining runs."""
        return run_path("pretrain", self.name)

    def recordings(self, field: bool = False) -> Path:
        """``<runs>/recordings/<name>`` (``<name>_field`` on the field recordings): the recordings
        experiment."""
        return run_path("recordings", f"{self.name}_field" if field else self.name)

    @property
    def still(self) -> Path:
        """``<cache>/data/still_<name>``: the still-frame dataset."""
        return _cache_root() / "data" / f"still_{self.name}"

    def sequences(self, field: bool = False) -> Path:
        """``<cache>/data/sequences_<name>`` (``..._field``: the field recordings)."""
        return _cache_root() / "data" / (f"sequences_{self.name}_field" if field else f"sequences_{self.name}")

    @property
    def prior(self) -> Path:
        """``<cache>/prior/<name>/vposer.pt``: the kit's pose prior."""
        return _cache_root() / "prior" / self.name / "vposer.pt"

    @property
    def results(self) -> Path:
        """``<checkout>/results/<name>`` (``./results/<name>`` for an installed kit): the committed
        tables, provenance and shipped networks."""
        root = repo_root()
        return (root if root is not None else Path.cwd().resolve()) / "results" / self.name

    @property
    def figures(self) -> Path:
        """``<checkout>/figures/<name>``: the figures ``reproduce`` collects."""
        return figures_root() / self.name
