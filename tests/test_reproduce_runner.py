"""The papermill runner on tiny notebooks: success, loud failures, parameter injection, and the
consistency of the real catalog, profiles and notebooks."""

import json
from pathlib import Path

import nbformat
import pytest
import yaml
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

from airpose_lib.reproduce import (
    CATALOG_PATH,
    PROFILES_DIR,
    ReproductionError,
    check_notebook,
    list_profiles,
    load_catalog,
    load_profile,
    notebook_outputs,
    run_profile,
)
from airpose_lib.reproduce.kernels import kernel_environment
from airpose_lib.reproduce.runner import NOTEBOOKS_DIR

PARAMS = 'profile = "none"\noutput_dir = "."\nsize = 1\n'

# The successful notebook writes its figure and echoes what it received, so the test can check
# the injected parameters and the kernel's environment.
OK_BODY = """
import json, os, sys
from pathlib import Path
out = Path(output_dir)
(out / "a.png").write_bytes(b"not really a png")
env = {k: os.environ.get(k) for k in ("MPLBACKEND", "PYVISTA_OFF_SCREEN", "VTK_DEFAULT_OPENGL_WINDOW")}
(out / "seen.json").write_text(json.dumps({"profile": profile, "output_dir": output_dir,
                                           "size": size, "env": env, "cwd": os.getcwd()}))
"""


def _write_nb(path: Path, body: str, params: str | None = PARAMS) -> None:
    cells = [new_markdown_cell("# test notebook")]
    if params is not None:
        cells.append(new_code_cell(params, metadata={"tags": ["parameters"]}))
    cells.append(new_code_cell(body))
    nb = new_notebook(cells=cells, metadata={"kernelspec": {"name": "python3", "language": "python",
                                                            "display_name": "Python 3"}})
    nbformat.write(nb, path)


@pytest.fixture()
def kit(tmp_path):
    """A catalog of four notebooks, a profile, and run/figure folders, all under tmp_path."""
    nbs = tmp_path / "notebooks"
    nbs.mkdir()
    _write_nb(nbs / "00_ok.ipynb", OK_BODY)
    _write_nb(nbs / "01_raise.ipynb", 'x = 1\nraise ValueError("boom from the notebook")')
    _write_nb(nbs / "02_forget.ipynb", "(__import__('pathlib').Path(output_dir) / 'c.png').write_text('x')")
    _write_nb(nbs / "03_noparams.ipynb", "output_dir = '.'", params=None)
    catalog = {"notebooks": [
        {"name": "00_ok", "file": "00_ok.ipynb", "reproduces": "a", "figures": ["a.png"]},
        {"name": "01_raise", "file": "01_raise.ipynb", "reproduces": "b", "figures": ["b.png"]},
        {"name": "02_forget", "file": "02_forget.ipynb", "reproduces": "c",
         "figures": ["c.png", "forgotten.png"]},
        {"name": "03_noparams", "file": "03_noparams.ipynb", "reproduces": "d", "figures": []},
    ]}
    (tmp_path / "catalog.yaml").write_text(yaml.safe_dump(catalog))
    profiles = tmp_path / "profiles"
    profiles.mkdir()
    (profiles / "tiny.yaml").write_text(yaml.safe_dump(
        {"description": "test profile", "cell_timeout_s": 60, "notebooks": {"00_ok": {"size": 7}}}))
    (profiles / "typo.yaml").write_text(yaml.safe_dump(
        {"description": "sets an undeclared parameter", "notebooks": {"00_ok": {"sise": 7}}}))
    (profiles / "stray.yaml").write_text(yaml.safe_dump(
        {"description": "names a notebook not in the catalog", "notebooks": {"99_nope": {"a": 1}}}))

    def run(profile="tiny", **kw):
        return run_profile(profile, out_dir=tmp_path / "runs", figures_dir=tmp_path / "figures",
                           notebooks_dir=nbs, catalog_path=tmp_path / "catalog.yaml",
                           profiles_dir=profiles, verbose=False, **kw)

    return tmp_path, run


