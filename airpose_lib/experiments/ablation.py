"""Notebook 02, Table I: the four variants trained and evaluated, the mean-body references, the
claims, and the qualitative figures' inputs.

:func:`run_ablation_experiment` trains and evaluates the variants on the kit's data
(:func:`airpose_lib.train.ablation.run_ablation`) or, with the official data source, evaluates the
authors' checkpoints on the official synthetic test split (:func:`airpose_lib.train.official.official_ablation`);
what differs between the two (the seeds, the test split, no mean-body reference on the official
data, the caption) is settled here so that the notebook reads the same for both.
:func:`ablation_references`, :func:`ablation_claims` and :func:`write_ablation_bundle` time their
step into the experiment's ``wall``, which the results bundle records.
The qualitative figures' inputs are :mod:`airpose_lib.experiments.ablation_samples`'s.
"""
from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from airpose_lib.assets import DataSource
from airpose_lib.data.official.synthetic import OfficialSyntheticDataset
from airpose_lib.data.still.dataset import StillFrameDataset, split_arrays
from airpose_lib.data.still.generate import ensure_still_dataset
from airpose_lib.eval.ablation import VARIANT_LABELS, per_seed_table
from airpose_lib.eval.agreement import agreement_message, claims_agreement, table_agreement, write_check
from airpose_lib.eval.mean_body import STATURE_FIT_SUBJECTS, mean_body_references
from airpose_lib.eval.reference import (
    check_against_reference,
    read_reference_table,
    reference_dir,
    train_settings,
    train_wall_s,
    write_reference,
)
from airpose_lib.eval.significance import claims_table
from airpose_lib.train.ablation import AblationRun, run_ablation
from airpose_lib.train.official import official_ablation

from .configs import KitConfigs
from .shipped import ShippedNetworks, shipped_ablation_tables, shipped_networks

__all__ = ["AblationExperiment", "run_ablation_experiment", "ablation_references", "ablation_claims",
           "write_ablation_bundle", "ablation_reference_dir", "reference_check"]


@dataclass
class AblationExperiment:
    """The trained (or official) networks of Table I, evaluated on a test split.

    Attributes:
        profile: how captions and records name the reproduction profile (a label).
        source: ``"generated"`` (the kit's networks on its data) or ``"official"`` (the
            authors' checkpoints on the official synthetic test split).
        variants: variant names, in table order.
        seeds: the seeds trained (for the official checkpoints: the seeded jitter draws of the test crops).
        runs: (variant, seed) -> ``AblationRun`` (checkpoint and evaluation tables).
        test: the test split (``StillFrameDataset`` or ``OfficialSyntheticDataset``).
        wall: step name -> wall time in seconds, recorded in the results bundle.
        shipped: the shipped networks evaluated (None: trained here, or the official ones).
        data_root: the kit's still-frame dataset (None: the official data).
    """

    profile: str
    source: str
    variants: list[str]
    seeds: list[int]
    runs: dict
    test: object
    wall: dict[str, float] = field(default_factory=dict)
    shipped: ShippedNetworks | None = None
    data_root: Path | None = None

    @property
    def official(self) -> bool:
        return self.source == "official"

    @property
    def per_view(self) -> dict:
        """(variant, seed) -> per-view evaluation table on the test split."""
        return {k: r.tables["per_view"] for k, r in self.runs.items()}

    @property
    def per_view_tight(self) -> dict:
        """(variant, seed) -> the same on tight-box crops, None where the run has none."""
        return {k: r.tables.get("per_view_tight") for k, r in self.runs.items()}

    def train_wall(self) -> dict:
        """(variant, seed) -> training wall time in seconds (None if unknown)."""
        return train_wall_s(self.runs)

    def runs_table(self) -> pd.DataFrame:
        """One row per network: variant, seed, checkpoint, test size, tight-box table, training time."""
        wall = self.train_wall()
        return pd.DataFrame([{"variant": r.variant, "seed": r.seed, "checkpoint": str(r.checkpoint),
                              "test images x views": len(r.tables["per_view"]),
                              "tight-box table": "per_view_tight" in r.tables, "training wall [s]": wall[k]}
                             for k, r in self.runs.items()])

    def per_seed(self) -> pd.DataFrame:
        """:func:`~airpose_lib.eval.ablation.per_seed_table` with the training times."""
        return per_seed_table(self.per_view, self.per_view_tight, wall_s=self.train_wall(), camera0=self.official)

    def caption(self) -> str:
        """Caption of the kit's Table I: which networks on which data."""
        if self.official:
            what = "the official checkpoints on the official synthetic test split"
        elif self.shipped is not None:
            what = (f"the '{self.shipped.profile}' profile's shipped networks (seed {self.shipped.seed}) on the test "
                    f"split of profile '{self.profile}', rendered on this machine")
        else:
            what = f"the kit's networks on its own data, profile '{self.profile}', seeds {list(self.seeds)}"
        return f"Table I reproduced by the kit: {what}; paper columns from Saini et al. (RA-L 2022), Table I."

    def few_steps_warning(self, compare_reference: bool = True) -> str | None:
        """The warning the numbers of networks trained a few steps need (None otherwise): the
        profile says so with ``compare_reference: false`` (the notebook's parameter), whatever its
        name."""
        if not compare_reference and not self.official:
            return "FEW-STEP NUMBERS: a few dozen training steps; they only show that the pipeline runs."
        return None


