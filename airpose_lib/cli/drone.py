"""``python -m airpose_lib.cli.drone ARGS`` = ``airpose node ARGS``: how the launcher starts a drone.

The same command in a process of its own that ends without the interpreter's teardown (torch's
takes seconds on a loaded machine, which would hold up the launcher and a restarted drone).
Not imported by :mod:`airpose_lib.cli` (``python -m`` would then run this module twice).
"""
from __future__ import annotations

import logging
import os
import sys
from collections.abc import Sequence

from airpose_lib.cli import main as cli_main  # one error policy: one line, exit status 2

__all__ = ["main"]


def main(argv: Sequence[str] | None = None) -> int:
    """``airpose node`` with ``argv`` (default: this process's arguments)."""
    return cli_main(["node", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":  # pragma: no cover
    status = main()
    # Everything is written and closed by now: skip the teardown.
    sys.stdout.flush()
    sys.stderr.flush()
    logging.shutdown()
    os._exit(status)
