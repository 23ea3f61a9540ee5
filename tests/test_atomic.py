"""Torch files on a full disk: the error names the file, and the previous file stays whole."""
from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest
import torch

import airpose_lib.atomic as atomic
from airpose_lib.engine.checkpoint import load_checkpoint, write_checkpoint


class _FillsUp:
    """A file on a disk with ``room`` bytes left: the next write past it fails as the kernel's does."""

    def __init__(self, f, room: int):
        self.f, self.room, self.written = f, room, 0

    def write(self, data) -> int:
        if self.written + len(data) > self.room:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self.written += len(data)
        return self.f.write(data)

    def __getattr__(self, name):
        return getattr(self.f, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.f.close()


def test_a_full_disk_during_a_checkpoint_names_it_and_keeps_the_last_one(tmp_path, monkeypatch):
    path = tmp_path / "checkpoints" / "last.pt"
    write_checkpoint(path, {"step": 1, "w": torch.arange(4.0)})
    before = path.read_bytes()
    real_open = open
    monkeypatch.setattr(atomic, "open", lambda p, mode: _FillsUp(real_open(p, mode), room=4096), raising=False)
    with pytest.raises(OSError) as caught:
        write_checkpoint(path, {"step": 2, "w": torch.zeros(100_000)})
    monkeypatch.undo()
    assert caught.value.errno == errno.ENOSPC and caught.value.filename == str(path)
    assert path.read_bytes() == before and sorted(path.parent.iterdir()) == [path]  # no temp file left
    assert load_checkpoint(path)["step"] == 1


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
def test_torch_through_a_file_object_reports_a_real_full_device_as_enospc():
    """What atomic_torch_save relies on, with the kernel's own ENOSPC (given a path instead, torch
    2.x raises a RuntimeError without an errno)."""
    with pytest.raises(OSError) as caught, open("/dev/full", "wb") as f:
        torch.save({"w": torch.zeros(100_000)}, f)
    assert caught.value.errno == errno.ENOSPC