def run_ablation_experiment(configs: KitConfigs, source: DataSource, variants: Sequence[str], seeds: Sequence[int],
                            eval_max_samples: int | None = None, workers: int = 1,
                            progress: bool = True) -> AblationExperiment:
    """Train (resuming finished runs) and evaluate every variant for every seed, or evaluate the
    official checkpoints when ``source`` is official.

    Args:
        configs: the profile's configs (its ``train:`` settings, still-frame data, ``networks:``).
        source: the resolved data source (needs ``official_synthetic`` and ``official_checkpoints``).
        variants, seeds: what to train (the official run has one network per variant, seed 0).
        eval_max_samples: evaluate on at most this many test samples (None: all).
        workers: runs trained at once.
    """
    t0 = time.perf_counter()
    shipped = shipped_networks(configs.networks) if source.source != "official" else None
    root = None
    if shipped is not None:  # another profile's networks on this profile's fresh test split
        root = ensure_still_dataset(configs.still, configs.folders.still, label=configs.label, progress=progress)
        evaluated = shipped_ablation_tables(shipped, root, variants, max_samples=eval_max_samples)
        runs = {(v, shipped.seed): AblationRun(v, shipped.seed, ckpt, tables) for v, (ckpt, tables) in evaluated.items()}
        seeds, test = [shipped.seed], StillFrameDataset(root, "test")
    elif source.source == "official":  # the paper's own networks on the paper's own test split
        runs = official_ablation(source.roots["official_checkpoints"], source.roots["official_synthetic"],
                                 variants=variants, max_samples=eval_max_samples, backbone=None)
        seeds = sorted({k for _, k in runs})  # the jitter draws of the test crops (official protocol)
        test = OfficialSyntheticDataset(source.roots["official_synthetic"], "test")
    else:
        runs = run_ablation(configs.train_inputs(), variants=variants, seeds=seeds, eval_max_samples=eval_max_samples,
                            workers=workers, progress=progress)
        root = configs.folders.still
        test = StillFrameDataset(root, "test")
    wall = {"train and evaluate": time.perf_counter() - t0}
    return AblationExperiment(configs.label, source.source, list(variants), list(seeds), runs, test, wall, shipped,
                              root)


def ablation_reference_dir(configs: KitConfigs) -> Path:
    """The committed reference notebook 02 compares with: ``results/<profile>/``, or for a
    profile on shipped networks, that of the profile that made them."""
    networks = configs.networks
    return reference_dir(networks.folders if networks is not None else configs.folders)


