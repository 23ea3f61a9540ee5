"""Writing a file without ever leaving half of one.

:func:`atomic_path` is how every writer of the kit puts a file on disk (shards, manifests,
checkpoints, predictions, sequence folders, runtime results); :func:`atomic_torch_save` is the
one way a torch file is written. Imports nothing of the kit, so any layer may use it; its temp
files are the ``.NAME.XXXX.tmp`` that :mod:`airpose_lib.folder_lock` clears after a writer died.
"""
from __future__ import annotations

import contextlib
import errno
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

__all__ = ["NO_ROOM", "atomic_path", "atomic_torch_save", "no_room_error"]


@contextlib.contextmanager
def atomic_path(target: Path) -> Iterator[Path]:
    """Yield a temporary path beside ``target``; move it over ``target`` only if the block succeeds.

    A crash or Ctrl-C leaves the previous file (or none) in place, never a truncated one. A full
    disk or a file size limit raises ``OSError`` (:data:`NO_ROOM`) naming ``target``.
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp_path, 0o666 & ~umask)  # mkstemp makes 0600; give the file normal permissions
        os.replace(tmp_path, target)
    except Exception as e:
        full = no_room_error(e)
        if full is not None and full.filename is None:
            # The writers (zipfile, torch.save, numpy) do not say which file the full disk stopped.
            raise OSError(full.errno, os.strerror(full.errno), str(target)) from e
        raise
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


#: The errors of a write that found no room: a full disk, a full quota, a file past the largest the
#: process may write (``ulimit -f``) or the file system holds.
NO_ROOM = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)


def no_room_error(exc: BaseException | None) -> OSError | None:
    """The :data:`NO_ROOM` error in the chain of ``exc``, if any: a writer's clean-up often raises
    again over it (zipfile's close, torch's end-of-archive ``RuntimeError: ... unexpected pos``)."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, OSError) and exc.errno in NO_ROOM:
            return exc
        exc = exc.__cause__ or exc.__context__
    return None


def atomic_torch_save(obj: object, target: Path) -> Path:
    """``torch.save(obj)`` to ``target`` through :func:`atomic_path`.

    torch writes through a Python file object here, not a path: given a path, torch's C++ writer
    turns a full disk into ``RuntimeError: ... unexpected pos`` with no errno anywhere, which reads
    as a bug; through a file object the ``OSError`` (:data:`NO_ROOM`) stays in the chain, and
    :func:`atomic_path` raises it naming ``target``, the previous file left in place.

    Returns:
        ``target`` as a Path.
    """
    import torch  # only the writers of torch files pay for it; the helpers stay standard library

    target = Path(target)
    with atomic_path(target) as tmp, open(tmp, "wb") as f:
        torch.save(obj, f)
    return target