def test_success_failure_and_stop(kit):
    root, run = kit
    report = run()  # 00 ok, 01 raises -> stop: 02 and 03 are skipped
    status = {r.name: r.status for r in report.results}
    assert status == {"00_ok": "ok", "01_raise": "failed", "02_forget": "skipped", "03_noparams": "skipped"}
    assert not report.ok

    # The successful notebook got the profile's parameters and an off-screen environment.
    run_dir = root / "runs" / "tiny"
    seen = json.loads((run_dir / "00_ok" / "seen.json").read_text())
    assert seen["profile"] == "tiny" and seen["size"] == 7
    assert Path(seen["output_dir"]) == run_dir / "00_ok"
    assert seen["env"] == {"MPLBACKEND": "Agg", "PYVISTA_OFF_SCREEN": "true",
                           "VTK_DEFAULT_OPENGL_WINDOW": "vtkEGLRenderWindow"}
    assert Path(seen["cwd"]) == root / "notebooks"
    # Executed notebooks and collected figures.
    assert (run_dir / "notebooks" / "00_ok.ipynb").is_file()
    assert (run_dir / "notebooks" / "01_raise.ipynb").is_file()  # kept, with the traceback
    assert (root / "figures" / "a.png").read_bytes() == b"not really a png"
    prov = json.loads((root / "figures" / "provenance.json").read_text())
    assert prov["a.png"]["notebook"] == "00_ok" and prov["a.png"]["profile"] == "tiny"

    # The failure names the notebook, the cell's exception and its message.
    msg = report.failure_message()
    assert "01_raise" in msg and "ValueError" in msg and "boom from the notebook" in msg
    with pytest.raises(ReproductionError, match="01_raise.*ValueError: boom"):
        report.raise_for_failures()

    # report.json: kit version, parameters and per-notebook wall time and status.
    rep = json.loads((run_dir / "report.json").read_text())
    assert rep["ok"] is False and rep["profile"] == "tiny" and rep["kit_version"]
    assert rep["results"][0]["parameters"] == {"profile": "tiny", "output_dir": str(run_dir / "00_ok"),
                                               "size": 7}
    assert rep["results"][0]["wall_s"] > 0 and rep["results"][1]["status"] == "failed"
    assert "00_ok" in report.table() and "FAILED" in report.table()


def test_a_failed_rerun_keeps_the_last_good_results_and_says_where_its_partial_run_is(kit):
    """A rerun writes into a fresh folder; when it fails, the folder, executed notebook, figure
    and report entry of the last good run are the ones in place, and the partial run is named."""
    root, run = kit
    run_dir = root / "runs" / "tiny"
    assert run(only=["00_ok"]).ok
    good = {p: p.read_bytes() for p in (run_dir / "00_ok" / "seen.json", run_dir / "00_ok" / "a.png",
                                        run_dir / "notebooks" / "00_ok.ipynb", root / "figures" / "a.png")}
    good_report = json.loads((run_dir / "report.json").read_text())
    _write_nb(root / "notebooks" / "00_ok.ipynb",
              "(__import__('pathlib').Path(output_dir) / 'a.png').write_text('half')\nraise RuntimeError('cut')")
    report = run(only=["00_ok"])
    assert not report.ok and report.results[0].status == "failed"
    assert f"partial run in {run_dir / '00_ok.partial'}" in report.results[0].error
    assert {p: p.read_bytes() for p in good} == good  # every last good file, byte for byte
    assert (run_dir / "00_ok.partial" / "a.png").read_text() == "half"
    assert (run_dir / "notebooks" / "00_ok.ipynb.partial").is_file()
    assert json.loads((run_dir / "report.json").read_text())["results"] == good_report["results"]
    partial = json.loads((run_dir / "report.partial.json").read_text())
    assert partial["results"][0]["status"] == "failed"
    assert not list(run_dir.glob("*.last-good"))


def test_an_own_profile_file_reaches_the_kernels_as_its_absolute_path(kit, monkeypatch):
    root, run = kit
    own = root / "mine" / "own.yaml"
    own.parent.mkdir()
    own.write_text("inherits: ../profiles/tiny.yaml\ndescription: my changes\nnotebooks: {00_ok: {size: 9}}\n")
    monkeypatch.chdir(root)  # a relative path: the kernels run in the notebooks' folder
    report = run("mine/own.yaml", only=["00_ok"])
    assert report.ok and report.profile == "own"
    seen = json.loads((root / "runs" / "own" / "00_ok" / "seen.json").read_text())
    assert seen["profile"] == str(own.resolve()) and seen["size"] == 9
    # a kit profile (here the fixture's) is still passed by its name
    run(only=["00_ok"])
    assert json.loads((root / "runs" / "tiny" / "00_ok" / "seen.json").read_text())["profile"] == "tiny"