def reference_check(exp: AblationExperiment, table: pd.DataFrame, claims: pd.DataFrame, ref_dir: str | Path,
                    compare: bool = True, out: str | Path | None = None) -> tuple[pd.DataFrame | None, str]:
    """This run against the committed reference in ``ref_dir``.

    On shipped networks: every variant's MPE, MPJPE and root median within the tolerances of
    :mod:`airpose_lib.eval.agreement`, and every claim's verdict the reference's. On networks
    trained here: each variant mean against the reference's seed spread
    (:func:`~airpose_lib.eval.reference.check_against_reference`). ``compare=False``: no comparison
    (a profile whose networks train a few steps checks that the code runs, not numbers).

    Returns:
        the comparison table (None without one) and a line saying what it shows; with ``out``
        both are also written to ``<out>/reference_check.md`` (:func:`~airpose_lib.eval.agreement.write_check`).
    """
    rows, message = _reference_check(exp, table, claims, Path(ref_dir), compare)
    if out is not None:
        write_check(out, message, rows)
    return rows, message


def _reference_check(exp: AblationExperiment, table: pd.DataFrame, claims: pd.DataFrame, ref_dir: Path,
                     compare: bool) -> tuple[pd.DataFrame | None, str]:
    if not compare:
        return None, ("no comparison with a reference: this profile's networks train a few steps, so its numbers "
                      "only show that every step of the pipeline runs")
    if exp.shipped is None:
        return check_against_reference(exp.per_seed(), ref_dir)
    reference = read_reference_table(ref_dir)
    if reference is None or not (ref_dir / "claims.csv").is_file():
        return None, f"no reference in {ref_dir}"
    per_view = {VARIANT_LABELS[v]: t for (v, _), t in exp.per_view.items()}
    parts = {"Table I values": table_agreement(table, reference, per_view),
             "claim verdicts": claims_agreement(claims, pd.read_csv(Path(ref_dir) / "claims.csv"))}
    rows = pd.concat([parts["Table I values"],
                      parts["claim verdicts"].rename(columns={"claim": "method", "verdict": "this run",
                                                              "reference verdict": "reference"})
                      .assign(quantity="verdict")], ignore_index=True)
    return rows, agreement_message(parts, ref_dir)


def ablation_references(exp: AblationExperiment, max_samples: int | None = None) -> pd.DataFrame | None:
    """:func:`~airpose_lib.eval.mean_body.mean_body_references` on the kit's test split: the
    neutral and the true-gender mean body, and the subject's body at the stature its proportions
    predict, the stature model fitted on the training split's subjects (None on the official data,
    whose arrays they do not read)."""
    t0 = time.perf_counter()
    references = None
    if not exp.official:
        train = split_arrays(exp.data_root, "train", ("beta", "gender"), STATURE_FIT_SUBJECTS)
        references = mean_body_references(exp.test.arrays, max_samples=max_samples, train_arrays=train)
    exp.wall["mean-body references"] = time.perf_counter() - t0
    return references


def ablation_claims(exp: AblationExperiment, n_resamples: int = 2000) -> pd.DataFrame:
    """:func:`~airpose_lib.eval.significance.claims_table` of the experiment's per-view errors."""
    t0 = time.perf_counter()
    claims = claims_table(exp.per_view, n_resamples=n_resamples)
    exp.wall["claims"] = time.perf_counter() - t0
    return claims


def write_ablation_bundle(exp: AblationExperiment, folder: str | Path, *, table: pd.DataFrame,
                          claims: pd.DataFrame, references: pd.DataFrame | None,
                          eval_max_samples: int | None = None) -> Path:
    """The run's results bundle (:func:`~airpose_lib.eval.reference.write_reference`), with every
    step's wall time, each network's training time and the device and precision it trained with."""
    steps = {**exp.wall, **{f"train {v} seed {s}": w for (v, s), w in exp.train_wall().items()}}
    training = {f"{v} seed {s}": t for (v, s), t in train_settings(exp.runs).items()}
    return write_reference(folder, table=table, per_seed=exp.per_seed(), claims=claims, references=references,
                           label=exp.profile,
                           command=f"airpose reproduce --profile {exp.profile} --only 02_ablation_table",
                           step_wall_s=steps, extra={"seeds": list(exp.seeds), "variants": list(exp.variants),
                                                     "data_source": exp.source,
                                                     "eval_max_samples": eval_max_samples,
                                                     "training": training})
