"""Run the kit's notebooks with a profile's parameters and collect their figures.

The catalog (``catalog.yaml``) lists the notebooks in order with the figures each must write;
a profile (``airpose_lib/profiles/<name>.yaml``, read through :mod:`airpose_lib.profiles`) is the
one place where sizes live (render size, dataset size, epochs ...). For every catalogued notebook the runner

1. checks that it has a cell tagged ``parameters`` that declares ``output_dir`` and every
   parameter the profile sets for it (so a typo in a profile fails before anything runs);
2. executes it in-process with papermill, injecting ``profile``, ``output_dir`` (a fresh per-run
   folder), ``data_source`` when asked for, and the profile's parameters, with an environment
   that renders off-screen and a kernel that talks over local (IPC) sockets;
3. checks that the expected figures exist, copies them into ``figures/<profile>/`` and records
   wall time, status and parameters in ``<runs>/<profile>/report.json``.

``<runs>`` is :func:`airpose_lib.paths.runs_root` (the checkout's ``runs/`` or ``$AIRPOSE_RUNS``),
the folder training runs and notebooks run by hand use too.

It stops at the first failure (later notebooks may consume earlier outputs) unless asked to keep
going. One run per ``<out>/<profile>/`` at a time (:func:`~airpose_lib.folder_lock.folder_lock`).
This module imports nothing else of the kit but the leaves :mod:`airpose_lib.paths` and
:mod:`airpose_lib.folder_lock` (and :mod:`.kernels`, the kernels' environment, sockets and
signals): it must be able to run any notebook.
"""

from __future__ import annotations

import ast
import dataclasses
import datetime as _dt
import json
import re
import shutil
import signal
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import nbformat
import yaml

from airpose_lib import __version__  # the package root holds only the version
from airpose_lib.config_fields import check_type, unknown_hint
from airpose_lib.errors import ConfigError, UserError
from airpose_lib.folder_lock import folder_lock
from airpose_lib.paths import figures_root, runs_root
from airpose_lib.profiles import PROFILES_DIR, ProfileError, loaded, read_profile
from airpose_lib.profiles import profile_names as list_profiles

from .kernels import Interrupted, in_worker_thread, ipc_kernel_manager, kernel_environment, stop_on_signals

__all__ = [
    "check_official_assets",
    "official_needs",
    "CATALOG_PATH",
    "PROFILES_DIR",
    "NOTEBOOKS_DIR",
    "CatalogEntry",
    "NotebookResult",
    "RunReport",
    "ReproductionError",
    "load_catalog",
    "load_profile",
    "check_profile_unchanged",
    "list_profiles",
    "check_notebook",
    "check_parameters",
    "notebook_outputs",
    "run_profile",
]

_HERE = Path(__file__).resolve().parent
#: Ordered list of notebooks and the figures each must produce.
CATALOG_PATH = _HERE / "catalog.yaml"
#: The checkout this package lives in (notebooks/, runs/ and figures/ sit at its root).
REPO_ROOT = _HERE.parents[1]
NOTEBOOKS_DIR = REPO_ROOT / "notebooks"

#: Parameters the runner itself injects into every notebook.
RESERVED_PARAMETERS = ("profile", "output_dir")
#: Values of the notebooks' ``data_source`` parameter (``reproduce --data-source``).
DATA_SOURCES = ("generated", "official")


class ReproductionError(UserError, RuntimeError):
    """A notebook failed, lacks a parameters cell, or did not write an expected figure."""


@dataclass(frozen=True)
class CatalogEntry:
    """One notebook of the reproduction, as listed in ``catalog.yaml``.

    Attributes:
        name: identifier (``00_body_model``); ``--only`` and the profiles refer to it.
        file: notebook file name relative to the notebooks folder.
        reproduces: the paper artefact (figure, table, section) the notebook reproduces.
        figures: file names the notebook must write into its ``output_dir``.
    """

    name: str
    file: str
    reproduces: str
    figures: tuple[str, ...] = ()


