"""Reference results of Table I kept in the repository (``results/<profile>/``), and the check of a
new run against them.

Notebook 02 writes a results bundle into its output folder with :func:`write_reference`:

* ``table1.csv`` / ``table1.md``: Table I (kit mean and seed std, paper, extra columns, the
  mean-body reference rows);
* ``per_seed.csv``: one row per variant x seed with the metric means (what the check compares);
* ``claims.csv`` / ``claims.md``: the six ordering claims with difference, interval and verdict;
* ``mean_body.csv``: the MPE summary of the references: the neutral and the true-gender mean body
  (what a stature-blind estimate with the ground-truth pose gets on the data) and, where the run
  made it, the subject's body at the stature its proportions predict;
* ``provenance.json``: kit version, git commit, machine, command and the wall time of each step
  (notebook 02 adds the device and precision each network trained with, :func:`train_settings`).

``airpose reproduce --write-reference`` copies that bundle to ``results/<profile>/`` (nothing else
writes there); without the flag, a run whose profile has a committed bundle prints
:func:`compare_to_reference`: every variant mean that moved by more than the reference's own
seed spread.

Reference results come from a clean commit, and their provenance names it: ``--write-reference``
refuses (:class:`ProvenanceError`) when the checkout has changes (:func:`require_clean_checkout`)
or when the bundle's ``provenance.json`` records a dirty checkout or a commit that is not an
ancestor of HEAD (:func:`provenance_problems`, the check a test runs on the committed files).
"""
from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import shutil
import subprocess
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pandas as pd

from airpose_lib import __version__
from airpose_lib.atomic import atomic_path
from airpose_lib.errors import UserError
from airpose_lib.paths import RunFolders

from .ablation import PER_SEED_METRICS, table_to_markdown

__all__ = ["REFERENCE_FILES", "RESULTS_ROOT", "ProvenanceError", "reference_dir", "machine_description", "git_commit",
           "require_clean_checkout", "reference_outputs", "provenance_problems", "provenance_record",
           "train_settings", "train_wall_s", "mean_body_summary", "write_reference", "read_reference_table", "side_by_side",
           "compare_to_reference", "check_against_reference", "install_reference", "reference_report",
           "machine_note", "RECORDING_FILES", "FIELD_RECORDING_FILES", "MARKER_RECORDING_FILES", "install_recordings_reference", "recordings_report"]

#: The files of a results bundle.
REFERENCE_FILES = ("table1.csv", "table1.md", "per_seed.csv", "claims.csv", "claims.md", "mean_body.csv",
                   "provenance.json")
#: ``results/`` at the root of the checkout this package lives in.
RESULTS_ROOT = Path(__file__).resolve().parents[2] / "results"
#: Metrics :func:`compare_to_reference` checks by default (those both runs have).
COMPARED_METRICS = (*PER_SEED_METRICS, "mpe_tight_m", "mpjpe_tight_m")


def reference_dir(folders: RunFolders, root: str | Path | None = None) -> Path:
    """``results/<name>`` of the checkout (or of ``root``; ``<name>``: ``folders.name``)."""
    return Path(root if root is not None else RESULTS_ROOT) / folders.name


# -- provenance -----------------------------------------------------------------------------------
# Vector extensions that set CPU training speed: two machines both named "AMD EPYC" differed 3x
# per thread (AVX2 only against AVX-512), so the model name alone does not explain wall times.
_VECTOR_FLAGS = ("avx2", "avx512f", "avx512_bf16", "amx_tile")


def machine_description() -> dict:
    """Platform, CPU model and vector extensions (``/proc/cpuinfo``), core count, RAM
    (``/proc/meminfo``) and load average."""
    cpu, ram_gib, vector = platform.processor() or None, None, None
    try:
        info = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        info = []
    model = next((line for line in info if line.startswith("model name")), None)
    if model is not None:
        cpu = model.split(":", 1)[1].strip()
    flags = next((line for line in info if line.startswith("flags")), None)
    if flags is not None:
        present = set(flags.split(":", 1)[1].split())
        vector = [f for f in _VECTOR_FLAGS if f in present]
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal"):
                ram_gib = round(int(line.split()[1]) / 2**20, 1)  # kB -> GiB
                break
    except (OSError, ValueError):
        pass
    load = os.getloadavg() if hasattr(os, "getloadavg") else None
    return {"platform": platform.platform(), "python": platform.python_version(), "cpu": cpu,
            "vector_extensions": vector, "cores": os.cpu_count(), "ram_gib": ram_gib,
            "load_average": [round(x, 2) for x in load] if load else None}


