"""Where the kit writes runs (one folder, whatever the current working directory) and where it
caches what it builds.

Training runs, fine-tuning, the recordings experiment, the reproduction runner and notebooks run
by hand all put their outputs under :func:`runs_root`, so that a run made by one of them is found
by the others (``airpose train --profile cpu`` from the repository root and ``airpose reproduce
--profile cpu`` share checkpoints; so does a notebook opened in JupyterLab from ``notebooks/``).
:func:`cache_dir` (``$AIRPOSE_CACHE``, default ``~/.cache/airpose``) holds what the kit builds
once and reuses: the open body model (and anny's own build cache, ``<cache>/anny`` unless
``ANNY_CACHE_DIR`` is set), datasets, priors, backbones, ONNX exports, the assets' default folders.
:func:`portable` names a path under these folders by its root's placeholder (``<cache>/...``), so
that a record committed to ``results/`` does not name the folders of the machine that made it.
This module imports nothing else of the kit.
"""
from __future__ import annotations

import os
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path, PurePath
from typing import Any

__all__ = ["CACHE_ENV", "RUNS_ENV", "RunFolders", "cache_dir", "repo_root", "runs_root", "run_path", "figures_root",
           "profile_name", "PLACEHOLDERS", "machine_roots", "portable"]

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


def machine_roots() -> dict[str, Path]:
    """The folders :func:`portable` names by a placeholder: ``<checkout>`` (when the kit is a
    checkout), ``<runs>`` (:func:`runs_root`), ``<cache>`` (the kit cache, not created) and ``~``
    (the home folder), as they are now."""
    roots = {"<runs>": runs_root(), "<cache>": _cache_root(), "~": Path.home()}
    root = repo_root()
    return {"<checkout>": root, **roots} if root is not None else roots


# A POSIX absolute path in a text: a "/" that no name character, "/", ":" (a URL's "//"), "<" (a
# closing tag), a placeholder's ">" nor an HTML-escaped one ("&gt;") comes right after, then names;
# a space ends a path. A data URI's base64 (an image in an HTML page) is passed over whole.
_NAME = r"[\w.~+@%-]"
#: What :func:`portable` puts in place of a root (``~`` too, for the home folder).
PLACEHOLDERS = ("<checkout>", "<runs>", "<cache>", "<abs>")
_ABSOLUTE = re.compile(r"(?P<base64>;base64,[A-Za-z0-9+/=]*)|"
                       + "".join(f"(?<!{re.escape(p)})" for p in (*PLACEHOLDERS, "&gt;"))
                       + rf"(?<![\w/.:~<+@%-])/{_NAME}+(?:/{_NAME}*)*")


def portable(value: Any, roots: Mapping[str, str | os.PathLike] | None = None) -> Any:
    """``value`` with every absolute path in it named without this machine's folders, for a record
    that is committed (``results/``): a file made on one machine must not name that machine's
    folders, which mean nothing in another clone (and tell the reader whose machine it was).

    A path under a root of ``roots`` (default :func:`machine_roots`; the deepest root that holds
    it wins, so the cache beats the home folder it lies in) becomes the root's placeholder and the
    rest: ``/home/u/.cache/airpose/prior/cpu/vposer.pt`` -> ``<cache>/prior/cpu/vposer.pt``. Any
    other absolute path of two or more names keeps its last two, after ``<abs>/``:
    ``/tmp/runs/straight/eval_val`` -> ``<abs>/straight/eval_val`` (enough to tell what it was,
    nothing of where). Paths are found inside longer text too (a command line, an HTML page): a
    ``/`` that starts a name and follows no name character, ``:`` or ``<``, nor a placeholder
    (the kit's, or one escaped in HTML, ``&lt;kit cache&gt;/data``), up to a space or a character
    a file name does not use here (quotes, ``&``, ``)``...); a path with a space is cut there, and
    the base64 of a data URI is left alone. A ``/`` right after an HTML tag (``<td>/root/...``)
    starts a path, so a placeholder of one's own written unescaped (``<mine>/x/y``) is taken for
    a tag. Only POSIX paths are rewritten (the kit runs on Linux and macOS); a second call changes
    nothing.

    Args:
        value: a str, a :class:`~pathlib.PurePath` (returned as a str), or a dict / list / tuple
            of them, walked recursively (dict keys too); any other value is returned as it is.
        roots: ``placeholder -> folder``; ``"/"`` as a folder is ignored.
    """
    if roots is None:
        roots = machine_roots()
    # deepest first; "<runs>/x" rather than "<checkout>/runs/x"
    table = sorted(((str(PurePath(r)), p) for p, r in roots.items() if str(PurePath(r)) != "/"),
                   key=lambda rp: -len(PurePath(rp[0]).parts))
    return _portable(value, table)


def _portable(value: Any, table: list[tuple[str, str]]) -> Any:
    if isinstance(value, str):
        return _ABSOLUTE.sub(lambda m: m.group(0) if m.group("base64") is not None
                             else _portable_path(m.group(0), table), value)
    if isinstance(value, PurePath):
        return _portable(str(value), table)
    if isinstance(value, Mapping):
        return {_portable(k, table): _portable(v, table) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        items = [_portable(v, table) for v in value]
        return items if isinstance(value, list) else tuple(items)
    return value


def _portable_path(path: str, table: list[tuple[str, str]]) -> str:
    """One absolute path, named by its deepest root of ``table``, else by its last two names."""
    for root, placeholder in table:
        if path == root or path.startswith(root + "/"):
            return placeholder + path[len(root):]
    names = [n for n in path.split("/") if n]
    if len(names) < 2:  # "/s" in "m /s", "/tmp" alone: too short to be worth a guess
        return path
    return "<abs>/" + "/".join(names[-2:]) + ("/" if path.endswith("/") else "")


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
