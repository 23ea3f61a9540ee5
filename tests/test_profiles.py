"""The profile reader (airpose_lib.profiles): where the files live, sections, one-line errors."""
import pytest

from airpose_lib.errors import ProfileError
from airpose_lib.profiles import PROFILES_DIR, profile_names, profile_path, profile_section, read_profile


def test_the_kits_profiles_are_found_by_name_and_by_path():
    assert {"smoke", "cpu", "paper"} <= set(profile_names())
    assert profile_path("smoke") == PROFILES_DIR / "smoke.yaml"
    by_name = read_profile("cpu")
    assert read_profile(PROFILES_DIR / "cpu.yaml") == by_name
    assert {"data", "train", "notebooks"} <= set(by_name)
    still = profile_section("paper", "data.still")
    assert still == by_name_section("paper", "data", "still") and still["crop_size"] == 224


def by_name_section(name, *keys):
    value = read_profile(name)
    for k in keys:
        value = value[k]
    return value


def test_sections_are_copies_and_empty_ones_take_the_defaults(tmp_path):
    path = tmp_path / "p.yaml"
    path.write_text("train:\n  steps: 3\nfitting:\ndata:\n  still: {}\n")
    section = profile_section(path, "train")
    section["steps"] = 99
    assert profile_section(path, "train") == {"steps": 3}
    assert profile_section(path, "fitting") == {} and profile_section(path, "data.still") == {}
    assert profile_names(tmp_path) == ["p"] and profile_section("p", "train", folder=tmp_path) == {"steps": 3}


def test_an_empty_file_or_a_missing_section_is_an_error_not_the_defaults(tmp_path):
    """Issue 33: an empty profile file, or one without the section a command reads, used to run
    silently on the defaults."""
    (tmp_path / "empty.yaml").write_text("")
    with pytest.raises(ProfileError, match=r"empty\.yaml is empty"):
        read_profile(tmp_path / "empty.yaml")
    path = tmp_path / "p.yaml"
    path.write_text("train:\n  steps: 3\n")
    with pytest.raises(ProfileError, match=r"p\.yaml has no `finetune:` section; add one"):
        profile_section(path, "finetune")
    with pytest.raises(ProfileError, match=r"p\.yaml has no `data: still:` section"):
        profile_section(path, "data.still")


def test_a_bad_value_or_key_in_a_profile_names_the_file_and_the_field(tmp_path):
    from airpose_lib.errors import ConfigError
    from airpose_lib.train import load_train_config

    path = tmp_path / "mine.yaml"
    path.write_text("train:\n  steps: thirty\n")
    with pytest.raises(ConfigError, match=r"mine\.yaml, section `train:`: steps: expected int, got 'thirty'"):
        load_train_config(path, "airpose")
    path.write_text("train:\n  stepz: 3\n")
    with pytest.raises(ConfigError, match=r"mine\.yaml, section `train:`: unknown key 'stepz'.*did you mean 'steps'"):
        load_train_config(path, "airpose")
    path.write_text("train:\n  lr: .inf\n")
    with pytest.raises(ConfigError, match=r"mine\.yaml.*lr must be a finite number > 0"):
        load_train_config(path, "airpose")


def test_errors_name_the_file_and_the_fix(tmp_path):
    with pytest.raises(ProfileError, match=r"unknown profile 'nope' \(no .*nope\.yaml\); available: cpu, paper, smoke"):
        read_profile("nope")
    with pytest.raises(ValueError, match="missing.yaml does not exist"):  # a ValueError, as before
        profile_section(tmp_path / "missing.yaml", "train")
    path = tmp_path / "p.yaml"
    path.write_text("train: 3\n")
    with pytest.raises(ProfileError, match=r"p\.yaml: `train:` must be a mapping"):
        profile_section(path, "train")
    with pytest.raises(ProfileError, match=r"p\.yaml has no `data: still:` section \(the sizes\); add one"):
        profile_section(path, "data.still", required="the sizes")
    path.write_text("- a list\n")
    with pytest.raises(ProfileError, match="must be a YAML mapping"):
        read_profile(path)
    path.write_text("train: [unclosed\n")
    with pytest.raises(ProfileError, match="not valid YAML"):
        read_profile(path)


def test_the_command_reports_a_profile_error_in_one_line():
    from airpose_lib.cli import user_error_message

    try:
        profile_section("smoke", "nope", required="the nope settings")
    except ProfileError as e:
        message = user_error_message(e)  # printed as `airpose: error: ...`, exit status 2
    assert message.startswith(f"{PROFILES_DIR / 'smoke.yaml'} has no `nope:` section (the nope settings)")
