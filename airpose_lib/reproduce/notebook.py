"""A notebook run by hand gets the same parameters as ``airpose reproduce --profile P``.

Under ``reproduce`` papermill injects a profile's ``notebooks: <name>:`` values; in JupyterLab
nobody does. A notebook leaves such parameters at ``None`` in its parameters cell and passes them
through :func:`notebook_defaults`, which fills each ``None`` from the profile it names, and an
unset ``output_dir`` with the folder ``reproduce`` would use (``<runs>/<profile>/<notebook>``), so a
run by hand and a run by ``reproduce`` read and write the same places.
"""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace
from typing import Any

from airpose_lib.paths import run_path
from airpose_lib.reproduce.runner import load_profile

__all__ = ["notebook_defaults"]


def notebook_defaults(notebook: str, profile: str, output_dir: str | Path | None = None,
                      **values: Any) -> SimpleNamespace:
    """Fill the parameters a notebook left at ``None`` from ``profile``'s ``notebooks:`` section.

    Args:
        notebook: catalogue name (``"02_ablation_table"``).
        profile: profile name or YAML path, as in the notebook's ``profile`` parameter.
        output_dir: the notebook's ``output_dir``; None: ``<runs>/<profile>/<notebook>``.
        **values: the notebook's parameters; a value given (not None) is kept as it is.

    Returns:
        A namespace with ``output_dir`` (an absolute :class:`~pathlib.Path`, created) and every
        key of ``values``; a ``None`` the profile does not set stays ``None``.
    """
    prof = load_profile(profile)
    section = prof["notebooks"].get(notebook, {})
    filled = {k: (section.get(k) if v is None else v) for k, v in values.items()}
    out = Path(output_dir) if output_dir is not None else run_path(prof["name"], notebook)
    out = out.expanduser().resolve()
    out.mkdir(parents=True, exist_ok=True)
    return SimpleNamespace(output_dir=out, **filled)
