"""One writer per run or data folder: an OS-level lock, and the temp files of dead writers.

Every command that writes a run folder (training, fine-tuning, the AirPose+ experiment cache) or
a data folder (still-frame generation) holds :func:`folder_lock` on it while it writes. The lock
is ``fcntl.flock`` on ``<folder>/.airpose.lock``: the kernel drops it when the holder's process
ends, however it ends (SIGKILL included), so there is never a stale lock to delete by hand. A
second writer is refused at once with :class:`FolderBusyError`, naming the holder's PID.

Whoever acquires the lock is the folder's only live writer, so temp files left there (the
``.NAME.XXXX.tmp`` of :func:`airpose_lib.atomic.atomic_path`, ``.shard_*.tmp``) belong to
a writer that died midway; they are removed right after the lock is taken, never before.

Within one process the lock is re-entrant (the training loop and its logger both hold it). With
DDP, rank 0 holds it (the process that writes).
Imports nothing of the kit, so any layer may use it.
"""
from __future__ import annotations

import contextlib
import fcntl
import functools
import inspect
import os
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import TypeVar

from airpose_lib.errors import UserError

__all__ = ["LOCK_NAME", "MAKER_WAIT_S", "STALE_PATTERNS", "FolderBusyError", "folder_lock", "file_lock_for",
           "locks_folder", "lock_holder", "file_lock"]

F = TypeVar("F", bound=Callable)

LOCK_NAME = ".airpose.lock"
#: How long a command waits for another process that is making what it needs (a dataset, the
#: recordings): the cpu profile's 32,000 pairs take 11-16 min on two cores, the paper profile's
#: 30,000 larger ones hours.
MAKER_WAIT_S = 6 * 3600.0
# Temp files of the kit's atomic writes, in the folder and one level down (checkpoints/).
STALE_PATTERNS = (".*.tmp", "*/.*.tmp")


class FolderBusyError(UserError, RuntimeError):
    """Another live process holds the folder's lock."""


_guard = threading.Lock()
_held: dict[Path, list] = {}  # lock file -> [open handle, depth] for the locks this process holds


def lock_holder(lock_file: str | Path) -> str:
    """What the holder wrote into a lock file (``pid=... cmd=...``), or ``unknown``."""
    try:
        return Path(lock_file).read_text().strip() or "unknown"
    except OSError:
        return "unknown"


def _busy_message(what: str, folder: Path, lock_file: Path) -> tuple[str, str]:
    """(the holder's PID, the sentence that names it) for a lock another process holds."""
    holder = lock_holder(lock_file)
    pid = holder.split()[0].removeprefix("pid=") if holder != "unknown" else "unknown"
    return pid, f"{what} {folder} is in use by another process (PID {pid}; lock {lock_file})"


def _flock_waiting(handle, lock_file: Path, folder: Path, what: str, wait: float | None) -> None:
    """``flock`` ``handle`` exclusively: at once, or (``wait`` seconds) after its holder lets go,
    with one line on stderr saying whom it waits for. Raises :class:`FolderBusyError`."""
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return
    except BlockingIOError:
        pid, busy = _busy_message(what, folder, lock_file)
    if wait is None:
        raise FolderBusyError(f"{busy}: wait for it to finish or stop it (kill {pid}), or choose another "
                              "output folder")
    print(f"airpose: {busy}; waiting for it to finish (at most {wait:.0f} s)", file=sys.stderr, flush=True)
    deadline = time.monotonic() + wait
    while True:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return
        except BlockingIOError:
            if time.monotonic() >= deadline:
                raise FolderBusyError(f"{busy} and still was after {wait:.0f} s: wait for it to finish or stop "
                                      f"it (kill {pid}), then run this again") from None
            time.sleep(min(1.0, max(0.0, deadline - time.monotonic())))


def _acquire(lock_file: Path, folder: Path, what: str, stale: Sequence[str], wait: float | None = None) -> None:
    with _guard:
        entry = _held.get(lock_file)
        if entry is not None:  # re-entrant within this process
            entry[1] += 1
            return
        folder.mkdir(parents=True, exist_ok=True)
        handle = open(lock_file, "a+")  # never truncated before we hold it: the holder's PID stays readable
        try:
            _flock_waiting(handle, lock_file, folder, what, wait)
        except BaseException:
            handle.close()
            raise
        handle.seek(0)
        handle.truncate()
        handle.write(f"pid={os.getpid()} cmd={' '.join(sys.argv)[:200]}\n")
        handle.flush()
        _held[lock_file] = [handle, 1]
    for pattern in stale:  # we are the only live writer: these are a dead writer's leftovers
        for tmp in folder.glob(pattern):
            if tmp.is_file():
                tmp.unlink(missing_ok=True)


def _release(lock_file: Path) -> None:
    with _guard:
        entry = _held[lock_file]
        entry[1] -= 1
        if entry[1] == 0:
            del _held[lock_file]
            handle = entry[0]
            handle.seek(0)
            handle.truncate()  # nobody holds it now
            fcntl.flock(handle, fcntl.LOCK_UN)
            handle.close()


@contextlib.contextmanager
def folder_lock(folder: str | Path, what: str = "run folder",
                stale: Sequence[str] = STALE_PATTERNS, wait: float | None = None) -> Iterator[Path]:
    """Hold the exclusive lock of ``folder`` (created if needed) for the block; yields the folder.

    Args:
        folder: run or data folder.
        what: how the refusal message calls it (``run folder``, ``dataset folder``).
        stale: glob patterns (relative to ``folder``) of temp files to delete once the lock is held.
        wait: None refuses a second writer at once (two writers of one output are a mistake);
            seconds to wait for the holder instead (a reader that needs what the holder makes),
            with one line on stderr.
    Raises:
        FolderBusyError: another process holds it (after ``wait`` seconds, if given).
    """
    folder = Path(folder).absolute()
    lock_file = folder / LOCK_NAME
    _acquire(lock_file, folder, what, stale, wait)
    try:
        yield folder
    finally:
        _release(lock_file)


@contextlib.contextmanager
def file_lock_for(path: str | Path, what: str = "output file") -> Iterator[Path]:
    """Like :func:`folder_lock` for one output file in a shared folder (``.NAME.lock`` beside it;
    only that file's own temp files ``.NAME.*.tmp`` count as stale)."""
    path = Path(path).absolute()
    lock_file = path.parent / f".{path.name}.lock"
    _acquire(lock_file, path.parent, f"{what} {path.name} in", (f".{path.name}.*.tmp",))
    try:
        yield path
    finally:
        _release(lock_file)


def locks_folder(param: str, what: str = "run folder",
                 stale: Sequence[str] = STALE_PATTERNS) -> Callable[[F], F]:
    """Decorator: hold :func:`folder_lock` on the call's argument ``param`` for the whole call."""
    def decorate(fn: F) -> F:
        signature = inspect.signature(fn)

        @functools.wraps(fn)
        def locked(*args, **kwargs):
            folder = signature.bind(*args, **kwargs).arguments[param]
            with folder_lock(folder, what, stale):
                return fn(*args, **kwargs)
        return locked  # type: ignore[return-value]
    return decorate


@contextlib.contextmanager
def file_lock(path: str | Path) -> Iterator[None]:
    """Exclusive inter-process lock on the file ``path`` that *waits* for its holder (unlike
    :func:`folder_lock`, which refuses a second writer): N processes that need the same cached
    artefact (the open body model, an ONNX export, a backbone) build it once, the others wait."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a+") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)
