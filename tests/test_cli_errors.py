"""One error policy for the `airpose` command: every user mistake (a missing, truncated or foreign
file, an output folder that cannot be created) ends in one line naming the file and the fix, exit
status 2, no traceback; `--debug` adds the traceback."""
from __future__ import annotations

import pickle
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from airpose_lib import cli

ROOT = Path(__file__).resolve().parents[1]


def _truncate(path: Path) -> Path:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    return path


@pytest.fixture(scope="module")
def inputs(module_tmp) -> dict[str, Path]:
    """A tiny recording, a truncated copy of it, a truncated checkpoint and .npz, and paths that
    do not exist or cannot be created."""

    tmp = module_tmp("inputs")
    seq = _recording(tmp / "seq")
    bad_seq = tmp / "bad_seq"
    shutil.copytree(seq, bad_seq)
    _truncate(bad_seq / "machine_1" / "openpose_res.pkl")
    short_seq = tmp / "short_seq"  # detections of frame 0 only
    shutil.copytree(seq, short_seq)
    pkl = short_seq / "machine_1" / "openpose_res.pkl"
    with open(pkl, "rb") as fh:
        res = pickle.load(fh)
    with open(pkl, "wb") as fh:
        pickle.dump({k: v for k, v in res.items() if int(k) == 0}, fh)
    ckpt = tmp / "last.pt"
    torch.save({"model": {"w": torch.zeros(1000)}, "step": 3}, ckpt)
    _truncate(ckpt)
    good_ckpt = _good_checkpoint(tmp / "good")
    good_npz = tmp / "good_pred.npz"
    np.savez(good_npz, phi=np.zeros((3, 2, 3, 3)), tau=np.zeros((3, 2, 3)), theta=np.zeros((3, 2, 21, 3, 3)),
             beta=np.zeros((3, 2, 10)))
    npz = tmp / "pred.npz"
    np.savez(npz, phi=np.zeros((3, 2, 3, 3)), tau=np.zeros((3, 2, 3)))
    _truncate(npz)
    a_file = tmp / "a_file"
    a_file.write_text("not a folder")
    run = tmp / "run"  # a training run whose last checkpoint was cut short
    (run / "checkpoints").mkdir(parents=True)
    shutil.copy(ckpt, run / "checkpoints" / "last.pt")
    data = tmp / "data"  # a dataset folder whose manifest was cut short
    data.mkdir()
    (data / "manifest.yaml").write_text("kind: airpose-still-frames\nshards: [{index: 0, file: ")
    return {"seq": seq, "bad_seq": bad_seq, "short_seq": short_seq, "ckpt": ckpt, "good_ckpt": good_ckpt, "npz": npz, "good_npz": good_npz, "missing": tmp / "does_not_exist",
            "uncreatable": a_file / "sub", "run": run, "data": data, "tmp": tmp}


def _recording(seq: Path) -> Path:
    """A recording of three blank 96x64 frames from two views, with detections, in ``seq``."""
    from airpose_lib.data.sequences.writer import OfficialLayoutWriter

    w = OfficialLayoutWriter(seq, num_views=2)
    for i in range(3):
        w.write_frame(i, [np.zeros((64, 96, 3), np.uint8)] * 2)
    K = np.array([[[100.0, 0, 48], [0, 100.0, 32], [0, 0, 1]]] * 2)
    kps = {"openpose": np.full((3, 2, 25, 3), 0.5), "alphapose": np.full((3, 2, 18, 3), 0.5)}
    w.finish(K, kps)
    return seq


def _good_checkpoint(folder: Path) -> Path:
    """An untrained AirPose checkpoint in the engine's format (what `airpose train` writes)."""
    from airpose_lib.engine.checkpoint import save_checkpoint
    from airpose_lib.model import build_model
    from airpose_lib.train import TrainConfig

    torch.manual_seed(0)
    cfg = TrainConfig(variant="airpose", backbone="resnet18", steps=0)
    return save_checkpoint(folder, {"model": build_model("airpose", "resnet18").state_dict(), "optimizer": {},
                                    "rng": [], "step": 0, "epoch": 0, "batch_in_epoch": 0, "config": cfg.to_dict(),
                                    "world_size": 1, "input_size": 64}, keep=0)


