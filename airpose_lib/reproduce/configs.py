"""A profile turned into typed configuration, once, at the entry: :func:`kit_configs`.

The ``airpose`` command, ``airpose reproduce`` and a notebook's set-up
(:func:`~airpose_lib.reproduce.notebook.setup_notebook`) call :func:`kit_configs` on the profile
they are given and pass the :class:`~airpose_lib.experiments.configs.KitConfigs` down: each
section read here into its package's config (``data: still:`` a
:class:`~airpose_lib.data.still.config.GenerationConfig`, ``train:`` a
:class:`~airpose_lib.train.config.TrainSection` ...), and the
:class:`~airpose_lib.paths.RunFolders` that name the profile's run, cache and results folders.
This module and :mod:`airpose_lib.profiles` are the only code that reads a profile's sections; the
library below takes the config it needs.
"""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from airpose_lib.errors import ProfileError, UserError
from airpose_lib.paths import RunFolders
from airpose_lib.profiles import PROFILES_DIR, loaded, profile_section, section_config, section_where

__all__ = ["kit_configs", "train_inputs"]


def kit_configs(profile: str | Path, folder: str | Path = PROFILES_DIR):
    """Every section of ``profile`` (a name, a YAML path, or a :class:`~airpose_lib.profiles.Profile`
    already read) as its typed config, with the profile's folders.

    A section the profile lacks or gets wrong is kept as the error its reading raised, and raised
    where it is used (:class:`~airpose_lib.experiments.configs.KitConfigs`).

    Returns:
        :class:`~airpose_lib.experiments.configs.KitConfigs`.
    Raises:
        ProfileError: no such profile, or a file that is not a profile.
    """
    # the configs' modules import torch (prior, fitting, training): imported when a profile is read,
    # so that `airpose --help` and `airpose reproduce`'s start stay light
    from airpose_lib.data.sequences.config import sequence_configs_from_profile
    from airpose_lib.data.sequences.presets import field_sequence_configs_from_profile
    from airpose_lib.data.still.config import GenerationConfig
    from airpose_lib.data.still.manifest import DatasetError
    from airpose_lib.experiments.configs import KitConfigs
    from airpose_lib.experiments.shipped import NetworksConfig
    from airpose_lib.finetune.config import FineTuneConfig
    from airpose_lib.fitting.airpose_plus import AirPosePlusConfig
    from airpose_lib.prior.build import PriorSetup
    from airpose_lib.prior.train import CorpusConfig, PriorTrainConfig
    from airpose_lib.train.config import train_section
    from airpose_lib.train.pretrain import PretrainSetup

    profile = loaded(profile, folder)
    folders, label = RunFolders.of(profile), str(profile)
    sections: dict[str, Any] = {}

    def read(name: str, make: Callable[[], Any]) -> None:
        try:
            sections[name] = make()
        except (UserError, TypeError, ValueError) as e:  # raised where the section is used
            sections[name] = e

    def still() -> GenerationConfig:
        try:  # the data commands report every unusable input as a DatasetError
            return section_config(profile, "data.still", GenerationConfig, required="the still-frame dataset sizes",
                                  build=GenerationConfig.from_dict, folder=folder)
        except ProfileError as e:  # before ValueError: it is one
            raise DatasetError(str(e)) from None
        except (TypeError, ValueError) as e:
            raise DatasetError(f"{profile.path}, `data: still:` section: {e}") from None

    def sequences(make):
        return lambda: make(profile_section(profile, "sequences", required="the recordings' sizes", folder=folder),
                            section_where(profile, "sequences", folder))

    def prior() -> PriorSetup:
        train, corpus = section_config(profile, "prior", (PriorTrainConfig, CorpusConfig), folder=folder)
        return PriorSetup(train, corpus, section_where(profile, "prior", folder), folders.prior, label)

    read("still", still)
    read("sequences", sequences(sequence_configs_from_profile))
    read("field_sequences", sequences(field_sequence_configs_from_profile))
    read("train", lambda: train_section(profile_section(profile, "train", folder=folder),
                                        section_where(profile, "train", folder)))
    read("pretrain", lambda: PretrainSetup(profile_section(profile, "pretrain", folder=folder),
                                           section_where(profile, "pretrain", folder),
                                           sections["still"] if not isinstance(sections["still"], BaseException)
                                           else None, folders, label))
    read("prior", prior)
    read("finetune", lambda: section_config(profile, "finetune", FineTuneConfig, folder=folder))
    read("fitting", lambda: section_config(profile, "fitting", AirPosePlusConfig, folder=folder))
    read("networks", lambda: None if "networks" not in profile.sections else section_config(
        profile, "networks", NetworksConfig, required="which profile's shipped networks", folder=folder))
    read("notebooks", lambda: dict(profile.sections.get("notebooks") or {}))
    read("others", lambda: _other_backbones(sections["train"], folder))
    sections["where"] = {name: section_where(profile, key, folder) for name, key in
                         (("still", "data.still"), ("sequences", "sequences"), ("train", "train"))}
    return KitConfigs(label, folders, sections)


def _other_backbones(train, folder: str | Path) -> dict:
    """name -> :class:`~airpose_lib.train.pretrain.PretrainSetup` of each profile that the
    ``train:`` section's ``pretrained: profile:<name>`` names (read here, at the entry, so that a
    training never opens a profile)."""
    if isinstance(train, BaseException):
        return {}
    from airpose_lib.train.pretrain import other_profile  # lazy: torch (see kit_configs)

    names = {other_profile(v.get("pretrained")) for v in (train.values, *train.variants.values())}
    return {name: other_backbone(name, folder) for name in sorted(n for n in names if n is not None)}


def other_backbone(name: str, folder: str | Path = PROFILES_DIR):
    """The :class:`~airpose_lib.train.pretrain.PretrainSetup` of profile ``name`` (``pretrained:
    profile:<name>``): its backbone for its own data."""
    return kit_configs(name, folder).pretrain


def train_inputs(configs, pretrained: str | None = None):
    """:class:`~airpose_lib.train.run.TrainInputs` of a profile's ``configs`` (a
    :class:`~airpose_lib.experiments.configs.KitConfigs`); ``pretrained``: a config's
    ``pretrained`` value (e.g. an option on the command line) whose ``profile:<name>`` the
    profile's section does not name, read here too."""
    return configs.train_inputs(extra_others=_extra_other(configs, pretrained))


def _extra_other(configs, pretrained: str | None) -> dict:
    from airpose_lib.train.pretrain import other_profile  # lazy: torch (see kit_configs)

    name = other_profile(pretrained)
    if name is None or (configs.has("others") and name in configs.sections["others"]):
        return {}
    return {name: other_backbone(name)}
