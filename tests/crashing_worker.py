"""A render worker's shard function that dies once, as a native crash in VTK or Mesa would
(tests/test_data_still.py); importable by the spawned workers because tests/ is on sys.path."""
import os
import signal
from pathlib import Path

from airpose_lib.data.still.generate import _worker_shard

CRASHING_SHARD = 1


def crash_once(args: tuple[int, str]) -> dict:
    k, _ = args
    flag = Path(os.environ["AIRPOSE_TEST_CRASH_FLAG"])
    if k == CRASHING_SHARD and not flag.exists():
        flag.touch()
        os.kill(os.getpid(), signal.SIGSEGV)
    return _worker_shard(args)