@dataclass
class NotebookResult:
    """Outcome of one notebook in a run.

    ``status`` is ``ok``, ``failed`` (a cell raised / the kernel died), ``missing_figures``,
    ``invalid`` (no parameters cell, unknown parameter, missing file), ``interrupted`` (SIGINT or
    SIGTERM killed its kernel) or ``skipped`` (not run because an earlier notebook failed).
    """

    name: str
    file: str
    status: str = "skipped"
    wall_s: float = 0.0
    parameters: dict = field(default_factory=dict)
    executed_notebook: str | None = None
    figures: list[str] = field(default_factory=list)
    missing_figures: list[str] = field(default_factory=list)
    error: str | None = None


@dataclass
class RunReport:
    """Everything a run did; written to ``<out>/<profile>/report.json``."""

    profile: str
    description: str
    kit_version: str
    kernel_name: str
    started_at: str
    run_dir: str
    figures_dir: str
    results: list[NotebookResult] = field(default_factory=list)
    wall_s: float = 0.0

    @property
    def ok(self) -> bool:
        """True when every selected notebook ran and wrote all its figures."""
        return bool(self.results) and all(r.status == "ok" for r in self.results)

    @property
    def failures(self) -> list[NotebookResult]:
        return [r for r in self.results if r.status not in ("ok", "skipped")]

    def to_dict(self) -> dict:
        d = asdict(self)
        d["ok"] = self.ok
        return d

    def write(self, path: Path) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".json.tmp")
        tmp.write_text(json.dumps(self.to_dict(), indent=2, default=str) + "\n")
        tmp.replace(path)  # atomic: a reader never sees half a report

    def table(self) -> str:
        """A short fixed-width summary table."""
        width = max([len("notebook")] + [len(r.name) for r in self.results])
        lines = [f"profile {self.profile!r} (airpose_lib {self.kit_version}) -> {self.run_dir}",
                 f"{'notebook':<{width}}  {'status':<15} {'time':>8}  figures"]
        for r in self.results:
            n_expected = len(r.figures) + len(r.missing_figures)
            lines.append(f"{r.name:<{width}}  {r.status:<15} {r.wall_s:>7.1f}s  "
                         f"{len(r.figures)}/{n_expected}")
        lines.append(f"{'total':<{width}}  {'ok' if self.ok else 'FAILED':<15} {self.wall_s:>7.1f}s")
        return "\n".join(lines)

    def failure_message(self) -> str:
        return "\n".join(f"{r.name}: {r.error}" for r in self.failures)

    def raise_for_failures(self) -> None:
        """Raise :class:`ReproductionError` naming each failed notebook and why."""
        if not self.ok:
            raise ReproductionError(self.failure_message() or "no notebook was run")


# -- catalog and profiles -------------------------------------------------------------------------
def load_catalog(path: Path = CATALOG_PATH) -> list[CatalogEntry]:
    """The ordered notebooks of ``catalog.yaml``; checks names and figure names are unique."""
    raw = yaml.safe_load(Path(path).read_text()) or {}
    entries = []
    for item in raw.get("notebooks") or []:
        try:
            entries.append(CatalogEntry(name=str(item["name"]), file=str(item["file"]),
                                        reproduces=str(item.get("reproduces", "")),
                                        figures=tuple(str(f) for f in item.get("figures") or ())))
        except (KeyError, TypeError) as e:
            raise ReproductionError(f"{path}: malformed catalog entry {item!r} ({e})") from None
    names = [e.name for e in entries]
    if len(set(names)) != len(names):
        raise ReproductionError(f"{path}: duplicate notebook names in {names}")
    figures = [f for e in entries for f in e.figures]
    if len(set(figures)) != len(figures):
        # Figures are collected into one flat folder, so two notebooks may not share a name.
        dup = sorted({f for f in figures if figures.count(f) > 1})
        raise ReproductionError(f"{path}: figure names used by more than one notebook: {dup}")
    return entries


