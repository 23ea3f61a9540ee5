"""One writer per run or data folder (an OS lock the kernel drops when its holder dies), temp files
of dead writers removed and those of a live one kept, workers that die with their parent, and no
command rewriting the tracked data_manifests/ unless asked."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from airpose_lib import cli
from airpose_lib.folder_lock import FolderBusyError, folder_lock

ROOT = Path(__file__).resolve().parents[1]
HOLD = ("import sys, time\n"
        "from airpose_lib.folder_lock import folder_lock\n"
        "with folder_lock(sys.argv[1]):\n"
        "    print('LOCKED', flush=True)\n"
        "    time.sleep(120)\n")


def _env() -> dict:
    return dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))


@pytest.fixture
def holder(tmp_path):
    """Another process holding the lock of ``tmp_path / "run"``; yields (folder, Popen)."""
    folder = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-c", HOLD, str(folder)], stdout=subprocess.PIPE, text=True,
                            env=_env())
    try:
        assert proc.stdout.readline().strip() == "LOCKED"
        yield folder, proc
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()


def test_a_second_writer_is_refused_with_the_holders_pid(holder):
    folder, proc = holder
    with pytest.raises(FolderBusyError, match=f"PID {proc.pid}"):
        with folder_lock(folder):
            pass


def test_temp_files_of_a_live_writer_are_kept_and_of_a_dead_one_removed(holder):
    folder, proc = holder
    shard = folder / ".shard_00003.npz.abc.tmp"
    ckpt = folder / "checkpoints" / ".last.pt.xyz.tmp"
    ckpt.parent.mkdir(parents=True)
    keep = folder / "checkpoints" / "last.pt"
    for f in (shard, ckpt, keep):
        f.write_bytes(b"partial")
    with pytest.raises(FolderBusyError):
        with folder_lock(folder):
            pass
    assert shard.exists() and ckpt.exists()  # the holder is alive: its temp files stay
    proc.send_signal(signal.SIGKILL)  # dies without cleaning up; the kernel releases the lock
    proc.wait()
    with folder_lock(folder):
        assert not shard.exists() and not ckpt.exists() and keep.exists()


def test_the_lock_is_reentrant_in_one_process(tmp_path):
    probe = ("import sys\n"
             "from airpose_lib.folder_lock import folder_lock\n"
             "with folder_lock(sys.argv[1]):\n"
             "    print('LOCKED')\n")
    with folder_lock(tmp_path / "run"):
        with folder_lock(tmp_path / "run"):
            pass
        # still held by us: another process is refused
        res = subprocess.run([sys.executable, "-c", probe, str(tmp_path / "run")], capture_output=True, text=True,
                             env=_env(), timeout=120)
        assert res.returncode != 0 and f"PID {os.getpid()}" in res.stderr
    res = subprocess.run([sys.executable, "-c", probe, str(tmp_path / "run")], capture_output=True, text=True,
                         env=_env(), timeout=120)
    assert res.stdout.strip() == "LOCKED", res.stderr  # released


def _finetune_inputs(tmp_path):
    """A loadable (untrained) checkpoint and a three-frame recording."""
    import numpy as np
    import torch

    from airpose_lib.data.sequences.writer import OfficialLayoutWriter
    from airpose_lib.engine.checkpoint import save_checkpoint
    from airpose_lib.model import build_model
    from airpose_lib.train import TrainConfig

    cfg = TrainConfig(variant="airpose", backbone="resnet18", steps=0)
    ckpt = save_checkpoint(tmp_path / "net", {"model": build_model("airpose", "resnet18").state_dict(),
                                              "optimizer": {}, "rng": [], "step": 0, "epoch": 0, "batch_in_epoch": 0,
                                              "config": cfg.to_dict(), "world_size": 1, "input_size": 64}, keep=0)
    w = OfficialLayoutWriter(tmp_path / "seq", num_views=2)
    for i in range(3):
        w.write_frame(i, [np.zeros((64, 96, 3), np.uint8)] * 2)
    w.finish(np.array([[[100.0, 0, 48], [0, 100.0, 32], [0, 0, 1]]] * 2),
             {"openpose": np.full((3, 2, 25, 3), 0.5), "alphapose": np.full((3, 2, 18, 3), 0.5)})
    torch.manual_seed(0)
    return ckpt, tmp_path / "seq"


@pytest.mark.parametrize("argv", [
    ["train", "--variant", "airpose", "--out", "{run}"],
    ["data", "generate", "--out", "{run}"],
    ["finetune", "--checkpoint", "{ckpt}", "--sequence", "{seq}", "--out", "{run}"],
    ["launch", "--drones", "1", "--backend", "fake", "--frames", "2", "--out", "{run}"],
], ids=["train", "data generate", "finetune", "launch"])
def test_commands_refuse_a_folder_in_use(argv, holder, tmp_path, capsys):
    folder, proc = holder
    ckpt, seq = _finetune_inputs(tmp_path)  # finetune reads its inputs before it locks --out
    code = cli.main([a.format(run=folder, ckpt=ckpt, seq=seq) for a in argv])
    err = capsys.readouterr().err
    assert code == 2 and f"PID {proc.pid}" in err and str(folder) in err and len(err.strip().splitlines()) == 1


def test_reproduce_refuses_a_profile_folder_in_use(tmp_path, capsys):
    """`airpose reproduce --out OUT` writes OUT/<profile>/: a second run into it is refused."""
    folder = tmp_path / "out" / "smoke"
    proc = subprocess.Popen([sys.executable, "-c", HOLD, str(folder)], stdout=subprocess.PIPE, text=True,
                            env=_env())
    try:
        assert proc.stdout.readline().strip() == "LOCKED"
        code = cli.main(["reproduce", "--profile", "smoke", "--only", "00", "--out", str(tmp_path / "out"),
                         "--figures", str(tmp_path / "figures")])
    finally:
        proc.kill()
        proc.wait()
    err = capsys.readouterr().err
    assert code == 2 and f"PID {proc.pid}" in err and str(folder) in err and len(err.strip().splitlines()) == 1
    assert not (folder / "report.json").exists()


def test_run_logger_is_a_writer(holder):
    from airpose_lib.engine.logger import RunLogger

    folder, proc = holder
    with pytest.raises(FolderBusyError, match=f"PID {proc.pid}"):
        RunLogger(folder, tensorboard=False)


# -- no orphans ------------------------------------------------------------------------------------
def _stat(pid: int) -> tuple[str, int] | None:
    """(state, ppid) of a process from /proc, None if it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None
    return fields[0], int(fields[1])


