"""The lab profiles (``airpose_lib/profiles/lab/``): each is ``inherits: cpu`` plus one change, and
every section the kit reads from it resolves into its config, so that the command of its entry in
``docs/findings.md`` runs on it."""
from __future__ import annotations

from pathlib import Path

import pytest

from airpose_lib.profiles import PROFILES_DIR, loaded, profile_names, read_profile

LAB = sorted((PROFILES_DIR / "lab").glob("*.yaml"))


def _readers():
    from airpose_lib.fitting.recording import fit_config
    from airpose_lib.reproduce.configs import kit_configs
    from airpose_lib.train.pretrain import pretrain_stages

    return [lambda p: [kit_configs(p).train.config(v) for v in ("baseline", "multiview", "fullcam", "airpose")],
            lambda p: pretrain_stages(kit_configs(p).pretrain), lambda p: kit_configs(p).finetune,
            lambda p: kit_configs(p).prior, lambda p: kit_configs(p).fitting,
            lambda p: fit_config(kit_configs(p).fitting), lambda p: kit_configs(p).still,
            lambda p: kit_configs(p).sequences]


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
