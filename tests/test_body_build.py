"""The builder itself: deterministic, atomic, and honest about what it wrote."""
from __future__ import annotations

import json
import os

import numpy as np
import pytest

from airpose_lib.body import open_model as om


@pytest.fixture
def small_build(tmp_path, monkeypatch, open_model_files, shared_anny_cache):
    # a private kit cache, but anny's own (expensive) cache stays shared
    monkeypatch.setenv("AIRPOSE_CACHE", str(tmp_path))
    return om.OpenModelConfig(num_samples=60, seed=7)


def _arrays(path):
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


def test_same_seed_same_model_and_no_leftovers(small_build, tmp_path):
    first = om.build_open_model(genders=("female",), config=small_build)["female"]
    a = _arrays(first)
    second = om.build_open_model(genders=("female",), config=small_build, force=True)["female"]
    b = _arrays(second)
    assert a.keys() == b.keys()
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    leftovers = [p.name for p in first.parent.iterdir() if p.name.endswith(".tmp")]
    assert not leftovers
    info = json.loads(first.with_suffix(".json").read_text())
    assert info["config"]["num_samples"] == 60 and info["config"]["seed"] == 7


def test_existing_file_is_not_rebuilt(small_build):
    path = om.build_open_model(genders=("male",), config=small_build)["male"]
    stamp = path.stat().st_mtime_ns
    om.build_open_model(genders=("male",), config=small_build)
    assert path.stat().st_mtime_ns == stamp


def test_failed_write_keeps_the_previous_file(tmp_path):
    from airpose_lib.atomic import atomic_path

    target = tmp_path / "model.npz"
    target.write_bytes(b"old")
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_bytes(b"half")
            raise RuntimeError("interrupted")
    assert target.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["model.npz"]


def test_anny_cache_follows_the_kit_cache_and_leaves_the_environment_alone(tmp_path, monkeypatch):
    """anny's cache is <$AIRPOSE_CACHE>/anny at every load, or $ANNY_CACHE_DIR when the user set it;
    the kit never writes it into os.environ (once it did, and a process that moved $AIRPOSE_CACHE
    kept building anny's ~0.8 GB into the first folder, after that folder was deleted)."""
    import anny
    import anny.paths

    monkeypatch.setattr(anny.paths, "_ANNY_CACHE_DIR", [anny.paths.get_anny_cache_path()])  # restored after
    monkeypatch.setattr(anny, "Anny", lambda: None)  # the cache path is set before anny builds anything
    monkeypatch.delenv("ANNY_CACHE_DIR", raising=False)
    for name in ("first", "second"):
        monkeypatch.setenv("AIRPOSE_CACHE", str(tmp_path / name))
        om._load_anny()
        assert anny.paths.get_anny_cache_path() == tmp_path / name / "anny"
        assert "ANNY_CACHE_DIR" not in os.environ
    monkeypatch.setenv("ANNY_CACHE_DIR", str(tmp_path / "mine"))
    om._load_anny()
    assert anny.paths.get_anny_cache_path() == tmp_path / "mine"
