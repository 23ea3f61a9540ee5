"""Child processes that never outlive their parent, however the parent dies.

:func:`die_with_parent` is called first thing in a worker (a pool initializer, a drone started by
the launcher). On Linux it asks the kernel for SIGKILL when the parent exits
(``prctl(PR_SET_PDEATHSIG)``, effective even if the parent is SIGKILLed); everywhere, a daemon
thread also checks once a second that the parent is still the one we started under, which
covers other systems and the race of a parent dying before the ``prctl`` call.
Imports nothing of the kit.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal
import sys
import threading
import time

__all__ = ["die_with_parent"]

_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


def _set_pdeathsig(sig: int) -> bool:
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        return libc.prctl(_PR_SET_PDEATHSIG, int(sig), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _watch(parent: int, period_s: float) -> None:
    while True:
        time.sleep(period_s)
        if os.getppid() != parent:  # re-parented: our parent is gone
            os._exit(1)


def die_with_parent(parent: int | None = None, period_s: float = 1.0) -> bool:
    """Make this process exit when its parent process dies.

    Args:
        parent: PID of the parent (default: the current ``os.getppid()``).
        period_s: how often the watchdog thread checks the parent.
    Returns:
        True if the kernel will also SIGKILL us on the parent's death (Linux).
    """
    parent = os.getppid() if parent is None else parent
    armed = _set_pdeathsig(signal.SIGKILL)
    if os.getppid() != parent:  # it died before the prctl took effect
        os._exit(1)
    threading.Thread(target=_watch, args=(parent, period_s), daemon=True, name="die-with-parent").start()
    return armed