def test_missing_figure_and_missing_parameters_cell(kit):
    root, run = kit
    # A figure left over from an earlier run must not hide the missing one.
    stale = root / "runs" / "tiny" / "02_forget"
    stale.mkdir(parents=True)
    (stale / "forgotten.png").write_text("old")
    report = run(only=["02_forget", "03"], keep_going=True)
    by_name = {r.name: r for r in report.results}
    assert [r.name for r in report.results] == ["02_forget", "03_noparams"]
    forget = by_name["02_forget"]
    assert forget.status == "missing_figures"
    assert forget.missing_figures == ["forgotten.png"] and forget.figures == ["c.png"]
    assert "forgotten.png" in forget.error
    assert not (root / "figures" / "c.png").exists()  # nothing is collected from a failed notebook
    noparams = by_name["03_noparams"]
    assert noparams.status == "invalid" and "parameters" in noparams.error
    assert not report.ok
    msg = report.failure_message()
    assert "02_forget" in msg and "03_noparams" in msg


def test_configuration_errors(kit):
    root, run = kit
    with pytest.raises(ReproductionError, match="unknown profile 'nope'"):
        run("nope")
    with pytest.raises(ReproductionError, match="99_nope"):
        run("stray")
    with pytest.raises(ReproductionError, match="matches no notebook"):
        run(only=["07"])
    # A profile parameter the notebook does not declare fails before any kernel starts or any
    # folder is made, naming the profile file and the closest parameter.
    with pytest.raises(ReproductionError, match=r"typo\.yaml: `notebooks: 00_ok:` sets 'sise'.*did you mean 'size'"):
        run("typo", only=["00_ok"])
    assert not (root / "runs").exists()


def test_catalog_validation(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump({"notebooks": [
        {"name": "a", "file": "a.ipynb", "figures": ["x.png"]},
        {"name": "b", "file": "b.ipynb", "figures": ["x.png"]}]}))
    with pytest.raises(ReproductionError, match="x.png"):
        load_catalog(path)
    path.write_text(yaml.safe_dump({"notebooks": [{"name": "a", "file": "a.ipynb"},
                                                  {"name": "a", "file": "b.ipynb"}]}))
    with pytest.raises(ReproductionError, match="duplicate"):
        load_catalog(path)
    path.write_text(yaml.safe_dump({"notebooks": [{"file": "a.ipynb"}]}))
    with pytest.raises(ReproductionError, match="malformed"):
        load_catalog(path)


def test_kernel_environment_is_restored(monkeypatch):
    monkeypatch.setenv("MPLBACKEND", "module://something")
    monkeypatch.delenv("PYVISTA_OFF_SCREEN", raising=False)
    import os

    with kernel_environment() as env:
        assert os.environ["MPLBACKEND"] == "Agg" and os.environ["PYVISTA_OFF_SCREEN"] == "true"
        assert env["VTK_DEFAULT_OPENGL_WINDOW"] == "vtkEGLRenderWindow"
    assert os.environ["MPLBACKEND"] == "module://something"
    assert "PYVISTA_OFF_SCREEN" not in os.environ


# -- the real catalog, profiles and notebooks (no execution) --------------------------------------
def test_real_catalog_profiles_and_notebooks():
    catalog = load_catalog(CATALOG_PATH)
    assert catalog and catalog[0].name == "00_body_model"
    assert [e.name for e in catalog] == sorted(e.name for e in catalog)  # 00_, 01_, ... in order
    assert {"smoke", "cpu", "paper"} <= set(list_profiles(PROFILES_DIR))
    profiles = [load_profile(p) for p in ("smoke", "cpu", "paper")]
    for entry in catalog:
        path = NOTEBOOKS_DIR / entry.file
        for prof in profiles:
            assert prof["description"]
            # Every parameter a profile sets is declared by the notebook's parameters cell.
            check_notebook(path, list(prof["notebooks"].get(entry.name, {})))
        # Every notebook can be pointed at the official assets (official assets are drop-ins).
        check_notebook(path, ["profile", "output_dir", "data_source"])
        assert notebook_outputs(path) == [], f"{entry.file} carries outputs; clear them before committing"
    for prof in profiles:
        assert set(prof["notebooks"]) <= {e.name for e in catalog}


