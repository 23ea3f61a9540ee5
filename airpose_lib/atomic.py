"""Writing a file without ever leaving half of one.

:func:`atomic_path` is how every writer of the kit puts a file on disk (shards, manifests,
checkpoints, predictions, sequence folders, runtime results). Imports nothing of the kit, so any
layer may use it; its temp files are the ``.NAME.XXXX.tmp`` that :mod:`airpose_lib.folder_lock`
clears after a writer died.
"""
from __future__ import annotations

import contextlib
import errno
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

__all__ = ["atomic_path"]


@contextlib.contextmanager
def atomic_path(target: Path) -> Iterator[Path]:
    """Yield a temporary path beside ``target``; move it over ``target`` only if the block succeeds.

    A crash or Ctrl-C leaves the previous file (or none) in place, never a truncated one. A full
    disk raises ``OSError(ENOSPC)`` naming ``target``.
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
    except OSError as e:
        if e.errno in (errno.ENOSPC, errno.EDQUOT) and e.filename is None:
            # The writers (zipfile, torch.save, numpy) do not say which file the full disk stopped.
            raise OSError(e.errno, os.strerror(e.errno), str(target)) from e
        raise
    finally:
        if tmp_path.exists():
            tmp_path.unlink()