def load_profile(profile: str | Path, profiles_dir: Path = PROFILES_DIR) -> dict:
    """A profile as ``{"name", "path", "description", "cell_timeout_s", "notebooks": {name: params},
    "profile"}``, the last the :class:`~airpose_lib.profiles.Profile` it was read into.

    ``profile`` is a profile name, a path to a YAML file of the same format, or a profile already
    read (:func:`airpose_lib.profiles.loaded`, not read again).
    """
    try:
        prof = loaded(profile, profiles_dir)
        path, raw = prof.path, read_profile(prof)
    except ProfileError as e:  # the runner reports every configuration error as its own
        raise ReproductionError(str(e)) from None
    notebooks = raw.get("notebooks") or {}
    if not isinstance(notebooks, dict) or not all(isinstance(v, dict) or v is None
                                                  for v in notebooks.values()):
        raise ReproductionError(f"{path}: `notebooks` must map notebook names to parameter dicts")
    for nb_name, params in notebooks.items():
        clash = set(params or {}) & set(RESERVED_PARAMETERS)
        if clash:
            raise ReproductionError(f"{path}: {nb_name} sets {sorted(clash)}, which the runner injects")
    return {"name": path.stem, "path": str(path), "description": str(raw.get("description", "")).strip(),
            "cell_timeout_s": raw.get("cell_timeout_s"),
            "notebooks": {k: dict(v or {}) for k, v in notebooks.items()}, "profile": prof}


def _kernel_profile(prof: dict) -> str:
    """The ``profile`` parameter a notebook receives: a kit profile's name, or the absolute path
    of a profile file of one's own (each kernel reads the profile again, from its own folder)."""
    given = str(prof["profile"])
    return given if given == prof["name"] else str(Path(prof["path"]).resolve())


def check_profile_unchanged(prof, before: str) -> None:
    """Raise :class:`ReproductionError` if the file of ``prof`` (a
    :class:`~airpose_lib.profiles.Profile`) now reads differently.

    The run reads its profile once, but each notebook's kernel reads it again by name: a file
    edited during a run would give its later notebooks other settings than its earlier ones.
    """
    try:
        now = loaded(prof.path).digest
    except ProfileError as e:
        now = f"unreadable ({e})"
    if now != prof.digest:
        raise ReproductionError(f"{prof.path} changed during the run, before {before}; a run's notebooks must "
                                "all read one profile: restore the file, or start the run again to use the new one")


# -- notebook checks ------------------------------------------------------------------------------
def _default_type(source: str | None):
    """The type a parameter's value must have: its default's (``256`` -> int; ``None``, an
    expression or a name: any). ``bool`` is not an int here, an int may stand for a float."""
    try:
        default = ast.literal_eval(source or "None")
    except (ValueError, SyntaxError):
        return Any
    if default is None:
        return Any
    return {tuple: list}.get(type(default), type(default))


def check_parameters(prof: dict, catalog: list[CatalogEntry], notebooks_dir: Path = NOTEBOOKS_DIR) -> None:
    """Every ``notebooks:`` entry of a profile (:func:`load_profile`) names a catalogued notebook
    and parameters its parameters cell declares, each of the type of its default; else a
    :class:`ReproductionError` naming the profile file, the entry and the closest name, before
    anything runs.
    """
    import papermill

    entries = {e.name: e for e in catalog}
    for nb_name, params in prof["notebooks"].items():
        where = f"{prof['path']}: `notebooks: {nb_name}:`"
        if nb_name not in entries:
            raise ReproductionError(f"{where} is not a catalogued notebook; {unknown_hint(nb_name, entries)}")
        path = Path(notebooks_dir) / entries[nb_name].file
        if not path.is_file() or not params:
            continue  # a missing notebook is reported when it runs
        declared = papermill.inspect_notebook(str(path))
        for key, value in params.items():
            if key not in declared:
                raise ReproductionError(f"{where} sets {key!r}, which {path.name} does not declare; "
                                        f"{unknown_hint(key, declared)}")
            try:
                check_type(key, value, _default_type(declared[key].get("default")))
            except ConfigError as e:
                raise ReproductionError(f"{where} {e}") from None


