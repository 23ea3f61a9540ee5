"""Appearance the networks never saw (``data.sequences.held_out``): each part
lies outside what the still-frame generator draws, by its sampling code and over many draws;
off, the recordings are the clean ones; the field preset and a profile's field recordings."""
from __future__ import annotations

import dataclasses
import hashlib
import json

import numpy as np
import pytest

from airpose_lib.data.sequences import (
    FIELD_PRESETS,
    HeldOutConfig,
    SequenceConfig,
    field_variant,
    sequence_configs_from_profile,
)
from airpose_lib.data.sequences.held_out import (
    HELD_OUT_GROUND_PHOTOS,
    held_out_appearance,
    held_out_betas,
    held_out_ground_photo,
)
from airpose_lib.data.sequences.markers import MarkerLayout
from airpose_lib.data.sequences.presets import field_sequence_configs_from_profile
from airpose_lib.data.still.appearance import (
    HELD_OUT_SATURATION,
    REGIONS,
    AppearanceConfig,
    held_out_clothing,
    held_out_clothing_color,
    sample_appearance,
    training_saturation_bound,
    vertex_colors,
)
from airpose_lib.data.still.scene import SceneConfig
from airpose_lib.errors import ConfigError, ProfileSettingError
from airpose_lib.paths import RunFolders
from airpose_lib.reproduce.configs import kit_configs


def _saturation(rgb: np.ndarray) -> np.ndarray:
    """HSV saturation ``(max - min) / max`` of ``(..., 3)`` colours (0 for black)."""
    rgb = np.asarray(rgb, dtype=np.float64)
    mx, mn = rgb.max(-1), rgb.min(-1)
    return np.where(mx > 0, (mx - mn) / np.where(mx > 0, mx, 1.0), 0.0)


# -- clothing -------------------------------------------------------------------------------------
@pytest.mark.parametrize("profile", ["smoke", "cpu", "cpu_paper_layout", "paper"])
def test_no_still_profile_can_draw_the_held_out_saturation(profile):
    bound = training_saturation_bound(kit_configs(profile).still.appearance)
    assert bound < HELD_OUT_SATURATION[0], (profile, bound)


def test_training_bound_by_hand():
    # 0.85 ** 1.3 (the clothing draw's largest saturation); skin and hair stay below it.
    assert training_saturation_bound() == pytest.approx(0.85 ** 1.3)
    assert 0.85 ** 1.3 == pytest.approx(0.80955, abs=1e-5)
    assert training_saturation_bound(AppearanceConfig(saturation_max=0.5)) == pytest.approx(0.55 / 0.70, abs=0.01)


def test_many_draws_never_meet():
    rng = np.random.default_rng(0)
    train = np.stack([sample_appearance(rng).region_colors for _ in range(20_000)])  # (N, 9, 3)
    held = np.stack([held_out_clothing_color(rng) for _ in range(20_000)])
    s_train, s_held = _saturation(train), _saturation(held)
    assert s_train.max() < training_saturation_bound() + 1e-12
    assert s_train.max() > 0.79  # the bound is reached, not just respected
    assert s_held.min() >= HELD_OUT_SATURATION[0] - 1e-12
    # Also as the stored uint8 vertex colours, with the shading folds (+-12 %) and rounding.
    regions = np.arange(len(REGIONS))
    verts = np.random.default_rng(1).normal(0, 0.4, (len(REGIONS), 3))
    lo = rng.uniform(size=(500, 3))
    train_u8 = np.concatenate([vertex_colors(sample_appearance(np.random.default_rng(i)), regions, verts + lo[i])
                               for i in range(500)])
    held_u8 = np.concatenate([vertex_colors(held_out_clothing(sample_appearance(np.random.default_rng(i)),
                                                              np.random.default_rng(10_000 + i)),
                                            regions, verts + lo[i])[[2, 3, 6]] for i in range(500)])
    assert _saturation(train_u8).max() < _saturation(held_u8).min()


def test_held_out_clothing_keeps_the_person():
    look = sample_appearance(np.random.default_rng(3))
    new = held_out_clothing(look, np.random.default_rng(0))
    changed = {"torso", "upper_arm", "thigh"} | ({"forearm"} if look.long_sleeves else set()) \
        | ({"shin"} if look.long_trousers else set())
    for i, name in enumerate(REGIONS):
        same = np.array_equal(new.region_colors[i], look.region_colors[i])
        assert same == (name not in changed), name
    assert (new.long_sleeves, new.long_trousers, new.bald, new.hairline) == \
        (look.long_sleeves, look.long_trousers, look.bald, look.hairline)
    off = held_out_appearance(look, HeldOutConfig(clothing=True), 3)  # not enabled: unchanged
    assert off is look
    on = held_out_appearance(look, HeldOutConfig(enabled=True, clothing=True), 3)
    assert on.region_colors[REGIONS.index("torso")].tolist() != look.region_colors[REGIONS.index("torso")].tolist()


