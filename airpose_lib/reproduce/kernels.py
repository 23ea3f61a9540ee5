"""The notebook kernels of a reproduction: the environment they inherit, the local (IPC) sockets
they listen on, the worker thread papermill runs in, and how SIGINT / SIGTERM stop them at once
(:mod:`airpose_lib.reproduce.runner` runs the notebooks with these). Like the runner, it imports
nothing of the kit but :mod:`airpose_lib.paths`.
"""
from __future__ import annotations

import contextlib
import logging
import os
import shutil
import signal
import threading
import weakref
from collections.abc import Iterator
from pathlib import Path

from airpose_lib.paths import repo_root

__all__ = ["kernel_environment", "ipc_kernel_manager", "Interrupted", "in_worker_thread", "stop_on_signals"]


@contextlib.contextmanager
def kernel_environment(extra: dict[str, str] | None = None) -> Iterator[dict[str, str]]:
    """Temporarily set the environment the notebook kernels inherit, then restore it.

    VTK renders through EGL without an X server, matplotlib uses Agg, progress bars print a text
    line every few seconds (a widget bar would be saved as a dead widget), interactive views draw
    their static fallback, and the checkout is put on ``PYTHONPATH`` so the kernel imports this kit
    even when it is not pip-installed.
    """
    env = {
        "PYVISTA_OFF_SCREEN": "true",
        "VTK_DEFAULT_OPENGL_WINDOW": "vtkEGLRenderWindow",
        "MPLBACKEND": "Agg",
        "AIRPOSE_PROGRESS": "log",
        "AIRPOSE_INTERACTIVE": "0",
    }
    if (checkout := repo_root()) is not None:
        paths = [str(checkout)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
        env["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(paths))
    env.update(extra or {})
    saved = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    try:
        yield env
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def ipc_kernel_manager():
    """A kernel manager whose kernel listens on IPC sockets in a private temporary folder.

    nbclient's default TCP transport makes ipykernel (>= 7) warn "Kernel is running over TCP
    without encryption" in every executed notebook; local sockets are neither exposed nor warned
    about. The kernel is not interrupted on its way to shutdown (see the method). The socket files live in one private temporary folder of this process (removed at
    exit), never in the checkout; the kernel manager deletes each kernel's sockets when it ends.
    """
    import uuid

    from jupyter_client.manager import AsyncKernelManager
    from traitlets import default

    class IPCKernelManager(AsyncKernelManager):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            _LIVE_KERNELS.add(self)  # a stop signal kills their kernels (stop_on_signals)

        async def _async_interrupt_kernel(self) -> None:
            # jupyter_client sends SIGINT before every shutdown; a kernel caught between messages
            # then logs "KeyboardInterrupt caught in kernel" on the runner's terminal. The notebook
            # has finished (or its cell timed out and was interrupted already): nothing to stop.
            if not self.shutting_down:
                await super()._async_interrupt_kernel()

        @default("transport")
        def _transport_default(self) -> str:
            return "ipc"

        @default("ip")
        def _ip_default(self) -> str:
            return str(_socket_dir() / f"kernel-{uuid.uuid4().hex[:8]}")

    return IPCKernelManager


_SOCKET_DIR: Path | None = None
_LIVE_KERNELS: "weakref.WeakSet" = weakref.WeakSet()


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM stopped the run (the notebook's kernel was killed; finished notebooks and
    checkpoints stay, and the same command resumes). A ``KeyboardInterrupt``: the ``airpose``
    command prints one line for it."""


def _kernel_pids() -> list[int]:
    pids = []
    for km in list(_LIVE_KERNELS):
        process = getattr(getattr(km, "provisioner", None), "process", None)
        if process is not None and process.poll() is None:
            pids.append(process.pid)
    return pids


def in_worker_thread(fn, *args, **kwargs):
    """``fn(*args, **kwargs)`` in a worker thread, while the main thread waits and keeps handling
    signals (:func:`stop_on_signals`). In the main thread nbclient replaces the SIGINT and SIGTERM
    handlers with its own, which shut the kernel down politely after the running cell (and print
    a ZMQ traceback); outside it, it leaves them alone."""
    box: dict = {}

    def target() -> None:
        try:
            box["value"] = fn(*args, **kwargs)
        except BaseException as e:  # noqa: BLE001 - re-raised in the caller's thread
            box["error"] = e

    worker = threading.Thread(target=target, name="papermill", daemon=True)
    worker.start()
    while worker.is_alive():
        worker.join(0.2)  # returns to the interpreter: a signal's handler runs within 0.2 s
    if "error" in box:
        raise box["error"]
    return box.get("value")


@contextlib.contextmanager
def stop_on_signals() -> Iterator[list[int]]:
    """SIGINT and SIGTERM stop the run at once and quietly.

    The signal kills the running notebook's kernel with its whole process group (the kernel is a
    session leader: its training workers go with it); nbclient, running in a worker thread
    (:func:`in_worker_thread`), then finds the kernel dead and papermill returns, and
    :func:`~airpose_lib.reproduce.runner.run_profile` raises :class:`Interrupted`. A run started in the background ignores
    SIGINT unless the handler is set here. Yields the list that receives the signal's number.
    """
    caught: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield caught
        return

    def handler(signum, frame):
        caught.append(signum)
        pids = _kernel_pids()
        for pid in pids:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(pid, signal.SIGKILL)
        if not pids:  # between notebooks: stop right here
            raise Interrupted(signal.Signals(signum).name)

    def after_stop(record) -> bool:  # nbclient's "Kernel died ..." is our doing, not news
        return not caught

    loggers = [logging.getLogger(name) for name in ("papermill", "traitlets")]
    previous = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}
    for log in loggers:
        log.addFilter(after_stop)
    try:
        yield caught
    finally:
        for log in loggers:
            log.removeFilter(after_stop)
        for sig, old in previous.items():
            signal.signal(sig, old)


def _socket_dir() -> Path:
    """This process's folder for kernel sockets, created on first use and removed at exit."""
    global _SOCKET_DIR
    if _SOCKET_DIR is None:
        import atexit
        import tempfile

        _SOCKET_DIR = Path(tempfile.mkdtemp(prefix="airpose-kernels-"))
        atexit.register(shutil.rmtree, _SOCKET_DIR, ignore_errors=True)
    return _SOCKET_DIR