def _node(*extra: str) -> list[str]:
    return ["node", "--id", "1", "--port", "5999", "--backend", "torch", "--insecure", *extra]


# (name, argv from the inputs, the path the message must name)
MISSING = [
    ("eval --checkpoint", lambda p: ["eval", "--checkpoint", p["missing"]], "missing"),
    ("fit --sequence", lambda p: ["fit", "--sequence", p["missing"], "--init", p["npz"]], "missing"),
    ("fit --init", lambda p: ["fit", "--sequence", p["seq"], "--init", p["missing"]], "missing"),
    ("fit --prior-path", lambda p: ["fit", "--sequence", p["seq"], "--init", p["npz"], "--prior-path",
                                    p["missing"]], "missing"),
    ("finetune --checkpoint", lambda p: ["finetune", "--checkpoint", p["missing"], "--sequence", p["seq"],
                                         "--out", p["tmp"] / "ft"], "missing"),
    ("finetune --sequence", lambda p: ["finetune", "--checkpoint", p["ckpt"], "--sequence", p["missing"],
                                       "--out", p["tmp"] / "ft"], "missing"),
    ("predict --checkpoint", lambda p: ["predict", "--checkpoint", p["missing"], "--sequence", p["seq"],
                                        "--out", p["tmp"] / "pred_out.npz"], "missing"),
    ("predict --sequence", lambda p: ["predict", "--checkpoint", p["ckpt"], "--sequence", p["missing"],
                                      "--out", p["tmp"] / "pred_out.npz"], "missing"),
    ("prior info --path", lambda p: ["prior", "info", "--path", p["missing"]], "missing"),
    ("node --source", lambda p: _node("--source", p["missing"]), "missing"),
    ("node --checkpoint", lambda p: _node("--checkpoint", p["missing"]), "missing"),
    ("node --onnx-dir", lambda p: _node("--backend", "onnx", "--onnx-dir", p["missing"]), "missing"),
    ("launch --source", lambda p: ["launch", "--source", p["missing"], "--out", p["tmp"] / "online"], "missing"),
    ("launch --checkpoint", lambda p: ["launch", "--checkpoint", p["missing"], "--out", p["tmp"] / "online"],
     "missing"),
    ("data verify --root", lambda p: ["data", "verify", "official_real", "--root", p["uncreatable"]],
     "uncreatable"),
    # outputs that cannot be created (a file where a folder should be)
    ("train --out", lambda p: ["train", "--variant", "airpose", "--out", p["uncreatable"]], "uncreatable"),
    ("data generate --out", lambda p: ["data", "generate", "--out", p["uncreatable"]], "uncreatable"),
    ("data sequence --out", lambda p: ["data", "sequence", "--out", p["uncreatable"]], "uncreatable"),
    ("prior train --out", lambda p: ["prior", "train", "--profile", "smoke", "--out",
                                     p["uncreatable"] / "prior.pt"], "uncreatable"),
    ("reproduce --out", lambda p: ["reproduce", "--only", "00", "--out", p["uncreatable"]], "uncreatable"),
    ("finetune --out", lambda p: ["finetune", "--checkpoint", p["good_ckpt"], "--sequence", p["seq"],
                                  "--out", p["uncreatable"]], "uncreatable"),
]

TRUNCATED = [
    ("eval --checkpoint", lambda p: ["eval", "--checkpoint", p["ckpt"]], "ckpt"),
    ("predict --checkpoint", lambda p: ["predict", "--checkpoint", p["ckpt"], "--sequence", p["seq"],
                                        "--out", p["tmp"] / "pred_out.npz"], "ckpt"),
    ("finetune --checkpoint", lambda p: ["finetune", "--checkpoint", p["ckpt"], "--sequence", p["seq"],
                                         "--out", p["tmp"] / "ft2"], "ckpt"),
    ("train resume", lambda p: ["train", "--variant", "airpose", "--out", p["run"]], "run"),
    ("fit --init", lambda p: ["fit", "--sequence", p["seq"], "--init", p["npz"]], "npz"),
    ("fit --sequence", lambda p: ["fit", "--sequence", p["bad_seq"], "--init", p["good_npz"]], "bad_seq"),
    ("fit --prior-path", lambda p: ["fit", "--sequence", p["seq"], "--init", p["good_npz"], "--prior-path",
                                    p["ckpt"]], "ckpt"),
    ("prior info --path", lambda p: ["prior", "info", "--path", p["ckpt"]], "ckpt"),
    ("node --checkpoint", lambda p: _node("--checkpoint", p["ckpt"]), "ckpt"),
    ("node --source", lambda p: _node("--source", p["bad_seq"]), "bad_seq"),
    ("data generate manifest", lambda p: ["data", "generate", "--out", p["data"]], "data"),
]


