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
    """An empty profile file, or one without the section a command reads, used to run
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
    from airpose_lib.reproduce.configs import kit_configs

    def load_train_config(path, variant):
        return kit_configs(path).train.config(variant)

    path = tmp_path / "mine.yaml"
    path.write_text("train:\n  steps: thirty\n")
    with pytest.raises(ConfigError, match=r"mine\.yaml, section `train:`: steps: expected int, got 'thirty'"):
        load_train_config(path, "airpose")
    path.write_text("train:\n  stepz: 3\n")
    with pytest.raises(ConfigError, match=r"mine\.yaml, section `train:`: unknown key 'stepz'.*did you mean 'steps'"):
        load_train_config(path, "airpose")
    path.write_text("train:\n  lr: .inf\n")
    with pytest.raises(ConfigError, match=r"mine\.yaml.*lr must be > 0"):
        load_train_config(path, "airpose")


def test_errors_name_the_file_and_the_fix(tmp_path):
    with pytest.raises(ProfileError, match=r"unknown profile 'nope' \(no .*nope\.yaml\); "
                                           r"available: cpu, cpu_paper_layout, demo, paper, smoke"):
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


def _with_key(tmp_path, section: str, key: str, value) -> object:
    """The smoke profile with ``key: value`` added to ``section`` (dots go deeper)."""
    import yaml

    raw = read_profile("smoke")
    target = raw
    for part in section.split("."):
        target = target[part]
    target[key] = value
    path = tmp_path / "mine.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


def _helpers():
    from airpose_lib.fitting.recording import fit_config
    from airpose_lib.reproduce.configs import kit_configs
    from airpose_lib.train.pretrain import pretrain_config

    # (what reads the section from the typed configs, section, a misspelt key, the field it should
    # suggest, the section as messages name it)
    return [
        (lambda p: kit_configs(p).train.config("airpose"), "train", "stepz", "steps", "train:"),
        (lambda p: pretrain_config(kit_configs(p).pretrain), "pretrain", "stepz", "steps", "pretrain:"),
        (lambda p: kit_configs(p).finetune, "finetune", "stepz", "steps", "finetune:"),
        (lambda p: kit_configs(p).prior, "prior", "n_posez", "n_poses", "prior:"),
        (lambda p: kit_configs(p).fitting, "fitting", "iterationz", "iterations", "fitting:"),
        (lambda p: fit_config(kit_configs(p).fitting), "fitting", "iterationz", "iterations", "fitting:"),
        (lambda p: kit_configs(p).still, "data.still", "num_samplez", "num_samples", "data: still:"),
        (lambda p: kit_configs(p).sequences, "sequences", "fpz", "fps", "sequences:"),
    ]


@pytest.mark.parametrize("case", range(8))
def test_every_section_reader_names_an_unknown_key_the_file_and_the_closest_key(tmp_path, case):
    """The eight section-to-config readers (at the entry, reproduce.configs) share one check (profiles.section_config /
    config_fields.config_from): the file, the section, the key and the closest known one."""
    from airpose_lib.errors import ConfigError, UserError

    helper, section, key, close, label = _helpers()[case]
    path = _with_key(tmp_path, section, key, 1)
    with pytest.raises(UserError) as e:
        helper(path)
    message = str(e.value)
    assert str(path) in message and f"`{label}" in message, message
    assert f"unknown key {key!r}" in message and f"did you mean {close!r}" in message, message
    if section != "data.still":  # the data commands report it as their DatasetError
        assert isinstance(e.value, ProfileError) and isinstance(e.value, ConfigError)
    assert helper("smoke") is not None  # the kit's profile itself is fine


def test_a_bad_value_in_a_section_names_the_file_and_a_bad_option_the_options(tmp_path):
    from airpose_lib.errors import ConfigError, ProfileSettingError
    from airpose_lib.finetune.config import finetune_config
    from airpose_lib.reproduce.configs import kit_configs

    path = _with_key(tmp_path, "finetune", "steps", "thirty")
    with pytest.raises(ProfileSettingError, match=r"mine\.yaml, section `finetune:`: steps: expected int"):
        assert kit_configs(path).finetune is None  # raises first
    with pytest.raises(ConfigError, match=r"^fine-tuning options: unknown key 'stepz'"):
        finetune_config(kit_configs("smoke").finetune, stepz=3)
    prior = kit_configs(_with_key(tmp_path, "prior", "seed", 7)).prior
    train, corpus = prior.train, prior.corpus
    assert train.seed == 7 and corpus.seed == 7  # a key of both configs goes to each


def test_a_profile_inherits_another_mapping_by_mapping(tmp_path):
    (tmp_path / "base.yaml").write_text("description: base\ntrain:\n  steps: 3\n  lr: 0.1\n"
                                        "data:\n  still:\n    seed: 0\n    scene: {focal: 1.0, num_views: 2}\n"
                                        "finetune:\n  steps: 5\nnotebooks:\n  a: {x: [1, 2]}\n")
    (tmp_path / "child.yaml").write_text("inherits: base\ndescription: child\ntrain:\n  steps: 4\n"
                                         "data:\n  still:\n    scene: {focal: 2.0}\nfinetune:\n"
                                         "notebooks:\n  a: {x: [3]}\n")
    child = read_profile("child", folder=tmp_path)
    assert child == {"description": "child", "train": {"steps": 4, "lr": 0.1},
                     "data": {"still": {"seed": 0, "scene": {"focal": 2.0, "num_views": 2}}},
                     "finetune": None, "notebooks": {"a": {"x": [3]}}}  # lists and empty sections replace
    assert profile_section("child", "finetune", folder=tmp_path) == {}
    assert read_profile(tmp_path / "child.yaml", folder=tmp_path) == child
    assert read_profile("base", folder=tmp_path)["train"] == {"steps": 3, "lr": 0.1}  # the parent unchanged
    (tmp_path / "mine.yaml").write_text("inherits: child.yaml\ntrain: {lr: 0.2}\n")  # a path beside the file
    assert read_profile(tmp_path / "mine.yaml", folder=tmp_path)["train"] == {"steps": 4, "lr": 0.2}


def test_a_bad_inheritance_names_the_file(tmp_path):
    (tmp_path / "a.yaml").write_text("inherits: b\ntrain: {}\n")
    (tmp_path / "b.yaml").write_text("inherits: a\n")
    with pytest.raises(ProfileError, match=r"a\.yaml: `inherits: b` comes back to .*b\.yaml"):
        read_profile("b", folder=tmp_path)
    (tmp_path / "c.yaml").write_text("inherits: [a, b]\n")
    with pytest.raises(ProfileError, match=r"c\.yaml: `inherits:` must name one profile"):
        read_profile("c", folder=tmp_path)
    (tmp_path / "d.yaml").write_text("inherits: nope\n")
    with pytest.raises(ProfileError, match=r"unknown profile 'nope'"):
        read_profile("d", folder=tmp_path)


def test_the_paper_layout_profile_is_cpu_on_other_data():
    cpu, paper = read_profile("cpu"), read_profile("cpu_paper_layout")
    assert set(paper) == set(cpu)
    for section in set(cpu) - {"data", "description", "train", "notebooks"}:
        assert paper[section] == cpu[section], section
    # notebook 02 with fewer seeds, every other notebook parameter cpu's
    ablation = {k: v for k, v in paper["notebooks"]["02_ablation_table"].items() if k != "seeds"}
    assert ablation == {k: v for k, v in cpu["notebooks"]["02_ablation_table"].items() if k != "seeds"}
    assert set(paper["notebooks"]["02_ablation_table"]["seeds"]) <= set(cpu["notebooks"]["02_ablation_table"]["seeds"])
    assert {k: v for k, v in paper["notebooks"].items() if k != "02_ablation_table"} == \
        {k: v for k, v in cpu["notebooks"].items() if k != "02_ablation_table"}
    assert paper["train"] == {**cpu["train"], "pretrained": "profile:cpu"}  # cpu's backbone
    assert {k: v for k, v in paper["data"]["still"].items() if k != "scene"} == cpu["data"]["still"]


def test_a_profile_read_once_is_passed_down_and_later_edits_do_not_reach_it(tmp_path):
    import copy
    import json
    import pickle

    import yaml

    from airpose_lib.data.still.config import GenerationConfig
    from airpose_lib.profiles import Profile, loaded, section_config

    path = tmp_path / "mine.yaml"
    path.write_text("data:\n  still:\n    num_samples: 40\n    seed: 3\nnotebooks: {}\n")
    prof = loaded(str(path))
    assert isinstance(prof, Profile) and prof == str(path) and prof.name == "mine" and prof.path == path
    assert loaded(prof) is prof  # not read again
    before = prof.digest
    path.write_text("data:\n  still:\n    num_samples: 99\n    seed: 3\nnotebooks: {}\n")
    # the reading passed down, not the file as it is now
    assert section_config(prof, "data.still", GenerationConfig).num_samples == 40
    assert profile_section(prof, "data.still") == {"num_samples": 40, "seed": 3}
    assert section_config(str(path), "data.still", GenerationConfig).num_samples == 99
    assert loaded(str(path)).digest != before and loaded(prof).digest == before
    # a reader's copy is its own
    read_profile(prof)["data"]["still"]["num_samples"] = 0
    assert prof.sections["data"]["still"]["num_samples"] == 40
    # it is the string it was given as: records and paths are unchanged, plain strings
    assert json.dumps({"profile": prof}) == json.dumps({"profile": str(path)})
    assert yaml.safe_dump({"profile": prof}) == yaml.safe_dump({"profile": str(path)})
    assert type(str(prof)) is str and (tmp_path / prof).name == "mine.yaml"
    # pickled (to a worker, into a checkpoint) or copied it is the plain string: loads without the class
    for back in (pickle.loads(pickle.dumps(prof)), copy.deepcopy(prof)):
        assert type(back) is str and back == str(path)


def test_a_kit_profile_by_name_reads_as_the_name():
    from airpose_lib.profiles import loaded

    prof = loaded("smoke")
    assert prof == "smoke" and prof.name == "smoke" and prof.path == PROFILES_DIR / "smoke.yaml"
    assert prof.sections == read_profile("smoke")


def test_a_command_reads_its_profile_once_and_passes_the_reading_down(monkeypatch):
    import airpose_lib.cli as cli
    from airpose_lib.profiles import Profile

    seen = []
    parser = cli.build_parser()
    parse = parser.parse_args

    def recording(argv):
        args = parse(argv)
        args.func = lambda a: seen.append(a.profile)
        return args

    monkeypatch.setattr(parser, "parse_args", recording)
    monkeypatch.setattr(cli, "build_parser", lambda: parser)
    assert cli.main(["data", "generate", "--profile", "smoke"]) == 0
    assert isinstance(seen[0], Profile) and seen[0] == "smoke" and seen[0].sections == read_profile("smoke")


def test_a_profile_given_as_a_file_names_its_folders_by_its_stem(tmp_path, monkeypatch):
    """A profile file outside the kit (e.g. results/cpu/selection/cpu_more.yaml) gets one folder
    per cache and run kind, named as a kit profile's would be: not a tree under its path."""
    from airpose_lib.eval.reference import reference_dir
    from airpose_lib.paths import RunFolders, profile_name
    from airpose_lib.prior import build
    from airpose_lib.prior.checkpoint import kit_prior_path
    from airpose_lib.profiles import loaded
    from airpose_lib.reproduce.configs import kit_configs

    monkeypatch.setenv("AIRPOSE_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("AIRPOSE_RUNS", str(tmp_path / "runs"))
    monkeypatch.setattr(build, "prior_is_current", lambda path, p: path == kit_prior_path("cpu_more"))  # no training
    path = tmp_path / "results" / "cpu" / "selection" / "cpu_more.yaml"
    path.parent.mkdir(parents=True)
    path.write_text("inherits: smoke\n")
    for given in (str(path), loaded(str(path))):
        assert profile_name(given) == "cpu_more"
        folders = kit_configs(given).folders
        assert folders == RunFolders.of(given) == RunFolders("cpu_more")
        assert folders.sequences() == tmp_path / "cache" / "data" / "sequences_cpu_more"
        assert folders.sequences(field=True) == tmp_path / "cache" / "data" / "sequences_cpu_more_field"
        assert folders.recordings(field=True) == tmp_path / "runs" / "recordings" / "cpu_more_field"
        assert folders.still == tmp_path / "cache" / "data" / "still_cpu_more"
        assert folders.train("airpose", 7) == tmp_path / "runs" / "train" / "cpu_more" / "airpose" / "seed7"
        assert build.ensure_prior(kit_configs(given).prior) == kit_prior_path("cpu_more")  # it used to raise on the path
        assert reference_dir(folders).name == "cpu_more"
    assert profile_name("cpu") == "cpu" and RunFolders.of("cpu").sequences().name == "sequences_cpu"