def test_body_model_catalog_entry():
    entry = load_catalog(CATALOG_PATH)[0]
    assert set(entry.figures) == {"body_tpose.png", "body_beta_sweep.png", "body_poses.png",
                                  "body_keypoints.png", "body_skeleton.png"}
    smoke = load_profile("smoke")["notebooks"]["00_body_model"]
    paper = load_profile("paper")["notebooks"]["00_body_model"]
    assert smoke["image_size"] <= paper["image_size"]


@pytest.mark.slow
def test_smoke_body_model_notebook_end_to_end(tmp_path):
    """The real 00_body_model notebook under the smoke profile (needs the built open model)."""
    body = pytest.importorskip("airpose_lib.body")
    if not body.resolve_model_file("open", "neutral", build=False).exists():
        pytest.skip("open body model not built yet: run `airpose body build` (takes minutes)")
    report = run_profile("smoke", only=["00_body_model"], out_dir=tmp_path / "runs",
                         figures_dir=tmp_path / "figures", verbose=False)
    report.raise_for_failures()
    for fig in load_catalog(CATALOG_PATH)[0].figures:
        assert (tmp_path / "figures" / fig).stat().st_size > 1000
    assert report.results[0].wall_s < 60, "the smoke run of 00_body_model must stay under a minute"


def test_data_source_reaches_only_notebooks_that_declare_it(kit, tmp_path):
    from airpose_lib.reproduce.runner import _data_source_parameter

    root, run = kit
    with pytest.raises(ReproductionError, match="data_source must be one of"):
        run(data_source="bogus")
    declares = tmp_path / "declares.ipynb"
    _write_nb(declares, "pass", params=PARAMS + 'data_source = "generated"\n')
    assert _data_source_parameter(declares, "official") == {"data_source": "official"}
    assert _data_source_parameter(root / "notebooks" / "00_ok.ipynb", "official") == {}
    assert _data_source_parameter(declares, None) == {}


def test_kernels_use_ipc_sockets_outside_the_checkout():
    km = __import__("airpose_lib.reproduce.kernels", fromlist=["x"]).ipc_kernel_manager()(kernel_name="python3")
    assert km.transport == "ipc"
    assert not Path(km.ip).resolve().is_relative_to(NOTEBOOKS_DIR.parent)


SLEEP_BODY = """
import os, subprocess, time
from pathlib import Path
child = subprocess.Popen(["sleep", "300"])  # a worker of the notebook: must die with its kernel
(Path(output_dir) / "started").write_text(str(child.pid))
time.sleep(300)
"""

STOPPER = """
import sys
from airpose_lib.reproduce.runner import run_profile
root = sys.argv[1]
try:
    run_profile("tiny", out_dir=root + "/runs", figures_dir=root + "/figures", notebooks_dir=root + "/notebooks",
                catalog_path=root + "/catalog.yaml", profiles_dir=root + "/profiles", verbose=False)
except KeyboardInterrupt:  # as airpose_lib.cli.main
    print("airpose: interrupted", file=sys.stderr)
    sys.exit(130)
"""


def _gone(pid: int, within_s: float) -> bool:
    """Whether process ``pid`` has ended (a zombie counts: in a container nobody may reap an orphan)."""
    import time

    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except (FileNotFoundError, ProcessLookupError):
            return True
        if state in ("Z", "X"):
            return True
        time.sleep(0.1)
    return False


@pytest.mark.parametrize("signame", ["SIGINT", "SIGTERM"])
def test_a_signal_stops_the_run_and_its_kernel_at_once_and_quietly(tmp_path, signame):
    """SIGINT to the process alone was ignored until the notebook ended; Ctrl-C printed a
    19-line ZMQ traceback. Now either signal kills the kernel's process group within seconds, the
    run says one line, and the report keeps the finished notebook."""
    import signal
    import subprocess
    import sys
    import time

    nbs = tmp_path / "notebooks"
    nbs.mkdir()
    _write_nb(nbs / "00_ok.ipynb", OK_BODY)
    _write_nb(nbs / "01_sleep.ipynb", SLEEP_BODY)
    (tmp_path / "catalog.yaml").write_text(yaml.safe_dump({"notebooks": [
        {"name": "00_ok", "file": "00_ok.ipynb", "reproduces": "a", "figures": ["a.png"]},
        {"name": "01_sleep", "file": "01_sleep.ipynb", "reproduces": "b", "figures": []}]}))
    (tmp_path / "profiles").mkdir()
    (tmp_path / "profiles" / "tiny.yaml").write_text(yaml.safe_dump(
        {"description": "test profile", "cell_timeout_s": 600, "notebooks": {}}))
    proc = subprocess.Popen([sys.executable, "-c", STOPPER, str(tmp_path)], stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))  # as `cmd &` does
    started = tmp_path / "runs" / "tiny" / "01_sleep" / "started"
    deadline = time.monotonic() + 120
    while not (started.is_file() and started.read_text()) and time.monotonic() < deadline:
        assert proc.poll() is None, proc.stderr.read()
        time.sleep(0.2)
    child = int(started.read_text())
    t0 = time.monotonic()
    proc.send_signal(getattr(signal, signame))
    err = proc.communicate(timeout=30)[1]
    assert time.monotonic() - t0 < 10
    assert proc.returncode == 130
    assert [line for line in err.splitlines() if line.strip()] == ["airpose: interrupted"], err
    assert _gone(child, within_s=5.0)
    report = json.loads((tmp_path / "runs" / "tiny" / "report.json").read_text())
    assert [r["status"] for r in report["results"]] == ["ok", "interrupted"]