def _run(argv, capsys) -> tuple[int, str]:
    """Exit status and stderr of ``airpose ARGV`` (stdout is kept in ``_run.out``)."""
    capsys.readouterr()
    code = cli.main([str(a) for a in argv])
    out = capsys.readouterr()
    _run.out = out.out
    return code, out.err


def _assert_one_line(code: int, err: str, path: Path) -> None:
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, err
    assert len(lines) == 1 and lines[0].startswith("airpose: error: "), err
    assert str(path) in lines[0], err
    assert "Traceback" not in err


@pytest.mark.parametrize("argv,named", [c[1:] for c in MISSING], ids=[c[0] for c in MISSING])
def test_every_subcommand_reports_a_missing_path_in_one_line(argv, named, inputs, capsys):
    code, err = _run(argv(inputs), capsys)
    if named == "uncreatable" and argv(inputs)[:2] == ["data", "verify"]:  # a report, not an error
        assert code == 1 and str(inputs["uncreatable"]) in _run.out + err
        return
    _assert_one_line(code, err, inputs[named])


@pytest.mark.parametrize("argv,named", [c[1:] for c in TRUNCATED], ids=[c[0] for c in TRUNCATED])
def test_every_subcommand_reports_a_truncated_input_in_one_line(argv, named, inputs, capsys):
    code, err = _run(argv(inputs), capsys)
    _assert_one_line(code, err, inputs[named])
    assert "damaged" in err or "truncated" in err or "not" in err


def test_node_without_keys_says_where_they_come_from(inputs, capsys, monkeypatch):
    monkeypatch.delenv("AIRPOSE_SWARM_KEYS", raising=False)
    code, err = _run(["node", "--id", "1", "--port", "5999", "--backend", "fake"], capsys)
    assert code == 2 and "AIRPOSE_SWARM_KEYS" in err and "--keys" in err and len(err.strip().splitlines()) == 1
    code, err = _run(["node", "--id", "1", "--port", "5999", "--peers", "2@6000", "--backend", "fake",
                      "--keys", inputs["tmp"] / "no_keys"], capsys)
    _assert_one_line(code, err, inputs["tmp"] / "no_keys")


def test_short_detections_name_the_cli_flag(inputs, capsys):
    code, err = _run(["fit", "--sequence", inputs["short_seq"], "--init", inputs["good_npz"]], capsys)
    _assert_one_line(code, err, inputs["short_seq"] / "machine_1" / "openpose_res.pkl")
    assert "--allow-missing-detections" in err


def test_debug_shows_the_traceback(inputs, capsys):
    code, err = _run(["eval", "--checkpoint", inputs["ckpt"], "--debug"], capsys)
    assert code == 2 and "Traceback" in err and err.strip().splitlines()[-1].startswith("airpose: error: ")


def test_a_bug_keeps_its_traceback(monkeypatch):
    def broken(args):
        raise ZeroDivisionError("a bug")

    parser = cli.build_parser()
    args = parser.parse_args(["data", "list"])
    monkeypatch.setattr(cli, "build_parser", lambda: parser)
    monkeypatch.setattr(args, "func", broken, raising=False)
    monkeypatch.setattr(parser, "parse_args", lambda argv=None: args)
    with pytest.raises(ZeroDivisionError):
        cli.main(["data", "list"])


def test_damaged_body_model_is_named_as_such(tmp_path, monkeypatch, capsys):
    """`body info` and `data generate --out NEW` on a truncated cached model name the file and
    the repair command, not "generated with other body-model files"."""
    from airpose_lib.body import open_model_path

    monkeypatch.setenv("AIRPOSE_CACHE", str(tmp_path / "cache"))
    for g in ("neutral", "male", "female"):
        path = open_model_path(g)
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(path, v_template=np.zeros((10, 3)))
        _truncate(path)
    bad = open_model_path("neutral")
    code, err = _run(["body", "info"], capsys)
    _assert_one_line(code, err, bad)
    assert "damaged" in err and "airpose body build --force" in err
    code, err = _run(["data", "generate", "--out", tmp_path / "new"], capsys)
    _assert_one_line(code, err, tmp_path / "cache")
    assert "damaged" in err and "airpose body build --force" in err and "other body-model" not in err


