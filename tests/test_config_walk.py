"""Every setting of every configuration, given wrong: generated from the config dataclasses.

For each profile section (and the typed config it becomes) and each of its fields, nested
dataclasses and the ``model:`` / ``data:`` / ``loss:`` options included, a value of the wrong
type, a value outside each bound the field declares (``config_fields.ranged``), a misspelt key and
a misspelt section go through a profile YAML of one's own (``inherits: smoke``) and, where the
command has one, through ``--set``. Each must end in exit status 2 and one line
``airpose: error: ...`` that names the profile file (or the ``--set`` key) and the setting, says
"did you mean" with the right key for a misspelling, and leaves no folder behind. The work a
command would do once its configuration is accepted is replaced by a stub that fails the case, so
an accepted bad value shows as such (and the test stays fast: in-process calls of ``cli.main``).
"""
from __future__ import annotations

import dataclasses
import subprocess
import sys
import types
import typing
from pathlib import Path

import pytest
import yaml

from airpose_lib import cli
from airpose_lib.config_fields import field_range, field_types
from airpose_lib.data.sequences.config import SequenceConfig
from airpose_lib.data.still.config import GenerationConfig
from airpose_lib.finetune.config import FineTuneConfig
from airpose_lib.fitting.airpose_plus import AirPosePlusConfig
from airpose_lib.prior.train import CorpusConfig, PriorTrainConfig
from airpose_lib.profiles import DATA_SECTIONS, SECTIONS
from airpose_lib.train import TrainConfig
from airpose_lib.train.config import option_types

ROOT = Path(__file__).resolve().parents[1]


class Accepted(Exception):
    """The command went on to its work: the bad setting was accepted."""


def _accepted(*args, **kwargs):
    raise Accepted


# section -> (config classes, argv of a command that reads it; P the profile file, O an output path,
# S a missing input: a command reads its configuration before its inputs), whether it has --set
COMMANDS = {
    "train": ((TrainConfig,), ["train", "--variant", "airpose", "--profile", "P", "--out", "O"], True),
    "pretrain": ((TrainConfig,), ["pretrain", "--profile", "P"], False),
    "data.still": ((GenerationConfig,), ["data", "generate", "--profile", "P", "--out", "O", "--quiet"], False),
    "sequences": ((SequenceConfig,), ["data", "sequence", "--profile", "P", "--out", "O", "--quiet"], False),
    "fitting": ((AirPosePlusConfig,), ["fit", "--sequence", "S", "--init", "S", "--profile", "P", "--out", "O"],
                False),
    "finetune": ((FineTuneConfig,), ["finetune", "--checkpoint", "S", "--sequence", "S", "--out", "O",
                                     "--profile", "P"], True),
    "prior": ((PriorTrainConfig, CorpusConfig), ["prior", "train", "--profile", "P", "--out", "O"], False),
}
# The stubs that stand for each command's work (reached only when the configuration is accepted).
WORK = ["airpose_lib.train.train", "airpose_lib.train.pretrain.ensure_still_dataset",
        "airpose_lib.data.still.generate.generate_still_dataset", "airpose_lib.data.sequences.ensure_sequences",
        "airpose_lib.finetune.train.finetune", "airpose_lib.prior.build.prior_corpus"]
# Where a `sequences:` setting goes: one recording's own settings win over the section's shared ones.
RECORDING = ("recordings", "person1")
# Fields a profile section does not set (the command or the kit fills them in).
NOT_IN_PROFILE = {"train": {"variant", "profile", "progress"}, "pretrain": {"variant", "task", "profile", "progress"},
                  "sequences": {"person", "cameras", "time_offsets", "markers"}}


def _options(annotation) -> tuple:
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        return typing.get_args(annotation)
    return (annotation,)


def _wrong_value(annotation):
    """A value of a type the annotation does not allow (None: every type is allowed)."""
    bases = {typing.get_origin(t) or t for t in _options(annotation)}
    if typing.Any in bases:
        return None
    if bases & {str, Path}:
        return {"x": 1} if not bases & {dict} else 1.5
    if bases & {int, float, bool, dict, list, tuple}:
        return "abc"
    return "abc" if all(isinstance(b, type) and dataclasses.is_dataclass(b) for b in bases - {type(None)}) else None


def _outside(annotation, rng) -> list:
    """Values just outside each bound of ``rng`` (an int field gets ints), NaN for a float one."""
    whole = int in _options(annotation) and float not in _options(annotation)
    step = 1 if whole else 0.5
    values = []
    if rng.ge is not None:
        values.append(rng.ge - step)
    if rng.gt is not None:
        values.append(rng.gt)
    if rng.le is not None:
        values.append(rng.le + step)
    if rng.lt is not None:
        values.append(rng.lt)
    return [int(v) if whole else float(v) for v in values] + ([] if whole else [float("nan")])