def _parameters_cell(nb) -> int | None:
    for i, cell in enumerate(nb.cells):
        if "parameters" in (cell.get("metadata", {}).get("tags") or []):
            return i
    return None


def check_notebook(path: Path, parameters: Sequence[str] = ()) -> dict:
    """Check a notebook can be parameterised; returns its declared defaults ``{name: source}``.

    Raises :class:`ReproductionError` if the file is missing, no cell is tagged ``parameters``,
    or the parameters cell does not declare ``output_dir`` or one of ``parameters``.
    """
    import papermill

    path = Path(path)
    if not path.is_file():
        raise ReproductionError(f"notebook {path} does not exist")
    nb = nbformat.read(path, as_version=4)
    if _parameters_cell(nb) is None:
        raise ReproductionError(
            f"notebook {path.name} has no cell tagged 'parameters': papermill cannot inject the "
            f"profile's values. Tag the cell that sets the defaults (View > Cell toolbar > Tags).")
    declared = {name: info.get("default") for name, info in papermill.inspect_notebook(str(path)).items()}
    missing = [p for p in ("output_dir", *parameters) if p not in declared]
    if missing:
        raise ReproductionError(
            f"notebook {path.name}: its parameters cell does not declare {missing} "
            f"(declared: {sorted(declared)}); a profile may only set parameters the notebook has")
    return declared


def notebook_outputs(path: Path) -> list[int]:
    """Indices of code cells that carry outputs or execution counts (notebooks in git must not)."""
    nb = nbformat.read(Path(path), as_version=4)
    return [i for i, c in enumerate(nb.cells)
            if c.cell_type == "code" and (c.get("outputs") or c.get("execution_count") is not None)]


# -- execution ------------------------------------------------------------------------------------
def _select(catalog: list[CatalogEntry], only: Sequence[str] | None) -> list[CatalogEntry]:
    if not only:
        return list(catalog)
    chosen = []
    for key in only:
        hits = [e for e in catalog if key in (e.name, e.file, Path(e.file).stem)]
        hits = hits or [e for e in catalog if e.name.startswith(key)]
        if len(hits) != 1:
            raise ReproductionError(
                f"--only {key!r} matches {[e.name for e in hits] or 'no notebook'}; "
                f"catalogued: {[e.name for e in catalog]}")
        if hits[0] not in chosen:
            chosen.append(hits[0])
    return [e for e in catalog if e in chosen]  # keep catalog order


def _execution_error(exc: Exception, executed: Path) -> str:
    from papermill.exceptions import PapermillExecutionError

    if isinstance(exc, PapermillExecutionError):
        return (f"cell In [{exc.exec_count}] (cell #{exc.cell_index}) raised "
                f"{exc.ename}: {exc.evalue} -- traceback in {executed}")
    return f"{type(exc).__name__}: {exc} -- partial output in {executed}"


def _record_provenance(figures_dir: Path, copied: dict[str, str], entry: CatalogEntry,
                       report: RunReport) -> None:
    path = figures_dir / "provenance.json"
    try:
        prov = json.loads(path.read_text())
    except (OSError, ValueError):
        prov = {}
    stamp = _dt.datetime.now().isoformat(timespec="seconds")
    for fig, src in copied.items():
        prov[fig] = {"notebook": entry.name, "profile": report.profile, "source": src,
                     "kit_version": report.kit_version, "collected_at": stamp}
    path.write_text(json.dumps(prov, indent=2, sort_keys=True) + "\n")


