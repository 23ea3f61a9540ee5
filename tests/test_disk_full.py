"""A write that finds no room is one line naming the file, and loses nothing already written.

A full file system cannot be mounted here without privileges, so a process file size limit
(``RLIMIT_FSIZE``, ``ulimit -f``) stands in for it: a write past it fails with ``EFBIG`` the way a
full disk fails with ``ENOSPC`` (the same writers, the same clean-up paths). Each case runs the real
``airpose`` process under the limit, with ``SIGXFSZ`` ignored as Python does, and checks the exit
status, the one line, that no half-written file is left and that an earlier good file is kept.
"""
from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import torch
import yaml

ROOT = Path(__file__).resolve().parents[1]


def _limited(limit_bytes: int):
    def start() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, resource.RLIM_INFINITY))
    return start


def _airpose(argv: list, limit_bytes: int, env: dict | None = None, code: str | None = None):
    command = [sys.executable, "-c", code] if code else [sys.executable, "-m", "airpose_lib", *map(str, argv)]
    return subprocess.run(command, capture_output=True, text=True, timeout=300, cwd=ROOT,
                          env={**os.environ, **(env or {})}, preexec_fn=_limited(limit_bytes))


def _one_line(res, named: Path) -> str:
    lines = [line for line in res.stderr.splitlines() if line.strip()]
    assert res.returncode == 2, res.stderr
    assert len(lines) == 1 and lines[0].startswith("airpose: error: "), res.stderr
    assert str(named) in lines[0] and "ulimit -f" in lines[0] and "rerun resumes" in lines[0], lines[0]
    return lines[0]


def _no_temp_files(folder: Path) -> None:
    assert not [p for p in folder.rglob(".*.tmp")], sorted(folder.rglob(".*.tmp"))


def test_a_checkpoint_past_the_limit(tmp_path):
    """``backbone import`` writes a torch checkpoint (``atomic_torch_save``, as every checkpoint):
    torch's own writer used to turn this into ``RuntimeError: ... unexpected pos``."""
    from airpose_lib.model import resnet18  # torchvision's keys

    weights = tmp_path / "resnet18.pth"
    torch.save(resnet18().state_dict(), weights)
    out = tmp_path / "out" / "backbone.pt"
    out.parent.mkdir()
    out.write_bytes(b"the earlier backbone")
    res = _airpose(["backbone", "import", weights, "--backbone", "resnet18", "--out", out], 1 << 20)
    line = _one_line(res, out)
    assert f"is {1 << 20} bytes" in line  # the limit the write ran into
    assert out.read_bytes() == b"the earlier backbone"
    _no_temp_files(out.parent)


def test_a_dataset_shard_past_the_limit(tmp_path, private_cache):
    """The first shard of `data generate` is about 0.4 MB; the manifest written before it is small."""
    out = tmp_path / "data"
    res = _airpose(["data", "generate", "--profile", "smoke", "--out", out, "--workers", "1", "--quiet"], 64 << 10,
                   env={"AIRPOSE_CACHE": str(private_cache)})
    _one_line(res, out / "shard_00000.npz")
    assert not (out / "shard_00000.npz").exists()
    _no_temp_files(out)
    again = _airpose(["data", "generate", "--profile", "smoke", "--out", out, "--workers", "1", "--quiet"], 64 << 10,
                     env={"AIRPOSE_CACHE": str(private_cache)})
    _one_line(again, out / "shard_00000.npz")  # the same line again, nothing in the way


def test_a_prediction_file_past_the_limit(tmp_path):
    """`predict`'s .npz (through ``atomic_path``): the earlier predictions stay."""
    from test_cli_errors import _recording

    from airpose_lib.engine.checkpoint import save_checkpoint
    from airpose_lib.model import build_model
    from airpose_lib.train import TrainConfig

    seq = _recording(tmp_path / "seq")
    torch.manual_seed(0)
    cfg = TrainConfig(variant="airpose", backbone="resnet18", steps=0)
    ckpt = save_checkpoint(tmp_path / "run", {
        "model": build_model("airpose", "resnet18").state_dict(), "optimizer": {}, "rng": [], "step": 0,
        "epoch": 0, "batch_in_epoch": 0, "config": cfg.to_dict(), "world_size": 1, "input_size": 64}, keep=0)
    out = tmp_path / "pred.npz"
    np.savez(out, earlier=np.arange(3))
    before = out.read_bytes()
    res = _airpose(["predict", "--checkpoint", ckpt, "--sequence", seq, "--out", out, "--quiet"], 2 << 10)
    _one_line(res, out)
    assert out.read_bytes() == before
    _no_temp_files(tmp_path)


NOTEBOOK_RUN = """
import sys
from airpose_lib.reproduce.runner import run_profile
root = sys.argv[1] if len(sys.argv) > 1 else {root!r}
report = run_profile("tiny", out_dir=root + "/runs", figures_dir=root + "/figures", notebooks_dir=root + "/notebooks",
                     catalog_path=root + "/catalog.yaml", profiles_dir=root + "/profiles", verbose=False)
print(report.results[0].status, report.results[0].error)
"""


def test_a_notebook_run_past_the_limit_keeps_the_last_good_results(tmp_path):
    """A notebook whose figure does not fit fails as a notebook (the report says so); the last
    good run's folder, executed notebook and report entry stay."""
    from test_reproduce_runner import _write_nb

    nbs = tmp_path / "notebooks"
    nbs.mkdir()
    body = "(__import__('pathlib').Path(output_dir) / 'a.png').write_bytes(b'x' * size)"
    _write_nb(nbs / "00_fig.ipynb", body)
    (tmp_path / "catalog.yaml").write_text(yaml.safe_dump({"notebooks": [
        {"name": "00_fig", "file": "00_fig.ipynb", "reproduces": "a", "figures": ["a.png"]}]}))
    (tmp_path / "profiles").mkdir()
    profile = tmp_path / "profiles" / "tiny.yaml"
    profile.write_text(yaml.safe_dump({"description": "t", "cell_timeout_s": 120, "notebooks": {"00_fig": {"size": 10}}}))
    code = NOTEBOOK_RUN.format(root=str(tmp_path))
    first = _airpose([], 1 << 30, code=code)
    assert first.stdout.startswith("ok"), first.stderr
    run_dir = tmp_path / "runs" / "tiny"
    good = {p: p.read_bytes() for p in (run_dir / "00_fig" / "a.png", run_dir / "notebooks" / "00_fig.ipynb",
                                        tmp_path / "figures" / "a.png")}
    good_results = json.loads((run_dir / "report.json").read_text())["results"]
    profile.write_text(yaml.safe_dump({"description": "t", "cell_timeout_s": 120,
                                       "notebooks": {"00_fig": {"size": 4 << 20}}}))
    second = _airpose([], 2 << 20, code=code)
    assert second.stdout.startswith("failed") and "File too large" in second.stdout, second.stdout + second.stderr
    assert {p: p.read_bytes() for p in good} == good
    assert json.loads((run_dir / "report.json").read_text())["results"] == good_results
    assert json.loads((run_dir / "report.partial.json").read_text())["results"][0]["status"] == "failed"