def _misspelt(name: str) -> str:
    return name + name[-1]


def _fields(cls, section: str) -> list[tuple[tuple[str, ...], typing.Any, object]]:
    """``(key path, annotation, range)`` of every field of ``cls`` a profile section sets, nested
    dataclass fields as deeper paths."""
    out = []
    skip = NOT_IN_PROFILE.get(section, set())
    for f in dataclasses.fields(cls):
        if f.name in skip:
            continue
        annotation = field_types(cls)[f.name]
        out.append(((f.name,), annotation, field_range(cls, f.name)))
        nested = [t for t in _options(annotation) if isinstance(t, type) and dataclasses.is_dataclass(t)]
        for sub in nested[:1]:
            out += [((f.name, *path), ann, rng) for path, ann, rng in _fields(sub, "")]
    return out


def _dict_options(section: str) -> list[tuple[tuple[str, ...], typing.Any, object]]:
    """The options of TrainConfig's dict fields (``model.dropout`` ...), with their ranges."""
    if section not in ("train", "pretrain"):
        return []
    task = "pretrain" if section == "pretrain" else "regressor"
    out = []
    for name in ("model", "loss") if section == "train" else ("model",):
        types_, ranges = option_types(name, task)
        out += [((name, key), ann, ranges.get(key)) for key, ann in types_.items()]
    return out


def _nest(path: tuple[str, ...], value) -> dict:
    for key in reversed(path):
        value = {key: value}
    return value


def _cases() -> list[tuple[str, str, dict | list, str, str]]:
    """``(id, section, profile settings or --set items, what the line must name, did-you-mean or "")``."""
    cases = []
    for section, (classes, _, has_set) in COMMANDS.items():
        seen = set()
        at = RECORDING if section == "sequences" else ()
        for cls in classes:
            for path, annotation, rng in _fields(cls, section) + _dict_options(section) * (cls is classes[0]):
                if path in seen:
                    continue
                seen.add(path)
                key = ".".join(path)
                wrong = _wrong_value(annotation)
                bad = [("type", wrong)] if wrong is not None else []
                bad += [("range", v) for v in (_outside(annotation, rng) if rng is not None else [])]
                for kind, value in bad:
                    cases.append((f"{section}:{key}:{kind}:{value!r}", section, _nest(at + path, value), path[-1], ""))
                    if has_set and len(path) <= 2:
                        item = f"{key}={yaml.safe_dump(value, default_flow_style=True).strip().removesuffix('...').strip()}"
                        cases.append((f"--set {section}:{key}:{kind}", section, [item], path[-1], ""))
                typo = _misspelt(path[-1])
                cases.append((f"{section}:{key}:misspelt", section, _nest((*at, *path[:-1], typo), 1), typo,
                              path[-1]))
                if has_set and len(path) <= 2:
                    cases.append((f"--set {section}:{key}:misspelt", section, [f"{'.'.join(path[:-1] + (typo,))}=1"],
                                  typo, path[-1]))
    return cases


CASES = _cases()
SECTION_CASES = [s for s in (*SECTIONS, *(f"data.{d}" for d in DATA_SECTIONS)) if s not in ("data", "inherits")]


@pytest.fixture
def walk(tmp_path, monkeypatch, capsys):
    """Runs one case: ``(section, settings or --set items) -> (exit status, stderr lines, profile file)``,
    asserting that no folder was made."""
    for target in WORK:
        monkeypatch.setattr(target, _accepted)
    monkeypatch.setenv("AIRPOSE_RUNS", str(tmp_path / "runs"))
    monkeypatch.setenv("AIRPOSE_CACHE", str(tmp_path / "cache"))

    def run(section: str, bad, top: dict | None = None) -> tuple[int, list[str], Path]:
        profile = tmp_path / "mine.yaml"
        settings = {"inherits": "smoke", **(top or {})}
        if isinstance(bad, dict) and top is None:
            settings.update(_nest(tuple(section.split(".")), bad))
        profile.write_text(yaml.safe_dump(settings))
        argv = [str(profile) if a == "P" else str(tmp_path / "out") if a == "O" else str(tmp_path / "missing")
                if a == "S" else a for a in COMMANDS[section][1]]
        if isinstance(bad, list):
            argv += ["--set", *bad]
        capsys.readouterr()
        try:
            code = cli.main(argv)
        except Accepted:
            code = "accepted"
        except SystemExit as e:  # argparse
            code = e.code
        err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
        made = sorted(p.name for p in tmp_path.iterdir() if p.name != "mine.yaml")
        assert not made, f"folders made: {made}; {err}"
        return code, err, profile

    return run