class ProvenanceError(UserError, RuntimeError):
    """Reference results that would not come from a clean commit: the message names the checkout
    or the ``provenance.json`` and the fix."""


def _git(root: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["git", *args], cwd=root, capture_output=True, text=True, timeout=10)


def reference_outputs(label: str) -> tuple[str, ...]:
    """The paths (relative to the checkout; a trailing ``/``: a folder) that a reproduction with
    ``--write-reference`` writes for the profile ``label`` (its name, or the path of a profile
    file of one's own: how records name it): its own outputs, which do not make the checkout
    dirty for the writers that come after the first (notebook 02's bundle, then notebook 05's
    recordings, then the report). Inputs under ``results/<profile>/`` (the committed backbone) are
    not among them: a change to one is a change to what the results depend on."""
    base = f"results/{RunFolders.of(label).name}/"
    return (*(base + name for name in REFERENCE_FILES), base + "recordings/", base + "report/")


def git_commit(root: str | Path | None = None, outputs: tuple[str, ...] = ()) -> dict:
    """``{"commit": sha or None, "dirty": bool or None}`` of the checkout at ``root`` (default:
    the one ``results/`` belongs to).

    Dirty: a change to a tracked file (staged or not) or an untracked file that git does not ignore
    (new code counts; run folders, caches and other ignored files do not), other than the
    ``outputs`` being written (:func:`reference_outputs`). None: not a git checkout, or git failed.
    """
    root = Path(root) if root is not None else RESULTS_ROOT.parent
    try:
        sha = _git(root, "rev-parse", "HEAD")
        status = _git(root, "status", "--porcelain", "--untracked-files=all")  # files, not folders
    except (OSError, subprocess.SubprocessError):
        return {"commit": None, "dirty": None}
    if sha.returncode or status.returncode:
        return {"commit": None, "dirty": None}
    changed = [line[3:].split(" -> ")[-1].strip('"') for line in status.stdout.splitlines() if line.strip()]
    own = lambda path: any(path == o or (o.endswith("/") and path.startswith(o)) for o in outputs)  # noqa: E731
    return {"commit": sha.stdout.strip(), "dirty": any(not own(path) for path in changed)}


def require_clean_checkout(root: str | Path | None = None, outputs: tuple[str, ...] = ()) -> dict:
    """:func:`git_commit` of a checkout that may write reference results (``outputs``: what this
    reproduction has already written there, :func:`reference_outputs`).

    Raises:
        ProvenanceError: not a git checkout, or it has changes (:func:`git_commit`'s rule).
    """
    root = Path(root) if root is not None else RESULTS_ROOT.parent
    state = git_commit(root, outputs)
    if state["commit"] is None:
        raise ProvenanceError(f"{root}: not a git checkout (or git failed), so reference results could not name "
                              f"their commit; write them from a clone of the repository")
    if state["dirty"]:
        raise ProvenanceError(f"{root} has changes that are not committed (see `git status`); reference results "
                              f"must come from a clean commit: commit or remove the changes, then run again")
    return state


