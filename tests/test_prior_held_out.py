"""The pose prior's held-out motions: the corpus never contains a pose of the
activities a profile holds out, those are the activities of its recordings, and the prior's
record says so."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from airpose_lib.data.sequences.motions import ACTIVITIES, sample_script
from airpose_lib.data.sequences.simulate import recording_script
from airpose_lib.data.still.poses import sample_body_pose
from airpose_lib.errors import ConfigError
from airpose_lib.prior.build import motion_poses, prior_corpus, prior_is_current, train_and_save_prior
from airpose_lib.prior.checkpoint import load_prior
from airpose_lib.prior.train import CorpusConfig
from airpose_lib.reproduce.configs import kit_configs

CPU_HELD_OUT = ("walk", "reach", "squat", "stand", "bend", "turn", "twist")


def test_sample_script_without_exclusion_is_unchanged():
    # exclude=() must leave the draws alone: the recordings' scripts (and frames) stay the same.
    for seed in range(5):
        a = sample_script(np.random.default_rng(seed), 40.0, "twisting")
        b = sample_script(np.random.default_rng(seed), 40.0, "twisting", exclude=())
        assert a == b


def test_sample_script_never_draws_an_excluded_activity():
    held = {"walk", "twist", "reach"}
    seen = set()
    for seed in range(30):
        script = sample_script(np.random.default_rng(seed), 60.0, exclude=held)
        acts = {s.activity for s in script.segments}
        assert not acts & held
        seen |= acts
    assert seen == set(ACTIVITIES) - held  # the others are still drawn
    with pytest.raises(ValueError, match="unknown"):
        sample_script(np.random.default_rng(0), 10.0, exclude={"jump"})
    with pytest.raises(ValueError, match="leaves no activity"):
        sample_script(np.random.default_rng(0), 10.0, exclude=set(ACTIVITIES))


def test_prior_corpus_has_no_pose_of_a_held_out_activity():
    corpus = CorpusConfig(n_poses=50, n_motion_poses=600, seed=3, held_out_motions=CPU_HELD_OUT)
    poses = prior_corpus(corpus, 0, 50, 600)
    assert poses.shape == (650, 21, 3)
    # The same draws by hand: the still poses, then the motion poses from the same stream.
    rng = np.random.default_rng([3, 0])
    np.testing.assert_array_equal(poses[:50], sample_body_pose(rng, 50).astype(np.float32))
    theta, share = motion_poses(rng, 600, corpus.motion_fps, CPU_HELD_OUT)
    np.testing.assert_array_equal(poses[50:], theta.astype(np.float32))
    np.testing.assert_allclose(share.sum(1), 1.0)
    held = [ACTIVITIES.index(a) for a in CPU_HELD_OUT]
    kept = [i for i in range(len(ACTIVITIES)) if i not in held]
    assert (share[:, held] == 0).all()  # not even in a cross-fade
    assert (share[:, kept].max(0) == 1).all()  # wave and arms fill the motion part
    # Without the setting the same stream does draw them (so the check above can fail).
    _, share_all = motion_poses(np.random.default_rng(0), 600, corpus.motion_fps)
    assert (share_all[:, held].max(0) > 0).sum() >= 5


def test_unchanged_corpus_without_held_out_motions():
    # The default leaves the record, hence every cached prior, as before.
    d = CorpusConfig().to_dict()
    assert "held_out_motions" not in d
    assert CorpusConfig(held_out_motions=("twist",)).to_dict()["held_out_motions"] == ["twist"]


@pytest.mark.parametrize("profile", ["cpu", "smoke"])
def test_profile_holds_out_every_activity_of_its_recordings(profile):
    corpus = kit_configs(profile).prior.corpus
    shown = {s.activity for c in kit_configs(profile).sequences.values() for s in recording_script(c).segments}
    assert shown <= set(corpus.held_out_motions), shown - set(corpus.held_out_motions)
    assert set(corpus.held_out_motions) < set(ACTIVITIES)  # motion poses remain to train on
    if profile == "cpu":
        assert set(corpus.held_out_motions) == set(CPU_HELD_OUT)


def test_bad_held_out_motions_name_the_profile(tmp_path):
    prof = tmp_path / "p.yaml"
    prof.write_text("prior:\n  steps: 1\n  held_out_motions: [twirl]\n")
    with pytest.raises(ConfigError, match="p.yaml.*twirl"):
        train_and_save_prior(kit_configs(str(prof)).prior, tmp_path / "prior.pt")


def test_record_states_the_held_out_motions(tmp_path, monkeypatch):
    monkeypatch.setenv("AIRPOSE_CACHE", str(tmp_path / "cache"))
    prof = tmp_path / "p.yaml"
    prof.write_text("prior:\n  steps: 2\n  batch_size: 16\n  kl_anneal_steps: 1\n  n_poses: 40\n"
                    "  n_motion_poses: 40\n  n_val: 20\n  w_joints: 0.0\n  log_every: 1\n"
                    "  held_out_motions: [twist, walk]\n")
    path, report = train_and_save_prior(kit_configs(str(prof)).prior, tmp_path / "prior.pt")
    _, prov = load_prior("kit", path, return_provenance=True)
    assert prov["corpus"]["held_out_motions"] == ["twist", "walk"]
    assert report["train_poses"] == 80
    assert prior_is_current(path, kit_configs(str(prof)).prior)
    # A profile with another corpus (here none held out) does not take this prior as its own.
    other = tmp_path / "q.yaml"
    other.write_text(prof.read_text().replace("  held_out_motions: [twist, walk]\n", ""))
    assert not prior_is_current(path, kit_configs(str(other)).prior)
    assert dataclasses.asdict(kit_configs(str(other)).prior.corpus)["held_out_motions"] == ()