def _assert_one_line(code, err: list[str], *named: str) -> None:
    assert code == 2, f"exit {code}: {err}"
    assert len(err) == 1 and err[0].startswith("airpose: error: "), err
    for text in named:
        assert text in err[0], f"{text!r} not in {err[0]!r}"


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_every_bad_setting_is_one_line_naming_it(case, walk):
    name, section, bad, key, close = case
    code, err, profile = walk(section, bad)
    named = [key] + ([f"did you mean {close!r}"] if close else [])
    if isinstance(bad, dict):  # from the profile: the line names the file
        named.append(str(profile))
    _assert_one_line(code, err, *named)


@pytest.mark.parametrize("section", SECTION_CASES)
def test_a_misspelt_section_is_one_line_with_the_right_one(section, walk):
    """``trian: {steps: 5}`` used to be ignored: the command ran on the inherited ``train:``."""
    *parent, last = section.split(".")
    top = _nest(tuple(parent), {_misspelt(last): {}}) if parent else {_misspelt(last): {}}
    command = section if section in COMMANDS else "train"
    code, err, profile = walk(command, {}, top)
    _assert_one_line(code, err, str(profile), _misspelt(last), f"did you mean {last!r}")


NOTEBOOK_CASES = [
    ("misspelt notebook", {"00_body_modell": {"image_size": 3}}, "did you mean '00_body_model'"),
    ("misspelt parameter", {"00_body_model": {"image_sizee": 3}}, "did you mean 'image_size'"),
    ("wrong type", {"02_ablation_table": {"n_resamples": "many"}}, "n_resamples: expected int"),
]


@pytest.mark.parametrize("notebooks, says", [c[1:] for c in NOTEBOOK_CASES], ids=[c[0] for c in NOTEBOOK_CASES])
def test_notebook_parameters_are_checked_naming_the_profile(notebooks, says, tmp_path, capsys):
    profile = tmp_path / "mine.yaml"
    profile.write_text(yaml.safe_dump({"inherits": "smoke", "notebooks": notebooks}))
    for argv in (["reproduce", "--list"], ["reproduce", "--out", str(tmp_path / "runs"),
                                           "--figures", str(tmp_path / "figures")]):
        code = cli.main([*argv, "--profile", str(profile)])
        err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
        _assert_one_line(code, err, str(profile), says)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine.yaml"]


@pytest.mark.parametrize("argv, says", [
    (["train", "--variant", "airpose", "--set", "dropout=abc"], "did you mean 'model.dropout'"),
    (["train", "--variant", "airpose", "--set", "lrate=1e-4"], "did you mean 'lr'"),
    (["train", "--variant", "airpose", "--set", "model.dropout=1.5"], "model.dropout must be in [0, 1], got 1.5"),
    (["train", "--variant", "airpose", "--set", "data.roott=/tmp"], "did you mean 'root'"),
], ids=["dropout", "lrate", "dropout range", "data.roott"])
def test_the_reported_holes_are_one_line_in_a_real_process(argv, says, tmp_path):
    """The real exit status of the ``airpose`` process, no run folder made."""
    out = tmp_path / "out"
    res = subprocess.run([sys.executable, "-m", "airpose_lib", *argv, "--out", str(out)], capture_output=True,
                         text=True, timeout=120, cwd=ROOT, env={**__import__("os").environ,
                                                               "AIRPOSE_RUNS": str(tmp_path / "runs")})
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and says in res.stderr, res.stderr
    assert not out.exists() and not (tmp_path / "runs").exists()


def test_zz_the_walk_tried_every_config(capsys):
    """The walk's size, printed (``-s`` or the captured output of a failure shows it); a walk that
    found no fields would pass its cases trivially."""
    per_section = {}
    for _, section, *_ in CASES:
        per_section[section] = per_section.get(section, 0) + 1
    total = len(CASES) + len(SECTION_CASES) + len(NOTEBOOK_CASES)
    with capsys.disabled():
        print(f"\nconfiguration walk: {total} bad settings tried ({len(CASES)} field cases "
              f"{per_section}, {len(SECTION_CASES)} misspelt sections, {len(NOTEBOOK_CASES)} notebook cases)")
    assert set(per_section) == set(COMMANDS) and len(CASES) > 400
