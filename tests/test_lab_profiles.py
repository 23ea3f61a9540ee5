"""The lab profiles (``airpose_lib/profiles/lab/``): each is ``inherits: cpu`` plus one change, and
every section the kit reads from it resolves into its config, so that the command of its entry in
``docs/findings.md`` runs on it."""
from __future__ import annotations

from pathlib import Path

import pytest

from airpose_lib.profiles import PROFILES_DIR, loaded, profile_names, read_profile

LAB = sorted((PROFILES_DIR / "lab").glob("*.yaml"))


def _readers():
    from airpose_lib.data.sequences.config import profile_sequences
    from airpose_lib.data.still.config import profile_config
    from airpose_lib.finetune.config import finetune_config
    from airpose_lib.fitting.airpose_plus import fitting_profile
    from airpose_lib.fitting.recording import fit_config
    from airpose_lib.prior.train import prior_profile
    from airpose_lib.train.config import load_train_config
    from airpose_lib.train.pretrain import pretrain_stages

    return [lambda p: [load_train_config(p, v) for v in ("baseline", "multiview", "fullcam", "airpose")],
            pretrain_stages, finetune_config, prior_profile, fitting_profile, fit_config, profile_config,
            profile_sequences]


def test_the_lab_folder_has_profiles_and_they_are_not_kit_profiles():
    assert {p.stem for p in LAB} >= {"cpu_backbone_seed1", "cpu_field_nomarkers", "cpu_tuning_paper_span"}
    assert not {p.stem for p in LAB} & set(profile_names())  # run by path, never by name


@pytest.mark.parametrize("path", LAB, ids=[p.stem for p in LAB])
def test_a_lab_profile_resolves_as_cpu_plus_its_change(path: Path):
    profile = loaded(str(path))
    assert profile.name == path.stem
    cpu, lab = read_profile("cpu"), read_profile(profile)
    assert set(lab) == set(cpu)
    changed = {s for s in cpu if lab[s] != cpu[s]} - {"description"}
    assert len(changed) == 1, f"{path.name} changes {sorted(changed)}: one change per lab profile"
    for reader in _readers():
        assert reader(profile) is not None
