"""Reproduce the paper's artefacts by running the kit's notebooks (papermill) under a profile.

Profiles (``airpose_lib/profiles/smoke.yaml``, ``cpu.yaml``, ``paper.yaml``, read through
:mod:`airpose_lib.profiles`) are the one place where sizes live; ``catalog.yaml`` lists the
notebooks in order and the figures each must write.
Library code never imports this package; ``airpose reproduce``, CI and the notebooks
(:func:`setup_notebook`) do.
"""

import importlib

from airpose_lib.reproduce.runner import (
    CATALOG_PATH,
    PROFILES_DIR,
    CatalogEntry,
    NotebookResult,
    ReproductionError,
    RunReport,
    check_notebook,
    list_profiles,
    load_catalog,
    load_profile,
    notebook_outputs,
    run_profile,
)

# The notebooks' set-up (.notebook) pulls in matplotlib and the assets; `airpose reproduce` does not
# need them to start, so those names are imported on first use.
_NOTEBOOK_NAMES = ("NotebookContext", "notebook_defaults", "setup_notebook")


def __getattr__(name: str):
    if name in _NOTEBOOK_NAMES:
        return getattr(importlib.import_module("airpose_lib.reproduce.notebook"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "CATALOG_PATH",
    "PROFILES_DIR",
    "CatalogEntry",
    "NotebookResult",
    "ReproductionError",
    "RunReport",
    "check_notebook",
    "list_profiles",
    "load_catalog",
    "load_profile",
    "NotebookContext",
    "notebook_defaults",
    "notebook_outputs",
    "run_profile",
    "setup_notebook",
]
