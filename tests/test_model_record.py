"""The network record of checkpoints (model.record) and the reconstruction for old checkpoints."""
import numpy as np
import pytest
import torch
import yaml

from airpose_lib.data.still.training_input import training_input
from airpose_lib.model.record import NETWORK_KEY, network_record, read_network
from airpose_lib.runtime.backends import checkpoint_settings
from airpose_lib.train import TrainConfig
from airpose_lib.train.loop import run_network_entry

# The paper's training camera, by hand: f = 1475 px, principal point at the centre of 1920x1080.
PAPER_K = np.array([[1475.0, 0.0, 959.5], [0.0, 1475.0, 539.5], [0.0, 0.0, 1.0]])


def _old_checkpoint(path, profile=None, **config):
    """A checkpoint as the kit wrote them before the record: config only (no weights needed here),
    which then named its profile."""
    cfg = {**TrainConfig(variant="fullcam", backbone="resnet18", **config).to_dict(), "profile": profile}
    torch.save({"model": {}, "config": cfg, "step": 0}, path)
    return path


def _profile_dataset(monkeypatch, tmp_path, name="smoke", crop_size=128):
    """The manifest of a profile's default dataset folder (``RunFolders.still``) in a cache of its own."""
    from airpose_lib.paths import CACHE_ENV, RunFolders

    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache"))
    folder = RunFolders(name).still
    folder.mkdir(parents=True)
    (folder / "manifest.yaml").write_text(yaml.safe_dump({"kind": "airpose-still-frames", "crop_size": crop_size,
                                                          "config": {"scene": {}}}))


def test_record_round_trips_through_a_weights_only_checkpoint(tmp_path):
    K = np.array([[1000.0, 0, 320], [0, 1010.0, 240], [0, 0, 1]])
    rec = network_record("airpose", "resnet34", {"num_iterations": 2}, 96, K)
    path = tmp_path / "c.pt"
    torch.save({NETWORK_KEY: rec, "config": TrainConfig().to_dict()}, path)
    net = read_network(torch.load(path, weights_only=True))
    assert (net.variant, net.backbone, net.model, net.input_size) == ("airpose", "resnet34", {"num_iterations": 2}, 96)
    assert (net.normalisation, net.camera_rule) == ("imagenet", "virtual_crop")
    np.testing.assert_array_equal(net.camera_K, K)
    assert checkpoint_settings(path) == {"variant": "airpose", "backbone": "resnet34",
                                         "model": {"num_iterations": 2}, "input_size": 96}
    with pytest.raises(ValueError, match="normalisation"):
        network_record("airpose", "resnet34", {}, 96, K, normalisation="none")


def test_old_checkpoints_fall_back_to_their_data(tmp_path, monkeypatch):
    # profile only: the data the smoke profile made in its default folder (128 px crops) and the paper's camera
    _profile_dataset(monkeypatch, tmp_path)
    state = torch.load(_old_checkpoint(tmp_path / "a.pt", profile="smoke"), weights_only=True)
    net = read_network(state, legacy=training_input)
    assert (net.variant, net.backbone, net.input_size) == ("fullcam", "resnet18", 128)
    np.testing.assert_array_equal(net.camera_K, PAPER_K)
    assert read_network(state).input_size is None  # without the reconstruction nobody can tell
    # a dataset folder's manifest wins over the profile
    root = tmp_path / "data"
    root.mkdir()
    (root / "manifest.yaml").write_text(yaml.safe_dump({"kind": "airpose-still-frames", "crop_size": 48,
                                                        "config": {"scene": {"focal": 1000.0}}}))
    path = _old_checkpoint(tmp_path / "b.pt", profile="smoke", data={"root": str(root)})
    net = read_network(torch.load(path, weights_only=True), legacy=training_input)
    assert net.input_size == 48
    np.testing.assert_array_equal(net.camera_K, [[1000.0, 0, 959.5], [0, 1000.0, 539.5], [0, 0, 1]])
    assert checkpoint_settings(path) == {"variant": "fullcam", "backbone": "resnet18", "model": {}, "input_size": 48}
    # the data settings' own crop size and scene win over both
    assert training_input({"profile": "smoke", "data": {"root": str(root), "crop_size": 40,
                                                        "scene": {"image_size": [640, 480]}}})[0] == 40
    # an old fine-tuning checkpoint's input_size and camera_K win over the reconstruction
    state = {"config": {**TrainConfig().to_dict(), "profile": "smoke"}, "input_size": 64, "camera_K": (2 * PAPER_K).tolist()}
    net = read_network(state, legacy=training_input)
    assert net.input_size == 64
    np.testing.assert_array_equal(net.camera_K, 2 * PAPER_K)


def test_a_run_records_its_datasets_crop_size(tmp_path, monkeypatch):
    class Crops:
        crop_size = 72

    cfg = TrainConfig(variant="baseline", backbone="resnet18").to_dict()
    rec = run_network_entry(cfg, Crops())[NETWORK_KEY]
    assert (rec["variant"], rec["input_size"], rec["model"]) == ("baseline", 72, {})
    np.testing.assert_array_equal(rec["camera_K"], PAPER_K)
    _profile_dataset(monkeypatch, tmp_path)  # the run's data: a dataset folder with its manifest
    with_data = dict(cfg, data={"root": str(tmp_path / "cache" / "data" / "still_smoke")})
    assert run_network_entry(with_data, object())[NETWORK_KEY]["input_size"] == 128  # no crop_size: the data's
    assert run_network_entry(dict(cfg, task="pretrain"), Crops()) == {}  # not a variant's network
