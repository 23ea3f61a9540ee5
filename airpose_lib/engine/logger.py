"""Training log: a CSV file (always) and TensorBoard (when ``tensorboard`` is installed).

The kit does not depend on ``tensorboard``; without it ``torch.utils.tensorboard`` does not import
and only the CSV is written (``RunLogger.tensorboard`` is then False).
"""

from __future__ import annotations

import contextlib
import csv
from collections.abc import Mapping
from pathlib import Path

from airpose_lib.folder_lock import folder_lock

__all__ = ["RunLogger", "read_log"]

_FIXED = ("step", "epoch", "split", "time_s", "lr")


class RunLogger:
    """Append rows ``step, epoch, split, time_s, lr, <loss terms>`` to ``<out>/log.csv``.

    Args:
        out_dir: run folder.
        resume_step: when resuming, rows of a later step (written after the checkpoint by the
            interrupted run) are dropped first, so the log matches a straight run.
        tensorboard: also write TensorBoard events under ``<out>/tb`` if available.
    """

    def __init__(self, out_dir: str | Path, resume_step: int | None = None, tensorboard: bool = True) -> None:
        self.path = Path(out_dir) / "log.csv"
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._lock = contextlib.ExitStack()  # one writer per run folder (re-entrant in this process)
        self._lock.enter_context(folder_lock(out_dir))
        self._columns: list[str] | None = None
        if resume_step is None or not self.path.exists():
            self.path.unlink(missing_ok=True)
        else:
            rows = [r for r in read_log(self.path) if int(r["step"]) <= resume_step]
            self._columns = _columns_of(rows)
            self._rewrite(rows)
        self._tb = None
        if tensorboard:
            try:
                from torch.utils.tensorboard import SummaryWriter

                self._tb = SummaryWriter(str(Path(out_dir) / "tb"), purge_step=resume_step)
            except Exception:  # noqa: BLE001 - tensorboard missing or broken: CSV only
                self._tb = None

    @property
    def tensorboard(self) -> bool:
        return self._tb is not None

    def _rewrite(self, rows: list[dict]) -> None:
        with open(self.path, "w", newline="") as f:
            if self._columns:
                w = csv.DictWriter(f, fieldnames=self._columns, extrasaction="ignore")
                w.writeheader()
                w.writerows(rows)

    def log(self, step: int, epoch: int, split: str, time_s: float, lr: float, values: Mapping[str, float]) -> None:
        row = {"step": step, "epoch": epoch, "split": split, "time_s": f"{time_s:.3f}", "lr": lr,
               **{k: f"{float(v):.8g}" for k, v in values.items()}}
        columns = list(_FIXED) + [k for k in values]
        if self._columns is None:
            self._columns = columns
            self._rewrite([])
        elif any(c not in self._columns for c in columns):  # a new term: rewrite with a wider header
            rows = read_log(self.path)
            self._columns += [c for c in columns if c not in self._columns]
            self._rewrite(rows)
        with open(self.path, "a", newline="") as f:
            csv.DictWriter(f, fieldnames=self._columns, extrasaction="ignore").writerow(row)
        if self._tb is not None:
            for k, v in values.items():
                self._tb.add_scalar(f"{split}/{k}", float(v), step)

    def close(self) -> None:
        if self._tb is not None:
            self._tb.close()
        self._lock.close()


def _columns_of(rows: list[dict]) -> list[str] | None:
    if not rows:
        return None
    cols: list[str] = []
    for r in rows:
        cols += [k for k in r if k not in cols]
    return cols


def read_log(path: str | Path) -> list[dict]:
    """Rows of a ``log.csv`` as dicts of strings (use ``pandas.read_csv`` for analysis)."""
    path = Path(path)
    if not path.exists() or path.stat().st_size == 0:
        return []
    with open(path, newline="") as f:
        return list(csv.DictReader(f))
