"""A profile's configuration, typed once at the entry: :class:`KitConfigs`.

The command line, ``airpose reproduce`` and a notebook's set-up turn the profile they are given
into one :class:`KitConfigs` (:func:`airpose_lib.reproduce.configs.kit_configs`): every section as
its package's typed config, and the :class:`~airpose_lib.paths.RunFolders` that name the run,
cache and results folders. An experiment takes that object; the library below it takes the one
config it needs (a :class:`~airpose_lib.data.still.config.GenerationConfig`, a
:class:`~airpose_lib.finetune.config.FineTuneConfig` ...) or plain values, and never reads a
profile.

A section the profile lacks, or one it gets wrong, is kept as the error reading it raised, and
raised where the section is used: a command that does not use it runs as before (``airpose
train`` with a profile that has no ``fitting:``).
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from airpose_lib.paths import RunFolders

if TYPE_CHECKING:  # the types only: the configs' modules import torch
    from airpose_lib.data.sequences.config import SequenceConfig
    from airpose_lib.data.still.config import GenerationConfig
    from airpose_lib.finetune.config import FineTuneConfig
    from airpose_lib.fitting.airpose_plus import AirPosePlusConfig
    from airpose_lib.prior.build import PriorSetup
    from airpose_lib.train.config import TrainSection
    from airpose_lib.train.pretrain import PretrainSetup
    from airpose_lib.train.run import TrainInputs

    from .shipped import NetworksConfig

__all__ = ["KitConfigs", "SECTION_NAMES"]

#: The keys of :attr:`KitConfigs.sections`.
SECTION_NAMES = ("still", "sequences", "field_sequences", "train", "pretrain", "prior", "finetune", "fitting",
                 "networks", "notebooks", "others", "where")


@dataclass(frozen=True)
class KitConfigs:
    """Every section of one profile as a typed config, and its folders.

    Attributes:
        label: how records, captions and messages name the profile (``"cpu"``, or the path of a
            profile file of one's own). A label, never read back.
        folders: the profile's run, cache and results folders.
        sections: section -> its typed config, or the error its reading raised (raised again by
            the property that gives it); ``where``: how messages name a section (its file).
            Use the properties.
    """

    label: str
    folders: RunFolders
    sections: Mapping[str, Any]

    def _get(self, name: str):
        value = self.sections[name]
        if isinstance(value, BaseException):
            raise value.with_traceback(None)
        return value

    def has(self, name: str) -> bool:
        """Whether the section ``name`` was read without an error."""
        return not isinstance(self.sections.get(name), BaseException)

    @property
    def still(self) -> GenerationConfig:
        """``data: still:``, the still-frame dataset."""
        return self._get("still")

    @property
    def sequences(self) -> dict[str, SequenceConfig]:
        """``sequences:``, the recordings (name -> config)."""
        return self._get("sequences")

    def recordings(self, field: bool = False) -> dict[str, SequenceConfig]:
        """The recordings, or (``field``) their field twins; a profile without field recordings
        raises then."""
        if not field:
            return self.sequences
        twins = self.field_sequences
        if not twins:
            from airpose_lib.data.sequences.presets import FIELD_PRESETS  # lazy: the configs' modules import torch
            from airpose_lib.errors import ConfigError

            where = self.sections.get("where", {}).get("sequences", f"profile {self.label}, section `sequences:`")
            raise ConfigError(f"{where} has no field recordings; add "
                              f"`field_recordings: <preset>` (presets: {', '.join(FIELD_PRESETS)})")
        return twins

    @property
    def field_sequences(self) -> dict[str, SequenceConfig]:
        """The field twins of the recordings (``sequences: field_recordings:``; ``{}``: none)."""
        return self._get("field_sequences")

    @property
    def train(self) -> TrainSection:
        """``train:``, the trainings (a config per variant and seed: ``train.config(variant, seed)``)."""
        return self._get("train")

    @property
    def pretrain(self) -> PretrainSetup:
        """``pretrain:``, the shared backbone's stages (with the dataset they pretrain on)."""
        return self._get("pretrain")

    @property
    def prior(self) -> PriorSetup:
        """``prior:``, the kit's pose prior (with its file)."""
        return self._get("prior")

    @property
    def finetune(self) -> FineTuneConfig:
        """``finetune:``, the fine-tuning on recordings."""
        return self._get("finetune")

    @property
    def fitting(self) -> AirPosePlusConfig:
        """``fitting:``, AirPose+."""
        return self._get("fitting")

    @property
    def networks(self) -> NetworksConfig | None:
        """``networks:``, another profile's shipped networks (None: the profile trains its own)."""
        return self._get("networks")

    @property
    def notebooks(self) -> dict[str, dict]:
        """``notebooks:``, each notebook's parameters."""
        return self._get("notebooks")

    def train_inputs(self, extra_others: Mapping[str, Any] | None = None) -> TrainInputs:
        """What the profile's trainings need besides their configs
        (:class:`~airpose_lib.train.run.TrainInputs`): the ``train:`` section, the still-frame
        dataset, the backbone, those of the profiles ``pretrained: profile:<name>`` names (and
        ``extra_others``), the folders."""
        from airpose_lib.train.run import TrainInputs  # lazy: training imports torch

        return TrainInputs(section=self.train, still=self.still if self.has("still") else None,
                           folders=self.folders, pretrain=self.pretrain if self.has("pretrain") else None,
                           others={**self._get("others"), **(extra_others or {})})
