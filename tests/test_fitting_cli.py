"""`airpose prior train` / `prior info` and `airpose fit` end to end on tiny inputs."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from airpose_lib.cli import main


@pytest.fixture(autouse=True)
def _one_thread():
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


def test_prior_train_and_info(tmp_path, capsys, open_model_files):
    out = tmp_path / "prior.pt"
    assert main(["prior", "train", "--profile", "smoke", "--steps", "5", "--out", str(out), "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "held-out reconstruction" in text and "joint limits" in text and out.is_file()
    assert main(["prior", "info", "--path", str(out)]) == 0
    prov = json.loads(capsys.readouterr().out)
    assert prov["profile"] == "smoke" and prov["train"]["steps"] == 5 and prov["train"]["device"] == "cpu"
    assert {"rot_err_deg", "joint_err_mm", "samples_within_joint_limits"} <= set(prov["validation"])


def test_prior_info_without_official_weights_is_a_clean_error(monkeypatch, capsys):
    monkeypatch.delenv("AIRPOSE_VPOSER_DIR", raising=False)
    assert main(["prior", "info", "--source", "vposer"]) == 2
    assert "AIRPOSE_VPOSER_DIR" in capsys.readouterr().err


def test_fit_a_sequence_in_the_official_layout(tmp_path, capsys, open_model_files):
    import roma

    from airpose_lib.body import BODY_25_FROM_SMPLX, COCO18_FROM_SMPLX, load_body_model
    from airpose_lib.body.forward import BodyForward
    from airpose_lib.data.sequences.writer import OfficialLayoutWriter
    from airpose_lib.geometry import project_points
    from airpose_lib.prior import VPoser, save_prior

    F = 6
    body = BodyForward(load_body_model("open", dtype=torch.float64), range(76), vertices=None)
    g = torch.Generator().manual_seed(0)
    theta = roma.rotvec_to_rotmat(0.2 * torch.randn(F, 21, 3, generator=g, dtype=torch.float64))
    phi = roma.rotvec_to_rotmat(torch.tensor([[[3.0, 0.0, 0.0], [2.6, 1.0, 0.0]]], dtype=torch.float64))
    phi = phi.expand(F, 2, 3, 3)
    tau = torch.tensor([[0.0, 0.5, 10.0], [0.2, 0.4, 9.0]], dtype=torch.float64).expand(F, 2, 3)
    K = np.array([[[1475.0, 0, 960], [0, 1475.0, 540], [0, 0, 1]]] * 2)
    J0, _ = body(theta, torch.zeros(1, 10, dtype=torch.float64))
    uv = project_points(J0[:, None] @ phi.transpose(-1, -2) + tau[:, :, None], torch.as_tensor(K)[None])
    kps = {}
    for name, idx in (("openpose", BODY_25_FROM_SMPLX), ("alphapose", COCO18_FROM_SMPLX)):
        p = uv[:, :, list(idx)].numpy()
        kps[name] = np.concatenate([p, np.full(p.shape[:-1] + (1,), 0.8)], -1)
    kps["openpose"][2] = 0.0  # frame 2: nobody detected by either detector -> skipped
    kps["alphapose"][2] = 0.0
    kps["mediapipe"] = kps["openpose"].copy()
    kps["mediapipe"][:, :, [20, 23]] = 0.0  # BODY_25 without the small toes, as MediaPipe's
    kps["mediapipe"][3] = 0.0  # MediaPipe alone misses frame 3 too
    root = tmp_path / "seq"
    w = OfficialLayoutWriter(root, num_views=2)
    for i in range(F):
        w.write_frame(10 + i, [np.zeros((1080, 1920, 3), np.uint8)] * 2)
    w.finish(K, kps)
    init = tmp_path / "pred.npz"
    np.savez(init, phi=phi.numpy(), tau=tau.numpy() + 0.1, theta=theta[:, None].expand(F, 2, 21, 3, 3).numpy(),
             beta=np.zeros((F, 2, 10)), frames=np.arange(10, 10 + F))
    torch.manual_seed(0)
    prior_file = save_prior(VPoser().eval(), tmp_path / "prior.pt")
    out = tmp_path / "fit.npz"
    code = main(["fit", "--sequence", str(root), "--init", str(init), "--out", str(out), "--profile", "smoke",
                 "--prior-path", str(prior_file), "--iterations", "5", "--device", "cpu", "--quiet"])
    assert code == 0, capsys.readouterr().err
    res = np.load(out)
    assert res["theta"].shape == (F, 21, 3, 3) and res["R_12"].shape == (F, 3, 3)
    assert res["kept"].tolist() == [True, True, False, True, True, True]
    prov = json.loads(str(res["provenance"]))
    assert prov["skipped_frames"] == [2] and prov["config"]["iterations"] == 5 and prov["config"]["device"] == "cpu"
    np.testing.assert_array_equal(res["frames"], np.arange(10, 10 + F))
    # --frames are image numbers, as in `predict` and `finetune` (the images here are numbered 10..15)
    part = tmp_path / "part.npz"
    assert main(["fit", "--sequence", str(root), "--init", str(init), "--out", str(part), "--frames", "12:15",
                 "--prior-path", str(prior_file), "--iterations", "2", "--quiet"]) == 0
    np.testing.assert_array_equal(np.load(part)["frames"], [12, 13, 14])
    # --detectors: AirPose+ on MediaPipe's keypoints alone skips the frames MediaPipe missed
    alone = tmp_path / "mediapipe.npz"
    assert main(["fit", "--sequence", str(root), "--init", str(init), "--out", str(alone), "--detectors", "mediapipe",
                 "--prior-path", str(prior_file), "--iterations", "2", "--quiet"]) == 0
    assert np.load(alone)["kept"].tolist() == [True, True, False, False, True, True]
    capsys.readouterr()
    assert main(["fit", "--sequence", str(root), "--init", str(init), "--frames", "0:5",
                 "--prior-path", str(prior_file)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no image numbered in [0, 5)" in err
    # Missing arrays in the initialisation are a clean error.
    np.savez(init, phi=phi.numpy())
    assert main(["fit", "--sequence", str(root), "--init", str(init), "--prior-path", str(prior_file)]) == 2
    assert "missing arrays" in capsys.readouterr().err