def _run_one(entry: CatalogEntry, nb_path: Path, params: dict, run_dir: Path, figures_dir: Path,
             kernel_name: str, cell_timeout_s, log_output: bool, report: RunReport) -> NotebookResult:
    import papermill

    result = NotebookResult(entry.name, entry.file, parameters=params)
    output_dir = Path(params["output_dir"])
    executed = run_dir / "notebooks" / Path(entry.file).name
    t0 = time.perf_counter()
    try:
        check_notebook(nb_path, [k for k in params if k not in RESERVED_PARAMETERS])
    except ReproductionError as e:
        result.status, result.error = "invalid", str(e)
        return result
    # A fresh output folder: a figure left from an earlier run must not hide a missing one. The
    # last good folder and executed notebook wait beside it and come back unless the run succeeds.
    kept = _set_aside([output_dir, executed])
    output_dir.mkdir(parents=True)
    executed.parent.mkdir(parents=True, exist_ok=True)
    result.executed_notebook = str(executed)
    try:
        with kernel_environment():
            in_worker_thread(
                papermill.execute_notebook,
                str(nb_path), str(executed), parameters=params, kernel_name=kernel_name,
                cwd=str(nb_path.parent), progress_bar=False, log_output=log_output,
                execution_timeout=cell_timeout_s, kernel_manager_class=ipc_kernel_manager())
    except BaseException as e:
        result.wall_s = time.perf_counter() - t0
        note = _restore(kept)
        result.status, result.error = "failed", _execution_error(e, _partial(executed) if executed in kept
                                                                 else executed) + note
        if not isinstance(e, Exception):
            raise
        return result
    result.wall_s = time.perf_counter() - t0

    for fig in entry.figures:
        f = output_dir / fig
        (result.figures if f.is_file() and f.stat().st_size > 0 else result.missing_figures).append(fig)
    if result.missing_figures:
        result.status = "missing_figures"
        note = _restore(kept)
        result.error = (f"ran, but did not write {result.missing_figures} into "
                        f"{_partial(output_dir) if output_dir in kept else output_dir} "
                        f"(the catalog expects {list(entry.figures)})" + note)
        return result
    for path in kept:
        _remove(_last_good(path))
    figures_dir.mkdir(parents=True, exist_ok=True)
    copied = {}
    for fig in entry.figures:
        shutil.copy2(output_dir / fig, figures_dir / fig)
        copied[fig] = str(output_dir / fig)
    _record_provenance(figures_dir, copied, entry, report)
    result.status = "ok"
    return result


def _last_good(path: Path) -> Path:
    """Where the last good ``path`` waits while a rerun writes ``path``: ``<name>.last-good``."""
    return path.with_name(path.name + ".last-good")


def _partial(path: Path) -> Path:
    """Where a rerun that did not succeed leaves what it wrote to ``path``: ``<name>.partial``."""
    return path.with_name(path.name + ".partial")


def _remove(path: Path) -> None:
    if path.is_dir():
        shutil.rmtree(path)
    elif path.exists():
        path.unlink()


def _set_aside(paths: list[Path]) -> list[Path]:
    """Move each existing ``path`` (a notebook's output folder, its executed notebook) to its
    :func:`_last_good` name; returns the paths moved. A last good copy left by a run that was
    killed outright is the good one: what that run wrote becomes its partial run."""
    moved = []
    for path in paths:
        aside = _last_good(path)
        if aside.exists():
            _remove(_partial(path))
            if path.exists():
                path.rename(_partial(path))
            moved.append(path)
        elif path.exists():
            path.rename(aside)
            moved.append(path)
    return moved


def _restore(kept: list[Path]) -> str:
    """After a run that did not succeed: what it wrote goes to the ``.partial`` names, the last
    good copies come back. Returns what the notebook's message adds (where each is)."""
    for path in kept:
        _remove(_partial(path))
        if path.exists():
            path.rename(_partial(path))
        _last_good(path).rename(path)
    if not kept:
        return ""
    return (f"; partial run in {', '.join(str(_partial(p)) for p in kept)}; the last good results stay in "
            f"{', '.join(str(p) for p in kept)}")