def test_kernels_are_not_interrupted_on_their_way_to_shutdown(monkeypatch):
    """jupyter_client interrupts before every shutdown, and ipykernel then logs "KeyboardInterrupt
    caught in kernel" on the terminal (seen after notebook 03); a timeout's interrupt still goes."""
    import asyncio

    from jupyter_client.manager import AsyncKernelManager

    sent = []

    async def interrupt(self):
        sent.append(self.shutting_down)

    monkeypatch.setattr(AsyncKernelManager, "_async_interrupt_kernel", interrupt)
    km = __import__("airpose_lib.reproduce.kernels", fromlist=["x"]).ipc_kernel_manager()(kernel_name="python3")
    km.shutting_down = True
    asyncio.run(km._async_interrupt_kernel())
    km.shutting_down = False
    asyncio.run(km._async_interrupt_kernel())
    assert sent == [False]


def test_explicit_official_data_source_fails_at_once_naming_the_missing_asset(tmp_path, monkeypatch, capsys):
    """`airpose reproduce --data-source official` with an asset missing: exit 2 naming it, before
    any notebook runs (the notebooks themselves fall back to generated data; asked for explicitly,
    that would silently start generating and training on the paper profile)."""
    from airpose_lib import cli
    from airpose_lib.reproduce.runner import NOTEBOOKS_DIR, official_needs

    assert official_needs(NOTEBOOKS_DIR / "02_ablation_table.ipynb") == [
        "official_synthetic", "official_checkpoints", "smplx_v1_1"]
    assert official_needs(NOTEBOOKS_DIR / "07_recording_3d.ipynb") == []
    monkeypatch.setenv("AIRPOSE_OFFICIAL_SYNTHETIC_DIR", str(tmp_path / "nowhere"))  # a mistyped folder
    monkeypatch.setenv("AIRPOSE_RUNS", str(tmp_path / "runs"))
    code = cli.main(["reproduce", "--profile", "smoke", "--only", "02_ablation_table", "--data-source", "official",
                     "--out", str(tmp_path / "runs"), "--figures", str(tmp_path / "figs")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.startswith("airpose: error: --data-source official: official_synthetic is missing")
    assert str(tmp_path / "nowhere") in err and "\n" not in err
    assert not (tmp_path / "runs" / "smoke").exists()  # nothing ran


def test_a_profile_edited_during_a_run_stops_it_before_the_next_notebook(kit):
    """The run reads its profile once; a kernel reads it again by name, so an edit would give
    the later notebooks other settings than the earlier ones: refused, naming the file."""
    root, run = kit
    profile = root / "profiles" / "tiny.yaml"
    edit = f"p = Path({str(profile)!r})\np.write_text(p.read_text().replace('size: 7', 'size: 8'))\n"
    _write_nb(root / "notebooks" / "00_ok.ipynb", OK_BODY + edit)
    _write_nb(root / "notebooks" / "02_forget.ipynb", "raise RuntimeError('must not run')")
    with pytest.raises(ReproductionError, match=r"tiny\.yaml changed during the run, before 02_forget"):
        run(only=["00_ok", "02_forget"])
    rep = json.loads((root / "runs" / "tiny" / "report.json").read_text())
    assert [r["status"] for r in rep["results"]] == ["ok", "skipped"]
    assert not (root / "runs" / "tiny" / "notebooks" / "02_forget.ipynb").exists()
