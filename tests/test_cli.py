"""The ``airpose`` command line: help, argument parsing and dispatch (with stand-in back ends)."""

import subprocess
import sys
import types
from pathlib import Path

import pytest

from airpose_lib import cli
from airpose_lib.reproduce.runner import NotebookResult, RunReport


def test_help_lists_subcommands(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "body" in out and "reproduce" in out


@pytest.mark.parametrize("argv", [["reproduce", "--help"], ["body", "--help"], ["body", "build", "--help"],
                                  ["body", "info", "--help"]])
def test_subcommand_help(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(argv)
    assert exc.value.code == 0
    assert "usage: airpose" in capsys.readouterr().out


def test_help_is_fast_and_light():
    """``airpose --help`` must not import torch, smplx, papermill or pyvista."""
    code = ("import sys\nfrom airpose_lib import cli\n"
            "try:\n    cli.main(['--help'])\nexcept SystemExit:\n    pass\n"
            "heavy = [m for m in ('torch', 'smplx', 'papermill', 'pyvista', 'vtk', 'matplotlib') "
            "if m in sys.modules]\nprint('HEAVY', heavy)")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                         cwd=Path(__file__).resolve().parents[1])
    assert "HEAVY []" in res.stdout, res.stdout + res.stderr


def test_parser_build_imports_no_runtime_libraries():
    """Building the whole parser (every `airpose` call, a drone's start-up included) imports neither
    torch nor ZeroMQ nor ONNX Runtime: the command groups import the library in their handlers."""
    code = ("import sys\nfrom airpose_lib import cli\ncli.build_parser()\n"
            "print('HEAVY', [m for m in ('torch', 'zmq', 'onnxruntime', 'numpy') if m in sys.modules])")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                         cwd=Path(__file__).resolve().parents[1])
    assert "HEAVY []" in res.stdout, res.stdout + res.stderr


def test_drone_process_entry_point_is_airpose_node():
    """The launcher starts drones as `python -m airpose_lib.cli.drone`: `airpose node` itself."""
    res = subprocess.run([sys.executable, "-m", "airpose_lib.cli.drone", "--help"], capture_output=True,
                         text=True, timeout=60, cwd=Path(__file__).resolve().parents[1])
    assert res.returncode == 0 and res.stdout.startswith("usage: airpose node"), res.stdout + res.stderr
    assert "RuntimeWarning" not in res.stderr  # runpy: the module is not imported twice


def test_parse_reproduce():
    p = cli.build_parser()
    a = p.parse_args(["reproduce", "--profile", "cpu", "--only", "00", "01_data", "--out", "x/runs",
                      "--figures", "figs", "--kernel", "k2", "--keep-going"])
    assert (a.command, a.profile, a.only, a.out, a.figures, a.kernel, a.keep_going) == (
        "reproduce", "cpu", ["00", "01_data"], Path("x/runs"), Path("figs"), "k2", True)
    d = p.parse_args(["reproduce"])
    assert (d.profile, d.only, d.out, d.figures, d.kernel, d.keep_going) == ("smoke", None, None, None,
                                                                            "python3", False)
    with pytest.raises(SystemExit):
        p.parse_args(["reproduce", "--profile", "huge"])
    with pytest.raises(SystemExit):
        p.parse_args(["reproduce", "--profile", "not_here.yaml"])


