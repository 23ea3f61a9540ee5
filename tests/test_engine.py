"""The training engine on a toy task: resume (after a stop or a crash) equals an uninterrupted run,
one writer per run folder, cadences of log / validation / checkpoints, in-memory runs.

The toy task draws from every source a real training does: a seeded data order (its own
generator), dropout (torch's global RNG) and per-step numpy noise (numpy's global RNG), so a
resume that lost or replayed any RNG state would end with other weights.
"""
from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest
import torch
from torch import nn

from airpose_lib.engine import Schedule, TrainingTask, load_checkpoint, read_log, run_engine
from airpose_lib.folder_lock import FolderBusyError

N, B = 24, 4  # samples, batch size: 6 batches per epoch


class ToyTask(TrainingTask):
    """Regress y = X w* with a dropout MLP; logs ``total`` and ``mse``."""

    def __init__(self, seed: int = 0, crash_at: int | None = None) -> None:
        torch.manual_seed(seed)
        self.model = nn.Sequential(nn.Linear(3, 8), nn.Dropout(0.3), nn.Linear(8, 1))
        self.optimizer = torch.optim.Adam(self.model.parameters(), lr=1e-2)
        g = torch.Generator().manual_seed(seed)
        self.X = torch.randn(N, 3, generator=g)
        self.y = self.X @ torch.tensor([[1.0], [-2.0], [0.5]])
        self.seed, self.crash_at = seed, crash_at
        self.validated: list[int] = []

    def batches(self, epoch, start):
        order = torch.randperm(N, generator=torch.Generator().manual_seed(self.seed * 1000 + epoch))
        for b in range(start, N // B):
            yield order[b * B:(b + 1) * B]

    def train_step(self, idx, step):
        if self.crash_at is not None and step + 1 == self.crash_at:
            raise KeyboardInterrupt  # a killed job: nothing is written on the way out
        noise = torch.from_numpy(np.random.normal(0.0, 0.01, (len(idx), 1))).float()
        mse = (self.model(self.X[idx]) - self.y[idx] - noise).square().mean()
        return {"total": mse, "mse": mse.detach()}

    def start(self, run):
        torch.manual_seed(self.seed + 1)
        np.random.seed(self.seed + 2)

    def validate(self, run):
        self.validated.append(run.step)
        was = self.model.training
        self.model.eval()
        with torch.no_grad():
            value = float((self.model(self.X) - self.y).square().mean())
        self.model.train(was)
        return {"total": value}

    def checkpoint_state(self):
        return {"config": {"seed": self.seed}}

    def config(self):
        return {"seed": self.seed}


SCHEDULE = Schedule(steps=15, log_every=2, checkpoint_every=4, val_every=5)


def _rows(folder):
    return [{k: v for k, v in r.items() if k != "time_s"} for r in read_log(folder / "log.csv")]


def _same_weights(a: nn.Module, b: nn.Module) -> None:
    for (k, x), y in zip(a.state_dict().items(), b.state_dict().values()):
        assert torch.equal(x, y), k


@pytest.fixture(scope="module")
def straight(module_tmp):
    out = module_tmp("straight")
    task = ToyTask()
    result = run_engine(task, SCHEDULE, out)
    return out, task, result


def test_straight_run_cadences(straight):
    out, task, result = straight
    assert result.step == 15 and not result.stopped_early and not result.resumed
    assert result.checkpoint == out / "checkpoints" / "last.pt"
    assert task.validated == [5, 10, 15]  # every 5 steps and at the last
    rows = _rows(out)
    assert [(int(r["step"]), r["split"]) for r in rows] == (
        [(s, "train") for s in (2, 4)] + [(5, "val")] + [(s, "train") for s in (6, 8, 10)] + [(10, "val")]
        + [(s, "train") for s in (12, 14, 15)] + [(15, "val")])
    assert list(rows[0]) == ["step", "epoch", "split", "lr", "total", "mse"]
    assert int(rows[-2]["epoch"]) == 2  # 6 batches per epoch: step 15 is in the third
    state = load_checkpoint(result.checkpoint)
    assert {"model", "optimizer", "rng", "step", "epoch", "batch_in_epoch", "config", "format_version",
            "kit_version"} <= set(state)
    assert (state["step"], state["epoch"], state["batch_in_epoch"]) == (15, 2, 3)
    assert sorted(p.name for p in (out / "checkpoints").glob("*.pt")) == ["last.pt", "step_00000012.pt",
                                                                           "step_00000015.pt"]


def test_resume_after_stop_equals_straight_run(straight, tmp_path):
    out, task, result = straight
    first = ToyTask()
    stopped = run_engine(first, Schedule(**{**SCHEDULE.__dict__, "stop_at": 7}), tmp_path)
    assert stopped.stopped_early and stopped.step == 7
    second = ToyTask(seed=0)
    resumed = run_engine(second, SCHEDULE, tmp_path)
    assert resumed.resumed and resumed.step == 15
    _same_weights(second.model, task.model)
    assert resumed.values == result.values
    assert _rows(tmp_path) == _rows(out)


def test_resume_after_a_crash_equals_straight_run(straight, tmp_path):
    out, task, result = straight
    with pytest.raises(KeyboardInterrupt):
        run_engine(ToyTask(crash_at=11), SCHEDULE, tmp_path)  # last checkpoint: step 8
    assert load_checkpoint(tmp_path / "checkpoints" / "last.pt")["step"] == 8
    assert max(int(r["step"]) for r in _rows(tmp_path)) == 10  # rows after the checkpoint ...
    again = ToyTask()
    run_engine(again, SCHEDULE, tmp_path)
    _same_weights(again.model, task.model)
    assert _rows(tmp_path) == _rows(out)  # ... are dropped on resume
    assert again.validated == [10, 15]


def test_resume_false_starts_afresh(straight, tmp_path):
    out, task, _ = straight
    run_engine(ToyTask(seed=3), SCHEDULE, tmp_path)
    fresh = ToyTask()
    result = run_engine(fresh, SCHEDULE, tmp_path, resume=False)
    assert not result.resumed
    _same_weights(fresh.model, task.model)


def test_second_writer_is_refused(tmp_path):
    holder = subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(f"""
            import sys, time
            from airpose_lib.folder_lock import folder_lock
            with folder_lock({str(tmp_path)!r}):
                print("held", flush=True)
                sys.stdin.readline()
        """)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        task = ToyTask()
        before = [p.detach().clone() for p in task.model.parameters()]
        with pytest.raises(FolderBusyError, match=str(holder.pid)):
            run_engine(task, SCHEDULE, tmp_path)
        assert all(torch.equal(a, b) for a, b in zip(before, task.model.parameters()))  # no step ran
        assert not (tmp_path / "checkpoints").exists()
    finally:
        holder.communicate("\n", timeout=30)


def test_in_memory_run_writes_nothing_and_matches(straight, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _, task, result = straight
    logged = []

    class Logged(ToyTask):
        def on_log(self, step, values):
            logged.append(step)

    mem = Logged()
    run = run_engine(mem, Schedule(steps=15, log_every=4, log_offset=1, val_every=None))
    assert run.checkpoint is None and run.step == 15 and mem.validated == []
    assert logged == [1, 5, 9, 13, 15]
    _same_weights(mem.model, task.model)  # validation leaves the weights and RNG states alone
    assert list(tmp_path.iterdir()) == []


def test_non_finite_loss_stops_the_run(tmp_path):
    class Diverging(ToyTask):
        def train_step(self, idx, step):
            terms = super().train_step(idx, step)
            return terms if step < 2 else {"total": terms["total"] * float("nan"), "mse": terms["mse"]}

    with pytest.raises(FloatingPointError, match="non-finite loss at step 3"):
        run_engine(Diverging(), SCHEDULE, tmp_path)
