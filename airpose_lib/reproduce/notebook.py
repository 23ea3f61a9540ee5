"""The set-up every notebook does first, in one call: :func:`setup_notebook`.

A notebook run by hand gets the same parameters as ``airpose reproduce --profile P``. Under
``reproduce`` papermill injects a profile's ``notebooks: <name>:`` values; in JupyterLab nobody
does. A notebook leaves such parameters at ``None`` in its parameters cell and passes them through
:func:`notebook_defaults`, which fills each ``None`` from the profile it names, and an unset
``output_dir`` with the folder ``reproduce`` would use (``<runs>/<profile>/<notebook>``), so a run
by hand and a run by ``reproduce`` read and write the same places.

:func:`setup_notebook` adds what every notebook did next in its own few lines: the kit's figure
style, the data source (official assets when asked for and present, else the generated data; its
message printed), the kit's warnings shown in the notebook, and the parameters recorded in every
figure (:func:`airpose_lib.viz.save_figure`). Unlike :mod:`.runner`, which must run any notebook,
this module is the notebooks' side of ``reproduce`` and uses the kit's ``assets`` and ``viz``.
"""
from __future__ import annotations

import logging
import sys
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from airpose_lib.assets import DataSource, resolve_data_source
from airpose_lib.paths import figures_root, run_path, runs_root
from airpose_lib.profiles import loaded
from airpose_lib.reproduce.configs import kit_configs
from airpose_lib.reproduce.runner import load_profile
from airpose_lib.viz import use_kit_style

__all__ = ["NotebookContext", "notebook_defaults", "setup_notebook"]

#: Loggers of the kit whose warnings a notebook shows in its output.
KIT_LOGGERS = ("airpose_lib", "airpose")


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


@dataclass
class NotebookContext:
    """What a notebook works with after :func:`setup_notebook`.

    Attributes:
        notebook: catalogue name.
        profile: the ``profile`` parameter (name or YAML path), read once
            (:class:`~airpose_lib.profiles.Profile`): how titles and records name the profile.
        configs: that profile's sections as typed configs, with its folders
            (:class:`~airpose_lib.experiments.configs.KitConfigs`): the notebook passes these down.
        out: the output folder (absolute, created).
        runs: the kit's runs folder (:func:`airpose_lib.paths.runs_root`).
        figures: ``figures/<profile>/``, where ``reproduce`` collects the catalogued figures.
        source: the resolved data source; ``source.roots`` names the official folders.
        values: the notebook's parameters, each ``None`` filled from the profile; also readable
            as attributes (``ctx.seeds``).
        params: what every figure records (notebook, profile, the data source used, ``values``
            and the notebook's extra entries).
    """

    notebook: str
    profile: str
    out: Path
    runs: Path
    figures: Path
    source: DataSource
    values: dict[str, Any] = field(default_factory=dict)
    params: dict[str, Any] = field(default_factory=dict)
    configs: Any = None

    def __getattr__(self, name: str) -> Any:
        # only called for names that are not fields: the resolved parameters
        values = self.__dict__.get("values", {})
        if name in values:
            return values[name]
        raise AttributeError(f"{self.notebook!r} has no parameter {name!r}")

    @property
    def official(self) -> bool:
        """True when the notebook runs on the official assets."""
        return self.source.source == "official"


def _show_kit_warnings() -> None:
    """Kit warnings go to the notebook's output (stdout), once per logger however often a
    notebook is set up in one kernel."""
    for name in KIT_LOGGERS:
        logger = logging.getLogger(name)
        if not any(getattr(h, "_airpose_notebook", False) for h in logger.handlers):
            handler = logging.StreamHandler(sys.stdout)
            handler.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
            handler.setLevel(logging.WARNING)
            handler._airpose_notebook = True
            logger.addHandler(handler)


def setup_notebook(notebook: str, profile: str, output_dir: str | Path | None = None, *,
                   data_source: str = "generated", needs: tuple[str, ...] | list[str] = (),
                   record: dict[str, Any] | None = None, generated_only: str | None = None,
                   **values: Any) -> NotebookContext:
    """Everything a notebook does before its first step, in one call.

    Args:
        notebook: catalogue name (``"06_online_runtime"``).
        profile: the notebook's ``profile`` parameter.
        output_dir: its ``output_dir`` parameter (None: ``<runs>/<profile>/<notebook>``).
        data_source: its ``data_source`` parameter, ``"generated"`` or ``"official"``.
        needs: the official assets an official run needs (``["official_real"]``); the official
            data is used only when all of them are present, else the generated data, and the
            message saying which is printed.
        record: extra entries for ``params`` (what the figures record).
        generated_only: for a notebook that shows the generated data whatever is asked for: why
            (printed when ``data_source`` is ``"official"``).
        **values: the notebook's parameters; each ``None`` takes the profile's value.

    Returns:
        The :class:`NotebookContext`.
    """
    profile = loaded(profile)  # read once here, and typed once (ctx.configs): the notebook passes those down
    p = notebook_defaults(notebook, profile, output_dir, **values)
    use_kit_style()
    _show_kit_warnings()
    if generated_only is not None and data_source != "generated":
        source = DataSource(data_source, "generated", f"Data source: the kit's generated data ({generated_only}).")
    else:
        source = resolve_data_source(data_source, needs=needs)
    print(source.message)
    filled = {k: getattr(p, k) for k in values}
    params = {"notebook": notebook, "profile": profile, "data_source": source.source, **filled,
              **(record or {})}
    name = profile.name
    return NotebookContext(notebook=notebook, profile=profile, out=p.output_dir, runs=runs_root(),
                           figures=figures_root() / name, source=source, values=filled, params=params,
                           configs=kit_configs(profile))