def test_reproduce_takes_an_own_profile_file(tmp_path, monkeypatch, capsys):
    (tmp_path / "mine.yaml").write_text("inherits: smoke\ndescription: smoke with my changes\n")
    monkeypatch.chdir(tmp_path)
    a = cli.build_parser().parse_args(["reproduce", "--profile", "mine.yaml"])
    assert a.profile == str(tmp_path / "mine.yaml")
    assert cli.main(["reproduce", "--profile", "mine.yaml", "--list"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("profile mine: smoke with my changes") and "image_size" in out


def test_parse_body():
    p = cli.build_parser()
    a = p.parse_args(["body", "build", "--gender", "all", "--force"])
    assert (a.body_command, a.gender, a.force) == ("build", "all", True)
    b = p.parse_args(["body", "info"])
    assert (b.body_command, b.source, b.gender) == ("info", "open", "neutral")
    with pytest.raises(SystemExit):
        p.parse_args(["body", "info", "--gender", "other"])
    with pytest.raises(SystemExit):
        p.parse_args(["body"])  # a body subcommand is required
    with pytest.raises(SystemExit):
        p.parse_args([])  # a command is required
    with pytest.raises(SystemExit):
        p.parse_args(["train"])  # not offered until it exists


@pytest.fixture()
def fake_body(monkeypatch):
    """Stand-in for airpose_lib.body (the CLI only dispatches; the body tests test the body)."""
    calls = {}
    mod = types.ModuleType("airpose_lib.body")

    def build_open_model(genders=("neutral",), force=False):
        calls["build"] = (tuple(genders), force)
        return {g: Path(f"/cache/SMPLX_{g.upper()}.npz") for g in genders}

    def load_body_model(source="open", gender="neutral", **kw):
        calls["load"] = (source, gender)
        return object()

    def body_model_info(model):
        return {"num_vertices": 13718, "num_joints": 76, "stature_m": 1.7234, "path": "/cache/x.npz"}

    mod.build_open_model, mod.load_body_model, mod.body_model_info = (build_open_model, load_body_model,
                                                                      body_model_info)
    mod.open_model_path = lambda gender: Path(f"/nonexistent/SMPLX_{gender.upper()}.npz")  # nothing cached
    mod.BodyModelError = RuntimeError
    monkeypatch.setitem(sys.modules, "airpose_lib.body", mod)
    return calls


def test_body_build_dispatch(fake_body, capsys):
    assert cli.main(["body", "build", "--gender", "all", "--force"]) == 0
    assert fake_body["build"] == (("neutral", "male", "female"), True)
    assert "SMPLX_FEMALE.npz" in capsys.readouterr().out
    assert cli.main(["body", "build"]) == 0
    assert fake_body["build"] == (("neutral",), False)


def test_body_info_dispatch(fake_body, capsys):
    assert cli.main(["body", "info", "--gender", "male"]) == 0
    out = capsys.readouterr().out
    assert fake_body["load"] == ("open", "male")
    assert "13718" in out and "76" in out and "1.723 m" in out and "/cache/x.npz" in out


def _fake_report(ok: bool) -> RunReport:
    r = RunReport(profile="smoke", description="", kit_version="0", kernel_name="python3",
                  started_at="now", run_dir="/tmp/runs/smoke", figures_dir="/tmp/figures")
    r.results = [NotebookResult("00_body_model", "00_body_model.ipynb", status="ok" if ok else "failed",
                                error=None if ok else "cell In [3] raised KeyError: 'x'")]
    return r


@pytest.mark.parametrize("ok", [True, False])
def test_reproduce_dispatch_and_exit_status(monkeypatch, capsys, ok):
    import airpose_lib.reproduce as rep

    seen = {}

    def fake_run(profile, **kw):
        seen.update(kw, profile=profile)
        return _fake_report(ok)

    monkeypatch.setattr(rep, "run_profile", fake_run)
    status = cli.main(["reproduce", "--profile", "paper", "--only", "00", "--kernel", "k"])
    assert seen["profile"] == "paper" and seen["only"] == ["00"] and seen["kernel_name"] == "k"
    err = capsys.readouterr().err
    if ok:
        assert status == 0
    else:
        assert status == 1
        assert "FAILED" in err and "00_body_model" in err and "KeyError" in err


def test_reproduce_configuration_error_is_reported(monkeypatch, capsys):
    assert cli.main(["reproduce", "--only", "99_not_there"]) == 2
    assert "99_not_there" in capsys.readouterr().err


def test_reproduce_list(capsys):
    assert cli.main(["reproduce", "--profile", "smoke", "--list"]) == 0
    out = capsys.readouterr().out
    assert "00_body_model" in out and "image_size" in out


def test_version_and_module_entry():
    res = subprocess.run([sys.executable, "-m", "airpose_lib", "--version"], capture_output=True,
                         text=True, timeout=60, cwd=Path(__file__).resolve().parents[1])
    assert res.returncode == 0 and res.stdout.startswith("airpose ")
