"""Damaged data is never read silently, a healthy dataset verifies on any machine, and a command
that needs a dataset another process is making waits for it."""
from __future__ import annotations

import shutil
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from airpose_lib.assets.verify import verify
from airpose_lib.data.still import manifest as manifest_mod
from airpose_lib.data.still.dataset import StillFrameDataset
from airpose_lib.data.still.generate import GenerationConfig, ensure_still_dataset, generate_still_dataset
from airpose_lib.data.still.manifest import ShardIntegrityError, record_manifest
from airpose_lib.data.still.scene import SceneConfig
from airpose_lib.data.still.shards import shard_name
from airpose_lib.folder_lock import FolderBusyError, folder_lock
from airpose_lib.reproduce.configs import kit_configs
from airpose_lib.train.features import FeatureDataset

CFG = GenerationConfig(num_samples=8, shard_size=4, crop_size=64, seed=11,
                       scene=SceneConfig(num_distractors=(0, 1)))
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def intact(module_tmp) -> Path:
    root = module_tmp("integrity") / "data"
    generate_still_dataset(CFG, root, workers=1, progress=False, label="test")
    return root


@pytest.fixture
def copy(intact, tmp_path) -> Path:
    root = tmp_path / "data"
    shutil.copytree(intact, root)
    return root


def _flip_one_byte(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))


def test_cached_features_are_not_served_with_a_damaged_shard(copy):
    """Features made from the intact copy, then one byte of a shard flipped: the labels of that
    shard must not be read (the old FeatureDataset opened the shards with verify=False)."""
    n = len(StillFrameDataset(copy, "train", augment=False))
    features = np.zeros((n, CFG.scene.num_views, 8), np.float32)
    assert len(FeatureDataset(copy, "train", features)) == n
    _flip_one_byte(copy / shard_name(0))
    with pytest.raises(ShardIntegrityError, match=r"shard_00000\.npz is damaged.*airpose data generate"):
        FeatureDataset(copy, "train", features)


def test_a_shard_is_hashed_once_per_process_and_again_when_it_changes(copy, monkeypatch):
    calls = []
    real = manifest_mod.sha256_file
    monkeypatch.setattr(manifest_mod, "sha256_file", lambda p: calls.append(Path(p).name) or real(p))
    StillFrameDataset(copy, "train")
    StillFrameDataset(copy, "train")
    first = sorted(calls)
    assert first and len(first) == len(set(first))  # each train shard once
    _flip_one_byte(copy / shard_name(0))
    with pytest.raises(ShardIntegrityError):
        StillFrameDataset(copy, "train")
    assert calls.count(shard_name(0)) == 2  # the new version of the file was hashed


def test_the_kit_rebuilds_a_damaged_shard_of_its_own_dataset_and_says_so(copy, intact, capfd):
    good = (intact / shard_name(1)).read_bytes()
    _flip_one_byte(copy / shard_name(1))
    capfd.readouterr()
    ensure_still_dataset(config=CFG, root=copy, progress=False, workers=1)
    err = capfd.readouterr().err
    assert f"{copy / shard_name(1)} is damaged" in err and "rebuild" in err
    assert (copy / shard_name(1)).read_bytes() == good
    StillFrameDataset(copy, "all")  # verifies


def test_generate_says_which_finished_shard_it_rebuilds(copy, capfd):
    (copy / shard_name(0)).write_bytes(b"cut")
    capfd.readouterr()
    generate_still_dataset(CFG, copy, workers=1, progress=False, label="test")
    err = capfd.readouterr().err
    assert f"airpose: shard {copy / shard_name(0)} is damaged" in err and "rebuilding it" in err


def _tracked_record(intact: Path, folder: Path, **changes) -> Path:
    manifest = yaml.safe_load((intact / "manifest.yaml").read_text())
    manifest.update(changes)
    return record_manifest(manifest, folder)


def test_a_healthy_dataset_verifies_against_a_record_made_on_another_machine(copy, intact, tmp_path):
    """The tracked record keeps only what is the same on every machine; the shard bytes are
    checked against the dataset's own manifest, so another machine's bytes cannot fail it."""
    record = _tracked_record(intact, tmp_path / "manifests")
    elsewhere = yaml.safe_load(record.read_text())
    assert all(set(r) & {"bytes", "sha256"} == set() for r in elsewhere["shards"])
    # An old-style record with the shard bytes of another machine: still judged on this machine's.
    for rec in elsewhere["shards"]:
        rec.update(bytes=123, sha256="0" * 64)
    old_style = tmp_path / "manifests" / "generated_elsewhere.yaml"
    old_style.write_text(yaml.safe_dump({**elsewhere, "profile": "elsewhere"}))
    for name in (record, old_style):
        report = verify(str(name), root=copy)
        assert report.ok, report.text()
    _flip_one_byte(copy / shard_name(1))
    report = verify(str(record), root=copy)
    assert not report.ok and shard_name(1) in report.text() and "checksum-mismatch" in report.text()


