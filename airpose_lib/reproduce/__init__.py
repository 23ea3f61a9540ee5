"""Reproduce the paper's artefacts by running the kit's notebooks (papermill) under a profile.

Profiles (``airpose_lib/profiles/smoke.yaml``, ``cpu.yaml``, ``paper.yaml``, read through
:mod:`airpose_lib.profiles`) are the one place where sizes live; ``catalog.yaml`` lists the
notebooks in order and the figures each must write.
Library code never imports this package; ``airpose reproduce`` and CI do.
"""

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
from airpose_lib.reproduce.notebook import notebook_defaults

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
    "notebook_defaults",
    "notebook_outputs",
    "run_profile",
]