# -- ground ---------------------------------------------------------------------------------------
def test_held_out_ground_is_no_training_texture():
    from airpose_lib.data.still.render import TRAINING_GROUND_PHOTOS, ground_textures

    bank = ground_textures()
    names = [n for n, _ in bank]
    assert set(TRAINING_GROUND_PHOTOS) <= set(names)  # skimage is installed: the bank has them
    assert not set(HELD_OUT_GROUND_PHOTOS) & set(names)
    photo = held_out_ground_photo("moon")
    assert photo.shape == (512, 512) and photo.dtype == np.uint8
    # Not one of the bank's images either, in any of the four quarter turns (normalised
    # correlation of the 256 px versions; a texture with itself gives 1).
    import cv2

    small = cv2.resize(photo.astype(np.float64), (256, 256), interpolation=cv2.INTER_AREA)
    z = (small - small.mean()) / small.std()
    for name, img in bank:
        t = (img - img.mean()) / img.std()
        assert max(abs((np.rot90(z, k) * t).mean()) for k in range(4)) < 0.3, name
    assert HELD_OUT_GROUND_PHOTOS["moon"] * 512 == pytest.approx(5.12)  # one tile, metres
    with pytest.raises(ValueError, match="moon"):
        held_out_ground_photo("grass")


# -- body shape -----------------------------------------------------------------------------------
def test_held_out_betas_leave_the_training_box():
    betas = np.array([0.8, 0.4, -0.3, 0.2, 0.0, -0.2, 0.1, 0.0, 0.1, -0.1])
    out = held_out_betas(betas, HeldOutConfig(enabled=True, betas_max=3.5))
    assert np.abs(out).max() == pytest.approx(3.5)
    # Beyond every still profile's clip (the draw is np.clip(N(0, std), -beta_clip, beta_clip)).
    assert all(3.5 > kit_configs(p).still.scene.beta_clip for p in ("smoke", "cpu", "cpu_paper_layout", "paper"))
    assert SceneConfig().beta_clip == 3.0
    np.testing.assert_allclose(out / np.linalg.norm(out), betas / np.linalg.norm(betas))  # same direction
    np.testing.assert_array_equal(held_out_betas(betas, HeldOutConfig(betas_max=3.5)), betas)  # not enabled


# -- the option in the recordings' config -----------------------------------------------------------
def _key(cfg: SequenceConfig) -> str:
    return hashlib.sha256(json.dumps(cfg.to_dict(), sort_keys=True).encode()).hexdigest()[:16]


def test_off_keeps_the_recordings_keys_and_on_round_trips():
    assert _key(SequenceConfig()) == "8c759625ec8a5cb0"  # as tests/test_data_field.py
    assert "held_out" not in SequenceConfig(held_out=HeldOutConfig(clothing=True, ground="moon")).to_dict()
    on = SequenceConfig(held_out=HeldOutConfig(enabled=True, clothing=True, ground="moon", betas_max=3.5))
    d = json.loads(json.dumps(on.to_dict()))
    assert d["held_out"]["ground"] == "moon"
    back = SequenceConfig.from_dict(d)
    assert back.held_out == on.held_out and json.loads(json.dumps(back.to_dict())) == d
    recs = sequence_configs_from_profile({"held_out": {"enabled": True, "clothing": True},
                                          "recordings": {"person1": {"n_frames": 10}}})
    assert recs["person1"].held_out == HeldOutConfig(enabled=True, clothing=True)
    with pytest.raises(ProfileSettingError, match="ground"):
        sequence_configs_from_profile({"held_out": {"ground": "grass"}, "recordings": {"person1": {}}})
    with pytest.raises(ProfileSettingError, match="did you mean 'clothing'"):
        sequence_configs_from_profile({"held_out": {"clotting": True}, "recordings": {"person1": {}}})


@pytest.mark.parametrize("profile", ["smoke", "cpu"])
def test_profile_field_recordings_are_the_clean_ones_through_the_preset(profile):
    clean, field = kit_configs(profile).sequences, kit_configs(profile).field_sequences
    assert list(field) == list(clean) == ["person1", "person2"]
    cam, held = FIELD_PRESETS["dji"]
    for name, c in clean.items():
        f = field[name]
        assert f.field == cam and f.held_out == held and cam.enabled and held.enabled
        # markers on the field twins only (`field_markers: {}`); nothing else differs
        assert f.markers == MarkerLayout() and c.markers is None
        assert dataclasses.replace(f, field=c.field, held_out=c.held_out, markers=None) == c
        assert _key(f) != _key(c)
    assert held.clothing and held.ground == "moon" and held.betas_max is None


