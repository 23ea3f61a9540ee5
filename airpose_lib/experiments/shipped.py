"""A profile that runs on another profile's shipped networks (``networks: {shipped: cpu}``).

Such a profile trains nothing: notebook 02 evaluates the shipped variants on the profile's own,
freshly rendered test split, notebooks 03-05 run the shipped fine-tuned networks and prior on its
recordings, and every table is compared with the shipping profile's committed reference
(``results/<shipped>/``) within tolerances (:mod:`airpose_lib.eval.agreement`).
:mod:`airpose_lib.experiments.zoo_build` makes the set.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import pandas as pd

from airpose_lib.eval.ablation import VARIANT_LABELS
from airpose_lib.eval.agreement import agreement_message, recordings_agreement, write_check
from airpose_lib.eval.reference import reference_dir
from airpose_lib.paths import RunFolders
from airpose_lib.train.evaluate import evaluate_features
from airpose_lib.zoo import kit_checkpoint, read_manifest, verified, zoo_dir

__all__ = ["NetworksConfig", "shipped_from", "ShippedNetworks", "shipped_networks", "shipped_ablation_tables",
           "recordings_check", "recordings_reference_dir", "TUNED", "REBUILD"]

#: Recording methods of notebooks 03-05 -> the manifest entry of their network (``{field}``: the
#: field recordings' fine-tuning adds ``_field``).
TUNED = {"Baseline (pre-trained)": "baseline", "AirPose (pre-trained)": "airpose",
         "Baseline": "baseline_tuned{field}", "AirPose": "airpose_tuned{field}"}
#: The command that rebuilds a profile's set.
REBUILD = "airpose zoo build --profile {profile}"


@dataclass(frozen=True)
class NetworksConfig:
    """The profile section ``networks:``.

    Attributes:
        shipped: the profile whose shipped networks this profile runs instead of training its own.
        folder: where they are (default ``results/<shipped>/networks/``).
    """

    shipped: str
    folder: str | None = None

    @property
    def folders(self) -> RunFolders:
        """The folders of the profile that made the networks (its ``results/<shipped>/``)."""
        return RunFolders.of(self.shipped)


def shipped_from(networks: NetworksConfig | None) -> str | None:
    """The profile whose shipped networks a profile with the ``networks:`` section ``networks``
    runs on (None: it trains its own)."""
    return None if networks is None else networks.shipped


@dataclass(frozen=True)
class ShippedNetworks:
    """A verified set of shipped networks, as kit checkpoints (made in the cache on first use).

    Attributes:
        profile: the profile that made them.
        folder: ``results/<profile>/networks``.
        seed: the training seed of the variants.
    """

    profile: str
    folder: Path
    seed: int

    @cached_property
    def backbone(self) -> Path:
        """The backbone file, verified once per set (every regressor is joined with it)."""
        return verified(self.folder, "backbone")

    def checkpoint(self, name: str) -> Path:
        """The kit checkpoint of manifest entry ``name`` (a regressor on the shipped backbone)."""
        return kit_checkpoint(verified(self.folder, name), self.backbone)

    def variant(self, variant: str) -> Path:
        return self.checkpoint(variant)

    def recordings(self, field: bool = False) -> dict[str, Path]:
        """method -> checkpoint for :func:`airpose_lib.experiments.recordings.run_recording_experiment`."""
        return {m: self.checkpoint(name.format(field="_field" if field else "")) for m, name in TUNED.items()}

    @property
    def prior(self) -> Path:
        return verified(self.folder, "prior")


def shipped_networks(networks: NetworksConfig | None) -> ShippedNetworks | None:
    """The shipped set a profile with the ``networks:`` section ``networks`` runs on (None when it
    trains its own), verified lazily file by file (:func:`airpose_lib.zoo.verified`)."""
    cfg = networks
    if cfg is None:
        return None
    folder = Path(cfg.folder) if cfg.folder is not None else zoo_dir(cfg.folders)
    seed = int(read_manifest(folder)["airpose"]["seed"])
    return ShippedNetworks(cfg.shipped, folder, seed)


def shipped_ablation_tables(nets: ShippedNetworks, data_root: str | Path, variants, max_samples: int | None = None
                            ) -> dict[str, dict]:
    """variant -> evaluation tables of the shipped network on ``data_root``'s test split (jittered
    crops, and ``per_view_tight`` on the tight-box crops)."""
    out = {}
    for variant in variants:
        ckpt = nets.variant(variant)
        tables = evaluate_features(ckpt, nets.backbone, data_root, VARIANT_LABELS[variant], max_samples=max_samples)
        tables["per_view_tight"] = evaluate_features(ckpt, nets.backbone, data_root, VARIANT_LABELS[variant],
                                                     crops="tight", max_samples=max_samples)["per_view"]
        out[variant] = (ckpt, tables)
    return out


def recordings_reference_dir(folders: RunFolders, networks: NetworksConfig | None) -> Path:
    """The recordings' reference of a profile on shipped networks: its own
    ``results/<profile>/recordings/`` when committed, else the shipping profile's.

    A median over a recording's frames depends on which frames (on the cpu recordings a 200-frame
    span's medians differ from the 900-frame ones by more than the tolerance), and a 200-frame
    render is another motion than the first 200 frames of a 900-frame one (its script is drawn
    for its own length). So a profile that renders shorter recordings keeps its own reference,
    made by the same networks on the same recordings from a clean commit
    (``airpose reproduce --profile P --only 05 --write-reference``); it then measures what another
    machine's render and kernels change.
    """
    own = reference_dir(folders) / "recordings"
    if (own / "recording_errors.csv").is_file() or networks is None:
        return own
    return reference_dir(networks.folders) / "recordings"


def recordings_check(folders: RunFolders, networks: NetworksConfig | None, errors: pd.DataFrame, field_markers: pd.DataFrame | None = None, *,
                     compare: bool = True, out: str | Path | None = None) -> tuple[pd.DataFrame | None, str]:
    """UAV2 in UAV1 on this profile's recordings against their reference
    (:func:`recordings_reference_dir`): the clean recordings' error table and the field
    recordings' marker table (rows against the generated cameras), AirPose and AirPose+.

    Returns:
        the comparison (None when the profile trains its own networks: ``airpose reproduce``
        compares those with ``results/<profile>/recordings/``) and a line saying what it shows;
        with ``out`` both also go to ``<out>/reference_check.md``.
    """
    rows, message = _recordings_check(folders, networks, errors, field_markers, compare)
    if out is not None:
        write_check(out, message, rows)
    return rows, message


def _recordings_check(folders: RunFolders, networks: NetworksConfig | None, errors: pd.DataFrame, field_markers: pd.DataFrame | None, compare: bool
                      ) -> tuple[pd.DataFrame | None, str]:
    source = shipped_from(networks)
    if not compare:
        return None, "no comparison with a reference: this profile's networks train a few steps"
    if source is None:
        return None, "networks trained here: `airpose reproduce` compares the recordings' claims with the reference"
    ref = recordings_reference_dir(folders, networks)
    parts = {"clean recordings": recordings_agreement(errors, pd.read_csv(ref / "recording_errors.csv"))}
    if field_markers is not None and not field_markers.empty and (ref / "field_markers.csv").is_file():
        cameras = lambda t: t[t["reference"] == "generated cameras"]  # noqa: E731
        parts["field recordings"] = recordings_agreement(cameras(field_markers),
                                                         cameras(pd.read_csv(ref / "field_markers.csv")))
    rows = pd.concat([v.assign(recordings=k) for k, v in parts.items() if not v.empty], ignore_index=True) \
        if any(not v.empty for v in parts.values()) else pd.DataFrame()
    return rows, agreement_message(parts, ref)