def _children(pid: int) -> set[int]:
    """All descendants of ``pid`` (Linux /proc)."""
    parents = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            st = _stat(int(entry.name))
            if st is not None:
                parents[int(entry.name)] = st[1]
    out, frontier = set(), {pid}
    while frontier:
        frontier = {c for c, pp in parents.items() if pp in frontier} - out
        out |= frontier
    return out


def _alive(pid: int) -> bool:
    st = _stat(pid)
    return st is not None and st[0] != "Z"


def _wait_gone(pids: set[int], timeout_s: float = 60.0) -> set[int]:
    """The processes of ``pids`` still alive after waiting up to ``timeout_s``; those are killed
    (so that a failing test leaks nothing into the machine)."""
    t_end = time.time() + timeout_s
    alive = set(pids)
    while alive and time.time() < t_end:
        time.sleep(0.25)
        alive = {k for k in alive if _alive(k)}
    for k in alive:
        os.kill(k, signal.SIGKILL)
    return alive


def _orphans_of_a_killed(argv: list[str], started, min_children: int, timeout_s: float = 300.0) -> set[int]:
    """Run ``python ARGV``, wait until ``started()`` is true (or it ends), SIGKILL it and return its
    descendants still alive a minute later."""
    proc = subprocess.Popen([sys.executable, *argv], env=_env(), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        t_end = time.time() + timeout_s
        while time.time() < t_end and proc.poll() is None and not started():
            time.sleep(0.25)
        kids = _children(proc.pid)
        assert len(kids) >= min_children, kids
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    return _wait_gone(kids)


def test_pool_workers_die_with_a_killed_parent(tmp_path, open_model_files):
    """SIGKILL `airpose data generate --workers 2` mid-run: its two render workers and the
    multiprocessing resource tracker exit too (they used to run on, ~1.7 GB)."""
    data = tmp_path / "data"
    alive = _orphans_of_a_killed(["-m", "airpose_lib", "data", "generate", "--profile", "smoke", "--workers", "2",
                                  "--out", str(data)],
                                 lambda: bool(list(data.glob("shard_*"))),  # the workers render
                                 min_children=3)  # 2 workers + the resource tracker
    assert not alive, f"orphans left: {alive}"


# A run that takes long: the worker leaves a file named by its PID (a file, not a line on the parent's
# stdout, so that nothing about inherited pipes decides the test), then sleeps.
SLEEPER = ("import os, pathlib, time\n"
           "def job(args):\n"
           "    (pathlib.Path(args[3]) / f'worker_{os.getpid()}').touch()\n"
           "    time.sleep(300)\n")
ABLATION_PARENT = ("import sys\n"
                   "sys.path.insert(0, sys.argv[2])\n"
                   "import sleeper\n"
                   "import airpose_lib.train.ablation as A\n"
                   "from airpose_lib.reproduce.configs import kit_configs\n"
                   "A._train_single_thread = sleeper.job  # a run that takes long: it sleeps\n"
                   "A.prepare_data = lambda *a, **k: None\n"
                   "A._finished_run = lambda *a: None\n"
                   "A._train_parallel(kit_configs('smoke').train_inputs(), ['airpose', 'baseline'], [0], sys.argv[1], 2)\n")


def test_ablation_training_workers_die_with_a_killed_parent(tmp_path):
    """SIGKILL the parent of `run_ablation(workers=2)` while both runs train: the two spawned
    training processes exit too (each would otherwise train on for minutes to hours)."""
    (tmp_path / "sleeper.py").write_text(SLEEPER)
    runs = tmp_path / "runs"
    runs.mkdir()
    err = open(tmp_path / "stderr.txt", "w")
    proc = subprocess.Popen([sys.executable, "-c", ABLATION_PARENT, str(runs), str(tmp_path)],
                            stdout=subprocess.DEVNULL, stderr=err, text=True, env=_env())
    workers: set[int] = set()
    try:
        deadline = time.monotonic() + 120
        while len(workers) < 2:
            workers = {int(f.name.split("_")[1]) for f in runs.glob("worker_*")}
            if proc.poll() is not None:  # say how it ended
                pytest.fail(f"the parent ended (exit status {proc.returncode}; negative: killed by that signal) "
                            f"before both workers started; its stderr: {(tmp_path / 'stderr.txt').read_text()!r}")
            assert time.monotonic() < deadline, f"only {len(workers)} of 2 workers started in 120 s"
            time.sleep(0.2)
        kids = _children(proc.pid)
        assert workers <= kids
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        err.close()
    assert not _wait_gone(kids), "orphans left"


def test_drones_die_with_a_killed_launcher(tmp_path):
    """SIGKILL `airpose launch --drones 2` while its drones run: both drone processes exit."""
    out = tmp_path / "online"
    alive = _orphans_of_a_killed(["-m", "airpose_lib", "launch", "--drones", "2", "--backend", "fake", "--frames",
                                  "100000", "--out", str(out)],
                                 lambda: all((out / f"node_{d}.jsonl").exists() for d in (1, 2)), min_children=2)
    assert not alive, f"orphans left: {alive}"


@pytest.mark.slow
def test_ddp_ranks_die_with_a_killed_parent(tmp_path):
    """SIGKILL `airpose train --world-size 2` while its two ranks train: both ranks exit (torch's
    spawn asks the kernel for it, PR_SET_PDEATHSIG; rank 0 holds the run folder's lock)."""
    run = tmp_path / "run"
    alive = _orphans_of_a_killed(["-m", "airpose_lib", "train", "--variant", "airpose", "--profile", "smoke",
                                  "--world-size", "2", "--steps", "100000", "--quiet", "--out", str(run)],
                                 lambda: (run / "log.csv").exists(), min_children=2)  # rank 0 trains
    assert not alive, f"orphans left: {alive}"


def test_die_with_parent_sets_the_kernel_signal():
    code = ("import ctypes, signal\n"
            "from airpose_lib.process_guard import die_with_parent\n"
            "assert die_with_parent()\n"
            "sig = ctypes.c_int()\n"
            "ctypes.CDLL(None).prctl(2, ctypes.byref(sig), 0, 0, 0)\n"  # PR_GET_PDEATHSIG
            "print(sig.value == signal.SIGKILL)\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=_env(), timeout=60)
    assert res.stdout.strip() == "True", res.stderr


# -- tracked files -----------------------------------------------------------------------------------
def test_generation_elsewhere_leaves_the_tracked_manifest_alone(tmp_path, monkeypatch):
    from airpose_lib.data.still.generate import GenerationConfig, generate_still_dataset
    from airpose_lib.data.still.scene import SceneConfig

    tracked = ROOT / "data_manifests" / "generated_smoke.yaml"
    before = tracked.read_bytes()
    cfg = GenerationConfig(num_samples=2, shard_size=2, crop_size=32, seed=3, scene=SceneConfig(num_distractors=(0, 0)))
    m = generate_still_dataset(cfg, tmp_path / "d", workers=1, progress=False, label="smoke")
    assert m["status"] == "complete" and tracked.read_bytes() == before
    generate_still_dataset(cfg, tmp_path / "d", workers=1, progress=False, label="smoke", record=tmp_path / "rec")
    assert (tmp_path / "rec" / "generated_smoke.yaml").is_file() and tracked.read_bytes() == before
    # the CLI records only with --record-manifest
    seen = {}
    import airpose_lib.data.still.generate as gen

    def fake(config, root, **kw):
        seen.update(kw)
        raise gen.DatasetError("stop here")

    monkeypatch.setattr(gen, "generate_still_dataset", fake)
    assert cli.main(["data", "generate", "--out", str(tmp_path / "x")]) == 2 and seen["record"] is False
    assert cli.main(["data", "generate", "--out", str(tmp_path / "x"), "--record-manifest"]) == 2
    assert seen["record"] is True