def _write_reports(report: RunReport, run_dir: Path) -> None:
    """``report.json`` keeps the last good result of every notebook: a notebook that did not
    succeed in this run keeps its earlier ``ok`` entry (its results were kept too). What this run
    did, failures included, is ``report.partial.json`` until a run succeeds."""
    path, partial = run_dir / "report.json", run_dir / "report.partial.json"
    if report.ok:
        report.write(path)
        partial.unlink(missing_ok=True)
        return
    report.write(partial)
    try:
        earlier = {r["name"]: r for r in json.loads(path.read_text()).get("results", [])}
    except (OSError, ValueError):
        earlier = {}
    kept = dataclasses.replace(report, results=[
        NotebookResult(**earlier[r.name]) if r.status != "ok" and earlier.get(r.name, {}).get("status") == "ok" else r
        for r in report.results])
    kept.write(path)


def _data_source_parameter(nb_path: Path, data_source: str | None) -> dict:
    """``{"data_source": ...}`` for a notebook that declares the parameter, else ``{}``."""
    if data_source is None or not nb_path.is_file():
        return {}
    import papermill

    return {"data_source": data_source} if "data_source" in papermill.inspect_notebook(str(nb_path)) else {}


def official_needs(nb_path: Path) -> list[str]:
    """The official assets a notebook needs for ``data_source="official"``: the ``needs=[...]``
    of its ``setup_notebook`` call (read from the notebook's code cells, nothing executed)."""
    names: list[str] = []
    for cell in nbformat.read(str(nb_path), as_version=4).cells:
        if cell.cell_type == "code":
            for found in re.findall(r"needs=(\[[^\]]*\])", cell.source):
                names += [n for n in ast.literal_eval(found) if n not in names]
    return names


def check_official_assets(notebooks: Sequence[Path]) -> None:
    """``--data-source official`` asked for explicitly: every asset the notebooks need must be
    there (presence and sizes; checksums are the notebooks' business), else a
    :class:`ReproductionError` naming the missing ones -- instead of the notebooks' silent
    fallback to generated data (on the paper profile: days of generating and training)."""
    from airpose_lib.assets import verify  # lazy: the runner's import stays light

    needed = list(dict.fromkeys(n for nb in notebooks if nb.is_file() for n in official_needs(nb)))
    missing = [r for r in (verify(name, checksums=False) for name in needed) if not r.ok]
    if missing:
        raise ReproductionError(
            "--data-source official: " + "; ".join(f"{r.name} is missing or incomplete in {r.root}" for r in missing)
            + f"; see `airpose data verify {missing[0].name}` for what is missing and how to get it, or run "
            "without --data-source official (the kit's generated data)")


