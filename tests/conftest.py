"""Shared fixtures. The open body model is built once per cache (~1 min cold, incl. anny's own
build) and reused by every test that needs it."""
from __future__ import annotations

import os

import pytest

os.environ.setdefault("PYVISTA_OFF_SCREEN", "true")
os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture(scope="session")
def open_model_files():
    """gender -> path of the cached open SMPL-X-format files (built on first use)."""
    from airpose_lib.body import build_open_model

    return build_open_model()


@pytest.fixture(scope="session")
def open_model(open_model_files):
    """The neutral open model as an ``smplx.SMPLX`` in float64."""
    import torch

    from airpose_lib.body import load_body_model

    return load_body_model("open", "neutral", dtype=torch.float64)