def provenance_problems(path: str | Path, root: str | Path | None = None) -> list[str]:
    """What is wrong with a results bundle's ``provenance.json`` as a record of a clean commit.

    Args:
        path: the ``provenance.json`` (``git: {"commit", "dirty"}`` of :func:`provenance_record`).
        root: the checkout whose HEAD the commit must precede (default: the one ``results/``
            belongs to).
    Returns:
        one sentence per problem, [] when the file records a clean checkout at a commit that is an
        ancestor of (or equal to) HEAD (``git merge-base --is-ancestor``).
    """
    root = Path(root) if root is not None else RESULTS_ROOT.parent
    try:
        record = json.loads(Path(path).read_text())
    except (OSError, ValueError) as e:
        return [f"no readable provenance ({type(e).__name__}: {e})"]
    git = record.get("git") if isinstance(record, dict) else None
    git = git if isinstance(git, dict) else {}
    commit, dirty = git.get("commit"), git.get("dirty")
    problems = []
    if dirty is True:
        problems.append("it was made from a checkout with uncommitted changes")
    elif dirty is not False:
        problems.append("it does not say whether the checkout was clean")
    if not isinstance(commit, str) or not commit:
        return problems + ["it names no git commit"]
    try:
        ancestor = _git(root, "merge-base", "--is-ancestor", commit, "HEAD")
    except (OSError, subprocess.SubprocessError) as e:
        return problems + [f"git could not check its commit {commit[:12]} ({type(e).__name__})"]
    if ancestor.returncode == 1:
        problems.append(f"its commit {commit[:12]} is not an ancestor of HEAD in {root}")
    elif ancestor.returncode:
        problems.append(f"its commit {commit[:12]} is not a commit of the repository at {root} "
                        f"({' '.join(ancestor.stderr.split()) or 'git failed'})")
    return problems


def _run_result(run) -> dict:
    """A run's ``result.json`` ({} when it has none or it is unreadable: an official checkpoint).

    ``run``: an ``AblationRun`` (its ``out_dir`` if it has one, else the folder above ``checkpoints/``).
    """
    folder = getattr(run, "out_dir", None) or Path(run.checkpoint).parent.parent
    try:
        result = json.loads((Path(folder) / "result.json").read_text())
    except (OSError, ValueError):
        return {}
    return result if isinstance(result, dict) else {}


def train_wall_s(runs: Mapping) -> dict:
    """(variant, seed) -> training wall time from each run folder's ``result.json`` (None if absent).

    Args:
        runs: (variant, seed) -> ``AblationRun`` (see :func:`_run_result`).
    """
    out = {}
    for key, run in runs.items():
        try:
            w = _run_result(run).get("wall_s")
            out[key] = float(w) if w is not None else None
        except (ValueError, TypeError):
            out[key] = None
    return out


def train_settings(runs: Mapping) -> dict:
    """(variant, seed) -> ``{"device", "precision", "git"}`` each network was trained with, from
    its ``result.json`` (the device the run resolved ``auto`` to; the commit that finished the
    training); None where unknown (no ``result.json``: the authors' checkpoints; a run from before
    precision existed trained in fp32, the config's default, but its file does not say so; a run
    from before its commit was recorded).

    Args:
        runs: (variant, seed) -> ``AblationRun`` (see :func:`_run_result`).
    """
    out = {}
    for key, run in runs.items():
        result = _run_result(run)
        config = result.get("config")
        config = config if isinstance(config, dict) else {}
        out[key] = {"device": config.get("device"), "precision": config.get("precision"), "git": result.get("git")}
    return out


# -- the bundle -----------------------------------------------------------------------------------
def mean_body_summary(references: pd.DataFrame) -> pd.DataFrame:
    """One row per mean-body reference (``method``): MPE mean, median, 90th percentile, signed /
    absolute depth error and reprojection residual over the test images
    (:func:`airpose_lib.eval.mean_body.mean_body_references` columns)."""
    return pd.DataFrame([{
        "method": method,
        "mpe_m": t["mpe_m"].mean(), "mpe_median_m": t["mpe_m"].median(),
        "mpe_p90_m": t["mpe_m"].quantile(0.9),
        "err_z_m": t["err_z_m"].mean(), "abs_err_z_m": t["err_z_m"].abs().mean(),
        "reproj_px": t["reproj_px"].mean() if "reproj_px" in t else np.nan,
        "images": len(t),
    } for method, t in references.groupby("method", sort=False)])