def run_profile(
    profile: str,
    only: Sequence[str] | None = None,
    out_dir: Path | str | None = None,
    figures_dir: Path | str | None = None,
    kernel_name: str = "python3",
    *,
    notebooks_dir: Path | str | None = None,
    catalog_path: Path | str = CATALOG_PATH,
    profiles_dir: Path | str = PROFILES_DIR,
    keep_going: bool = False,
    log_output: bool = False,
    verbose: bool = True,
    data_source: str | None = None,
) -> RunReport:
    """Execute the catalogued notebooks with a profile's parameters.

    Args:
        profile: ``smoke``, ``cpu``, ``paper`` (or a path to a profile YAML file).
        only: notebook names (or unique prefixes such as ``00``) to run; default all, in order.
        out_dir: run root; executed notebooks go to ``<out>/<profile>/notebooks/``, each notebook's
            figures to ``<out>/<profile>/<notebook name>/``. Default
            :func:`airpose_lib.paths.runs_root` (``<checkout>/runs`` or ``$AIRPOSE_RUNS``).
        figures_dir: where the expected figures are collected. Default
            ``<checkout>/figures/<profile>`` (one folder per profile: a smoke run does not
            overwrite the cpu figures).
        kernel_name: Jupyter kernel to execute with.
        notebooks_dir: folder of the notebooks (default: the checkout's ``notebooks/``).
        keep_going: run the remaining notebooks after a failure instead of stopping.
        log_output: stream the notebooks' cell outputs to the log while they run.
        verbose: print the summary table.
        data_source: ``generated`` or ``official``: injected as ``data_source`` into every selected
            notebook that declares it (a profile's own ``data_source`` for a notebook wins, so it can
            be set per notebook). None: each notebook's default. ``official`` fails at once
            (:func:`check_official_assets`) when an asset a selected notebook needs is missing.

    Returns:
        A :class:`RunReport` (also written to ``<out>/<profile>/report.json``); check ``.ok`` or
        call ``.raise_for_failures()``. Configuration errors (unknown profile or notebook, a
        profile entry for a notebook not in the catalog) raise :class:`ReproductionError` at once.
    """
    notebooks_dir = Path(notebooks_dir) if notebooks_dir is not None else NOTEBOOKS_DIR
    if data_source is not None and data_source not in DATA_SOURCES:
        raise ReproductionError(f"data_source must be one of {DATA_SOURCES}, got {data_source!r}")
    prof = load_profile(profile, Path(profiles_dir))
    out_dir = Path(out_dir) if out_dir is not None else runs_root()
    figures_dir = Path(figures_dir) if figures_dir is not None else figures_root() / prof["name"]
    catalog = load_catalog(Path(catalog_path))
    check_parameters(prof, catalog, notebooks_dir)
    selected = _select(catalog, only)
    if data_source == "official":
        check_official_assets([notebooks_dir / e.file for e in selected])
    run_dir = (out_dir / prof["name"]).resolve()
    figures_dir = figures_dir.resolve()

    report = RunReport(profile=prof["name"], description=prof["description"], kit_version=__version__,
                       kernel_name=kernel_name,
                       started_at=_dt.datetime.now().isoformat(timespec="seconds"),
                       run_dir=str(run_dir), figures_dir=str(figures_dir))
    report.results = [NotebookResult(e.name, e.file) for e in selected]
    # stale=(): a notebook run by hand may be writing below run_dir; its temp files are not ours
    with folder_lock(run_dir, "reproduction folder", stale=()), stop_on_signals() as caught:
        t_start = time.perf_counter()
        stop = False
        for i, entry in enumerate(selected):
            params = {"profile": _kernel_profile(prof), "output_dir": str(run_dir / entry.name),
                      **_data_source_parameter(notebooks_dir / entry.file, data_source),
                      **prof["notebooks"].get(entry.name, {})}
            if stop:
                report.results[i].parameters = params
                report.results[i].error = "not run: an earlier notebook failed"
                continue
            check_profile_unchanged(prof["profile"], entry.name)
            if verbose:
                print(f"[reproduce:{prof['name']}] {entry.name} ...", flush=True)
            result = _run_one(entry, notebooks_dir / entry.file, params, run_dir, figures_dir,
                              kernel_name, prof["cell_timeout_s"], log_output, report)
            if caught:  # stopped by a signal: the kernel was killed, not the notebook's fault
                result.status, result.error = "interrupted", f"stopped by {signal.Signals(caught[0]).name}"
            report.results[i] = result
            report.wall_s = time.perf_counter() - t_start
            _write_reports(report, run_dir)  # after every notebook: a killed run leaves a trace
            if caught:
                raise Interrupted(signal.Signals(caught[0]).name)
            if result.status != "ok" and not keep_going:
                stop = True
        report.wall_s = time.perf_counter() - t_start
        _write_reports(report, run_dir)
    if verbose:
        print(report.table(), flush=True)
    return report
