"""torchrun: processes launched by ``python -m torch.distributed.run`` (the same as
``torchrun``) train from the environment alone, finish, resume, and match one process.

The default run launches the kit's training on fake still frames (tests/torchrun_train.py, gloo on
CPU: two launches of 2 processes, ~15 s each); the slow test runs ``airpose train`` under torchrun
on a profile file of one's own with an empty cache (dataset generation and the nested pretraining
that used to deadlock: ~3 min on 2 cores)."""
from __future__ import annotations

import os
import subprocess
import sys
import warnings
from pathlib import Path

import pytest
import torch

from airpose_lib.train import load_checkpoint, read_log, train

REPO = Path(__file__).resolve().parents[1]
HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from test_train_loop import FAKES  # noqa: E402
from torchrun_train import config  # noqa: E402

#: Max |difference| of the weights between 2 processes and 1 after 4 Adam steps of lr 5e-5: the
#: float summation order differs (gradients all-reduced over 2 shares of 2 + 1 samples, weighted
#: 2*2/3 and 1*2/3); measured ~1e-6 on most coordinates. Adam normalises each update to ~lr, so a
#: coordinate whose gradient is ~0 may differ by up to 2 lr per step: allowed for a tiny fraction.
ATOL = 2e-6


def _torchrun(out: Path, steps: int, nproc: int = 2, timeout: int = 300) -> str:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]),
               OMP_NUM_THREADS="1")
    for name in ("RANK", "WORLD_SIZE", "LOCAL_RANK", "MASTER_ADDR", "MASTER_PORT"):
        env.pop(name, None)
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", f"--nproc_per_node={nproc}",
           str(HERE / "torchrun_train.py"), str(out), str(steps)]
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc.stdout


def _close(a: dict, b: dict, steps: int, lr: float) -> None:
    diff = torch.cat([(a[k].double() - b[k].double()).abs().reshape(-1) for k in a])
    assert (diff <= ATOL).double().mean() > 0.9999 and diff.max() <= 2 * steps * lr


def test_torchrun_two_processes_finish_resume_and_match_one(tmp_path, open_model_files):
    """Global batch 3 over 2 processes (2 + 1 samples: the uneven split), stopped at step 2 and
    resumed to 4 by a second launch; equal to a single process within ATOL; the resumed launch
    continues bit for bit; a single process resumes the 2-process checkpoint (another world size)."""
    out = tmp_path / "ddp"
    assert _torchrun(out, 2).count("rank done: step 2 world 2") == 2
    mid = load_checkpoint(out / "checkpoints" / "last.pt")
    assert mid["step"] == 2 and mid["world_size"] == 2 and len(mid["rng"]) == 2
    assert _torchrun(out, 4).count("rank done: step 4 world 2") == 2
    ddp = load_checkpoint(out / "checkpoints" / "last.pt")
    assert ddp["step"] == 4 and ddp["config"]["device"] == "cpu"
    assert not (out / ".airpose.lock").read_text()  # released; rank 0 held it (one writer: one log)
    assert [int(r["step"]) for r in read_log(out / "log.csv")] == [1, 2, 3, 4]

    cfg = config(4, 3)
    single = train("airpose", config=cfg, out_dir=tmp_path / "single", **FAKES)
    a = load_checkpoint(single.checkpoint)["model"]
    _close(a, ddp["model"], cfg.steps, cfg.lr)
    la = [float(r["total"]) for r in read_log(tmp_path / "single" / "log.csv")]
    lb = [float(r["total"]) for r in read_log(out / "log.csv")]
    assert la == pytest.approx(lb, rel=1e-5)  # the logged loss is the global batch's mean
    moved = (a["regressor.fc2.weight"] - mid["model"]["regressor.fc2.weight"]).abs().max()
    assert moved > 10 * ATOL  # steps 3-4 moved the weights far more than the tolerance

    # another world size: one process resumes the 2-process checkpoint of step 2
    other = tmp_path / "resumed1"
    (other / "checkpoints").mkdir(parents=True)
    torch.save(mid, other / "checkpoints" / "last.pt")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r1 = train("airpose", config=cfg, out_dir=other, **FAKES)
    assert r1.step == 4 and any("re-seeded" in str(w.message) for w in caught)
    _close(a, load_checkpoint(r1.checkpoint)["model"], cfg.steps, cfg.lr)


def test_rank_comes_from_torchruns_environment(monkeypatch):
    """Before the process group exists the environment says the rank: `airpose train` under torchrun
    without --world-size lets only rank 0 take the run folder's lock (it used to be every rank, and
    rank 1 exited 'in use by another process'); a prerequisite built alone is rank 0 of 1."""
    from airpose_lib.engine.launch import launch_env, process_rank, single_process

    monkeypatch.setenv("RANK", "1")
    monkeypatch.setenv("WORLD_SIZE", "2")
    monkeypatch.setenv("LOCAL_RANK", "1")
    assert launch_env() == (1, 1, 2) and process_rank() == (1, 2)
    with single_process():  # a prerequisite built alone: rank 0 of 1, joins no group
        assert launch_env() is None and process_rank() == (0, 1)
    monkeypatch.delenv("LOCAL_RANK")
    assert launch_env() == (1, 1, 2)  # one node: LOCAL_RANK defaults to RANK


@pytest.mark.slow
def test_cli_torchrun_on_an_own_profile_with_an_empty_cache(tmp_path):
    """`torchrun -m airpose_lib.cli train --profile FILE.yaml` with nothing cached: the dataset and
    the pretrained backbone are made before the process group exists (a pretraining nested inside the
    group deadlocks), then resumed by a second launch."""
    profile = tmp_path / "tiny.yaml"
    profile.write_text((HERE / "data" / "tiny_profile.yaml").read_text())
    env = dict(os.environ, AIRPOSE_CACHE=str(tmp_path / "cache"), AIRPOSE_RUNS=str(tmp_path / "runs"),
               PYTHONPATH=str(REPO), OMP_NUM_THREADS="1")
    for steps in (2, 4):
        cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node=2", "-m",
               "airpose_lib.cli", "train", "--variant", "airpose", "--profile", str(profile), "--out",
               str(tmp_path / "ddp"), "--steps", str(steps), "--quiet"]
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=900)
        assert proc.returncode == 0, proc.stderr[-3000:]
        assert f"step {steps}  train loss" in proc.stdout
    state = load_checkpoint(tmp_path / "ddp" / "checkpoints" / "last.pt")
    assert state["step"] == 4 and state["world_size"] == 2
    assert len(list((tmp_path / "cache" / "backbones").glob("*.pt"))) == 1