def test_body_build_verifies_an_existing_file(tmp_path, monkeypatch, capsys):
    """Without --force, `body build` rebuilds a damaged cached file instead of trusting it."""
    import airpose_lib.body as body

    monkeypatch.setenv("AIRPOSE_CACHE", str(tmp_path / "cache"))
    path = body.open_model_path("neutral")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b"PK\x03\x04 cut short")
    calls = []

    def fake_build(genders=("neutral",), force=False, **kw):
        calls.append((tuple(genders), force))
        return {g: body.open_model_path(g) for g in genders}

    monkeypatch.setattr(body, "build_open_model", fake_build)
    code, err = _run(["body", "build"], capsys)
    assert code == 0, err
    assert (("neutral",), True) in calls  # the damaged file was rebuilt
    assert "damaged" in _run.out


def test_module_entry_prints_one_line_without_traceback(tmp_path):
    res = subprocess.run([sys.executable, "-m", "airpose_lib", "eval", "--checkpoint", str(tmp_path / "x.pt")],
                         capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert res.returncode == 2 and "Traceback" not in res.stderr
    assert res.stderr.strip().count("\n") == 0 and str(tmp_path / "x.pt") in res.stderr


def test_body_info_smplx_in_a_missing_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("AIRPOSE_SMPLX_DIR", str(tmp_path / "nope"))
    code, err = _run(["body", "info", "--source", "smplx"], capsys)
    _assert_one_line(code, err, tmp_path / "nope")
    assert "AIRPOSE_SMPLX_DIR" in err


# Exceptions of the kit that are not user errors: a bad packet from another drone is logged and
# dropped by the node; a pickle naming a forbidden global is turned into a DamagedFileError by
# ``errors.reading`` (the file and the fix), so neither reaches the command line as such.
INTERNAL_ERRORS = {"WireError", "ForbiddenGlobalError"}


def _kit_exception_classes() -> dict[str, type]:
    """Every ``Exception`` class defined in airpose_lib, by ``module:name`` (the modules are imported)."""
    import importlib
    import re

    found = {}
    for path in sorted((ROOT / "airpose_lib").rglob("*.py")):
        names = re.findall(r"^class (\w+)\(", path.read_text(), re.M)
        if not names:
            continue
        module = ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
        mod = importlib.import_module(module)
        for name in names:
            cls = getattr(mod, name)
            if isinstance(cls, type) and issubclass(cls, Exception):  # not reproduce's Interrupted (^C)
                found[f"{module}:{name}"] = cls
    return found


def test_every_kit_error_is_a_user_error_or_listed_as_internal():
    """The CLI reports UserError and its subclasses on one line and nothing else of the kit; a
    new error class must choose (derive from UserError, or be listed above as a bug's error)."""
    from airpose_lib.errors import UserError

    classes = _kit_exception_classes()
    assert len(classes) >= 25, sorted(classes)  # the scan found the kit's classes
    wrong = [spec for spec, cls in classes.items()
             if issubclass(cls, UserError) == (cls.__name__ in INTERNAL_ERRORS)]
    assert not wrong, f"decide: derive from airpose_lib.errors.UserError or add to INTERNAL_ERRORS: {wrong}"
    # the built-in bases stay, so that `except ValueError` / `except FileNotFoundError` callers keep working
    assert issubclass(classes["airpose_lib.data.sequences.layout:SequenceFormatError"], ValueError)
    assert issubclass(classes["airpose_lib.prior.checkpoint:PriorError"], FileNotFoundError)
    assert issubclass(classes["airpose_lib.assets.fetch:ChecksumError"], RuntimeError)


def _raise_internal(*args, **kwargs):
    raise ValueError("an internal invariant broke")  # a bug: not a UserError


@pytest.mark.parametrize("debug", [False, True], ids=["plain", "debug"])
@pytest.mark.parametrize("command", ["train", "fit", "finetune"])
def test_an_internal_value_error_stays_a_traceback(command, debug, inputs, monkeypatch, capsys):
    """A plain ValueError inside a command (a bug) propagates out of ``cli.main``, with --debug or
    not: the command line no longer turns any ValueError into a one-line user error."""
    out = inputs["tmp"] / f"bug_{command}_{debug}"
    if command == "train":
        import airpose_lib.train as lib

        monkeypatch.setattr(lib, "train", _raise_internal)
        argv = ["train", "--variant", "airpose", "--out", out]
    elif command == "fit":
        import airpose_lib.fitting as lib

        monkeypatch.setattr(lib, "fit_sequence", _raise_internal)
        monkeypatch.setattr("airpose_lib.prior.load_prior", lambda *a, **k: (None, {}))
        argv = ["fit", "--sequence", inputs["seq"], "--init", inputs["good_npz"], "--out", out / "x.npz"]
    else:
        import airpose_lib.finetune.train as lib

        monkeypatch.setattr(lib, "finetune", _raise_internal)
        argv = ["finetune", "--checkpoint", inputs["good_ckpt"], "--sequence", inputs["seq"], "--out", out]
    with pytest.raises(ValueError, match="an internal invariant broke"):
        cli.main([str(a) for a in argv] + (["--debug"] if debug else []))
    assert "airpose: error" not in capsys.readouterr().err


def _fake_node(*extra: str) -> list[str]:
    return ["node", "--id", "1", "--port", "5999", "--backend", "fake", "--insecure", "--frames", "2", *extra]


# (name, argv, what the one line must say): bad flag values, caught before a drone starts
BAD_VALUES = [
    ("node --peers bad", _fake_node("--peers", "bad"), "--peers: peer 'bad': expected ID@PORT"),
    ("node --peers x@5002", _fake_node("--peers", "x@5002"), "drone id 1..255 and a port 1..65535"),
    ("node --peers own id", _fake_node("--peers", "1@5002"), "own id 1"),
    ("node --id 0", ["node", "--id", "0", "--port", "5999", "--backend", "fake", "--insecure"], "--id 0: give a drone id"),
    ("node --port 99999", ["node", "--id", "1", "--port", "99999", "--backend", "fake", "--insecure"], "--port 99999"),
    ("node --window-ms -5", _fake_node("--window-ms", "-5"), "--window-ms -5.0: give > 0"),
    ("node --link-loss 2", _fake_node("--link-loss", "2"), "--link-loss 2.0: give a probability"),
    ("node --detector foo", _fake_node("--detector", "foo", "--source", "SEQ"), "--detector foo: unknown; give one of openpose"),
    ("predict --detector foo", ["predict", "--checkpoint", "SEQ", "--sequence", "SEQ", "--out", "x.npz", "--detector",
                                "foo"], "--detector foo: unknown; give one of openpose, alphapose, mediapipe"),
    ("fit --detectors", ["fit", "--sequence", "SEQ", "--init", "SEQ", "--detectors", "openpose,yolo"],
     "--detectors openpose,yolo: give one or more of openpose, alphapose, mediapipe"),
    ("node --source synthetic:bogus=1", _fake_node("--source", "synthetic:bogus=1"), "unknown synthetic option 'bogus'"),
    ("node --source synthetic:views=abc", _fake_node("--source", "synthetic:views=abc"), "views='abc' is not a valid"),
    ("node --view 5", _fake_node("--view", "5"), "view 5 not in the 2-view source synthetic; give --view 0..1"),
    ("launch --drones 0", ["launch", "--drones", "0", "--backend", "fake"], "--drones 0: give 1..255 drones"),
    ("keys --drones 0", ["keys", "--drones", "0", "--out", "KEYS"], "--drones 0: give 1..255 drones"),
    ("export --calibration", ["export", "--calibration", "SEQ"], "is not a still-frame dataset (no manifest.yaml)"),
]


@pytest.mark.parametrize("argv,says", [c[1:] for c in BAD_VALUES], ids=[c[0] for c in BAD_VALUES])
def test_bad_option_values_are_one_line(argv, says, inputs, capsys, monkeypatch, tmp_path):
    monkeypatch.setenv("AIRPOSE_RUNS", str(tmp_path / "runs"))  # a drone that does start writes there
    argv = [str(inputs["tmp"] / "keys0") if a == "KEYS" else str(inputs["seq"]) if a == "SEQ" else a for a in argv]
    code, err = _run(argv, capsys)
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1 and lines[0].startswith("airpose: error: "), err
    assert says in lines[0] and "Traceback" not in err, err
    assert not (inputs["tmp"] / "keys0").exists()


@pytest.mark.parametrize("argv,says", [
    (["train", "--variant", "airpose", "--steps", "abc"], "argument --steps: invalid int value: 'abc'; "
                                                          "see `airpose train --help`"),
    (["train"], "the following arguments are required: --variant; see `airpose train --help`"),
    (["fit", "--sequence", "x", "--init", "y", "--profile", "huge"], "unknown profile 'huge'"),
], ids=["bad int", "missing flag", "bad choice"])
def test_argparse_errors_are_one_line_too(argv, says, capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(argv)
    err = capsys.readouterr().err
    assert exc.value.code == 2 and err.count("\n") == 1 and err.startswith("airpose: error: ") and says in err, err


# -- a full disk, bad values and a refused command -------------------------------------
def _enospc(*args, **kwargs):
    raise OSError(28, "No space left on device")


@pytest.mark.parametrize("patch, argv", [
    ("zipfile.ZipFile.writestr", lambda p: ["data", "generate", "--profile", "smoke", "--workers", "1", "--quiet",
                                           "--out", p["tmp"] / "full"]),
    ("airpose_lib.data.sequences.recording.generate_sequence",
     lambda p: ["data", "sequence", "--profile", "smoke", "--quiet", "--out", p["tmp"] / "full_seq"]),
])
def test_a_full_disk_is_one_line_naming_the_file(inputs, capsys, monkeypatch, patch, argv):
    """ENOSPC used to end in three chained tracebacks (zipfile's clean-up raised again)."""
    module, _, name = patch.rpartition(".")
    if patch.startswith("zipfile"):
        import zipfile

        monkeypatch.setattr(zipfile.ZipFile, "writestr", _enospc)
    else:
        import airpose_lib.data.sequences.cache as cache

        def full(config, out, progress=False):  # as the renderer would: a frame half written
            from airpose_lib.atomic import atomic_path

            (Path(out) / "machine_1").mkdir(parents=True, exist_ok=True)
            with atomic_path(Path(out) / "machine_1" / "000000.jpg") as tmp:
                tmp.write_bytes(b"x")
                _enospc()

        monkeypatch.setattr(cache, "generate_sequence", full)
    code, err = _run(argv(inputs), capsys)
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1, err
    assert lines[0].startswith("airpose: error: no space left on the device while writing ")
    assert ("shard_" in lines[0] or "000000.jpg" in lines[0]) and "rerun resumes" in lines[0]
    assert not list((inputs["tmp"] / "full_seq").glob("*.partial"))  # nothing half-made kept


@pytest.mark.parametrize("setting, says", [
    ("lr=inf", "lr must be > 0, got inf"),
    ("device=tpu", "device must be"),
    ("model.dropout=abc", "--set model.dropout=abc: expected float"),
    ("keep_checkpoints=-1", "keep_checkpoints must be >= 0"),
    ("val_every=-3", "val_every must be"),
    ("val_batches=0", "val_batches must be"),
    ("data.root=/nonexistent", "no dataset in /nonexistent"),
])
def test_bad_training_values_are_one_line_before_a_run_folder_exists(inputs, capsys, setting, says):
    out = inputs["tmp"] / f"never_{abs(hash(setting))}"
    code, err = _run(["train", "--variant", "airpose", "--out", out, "--set", setting], capsys)
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1 and says in lines[0], err
    assert not out.exists()


def test_a_refused_finetune_leaves_no_folder(inputs, capsys):
    """A damaged detection file used to be found after the --out folder and its lock existed."""
    out = inputs["tmp"] / "ft_refused"
    code, err = _run(["finetune", "--checkpoint", inputs["good_ckpt"], "--sequence", inputs["bad_seq"], "--out", out],
                     capsys)
    assert code == 2 and "openpose_res.pkl" in err, err
    assert not out.exists()