def test_other_settings_than_the_record_warn_and_the_printed_fix_ends_the_warning(copy, intact, tmp_path):
    """A record of other settings (a changed generator or profile) is not damage: the healthy
    dataset verifies with a warning that gives the command rewriting the record, and doing what
    it says (the record made from this dataset's manifest) ends the warning."""
    folder = tmp_path / "manifests"
    record = _tracked_record(intact, folder, fingerprint="f" * 64)
    report = verify(str(record), root=copy)
    assert report.ok, report.text()
    assert "other settings" in report.warning and "--record-manifest" in report.warning
    assert "Damaged" not in report.text() and "warning: made with other settings" in report.text()
    assert f"--out {copy}" in report.warning  # not the default folder: the command names this one
    _flip_one_byte(copy / shard_name(1))  # damage on top of other settings is named as damage
    damaged = verify(str(record), root=copy)
    assert not damaged.ok and f"Damaged: {copy / shard_name(1)}" in damaged.text()
    # the printed fix: the record rewritten from the dataset's own manifest
    record_manifest(yaml.safe_load((intact / "manifest.yaml").read_text()) | {"profile": "test"}, folder)
    after = verify(str(record), root=intact)
    assert after.ok and after.warning == "", after.text()


def test_the_tracked_smoke_record_is_what_the_generator_makes_now():
    """The record says which data the smoke results were made from: a change of the generator or
    of the smoke profile's `data: still:` fails here until the record is made again
    (`airpose data generate --profile smoke --record-manifest`)."""
    from airpose_lib.data.still.config import GENERATOR_VERSION, SPLITS

    record = yaml.safe_load((ROOT / "data_manifests" / "generated_smoke.yaml").read_text())
    cfg = kit_configs("smoke").still
    assert (record["generator_version"], record["fingerprint"]) == (GENERATOR_VERSION, cfg.fingerprint())
    assert record["config"] == cfg.to_dict() and record["num_shards"] == cfg.num_shards
    splits = {s: [k for k in range(cfg.num_shards) if cfg.shard_split(k) == s] for s in SPLITS}
    assert record["splits"] == {s: ks for s, ks in splits.items() if ks}
    assert record["status"] == "complete" and [r["file"] for r in record["shards"]] == [
        shard_name(k) for k in range(cfg.num_shards)]


def test_the_tracked_records_hold_no_machine_dependent_bytes():
    for path in (ROOT / "data_manifests").glob("generated_*.yaml"):
        data = yaml.safe_load(path.read_text())
        assert all("sha256" not in r and "bytes" not in r for r in data["shards"]), path
        assert "bytes" not in (data.get("totals") or {}), path
        assert "sha256" not in (data.get("body_models") or {}), path


# -- waiting for the process that makes a dataset --------------------------------------------------
def _hold_lock(folder: Path, seconds: float) -> subprocess.Popen:
    code = textwrap.dedent(f"""
        import sys, time
        from airpose_lib.folder_lock import folder_lock
        with folder_lock({str(folder)!r}, "dataset folder"):
            print("held", flush=True)
            time.sleep({seconds})
    """)
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, cwd=ROOT)
    assert proc.stdout.readline().strip() == "held"
    return proc


def test_a_reader_waits_for_the_writer_and_says_so(tmp_path, capfd):
    folder = tmp_path / "busy"
    proc = _hold_lock(folder, 1.5)
    try:
        with pytest.raises(FolderBusyError, match="in use by another process"):
            with folder_lock(folder, "dataset folder"):  # a second writer: refused at once
                pass
        with pytest.raises(FolderBusyError, match=r"still was after 0 s"):
            with folder_lock(folder, "dataset folder", wait=0.3):
                pass
        start = time.monotonic()
        with folder_lock(folder, "dataset folder", wait=30):
            waited = time.monotonic() - start
        assert waited > 0.3
        assert f"PID {proc.pid}" in capfd.readouterr().err
    finally:
        proc.wait(timeout=30)


def test_ensure_waits_for_a_dataset_being_generated_and_does_not_make_it_again(tmp_path, capfd):
    """Two commands that need the same dataset on a fresh cache: the second waits for the first."""
    root = tmp_path / "data"
    code = textwrap.dedent(f"""
        from airpose_lib.data.still.generate import generate_still_dataset
        from airpose_lib.data.still.scene import SceneConfig
        from airpose_lib.data.still.generate import GenerationConfig
        from airpose_lib.folder_lock import folder_lock
        import time
        cfg = GenerationConfig(num_samples=8, shard_size=4, crop_size=64, seed=11,
                               scene=SceneConfig(num_distractors=(0, 1)))
        with folder_lock({str(root)!r}, "dataset folder"):
            print("held", flush=True)
            time.sleep(1.0)
            generate_still_dataset(cfg, {str(root)!r}, workers=1, progress=False, label="test")
    """)
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        assert proc.stdout.readline().strip() == "held"
        capfd.readouterr()
        ensure_still_dataset(config=CFG, root=root, progress=False, workers=1)
        assert "waiting for it to finish" in capfd.readouterr().err
        assert proc.wait(timeout=120) == 0
    finally:
        proc.kill()
    made = {p.name: p.stat().st_mtime_ns for p in root.glob("shard_*.npz")}
    assert len(made) == CFG.num_shards
    ensure_still_dataset(config=CFG, root=root, progress=False, workers=1)
    assert {p.name: p.stat().st_mtime_ns for p in root.glob("shard_*.npz")} == made


def test_training_on_a_damaged_named_dataset_is_refused_before_its_run_folder_exists(copy, tmp_path, capsys):
    from airpose_lib import cli

    _flip_one_byte(copy / shard_name(1))
    out = tmp_path / "run"
    code = cli.main(["train", "--variant", "airpose", "--quiet", "--set", f"data.root={copy}", "--out", str(out)])
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert code == 2 and len(err) == 1 and f"{copy / shard_name(1)} is damaged" in err[0], err
    assert not out.exists()