def test_field_recordings_setting():
    section = {"recordings": {"person1": {"n_frames": 5}}}
    assert field_sequence_configs_from_profile(section) == {}
    assert kit_configs("paper").field_sequences == {}
    with pytest.raises(ProfileSettingError, match="unknown preset 'gopro'"):
        field_sequence_configs_from_profile({**section, "field_recordings": "gopro"})
    with pytest.raises(ConfigError, match="unknown field preset"):
        field_variant(SequenceConfig(), "gopro")
    # markers on the field twins: a layout's settings, checked like every section's
    twins = field_sequence_configs_from_profile({**section, "field_recordings": "dji", "field_markers": {"side_m": 0.5}})
    assert twins["person1"].markers == MarkerLayout(side_m=0.5)
    assert sequence_configs_from_profile({**section, "field_markers": {}})["person1"].markers is None
    for bad, match in (({"field_markers": {}}, "needs `field_recordings"),
                       ({"field_recordings": "dji", "field_markers": True}, "marker layout's settings"),
                       ({"field_recordings": "dji", "field_markers": {"side": 1}}, "did you mean 'side_m'")):
        with pytest.raises(ProfileSettingError, match=match):
            field_sequence_configs_from_profile({**section, **bad})
    # every recording's `markers:` goes through the same rule
    assert sequence_configs_from_profile({**section, "markers": {}})["person1"].markers == MarkerLayout()
    for bad, match in ((True, "marker layout's settings"), ({"side": 1}, "did you mean 'side_m'")):
        with pytest.raises(ProfileSettingError, match=match):
            sequence_configs_from_profile({**section, "markers": bad})


def test_renderer_applies_the_option_only_when_on(open_model_files):
    from airpose_lib.data.sequences import SequenceRenderer, simulate_sequence

    cfg = SequenceConfig(person="person2", n_frames=3, seed=2, render_scale=0.25, anti_aliasing=False)

    def render(held: HeldOutConfig):
        sim = simulate_sequence(dataclasses.replace(cfg, held_out=held))
        with SequenceRenderer(sim) as r:
            return sim, r.colors, r.environment, next(r.render_frames([1]))[1]

    sim0, colors0, env0, clean = render(HeldOutConfig())
    _, _, _, off = render(HeldOutConfig(clothing=True, ground="moon", betas_max=3.5))
    sim1, colors1, env1, on = render(HeldOutConfig(enabled=True, clothing=True, ground="moon", betas_max=3.5))
    for v in range(2):
        np.testing.assert_array_equal(off[v], clean[v])
        assert np.abs(on[v].astype(int) - clean[v]).mean() > 10  # another ground
    # The person's clothes are vivid, their skin is not.
    assert _saturation(colors1 / 255.0).max() >= 0.88 > _saturation(colors0 / 255.0).max()
    assert env1.ground_tile == pytest.approx(5.12) and env1.distractors[0].position.tolist() == \
        env0.distractors[0].position.tolist()
    assert np.abs(sim1.gt["betas"]).max() == pytest.approx(3.5)


def test_ensure_sequences_makes_the_field_recordings_in_their_own_folder(tmp_path, monkeypatch):
    from airpose_lib.data.sequences import cache

    monkeypatch.setenv("AIRPOSE_CACHE", str(tmp_path))
    made = {}

    def fake_generate(config, root, progress=False):
        made[root.name] = config
        root.mkdir(parents=True)

    monkeypatch.setattr(cache, "generate_sequence", fake_generate)
    smoke = kit_configs("smoke")
    out = cache.ensure_sequences(smoke.recordings(field=True), smoke.folders.sequences(field=True))
    assert out == {n: tmp_path / "data" / "sequences_smoke_field" / n for n in ("person1", "person2")}
    assert made == {f"{n}.partial": c for n, c in kit_configs("smoke").field_sequences.items()}
    assert RunFolders.of("smoke").sequences() == tmp_path / "data" / "sequences_smoke"
    with pytest.raises(ConfigError, match="no field recordings"):
        kit_configs("paper").recordings(field=True)


def test_cli_makes_the_field_recordings_or_says_there_are_none(tmp_path, monkeypatch, capsys):
    from airpose_lib import cli
    from airpose_lib.data.sequences import cache

    made = []
    monkeypatch.setattr(cache, "generate_sequence", lambda config, root, progress=False: (made.append(config),
                                                                                         root.mkdir(parents=True)))
    assert cli.main(["data", "sequence", "--profile", "smoke", "--field", "--quiet", "--out", str(tmp_path)]) == 0
    assert made == list(kit_configs("smoke").field_sequences.values())
    capsys.readouterr()
    assert cli.main(["data", "sequence", "--profile", "paper", "--field", "--out", str(tmp_path / "p")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("airpose: error:") and "paper.yaml, section `sequences:` has no field recordings" in err[0]
