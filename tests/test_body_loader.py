"""load_body_model: the licensed-model path, clear errors on missing or damaged files."""
from __future__ import annotations

import shutil

import numpy as np
import pytest
import torch

from airpose_lib.body import BodyModelError, load_body_model, resolve_model_file


def test_smplx_source_without_env_names_files_and_registration(monkeypatch):
    monkeypatch.delenv("AIRPOSE_SMPLX_DIR", raising=False)
    with pytest.raises(BodyModelError) as err:
        load_body_model(source="smplx")
    msg = str(err.value)
    assert "AIRPOSE_SMPLX_DIR" in msg and "SMPLX_NEUTRAL.npz" in msg and "smpl-x.is.tue.mpg.de" in msg


def test_smplx_source_with_empty_folder_names_the_missing_file(monkeypatch, tmp_path):
    monkeypatch.setenv("AIRPOSE_SMPLX_DIR", str(tmp_path))
    with pytest.raises(BodyModelError, match="SMPLX_FEMALE.npz"):
        load_body_model(source="smplx", gender="female")
    with pytest.raises(BodyModelError, match=str(tmp_path)):
        load_body_model(source="smplx", gender="female")


def test_truncated_file_is_reported_with_its_path(monkeypatch, tmp_path, open_model_files):
    data = open_model_files["neutral"].read_bytes()
    (tmp_path / "SMPLX_NEUTRAL.npz").write_bytes(data[: len(data) // 3])
    monkeypatch.setenv("AIRPOSE_SMPLX_DIR", str(tmp_path))
    with pytest.raises(BodyModelError, match="SMPLX_NEUTRAL.npz.*damaged"):
        load_body_model(source="smplx")


def test_foreign_npz_is_rejected(monkeypatch, tmp_path):
    np.savez(tmp_path / "SMPLX_NEUTRAL.npz", something=np.zeros(3))
    monkeypatch.setenv("AIRPOSE_SMPLX_DIR", str(tmp_path))
    with pytest.raises(BodyModelError, match="not an SMPL-X model file"):
        load_body_model(source="smplx")


def test_a_file_in_smplx_dir_is_a_drop_in(monkeypatch, tmp_path, open_model_files):
    """Any SMPL-X-format npz in AIRPOSE_SMPLX_DIR loads through the same entry point."""
    shutil.copyfile(open_model_files["male"], tmp_path / "SMPLX_MALE.npz")
    monkeypatch.setenv("AIRPOSE_SMPLX_DIR", str(tmp_path))
    assert resolve_model_file("smplx", "male") == tmp_path / "SMPLX_MALE.npz"
    real = load_body_model("smplx", "male", dtype=torch.float64)
    ours = load_body_model("open", "male", dtype=torch.float64)
    with torch.no_grad():
        torch.testing.assert_close(real().joints, ours().joints)


def test_bad_arguments():
    with pytest.raises(ValueError, match="gender"):
        load_body_model(gender="robot")
    with pytest.raises(ValueError, match="source"):
        load_body_model(source="mixamo")
