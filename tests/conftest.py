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


@pytest.fixture(scope="module")
def module_tmp(tmp_path_factory, request):
    """``mktemp(name) -> Path``: folders that one module's tests share, removed when the module
    ends without a failure (kept for a look otherwise). ``tmp_path_factory``'s own folders stay
    until the session ends: the modules' checkpoints and datasets added up to ~0.85 GB there, on
    top of the running test's, and a CI machine's disk ran out."""
    import shutil

    made = []
    failed_before = request.session.testsfailed

    def mktemp(name: str):
        made.append(tmp_path_factory.mktemp(name))
        return made[-1]

    yield mktemp
    if request.session.testsfailed == failed_before:
        for path in made:
            shutil.rmtree(path, ignore_errors=True)


@pytest.fixture
def shared_anny_cache(monkeypatch):
    """Keep anny's build cache (~0.8 GB) the shared one, ``$ANNY_CACHE_DIR`` or ``<cache>/anny``,
    for a test that then moves ``$AIRPOSE_CACHE``: anny is never rebuilt in a test's folder."""
    from airpose_lib.paths import cache_dir

    monkeypatch.setenv("ANNY_CACHE_DIR", os.environ.get("ANNY_CACHE_DIR") or str(cache_dir() / "anny"))


@pytest.fixture
def private_cache(tmp_path, monkeypatch, open_model_files, shared_anny_cache):
    """``$AIRPOSE_CACHE`` in the test's own folder, for the datasets, backbones and features a test
    makes, with the session's open body model linked in: otherwise each such test rebuilt the body
    (~25 s) in its folder."""
    from airpose_lib.paths import cache_dir

    cache = tmp_path / "cache"
    cache.mkdir()
    (cache / "body").symlink_to(cache_dir() / "body", target_is_directory=True)
    monkeypatch.setenv("AIRPOSE_CACHE", str(cache))
    return cache
