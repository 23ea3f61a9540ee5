"""One progress bar for the whole kit: widgets in Jupyter, a live bar in terminals, a line every
few seconds in logs.

``tqdm.auto`` already picks the widget bar inside a notebook kernel (it needs ``ipywidgets``);
what it does not do is notice that its output goes to a file or a pipe, where every redraw of a
plain ``tqdm`` bar is written out (about 176 bytes per training step). :func:`progress_bar` keeps
the bar's behaviour on a terminal and in Jupyter and, anywhere else, redraws at most once per
:data:`LOG_INTERVAL_S` seconds. This module imports nothing else of the kit.
"""
from __future__ import annotations

import os
import sys
from collections.abc import Iterable
from typing import Any

__all__ = ["LOG_INTERVAL_S", "progress_bar", "in_notebook", "on_terminal"]

#: Seconds between two progress lines when the output is neither a terminal nor a notebook.
LOG_INTERVAL_S = 5.0


def in_notebook() -> bool:
    """True inside a Jupyter kernel (JupyterLab, Notebook, or a papermill run)."""
    try:
        from IPython import get_ipython
    except ImportError:
        return False
    shell = get_ipython()
    return shell is not None and type(shell).__name__ == "ZMQInteractiveShell"


def on_terminal(stream=None) -> bool:
    """True when ``stream`` (default ``sys.stderr``, where tqdm writes) is an interactive terminal."""
    stream = sys.stderr if stream is None else stream
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # closed or replaced streams
        return False


def _widgets_available() -> bool:
    try:
        import ipywidgets  # noqa: F401
    except ImportError:
        return False
    return True


class _LineStream:
    """A text stream in which each redraw of a bar starts a new line: tqdm returns to the start
    of the line with a carriage return, which a log file keeps, so every redraw of a run would
    otherwise pile up on one physical line."""

    def __init__(self, stream) -> None:
        self._stream = stream
        self._at_line_start = True

    def write(self, s: str) -> int:
        if s.startswith("\r"):
            s = ("" if self._at_line_start else "\n") + s[1:]
        s = s.replace("\r", "\n")
        if s:
            self._at_line_start = s.endswith("\n")
        return self._stream.write(s)

    def flush(self) -> None:
        self._stream.flush()


def progress_bar(iterable: Iterable | None = None, *, total: int | None = None, desc: str | None = None,
                 enabled: bool = True, **kwargs: Any):
    """A ``tqdm`` bar suited to where the output goes.

    * in a Jupyter kernel with ``ipywidgets``: the widget bar (``tqdm.notebook``), unless the
      kernel is run by papermill (``AIRPOSE_PROGRESS=log``), whose saved notebook keeps text;
    * on a terminal: the usual bar;
    * anywhere else (a log file, CI, a pipe): a text line at most every :data:`LOG_INTERVAL_S`
      seconds (``mininterval``), without cursor tricks.

    ``AIRPOSE_PROGRESS=off`` disables every bar, ``log`` forces the throttled text form.

    Args:
        iterable: wrapped like ``tqdm(iterable)``; None for a manual bar (``update``).
        total: number of steps (default ``len(iterable)`` when it has one).
        desc: label in front of the bar.
        enabled: False returns a disabled bar (same interface, prints nothing).
        **kwargs: passed to ``tqdm`` (``unit``, ``initial``, ``smoothing`` ...).
    """
    mode = os.environ.get("AIRPOSE_PROGRESS", "auto").lower()
    disable = not enabled or mode == "off"
    if not disable and mode != "log" and in_notebook() and _widgets_available():
        from tqdm.notebook import tqdm as widget_tqdm

        return widget_tqdm(iterable, total=total, desc=desc, **kwargs)
    from tqdm import tqdm

    if not disable and (mode == "log" or not on_terminal()):
        kwargs.setdefault("mininterval", LOG_INTERVAL_S)
        kwargs.setdefault("maxinterval", max(LOG_INTERVAL_S, 10.0))
        kwargs.setdefault("dynamic_ncols", False)
        kwargs.setdefault("ncols", 100)
        kwargs.setdefault("ascii", True)
        kwargs.setdefault("file", _LineStream(sys.stderr))
    return tqdm(iterable, total=total, desc=desc, disable=disable, **kwargs)