def _write_text(path: Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def _portable(label: str) -> str:
    """A profile file inside the checkout as its path from the checkout's root (what another
    clone finds it by); a kit profile's name, or a file elsewhere, as it is."""
    path = Path(str(label))
    if path.suffix in (".yaml", ".yml") and path.is_absolute():
        try:
            return path.resolve().relative_to(RESULTS_ROOT.parent).as_posix()
        except ValueError:
            pass
    return str(label)


def provenance_record(label: str, command: str) -> dict:
    """What every results bundle records about how it was made: the profile (``label``: its name
    or file), kit version, git commit (clean but for the profile's own reference outputs,
    :func:`reference_outputs`), time (UTC), machine and the command."""
    return {"profile": _portable(label), "kit_version": __version__,
            "git": git_commit(outputs=reference_outputs(label)),
            "created_at": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            "machine": machine_description(), "command": command}


def _write_csv(path: Path, frame: pd.DataFrame, index: bool) -> None:
    with atomic_path(path) as tmp:
        frame.to_csv(tmp, index=index)


def write_reference(out_dir: str | Path, *, table: pd.DataFrame, per_seed: pd.DataFrame, claims: pd.DataFrame,
                    references: pd.DataFrame | None, label: str, command: str,
                    step_wall_s: Mapping[str, float | None], extra: Mapping | None = None) -> Path:
    """Write a results bundle (:data:`REFERENCE_FILES`), each file atomically.

    Args:
        out_dir: the bundle folder (the notebook's output folder, or ``results/<profile>``).
        table: :func:`airpose_lib.eval.ablation.ablation_table`.
        per_seed: :func:`airpose_lib.eval.ablation.per_seed_table`.
        claims: :func:`airpose_lib.eval.significance.claims_table`.
        references: :func:`airpose_lib.eval.mean_body.mean_body_references` (None: no
            ``mean_body.csv``).
        label: how the record names the reproduction profile (its name or file).
        command: the command that regenerates the bundle.
        step_wall_s: step name -> wall time in seconds (None when unknown).
        extra: more provenance entries (seeds, data source ...).
    Returns:
        ``out_dir``.
    """
    out = Path(out_dir)
    _write_csv(out / "table1.csv", table, index=True)
    _write_text(out / "table1.md", table_to_markdown(table))
    _write_csv(out / "per_seed.csv", per_seed, index=False)
    _write_csv(out / "claims.csv", claims, index=True)
    _write_text(out / "claims.md", table_to_markdown(claims, digits=4))
    if references is not None:
        _write_csv(out / "mean_body.csv", mean_body_summary(references), index=False)
    provenance = {
        **provenance_record(label, command),
        "wall_s": {k: (round(float(v), 1) if v is not None else None) for k, v in step_wall_s.items()},
        **dict(extra or {}),
    }
    _write_text(out / "provenance.json", json.dumps(provenance, indent=2, default=str) + "\n")
    return out


def read_reference_table(ref_dir: str | Path) -> pd.DataFrame | None:
    """The committed ``table1.csv`` of a bundle, or None when there is none."""
    path = Path(ref_dir) / "table1.csv"
    return pd.read_csv(path, index_col=0) if path.is_file() else None


def side_by_side(table: pd.DataFrame, reference: pd.DataFrame | None,
                 metrics: tuple[str, ...] = ("MPE", "MPJPE")) -> pd.DataFrame:
    """This run, the committed reference and the paper, per metric, in adjacent columns.

    Args:
        table, reference: Table I of this run and of the reference (:func:`read_reference_table`;
            None: the reference columns are NaN).
    Returns:
        one row per method of ``table``, columns ``<metric> kit [m]``, ``<metric> kit std [m]``,
        ``<metric> reference [m]``, ``<metric> reference std [m]``, ``<metric> paper [m]``.
    """
    out = pd.DataFrame(index=table.index)
    for m in metrics:
        out[f"{m} kit [m]"] = table[f"{m} [m]"]
        out[f"{m} kit std [m]"] = table[f"{m} std [m]"]
        for col, src in ((f"{m} reference [m]", f"{m} [m]"), (f"{m} reference std [m]", f"{m} std [m]")):
            out[col] = (reference[src].reindex(table.index) if reference is not None and src in reference
                        else np.nan)
        out[f"{m} paper [m]"] = table[f"{m} paper [m]"]
    return out


# -- the check ------------------------------------------------------------------------------------
def compare_to_reference(new_per_seed: pd.DataFrame, reference: str | Path | pd.DataFrame,
                         single_seed_rtol: float = 0.10) -> pd.DataFrame:
    """Where a new run's variant means moved by more than the reference's seed spread.

    For each variant and metric both per-seed tables have, the allowed deviation of the new
    mean over seeds from the reference mean is the reference's standard deviation over seeds
    (ddof 1); with a single reference seed there is no spread, so it is ``single_seed_rtol``
    times the reference mean (10 % by default).

    Args:
        new_per_seed: :func:`airpose_lib.eval.ablation.per_seed_table` of the new run.
        reference: a bundle folder (its ``per_seed.csv``) or that table.
        single_seed_rtol: relative tolerance when the reference has one seed.
    Returns:
        one row per (variant, metric): ``variant, metric, new, reference, reference_std,
        allowed, basis, difference, differs`` (bool); variants of only one side are left out.
    """
    ref = reference if isinstance(reference, pd.DataFrame) else pd.read_csv(Path(reference) / "per_seed.csv")
    metrics = [m for m in COMPARED_METRICS if m in new_per_seed and m in ref]
    rows = []
    new_g, ref_g = new_per_seed.groupby("variant", sort=False), ref.groupby("variant", sort=False)
    for variant, r in ref_g:
        if variant not in new_g.groups:
            continue
        n = new_g.get_group(variant)
        for m in metrics:
            new_mean, ref_mean = float(n[m].mean()), float(r[m].mean())
            if not (np.isfinite(new_mean) and np.isfinite(ref_mean)):
                continue
            if len(r) > 1:
                std = float(r[m].std(ddof=1))
                allowed, basis = std, f"reference std over {len(r)} seeds"
            else:
                std = np.nan
                allowed, basis = single_seed_rtol * abs(ref_mean), f"{single_seed_rtol:.0%} of the reference (one seed)"
            diff = new_mean - ref_mean
            rows.append({"variant": variant, "metric": m, "new": new_mean, "reference": ref_mean,
                         "reference_std": std, "allowed": allowed, "basis": basis, "difference": diff,
                         "differs": bool(abs(diff) > allowed)})
    cols = ["variant", "metric", "new", "reference", "reference_std", "allowed", "basis", "difference", "differs"]
    return pd.DataFrame(rows, columns=cols)


def check_against_reference(new_per_seed: pd.DataFrame, ref_dir: str | Path) -> tuple[pd.DataFrame | None, str]:
    """:func:`compare_to_reference` against the bundle in ``ref_dir`` if it has one.

    Returns:
        the comparison (None without a reference) and a line saying how many variant means differ.
    """
    ref_dir = Path(ref_dir)
    if not (ref_dir / "per_seed.csv").is_file():
        return None, f"no reference in {ref_dir}"
    comparison = compare_to_reference(new_per_seed, ref_dir)
    return comparison, f"{int(comparison['differs'].sum())} of {len(comparison)} variant means differ from {ref_dir}"


def _checkout_of(root: str | Path | None) -> Path:
    """The checkout a results folder belongs to (the folder above ``results/``)."""
    return Path(root if root is not None else RESULTS_ROOT).parent


def install_reference(bundle: str | Path, label: str, command: str | None = None,
                      root: str | Path | None = None) -> Path:
    """Copy a run's results bundle into ``results/<profile>/`` (what ``--write-reference`` does).

    ``command`` replaces the bundle's recorded command (the one that really ran). Files are
    copied atomically one by one; a file of the bundle that is absent is removed from the target.

    Raises:
        ProvenanceError: the checkout ``root`` belongs to has changes (:func:`require_clean_checkout`),
            or the bundle's provenance has :func:`provenance_problems` against it.
    """
    src, dst = Path(bundle), reference_dir(RunFolders.of(label), root)
    if not (src / "per_seed.csv").is_file():
        raise FileNotFoundError(f"{src}: no results bundle (per_seed.csv); run notebook 02 first")
    checkout = _checkout_of(root)
    require_clean_checkout(checkout, reference_outputs(label))
    problems = provenance_problems(src / "provenance.json", checkout)
    if problems:
        raise ProvenanceError(f"{src / 'provenance.json'}: {'; '.join(problems)}; reference results must come "
                              f"from a clean commit: rerun notebook 02 from one (airpose reproduce "
                              f"--profile {label} --only 02_ablation_table --write-reference)")
    for name in REFERENCE_FILES:
        if not (src / name).is_file():
            (dst / name).unlink(missing_ok=True)
            continue
        if name == "provenance.json" and command is not None:
            prov = json.loads((src / name).read_text())
            prov["command"] = command
            _write_text(dst / name, json.dumps(prov, indent=2, default=str) + "\n")
            continue
        with atomic_path(dst / name) as tmp:
            shutil.copyfile(src / name, tmp)
    return dst


def _setup(per_seed: pd.DataFrame) -> tuple[list, list]:
    """The seeds and the test-image counts of a per-seed table (what makes two runs comparable)."""
    return sorted(per_seed["seed"].unique().tolist()), sorted(per_seed["images"].unique().tolist())


def _machine(provenance: Path) -> tuple[str | None, tuple[str, ...]] | None:
    """The CPU model and vector extensions a provenance file records (None: unreadable or absent)."""
    try:
        m = json.loads(provenance.read_text()).get("machine")
    except (OSError, ValueError, AttributeError):
        return None
    return (m.get("cpu"), tuple(m.get("vector_extensions") or ())) if isinstance(m, dict) and m else None


def machine_note(new_provenance: str | Path, reference_provenance: str | Path) -> str:
    """A line saying that two runs come from CPUs of another model or other vector extensions
    ("" when both record the same, or either record is missing). Such runs can differ beyond the
    seeds' spread without any change of code: bf16 autocast and the matrix kernels take other
    paths (AVX-512 BF16, AMX tiles) and round differently, and training amplifies it."""
    new, old = _machine(Path(new_provenance)), _machine(Path(reference_provenance))
    if new is None or old is None or new == old:
        return ""

    def say(m):
        return f"{m[0] or 'an unnamed CPU'} ({', '.join(m[1]) or 'no vector extensions recorded'})"

    return (f"reference: note the reference was made on {say(old)}, this run on {say(new)}; other CPU kernels "
            "round differently, so a mean may differ by more than the seeds' spread without any change of code")


def reference_report(bundle: str | Path, label: str, write: bool = False, command: str | None = None,
                     root: str | Path | None = None) -> str:
    """What ``airpose reproduce`` prints after notebook 02: the new run against ``results/<profile>/``.

    Args:
        bundle: the notebook's results bundle (``<run>/02_ablation_table/results``).
        write: install the bundle as the new reference (``--write-reference``) instead of comparing.
    Returns:
        a few lines of text ("" when there is nothing to say: no bundle, or no reference).
    """
    bundle, ref = Path(bundle), reference_dir(RunFolders.of(label), root)
    if not (bundle / "per_seed.csv").is_file():
        return f"reference: notebook 02 wrote no {bundle / 'per_seed.csv'}; nothing compared" if write else ""
    if write:
        return f"reference: wrote {install_reference(bundle, label, command, root)}"
    if not (ref / "per_seed.csv").is_file():
        return f"reference: none for profile {label!r} ({ref}); `--write-reference` records this run as one"
    new, old = pd.read_csv(bundle / "per_seed.csv"), pd.read_csv(ref / "per_seed.csv")
    cmp = compare_to_reference(new, old)
    moved = cmp[cmp["differs"]]
    head = (f"reference: {len(cmp)} variant means compared with {ref}; "
            f"{len(moved)} differ by more than the reference's seed spread")
    if _setup(new) != _setup(old):
        head += (f"\nreference: note the runs differ in seeds / test images per run: reference {_setup(old)}, "
                 f"this run {_setup(new)}")
    if note := machine_note(bundle / "provenance.json", ref / "provenance.json"):
        head += "\n" + note
    if moved.empty:
        return head
    return head + "\n" + moved.drop(columns=["reference_std"]).to_string(index=False, float_format="%.4f")


# -- the recordings (notebooks 03-05) -------------------------------------------------------------
#: The files notebook 05 writes into its output folder that make the recordings' reference.
RECORDING_FILES = ("recording_errors.csv", "recording_errors.md", "comparisons.csv", "comparisons.md",
                   "paper_claims.csv", "paper_claims.md", "finetune_transfer.csv", "finetune_transfer.md")
#: Notebook 05's tables of the field recordings, installed beside them when it made them
#: (a profile with ``sequences: field_recordings:``), removed from the reference when it did not.
FIELD_RECORDING_FILES = ("field_gap.csv", "field_gap.md", "field_finetune_transfer.csv", "field_finetune_transfer.md",
                         "field_recovery.csv", "field_recovery.md", "field_comparisons.csv", "field_comparisons.md",
                         "field_paper_claims.csv", "field_paper_claims.md")
#: Notebook 05's tables of the ArUco markers' UAV2-in-UAV1, on the clean and on the
#: field recordings, installed the same way when the recordings had markers.
MARKER_RECORDING_FILES = ("markers.csv", "markers.md", "field_markers.csv", "field_markers.md")
_OPTIONAL_RECORDING_FILES = FIELD_RECORDING_FILES + MARKER_RECORDING_FILES


def install_recordings_reference(notebook_dir: str | Path, label: str, command: str,
                                 root: str | Path | None = None) -> Path:
    """Copy notebook 05's tables into ``results/<profile>/recordings/`` with a provenance file.

    Args:
        notebook_dir: notebook 05's output folder (``<run>/<profile>/05_airpose_plus``).
        command: the command that made them (recorded in ``provenance.json``).
    Raises:
        FileNotFoundError: a file of :data:`RECORDING_FILES` is missing (notebook 05 did not finish).
        ProvenanceError: the checkout ``root`` belongs to has changes (:func:`require_clean_checkout`).
    """
    src, dst = Path(notebook_dir), reference_dir(RunFolders.of(label), root) / "recordings"
    missing = [n for n in RECORDING_FILES if not (src / n).is_file()]
    if missing:
        raise FileNotFoundError(f"{src}: no {', '.join(missing)}; run notebook 05_airpose_plus first")
    require_clean_checkout(_checkout_of(root), reference_outputs(label))
    for name in RECORDING_FILES + tuple(n for n in _OPTIONAL_RECORDING_FILES if (src / n).is_file()):
        with atomic_path(dst / name) as tmp:
            shutil.copyfile(src / name, tmp)
    for name in _OPTIONAL_RECORDING_FILES:
        if not (src / name).is_file():
            (dst / name).unlink(missing_ok=True)  # a reference never mixes two runs' tables
    _write_text(dst / "provenance.json", json.dumps(provenance_record(label, command), indent=2, default=str) + "\n")
    return dst


def recordings_report(notebook_dir: str | Path, label: str, write: bool = False, command: str | None = None,
                      root: str | Path | None = None) -> str:
    """What ``airpose reproduce`` prints after notebook 05: the claims' verdicts that differ from
    the committed ``results/<profile>/recordings/paper_claims.csv`` (or the install, with ``write``)."""
    src, ref = Path(notebook_dir), reference_dir(RunFolders.of(label), root) / "recordings"
    if write:
        return f"reference: wrote {install_recordings_reference(src, label, command or '', root)}"
    new_path, old_path = src / "paper_claims.csv", ref / "paper_claims.csv"
    if not (new_path.is_file() and old_path.is_file()):
        return ""
    key = ["claim", "sequence", "measure"]  # a claim has one row per measure and sequence
    new, old = pd.read_csv(new_path), pd.read_csv(old_path)
    both = new.merge(old, on=key, how="outer", suffixes=("", "_reference"))
    changed = both[both["holds"].astype(str) != both["holds_reference"].astype(str)]
    if changed.empty:
        return f"reference: the {len(new)} recording claims have the same verdicts as {old_path}"
    lines = [f"reference: {len(changed)} of {len(new)} recording claims differ from {old_path}:"]
    lines += [f"  {r.claim} ({r.sequence}): {r.holds_reference} -> {r.holds}" for r in changed.itertuples()]
    return "\n".join(lines)
