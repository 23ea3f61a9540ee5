"""Fine-tuning on detections: agreement filter, loss, predictions file, frozen-backbone training,
resume. Tiny: a random ResNet-18 AirPose network at 64 px, the first frames of the smoke recording."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import torch

from airpose_lib.body.joint_sets import BODY_25_NAMES, COCO18_NAMES
from airpose_lib.finetune import (
    BODY25_FROM_COCO18,
    UNMATCHED_BODY25,
    FineTuneConfig,
    FineTuneLoss,
    PredictionFormatError,
    agreement_masks,
    agreement_targets,
    detection_boxes,
    finetune,
    finetune_config,
    finetune_loss_config,
    load_predictions,
    load_sized_network,
    predict_sequence,
    regress_features,
    save_predictions,
)
from airpose_lib.finetune.selection import Selection, select_step
from airpose_lib.geometry import axis_angle_to_matrix, matrix_to_axis_angle
from airpose_lib.reproduce.configs import kit_configs

S = 64  # crop side of the tiny network


@pytest.fixture(autouse=True)
def _one_thread():
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


@pytest.fixture(scope="module")
def smoke_root():
    from airpose_lib.data.sequences import ensure_sequences

    smoke = kit_configs("smoke")
    return ensure_sequences(smoke.sequences, smoke.folders.sequences(), only=["person1"])["person1"]


def _save_tiny(folder, variant: str):
    from airpose_lib.engine.checkpoint import save_checkpoint
    from airpose_lib.model import build_model
    from airpose_lib.train import TrainConfig

    torch.manual_seed(0)
    model = build_model(variant, "resnet18")
    cfg = TrainConfig(variant=variant, backbone="resnet18", steps=0)
    return save_checkpoint(folder, {"model": model.state_dict(), "optimizer": {}, "rng": [], "step": 0, "epoch": 0,
                                    "batch_in_epoch": 0, "config": cfg.to_dict(), "world_size": 1, "input_size": S},
                           keep=0)


@pytest.fixture(scope="module")
def tiny_ckpt(module_tmp):
    return _save_tiny(module_tmp("airpose"), "airpose")


@pytest.fixture(scope="module")
def baseline_ckpt(module_tmp):
    return _save_tiny(module_tmp("baseline"), "baseline")


@pytest.fixture(scope="module")
def body32(open_model_files):
    from airpose_lib.body import load_body_model

    return load_body_model("open", "neutral")


@pytest.fixture()
def tiny_prior():
    from airpose_lib.prior import VPoser

    torch.manual_seed(1)
    return VPoser(num_neurons=32, latent_dim=8).eval()


# -- agreement filter ------------------------------------------------------------------------------
def test_correspondence_follows_the_joint_names():
    for j, k in enumerate(BODY25_FROM_COCO18):
        if k >= 0:
            assert COCO18_NAMES[k] == BODY_25_NAMES[j]
        else:
            assert BODY_25_NAMES[j] not in COCO18_NAMES
    assert [BODY_25_NAMES[j] for j in UNMATCHED_BODY25] == [
        "MidHip", "LBigToe", "LSmallToe", "LHeel", "RBigToe", "RSmallToe", "RHeel"]


def _agreeing_pair():
    """One frame, one view: OpenPose and AlphaPose at the same spots, distinct confidences."""
    op = np.zeros((1, 1, 25, 3))
    op[..., 0] = 300 + 10 * np.arange(25)
    op[..., 1] = 200 + 7 * np.arange(25)
    op[..., 2] = 0.3 + 0.02 * np.arange(25)
    ap = np.zeros((1, 1, 18, 3))
    for j, k in enumerate(BODY25_FROM_COCO18):
        if k >= 0:
            ap[0, 0, k] = (op[0, 0, j, 0], op[0, 0, j, 1], 0.8)
    return op, ap


def _b(name):
    return BODY_25_NAMES.index(name)


def _c(name):
    return COCO18_NAMES.index(name)


def test_agreement_filter_on_hand_made_keypoints():
    op, ap = _agreeing_pair()
    ap[0, 0, _c("RWrist"), 0] += 99.0  # kept
    ap[0, 0, _c("RElbow"), 1] -= 101.0  # dropped
    ap[0, 0, _c("LWrist"), :2] += (60.0, 80.0)  # exactly 100 px: kept
    ap[0, 0, _c("LKnee"), :2] += (71.0, 71.0)  # 100.4 px: dropped
    op[0, 0, _b("Nose"), 0] = np.nan  # OpenPose NaN: dropped
    ap[0, 0, _c("LEye"), 1] = np.nan  # AlphaPose NaN: unconfirmed, dropped
    ap[0, 0, _c("REar")] = 0.0  # AlphaPose missed it: dropped
    op[0, 0, _b("LEar"), 2] = 0.01  # below min_confidence: dropped
    op[0, 0, _b("RKnee")] = 0.0  # OpenPose missed it
    t = agreement_targets(op, ap, threshold_px=100.0, min_confidence=0.05)
    assert t.shape == (1, 1, 25, 3) and t.dtype == np.float32 and np.isfinite(t).all()
    w = t[0, 0, :, 2]
    dropped = {"RElbow", "LKnee", "Nose", "LEye", "REar", "LEar", "RKnee",
               "MidHip", "LBigToe", "LSmallToe", "LHeel", "RBigToe", "RSmallToe", "RHeel"}
    for j, name in enumerate(BODY_25_NAMES):
        if name in dropped:
            assert w[j] == 0 and (t[0, 0, j, :2] == 0).all(), name
        else:  # weight = OpenPose confidence, position = OpenPose's
            assert w[j] == pytest.approx(0.3 + 0.02 * j), name
            np.testing.assert_allclose(t[0, 0, j, :2], op[0, 0, j, :2], rtol=0, atol=1e-4)
    m = agreement_masks(op, ap)
    assert m.disagree[0, 0, [_b("RElbow"), _b("LKnee")]].all()
    assert m.unconfirmed[0, 0, [_b("LEye"), _b("REar"), _b("MidHip")]].all()
    assert m.low_confidence[0, 0, _b("LEar")] and m.missing[0, 0, _b("Nose")] and m.missing[0, 0, _b("RKnee")]

    # "keep": the joints COCO-18 lacks stay, unchecked; a missed AlphaPose joint is still dropped
    t_keep = agreement_targets(op, ap, unmatched="keep")
    for j in UNMATCHED_BODY25:
        assert t_keep[0, 0, j, 2] == pytest.approx(0.3 + 0.02 * j)
    assert t_keep[0, 0, _b("REar"), 2] == 0
    # a tighter threshold drops the 99 px joint too
    assert agreement_targets(op, ap, threshold_px=98.0)[0, 0, _b("RWrist"), 2] == 0


def test_agreement_filter_rejects_bad_input():
    op, ap = _agreeing_pair()
    with pytest.raises(ValueError, match="frames, views"):
        agreement_targets(np.repeat(op, 3, axis=0), np.repeat(ap, 2, axis=0))
    with pytest.raises(ValueError, match="BODY_25"):
        agreement_targets(op[..., :18, :], ap)
    with pytest.raises(ValueError, match="COCO-18"):
        agreement_targets(op, ap[..., :17, :])
    bad = op.copy()
    bad[0, 0, 3, 2] = -0.5
    with pytest.raises(ValueError, match="negative"):
        agreement_targets(bad, ap)
    with pytest.raises(ValueError, match="unmatched"):
        agreement_targets(op, ap, unmatched="maybe")


# -- loss -----------------------------------------------------------------------------------------
def _random_pred(B=2, V=2, seed=0, dtype=torch.float64):
    g = torch.Generator().manual_seed(seed)
    aa_root = torch.tensor([np.pi, 0.0, 0.0], dtype=dtype) + 0.3 * torch.randn(B, V, 3, generator=g, dtype=dtype)
    theta_aa = 0.3 * torch.randn(B, 1, 21, 3, generator=g, dtype=dtype)
    return {"phi": axis_angle_to_matrix(aa_root),
            "theta": axis_angle_to_matrix(theta_aa).expand(B, V, 21, 3, 3).clone(),
            "beta": torch.randn(B, 1, 10, generator=g, dtype=dtype).expand(B, V, 10).clone(),
            "tau": torch.tensor([0.2, -0.1, 6.0], dtype=dtype) + 0.3 * torch.randn(B, V, 3, generator=g, dtype=dtype)}


def _K(V=2, dtype=torch.float64):
    return torch.tensor([[[1000.0, 0, 480], [0, 990.0, 270], [0, 0, 1]],
                         [[900.0, 0, 500], [0, 910.0, 260], [0, 0, 1]]], dtype=dtype)[:V]


def test_projection_matches_smplx_forward_and_opencv(open_model):
    """Independent reference: smplx's forward (identity root, zero translation), then X = phi X0 + tau,
    projected by cv2.projectPoints, at the BODY_25 joints."""
    from airpose_lib.body.joint_sets import BODY_25_FROM_SMPLX

    loss = FineTuneLoss(finetune_loss_config("airpose", w_vposer=0.0), body_model=open_model)
    pred, K = _random_pred(), _K()
    uv = loss.project(pred, K)
    for b in range(2):
        for v in range(2):
            out = open_model(betas=pred["beta"][b, v][None], body_pose=matrix_to_axis_angle(pred["theta"][b, v])[None]
                             .reshape(1, 63), global_orient=torch.zeros(1, 3, dtype=torch.float64))
            J0 = out.joints[0, list(BODY_25_FROM_SMPLX)]
            X = (J0 @ pred["phi"][b, v].T + pred["tau"][b, v]).detach().numpy()
            ref, _ = cv2.projectPoints(X, np.zeros(3), np.zeros(3), K[v].numpy(), None)
            np.testing.assert_allclose(uv[b, v].numpy(), ref[:, 0], atol=1e-3)


def test_loss_is_zero_on_its_own_projection_and_cross_view_terms(open_model, tiny_prior):
    cfg = finetune_loss_config("airpose")  # w_theta 100, cross-view beta
    loss = FineTuneLoss(cfg, body_model=open_model, prior=tiny_prior.double())
    pred, K = _random_pred(), _K()
    uv = loss.project(pred, K)
    w = torch.rand(2, 2, 25, 1, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    terms = loss(pred, torch.cat((uv, w), -1), K)
    assert terms["j2d"].item() == 0.0
    # identical views: no cross-view penalty; the beta term is the plain prior sum_c mean(beta^2)
    assert terms["theta"].item() == 0.0
    assert terms["beta"].item() == pytest.approx(2 * pred["beta"][:, 0].square().mean().item(), rel=1e-12)
    # views that differ: positive cross-view terms, and the 2D error shows up with the weights
    other = dict(pred)
    other["theta"] = pred["theta"].clone()
    other["theta"][:, 1, 4] = axis_angle_to_matrix(torch.tensor([0.0, 0.0, 0.5], dtype=torch.float64))
    other["beta"] = pred["beta"].clone()
    other["beta"][:, 1, 0] += 1.0
    t2 = loss(other, torch.cat((uv, w), -1), K)
    assert t2["theta"].item() > 0 and t2["beta"].item() > terms["beta"].item() and t2["j2d"].item() > 0
    expected_total = 0.01 * t2["j2d"] + 5 * t2["beta"] + 0.1 * t2["vposer"] + 100 * t2["theta"]
    assert t2["total"].item() == pytest.approx(expected_total.item(), rel=1e-12)
    # shifting every target by (3, 4) px gives exactly the weighted mean of 25 = 3^2 + 4^2, summed over views
    shifted = torch.cat((uv + torch.tensor([3.0, 4.0], dtype=torch.float64), w), -1)
    j2d = loss(pred, shifted, K)["j2d"].item()
    assert j2d == pytest.approx(sum((w[:, v] * 25.0).sum().item() / (2 * 25 * 2) for v in range(2)), rel=1e-9)


def test_vposer_term_sample_and_mean(open_model, tiny_prior):
    pred, K = _random_pred(), _K()
    targets = torch.zeros(2, 2, 25, 3, dtype=torch.float64)
    prior = tiny_prior.double()
    mean_loss = FineTuneLoss(finetune_loss_config("baseline", vposer_latent="mean"), open_model, prior)
    z = prior.encode(matrix_to_axis_angle(pred["theta"]).reshape(-1, 63)).loc.reshape(2, 2, -1)
    # Baseline: monocular, views averaged
    assert mean_loss(pred, targets, K)["vposer"].item() == pytest.approx(z.square().mean().item(), rel=1e-12)
    sample_loss = FineTuneLoss(finetune_loss_config("baseline"), open_model, prior)
    torch.manual_seed(5)
    a = sample_loss(pred, targets, K)["vposer"].item()
    torch.manual_seed(5)
    assert sample_loss(pred, targets, K)["vposer"].item() == a
    assert a != pytest.approx(z.square().mean().item(), rel=1e-6)


def test_loss_rejects_bad_targets(open_model):
    loss = FineTuneLoss(finetune_loss_config("airpose", w_vposer=0.0), body_model=open_model)
    pred, K = _random_pred(), _K()
    t = torch.zeros(2, 2, 25, 3, dtype=torch.float64)
    t[0, 1, 3, 0] = float("nan")
    with pytest.raises(ValueError, match="NaN"):
        loss(pred, t, K)
    with pytest.raises(ValueError, match="BODY_25"):
        loss(pred, torch.zeros(2, 2, 18, 3, dtype=torch.float64), K)
    with pytest.raises(ValueError, match="unknown"):
        finetune_loss_config("airpose", w_bogus=1.0)


# -- predictions ----------------------------------------------------------------------------------
def test_regress_features_equals_forward(tiny_ckpt):
    model, _, size = load_sized_network(tiny_ckpt)
    assert size == S and model.input_size == S
    g = torch.Generator().manual_seed(0)
    images = torch.randn(2, 2, 3, S, S, generator=g)
    P = torch.tensor([[[0.1, -0.2, 0.3], [-0.3, 0.1, 0.5]]]).expand(2, 2, 3)
    ref = model(images, P)
    feat = model.features(images.flatten(0, 1)).unflatten(0, (2, 2))
    out = regress_features(model, feat, P, S)
    for k in ("phi6d", "theta6d", "beta", "tau"):
        assert torch.equal(out[k], ref[k]), k
    # from the cached input of the last block (fine-tuning's trainable_from)
    h = model.backbone.forward_until(images.flatten(0, 1), "layer4.1").unflatten(0, (2, 2))
    cut = regress_features(model, h, P, S, cut="layer4.1")
    for k in ("phi6d", "theta6d", "beta", "tau"):
        torch.testing.assert_close(cut[k], ref[k], rtol=1e-5, atol=1e-6)
    with pytest.raises(ValueError, match=r"\(B, V, C, h, w\)"):
        regress_features(model, feat, P, S, cut="layer4.1")


def test_detection_boxes_reuse_and_flag():
    kp = np.zeros((4, 2, 25, 3))
    kp[:, :, :5] = [[100.0, 100.0, 0.9]]
    kp[:, :, 1:5, 0] += np.arange(1, 5) * 20
    kp[:, :, 1:5, 1] += np.arange(1, 5) * 30
    kp[1, 0, :, 0] += 50  # another box in frame 1
    kp[0, 0] = 0.0  # view 0: nothing in frame 0 (take frame 1's box) and frame 2 (keep frame 1's)
    kp[2, 0] = 0.0
    boxes, valid = detection_boxes(kp, [(960, 540), (960, 540)])
    assert valid.tolist() == [[False, True], [True, True], [False, True], [True, True]]
    np.testing.assert_array_equal(boxes[0, 0], boxes[1, 0])
    np.testing.assert_array_equal(boxes[2, 0], boxes[1, 0])
    np.testing.assert_allclose(boxes[1, 1], [80, 80, 200, 240])  # keypoints (100..180, 100..220) +- 20 px
    kp[:, 1] = 0.0
    with pytest.raises(ValueError, match="view 1"):
        detection_boxes(kp, [(960, 540), (960, 540)], where="rec")


@pytest.mark.parametrize("variant", ["airpose", "baseline"])
def test_predict_sequence_roundtrip_and_airpose_plus_init(variant, request, smoke_root, tmp_path):
    from airpose_lib.data.sequences.reader import load_sequence
    from airpose_lib.fitting import init_from_views
    from airpose_lib.model import to_smplx_params
    from airpose_lib.runtime.offline import offline_inputs
    from airpose_lib.runtime.source import open_source

    tiny_ckpt = request.getfixturevalue("tiny_ckpt" if variant == "airpose" else "baseline_ckpt")
    model, _, _ = load_sized_network(tiny_ckpt)
    seq = load_sequence(smoke_root, frames=range(4), detectors=("openpose",), ground_truth=False)
    pred = predict_sequence(model, seq, batch_size=3, provenance={"checkpoint": str(tiny_ckpt)})
    F, V = 4, 2
    shapes = {"phi": (F, V, 3, 3), "tau": (F, V, 3), "theta": (F, V, 21, 3, 3), "beta": (F, V, 10),
              "frames": (F,), "P": (F, V, 3), "boxes": (F, V, 4), "valid": (F, V)}
    assert {k: pred[k].shape for k in shapes} == shapes
    assert pred["frames"].tolist() == [0, 1, 2, 3] and pred["valid"].dtype == np.bool_
    # reference: the runtime's own boxes (its default margin rule, from its own reading of the
    # detections) and crops, through the batched forward
    src = open_source(str(smoke_root))
    crops, P, boxes = offline_inputs(src, np.tile(np.arange(4)[:, None], (1, V)), S)
    np.testing.assert_allclose(pred["boxes"], boxes, atol=1e-3)  # float32 storage
    with torch.no_grad():
        P_t = torch.from_numpy(P)
        # P lives in the network's camera (the camera rule): a weak camera converts with it
        K_net = torch.from_numpy(model.camera_K).float().expand(F, V, 3, 3)
        ref = to_smplx_params(model(torch.from_numpy(crops), P_t), P_t, K_net)
    np.testing.assert_allclose(pred["P"], P, atol=1e-6)
    for k in ("phi", "tau", "theta", "beta"):
        # rtol: batches of 3 and of 4 take other float32 kernel paths (oneDNN on an AMX Xeon put
        # tau ~9 m 1.5e-5 m apart); a wrong crop or camera moves these by 1e-2 and more
        np.testing.assert_allclose(pred[k], ref[k].numpy(), rtol=1e-4, atol=1e-5, err_msg=k)

    path = save_predictions(tmp_path / "pred.npz", pred)
    back = load_predictions(path)
    for k in shapes:
        np.testing.assert_array_equal(back[k], pred[k])
    assert back["provenance"]["input_size"] == S and back["provenance"]["checkpoint"] == str(tiny_ckpt)
    np.testing.assert_allclose(back["provenance"]["K_net"], model.camera_K)  # the camera rule is recorded
    assert "virtual camera" in back["provenance"]["camera_rule"]
    np.testing.assert_allclose(back["provenance"]["focal_ratio"], 1475.0 / seq.K[:, 0, 0], rtol=1e-9)
    init = init_from_views(back["phi"], back["tau"], back["theta"], back["beta"], num_frames=F)
    assert init["theta"].shape == (F, 21, 3, 3) and init["beta"].shape == (10,)
    # the same file through the `airpose fit --init` reader's key contract
    with np.load(path) as data:
        assert {"phi", "tau", "theta", "beta", "frames"} <= set(data.files)


def test_predictions_file_errors(tmp_path):
    F, V = 3, 2
    good = {"phi": np.tile(np.eye(3, dtype=np.float32), (F, V, 1, 1)), "tau": np.ones((F, V, 3), np.float32),
            "theta": np.tile(np.eye(3, dtype=np.float32), (F, V, 21, 1, 1)), "beta": np.zeros((F, V, 10), np.float32),
            "frames": np.arange(F), "valid": np.ones((F, V), bool), "provenance": json.dumps({"a": 1})}
    save_predictions(tmp_path / "ok.npz", good)
    bad = dict(good, tau=good["tau"].copy())
    bad["tau"][1, 0, 2] = np.nan
    with pytest.raises(PredictionFormatError, match="NaN"):
        save_predictions(tmp_path / "nan.npz", bad)
    assert not (tmp_path / "nan.npz").exists()
    np.savez(tmp_path / "nan2.npz", **{k: v for k, v in bad.items() if k != "provenance"})
    with pytest.raises(PredictionFormatError, match="nan2.npz.*tau.*NaN"):
        load_predictions(tmp_path / "nan2.npz")
    np.savez(tmp_path / "short.npz", **dict({k: v for k, v in good.items() if k != "provenance"},
                                            beta=np.zeros((F - 1, V, 10), np.float32)))
    with pytest.raises(PredictionFormatError, match="short.npz: beta"):
        load_predictions(tmp_path / "short.npz")
    np.savez(tmp_path / "nokey.npz", phi=good["phi"])
    with pytest.raises(PredictionFormatError, match="missing arrays"):
        load_predictions(tmp_path / "nokey.npz")
    with pytest.raises(PredictionFormatError, match="no predictions file"):
        load_predictions(tmp_path / "absent.npz")


# -- fine-tuning ----------------------------------------------------------------------------------
def _cfg(**kw):
    # Checkpoints only when stopping or done (writing them is the slow part here).
    base = dict(steps=6, batch_size=2, lr=1e-4, frames=[0, 6], checkpoint_every=100, keep_checkpoints=0,
                log_every=1, seed=0, feature_batch_size=6, holdout_fraction=0.0)
    return FineTuneConfig(**{**base, **kw})


def test_finetune_freezes_backbone_and_lowers_the_2d_loss(tiny_ckpt, smoke_root, tmp_path, body32, tiny_prior):
    from airpose_lib.train import load_checkpoint, load_trained_model, read_log

    res = finetune(tiny_ckpt, smoke_root, tmp_path / "ft", _cfg(steps=8), prior=tiny_prior, body_model=body32)
    assert res.step == 8 and res.num_frames == 6 and not res.stopped_early
    before = load_checkpoint(tiny_ckpt)["model"]
    after = load_checkpoint(res.checkpoint)["model"]
    assert set(before) == set(after)
    for k in before:
        if not k.startswith("regressor."):  # backbone weights, BatchNorm statistics, mean parameters
            assert torch.equal(before[k], after[k]), k
    changed = [k for k in before if k.startswith("regressor.") and not torch.equal(before[k], after[k])]
    assert "regressor.fc1.weight" in changed and "regressor.decpose.bias" in changed
    assert res.final["j2d"] < 0.5 * res.initial["j2d"]
    assert res.keypoints["kept"] > 0 and res.keypoints["disagree"] + res.keypoints["unconfirmed"] > 0
    model, cfg = load_trained_model(res.checkpoint)  # the kit checkpoint format
    assert cfg.variant == "airpose" and load_sized_network(res.checkpoint)[2] == S
    net = load_checkpoint(res.checkpoint)["network"]  # the record of what rebuilds the network
    assert (net["variant"], net["backbone"], net["input_size"], net["camera_rule"]) == ("airpose", "resnet18", S,
                                                                                         "virtual_crop")
    np.testing.assert_allclose(net["camera_K"], load_sized_network(tiny_ckpt)[0].camera_K)
    assert [int(r["step"]) for r in read_log(tmp_path / "ft" / "log.csv")] == list(range(1, 9))
    assert res.history["step"] == list(range(1, 9)) and len(res.history["j2d"]) == 8


def test_finetune_trains_the_backbones_last_block_from_its_cached_input(tiny_ckpt, smoke_root, tmp_path, body32,
                                                                       tiny_prior):
    """trainable_from: block layer4.1 and the regressor change, nothing before the block, nor its
    BatchNorm statistics; before a step the loss is the frozen network's (the block's cached input
    gives the same outputs), and the test person's diagnostic with the cut is the one without it.
    A block the backbone lacks is refused before anything is written."""
    from airpose_lib.data.sequences.reader import load_sequence
    from airpose_lib.errors import ConfigError
    from airpose_lib.experiments.recording_diagnostic import ground_truth_diagnostic
    from airpose_lib.train import load_checkpoint

    kw = dict(prior=tiny_prior, body_model=body32)
    frozen = finetune(tiny_ckpt, smoke_root, tmp_path / "frozen", _cfg(steps=0), **kw)
    res = finetune(tiny_ckpt, smoke_root, tmp_path / "tail", _cfg(steps=8, trainable_from="layer4.1",
                                                                  backbone_lr_scale=1.0), **kw)
    for k, v in frozen.initial.items():
        assert np.isclose(res.initial[k], v, rtol=1e-5, atol=1e-8), k
    assert res.final["j2d"] < res.initial["j2d"]
    before, after = load_checkpoint(tiny_ckpt)["model"], load_checkpoint(res.checkpoint)["model"]
    trainable = [k for k in before if k.startswith(("regressor.", "backbone.layer4.1."))
                 and not k.endswith(("running_mean", "running_var", "num_batches_tracked"))]
    changed = {k for k in before if not torch.equal(before[k], after[k])}
    assert changed <= set(trainable)
    assert {"backbone.layer4.1.conv1.weight", "backbone.layer4.1.bn2.weight", "regressor.fc1.weight"} <= changed
    model, _, _ = load_sized_network(tiny_ckpt)
    test = load_sequence(smoke_root, frames=range(40, 43), detectors=("openpose",))
    with torch.no_grad():  # as fine-tuning calls it
        plain = ground_truth_diagnostic(model, test, input_size=S)(model)
        with_cut = ground_truth_diagnostic(model, test, input_size=S, cut="layer4.1")(model)
    for k, v in plain.items():
        assert np.isclose(with_cut[k], v, rtol=1e-4), k
    with pytest.raises(ConfigError, match="trainable_from='layer9.0' is not a block"):
        finetune(tiny_ckpt, smoke_root, tmp_path / "bad", _cfg(trainable_from="layer9.0"), **kw)
    assert not (tmp_path / "bad").exists()


def test_adapt_batchnorm_takes_the_recordings_statistics(tiny_ckpt, smoke_root):
    """AdaBN: with one batch of all crops, the stem's BatchNorm mean and variance are the
    channel-wise mean and unbiased variance of conv1's output over those crops (computed here by
    hand on the crops :func:`sequence_features` makes); the weights and the training flags are
    unchanged."""
    from airpose_lib.data.sequences.reader import load_sequence
    from airpose_lib.errors import ConfigError
    from airpose_lib.finetune.predict import adapt_batchnorm, sequence_features

    model, _, _ = load_sized_network(tiny_ckpt)
    model.train()
    seq = load_sequence(smoke_root, frames=range(0, 6), detectors=("openpose",))
    weights = {k: v.clone() for k, v in model.state_dict().items()
               if not k.endswith(("running_mean", "running_var", "num_batches_tracked"))}
    n = adapt_batchnorm(model, seq, input_size=S, frames=seq.frames[:3], batch_size=6)
    assert n == 6 and model.training and model.backbone.bn1.momentum == 0.1
    seen = []  # conv1's output on the crops fine-tuning's cached features come from
    hook = model.backbone.conv1.register_forward_hook(lambda m, i, o: seen.append(o.detach().double()))
    sequence_features(model, seq, input_size=S, frames=seq.frames[:3])
    hook.remove()
    y = torch.cat(seen)
    assert y.shape[0] == 6
    mean = y.mean(dim=(0, 2, 3))
    var = y.permute(1, 0, 2, 3).flatten(1).var(dim=1, unbiased=True)
    torch.testing.assert_close(model.backbone.bn1.running_mean.double(), mean, rtol=1e-4, atol=1e-6)
    torch.testing.assert_close(model.backbone.bn1.running_var.double(), var, rtol=1e-4, atol=1e-6)
    for k, v in model.state_dict().items():
        if k in weights:
            assert torch.equal(v, weights[k]), k
    # a share: the convex combination of the stored statistics and the recording's
    half, _, _ = load_sized_network(tiny_ckpt)
    stored = {k: v.clone() for k, v in half.state_dict().items() if k.endswith(("running_mean", "running_var"))}
    adapt_batchnorm(half, seq, input_size=S, frames=seq.frames[:3], batch_size=6, weight=0.25)
    for k, v in stored.items():
        torch.testing.assert_close(half.state_dict()[k], 0.75 * v + 0.25 * model.state_dict()[k], msg=k)
    with pytest.raises(ConfigError, match="batch_size must be >= 2"):
        adapt_batchnorm(model, seq, input_size=S, batch_size=1)
    with pytest.raises(ConfigError, match="weight must be in"):
        adapt_batchnorm(model, seq, input_size=S, weight=0.0)
    # a pass that fails half-way (an unreadable image) leaves the statistics as they were
    before = {k: v.clone() for k, v in model.state_dict().items()}
    image, calls = seq.image, []

    def failing(row, view):
        calls.append(row)
        if len(calls) > 3:
            raise OSError("unreadable image")
        return image(row, view)

    seq.image = failing
    with pytest.raises(OSError, match="unreadable"):
        adapt_batchnorm(model, seq, input_size=S, batch_size=2)
    seq.image = image
    for k, v in model.state_dict().items():
        assert torch.equal(v, before[k]), k


def test_finetune_with_adapted_batchnorm(tiny_ckpt, smoke_root, tmp_path, body32, tiny_prior):
    """adapt_bn: the checkpoint carries the statistics of the training frames only (the held-out
    ones unseen), every other backbone tensor is the base network's, and a finished frozen run is
    not reused for it."""
    from airpose_lib.data.sequences.reader import load_sequence
    from airpose_lib.finetune.predict import adapt_batchnorm
    from airpose_lib.finetune.train import finetune_done
    from airpose_lib.train import load_checkpoint

    kw = dict(prior=tiny_prior, body_model=body32)
    cfg = _cfg(steps=2, holdout_fraction=0.5, adapt_bn=1.0)
    res = finetune(tiny_ckpt, smoke_root, tmp_path / "adabn", cfg, **kw)
    assert res.step == 2
    model, _, _ = load_sized_network(tiny_ckpt)
    seq = load_sequence(smoke_root, frames=range(0, 6), detectors=("openpose",))
    adapt_batchnorm(model, seq, input_size=S, frames=seq.frames[:3], seed=cfg.seed)  # the first half trains
    before, after = load_checkpoint(tiny_ckpt)["model"], load_checkpoint(res.checkpoint)["model"]
    stats = [k for k in before if k.startswith("backbone.") and k.endswith(("running_mean", "running_var"))]
    for k in before:
        if k.startswith("backbone."):
            expected = model.state_dict()[k] if k in stats or k.endswith("num_batches_tracked") else before[k]
            torch.testing.assert_close(after[k], expected, rtol=0, atol=0, msg=k)
    assert any(not torch.equal(before[k], after[k]) for k in stats)
    frozen = finetune(tiny_ckpt, smoke_root, tmp_path / "frozen", cfg.replace(adapt_bn=0.0), **kw)
    assert finetune_done(tmp_path / "adabn", tiny_ckpt, smoke_root, cfg)
    assert not finetune_done(frozen.out_dir, tiny_ckpt, smoke_root, cfg)


def test_resume_matches_an_uninterrupted_run(tiny_ckpt, smoke_root, tmp_path, body32, tiny_prior):
    from airpose_lib.train import load_checkpoint, read_log

    kw = dict(prior=tiny_prior, body_model=body32)
    sel = dict(frames=[0, 8], holdout_fraction=0.25)  # 6 training, 2 held-out frames
    straight = finetune(tiny_ckpt, smoke_root, tmp_path / "a", _cfg(**sel), **kw)
    part = finetune(tiny_ckpt, smoke_root, tmp_path / "b", _cfg(**sel), stop_at=3, **kw)
    assert part.stopped_early and part.step == 3 and part.final is None
    resumed = finetune(tiny_ckpt, smoke_root, tmp_path / "b", _cfg(**sel), **kw)
    assert resumed.step == 6
    a, b = load_checkpoint(straight.checkpoint), load_checkpoint(resumed.checkpoint)
    for k in a["model"]:
        assert torch.equal(a["model"][k], b["model"][k]), k
    strip = lambda rows: [{k: v for k, v in r.items() if k != "time_s"} for r in rows]  # noqa: E731
    assert strip(read_log(tmp_path / "a" / "log.csv")) == strip(read_log(tmp_path / "b" / "log.csv"))
    assert straight.final == resumed.final and straight.initial == resumed.initial
    assert straight.selection == resumed.selection and straight.best_step == resumed.best_step
    assert straight.selection["step"] == [0, 6]  # before training and at the end (no step at the interruption)
    with pytest.raises(ValueError, match="cannot resume.*lr"):
        finetune(tiny_ckpt, smoke_root, tmp_path / "b", _cfg(steps=8, lr=5e-5, **sel), **kw)


def test_a_finished_run_from_another_network_or_recording_is_not_done(tiny_ckpt, smoke_root, tmp_path, body32,
                                                                       tiny_prior):
    """The recordings experiment computes the test person's diagnostics only for runs it will
    train, and reuses a finished run otherwise: a run from another base network (the profile's
    networks retrained), on other pixels (the recording rendered again with other settings) or
    with another diagnostic's recordings is not finished; a copy of the same recording is."""
    import shutil

    import cv2

    from airpose_lib.engine.checkpoint import load_checkpoint, save_checkpoint
    from airpose_lib.finetune.train import finetune_done

    root = shutil.copytree(smoke_root, tmp_path / "rec")
    cfg = _cfg(steps=2)
    finetune(tiny_ckpt, root, tmp_path / "ft", cfg, prior=tiny_prior, body_model=body32, diagnostic_key="tests-a")
    assert finetune_done(tmp_path / "ft", tiny_ckpt, root, cfg, diagnostic_key="tests-a")
    copy = shutil.copytree(root, tmp_path / "copy")
    assert finetune_done(tmp_path / "ft", tiny_ckpt, copy, cfg, diagnostic_key="tests-a")  # content, not the
    cache = tmp_path / "ft" / "feature_cache.pt"  # path or the files' dates; the cached features too:
    written = cache.stat().st_mtime_ns
    finetune(tiny_ckpt, copy, tmp_path / "ft", cfg, prior=tiny_prior, body_model=body32, diagnostic_key="tests-a")
    assert cache.stat().st_mtime_ns == written  # reused, not computed again
    assert not finetune_done(tmp_path / "ft", tiny_ckpt, root, cfg, diagnostic_key="tests-b")
    assert not finetune_done(tmp_path / "ft", tiny_ckpt, root, cfg)
    state = load_checkpoint(tiny_ckpt)
    state["model"]["regressor.fc1.bias"] = state["model"]["regressor.fc1.bias"] + 1.0
    other = save_checkpoint(tmp_path / "other", state, keep=0)
    assert not finetune_done(tmp_path / "ft", other, root, cfg, diagnostic_key="tests-a")
    assert not finetune_done(tmp_path / "ft", tiny_ckpt, root, _cfg(steps=3), diagnostic_key="tests-a")
    assert not finetune_done(tmp_path / "ft", tiny_ckpt, root, _cfg(steps=2, lr=5e-5), diagnostic_key="tests-a")
    assert not finetune_done(tmp_path / "empty", tiny_ckpt, root, cfg, diagnostic_key="tests-a")
    # one image with other pixels (a marker on the ground, say): not done, and not resumed either
    image = sorted((root / "machine_1" / "images").glob("*.jpg"))[0]
    pixels = cv2.imread(str(image))
    pixels[:20, :20] = 255 - pixels[:20, :20]
    cv2.imwrite(str(image), pixels)
    assert not finetune_done(tmp_path / "ft", tiny_ckpt, root, cfg, diagnostic_key="tests-a")
    with pytest.raises(ValueError, match="cannot resume.*recording"):
        finetune(tiny_ckpt, root, tmp_path / "ft", _cfg(steps=3), prior=tiny_prior, body_model=body32,
                 diagnostic_key="tests-a")


def test_finetune_bad_input(tiny_ckpt, smoke_root, tmp_path, body32, tiny_prior):
    kw = dict(prior=tiny_prior, body_model=body32)
    with pytest.raises(ValueError, match="fewer than one batch"):
        finetune(tiny_ckpt, smoke_root, tmp_path / "x", _cfg(frames=[0, 2], batch_size=4), **kw)
    with pytest.raises(ValueError, match="no image numbered"):
        finetune(tiny_ckpt, smoke_root, tmp_path / "y", _cfg(frames=[5000, 5010]), **kw)
    with pytest.raises(ValueError, match="start < stop"):
        _cfg(frames=[6, 2])


def test_finetune_config_from_profiles(tmp_path):
    assert finetune_config(None) == FineTuneConfig()
    cfg = kit_configs("smoke").finetune  # with or without a `finetune:` section
    assert isinstance(cfg, FineTuneConfig)
    prof = tmp_path / "p.yaml"
    prof.write_text("finetune:\n  steps: 5\n  frames: [0, 7000]\n  loss: {w_vposer: 0.5}\n")
    cfg = finetune_config(kit_configs(prof).finetune, seed=7)
    assert (cfg.steps, cfg.frames, cfg.loss, cfg.seed, cfg.lr) == (5, [0, 7000], {"w_vposer": 0.5}, 7, 5e-5)
    prof.write_text("finetune:\n  stepz: 5\n")
    with pytest.raises(ValueError, match="p.yaml.*stepz"):
        assert kit_configs(prof).finetune is None  # raises first


def test_cli_predict_and_finetune(tiny_ckpt, smoke_root, tmp_path, body32, capsys):
    """The subcommand builders in a parser of their own (airpose_lib.cli registers them)."""
    import argparse

    from airpose_lib.cli import CLIError
    from airpose_lib.cli.finetune import add_finetune, add_predict
    from airpose_lib.prior import VPoser, save_prior

    parser = argparse.ArgumentParser(prog="airpose")
    sub = parser.add_subparsers(dest="command", required=True)
    add_finetune(sub)
    add_predict(sub)
    run = lambda argv: (a := parser.parse_args(argv)).func(a)  # noqa: E731

    out = tmp_path / "pred.npz"
    assert run(["predict", "--checkpoint", str(tiny_ckpt), "--sequence", str(smoke_root), "--out", str(out),
                "--frames", ":3", "--quiet"]) == 0
    assert load_predictions(out)["frames"].tolist() == [0, 1, 2]
    torch.manual_seed(1)
    prior = save_prior(VPoser(32, 8).eval(), tmp_path / "prior.pt")
    # the predictions file is what `airpose fit --init` reads (its `--frames` are image numbers too)
    from airpose_lib import cli

    assert cli.main(["fit", "--sequence", str(smoke_root), "--init", str(out), "--frames", "0:3", "--iterations", "1",
                     "--prior-path", str(prior), "--profile", "smoke", "--quiet", "--out",
                     str(tmp_path / "fit.npz")]) == 0
    with np.load(tmp_path / "fit.npz") as fit:
        assert fit["frames"].tolist() == [0, 1, 2] and fit["tau"].shape == (3, 2, 3)
    assert run(["finetune", "--checkpoint", str(tiny_ckpt), "--sequence", str(smoke_root), "--out",
                str(tmp_path / "ft"), "--profile", "smoke", "--frames", "0:4", "--steps", "2", "--batch-size", "2",
                "--prior-path", str(prior), "--quiet", "--set", "lr=1e-4", "loss.w_beta=4"]) == 0
    assert "2D loss" in capsys.readouterr().out
    cfg = json.loads((tmp_path / "ft" / "config.json").read_text())
    assert (cfg["steps"], cfg["frames"], cfg["lr"], cfg["loss"]) == (2, [0, 4], 1e-4, {"w_beta": 4})
    with pytest.raises(CLIError, match="--checkpoint .*nope.pt: no such file"):
        run(["predict", "--checkpoint", str(tmp_path / "nope.pt"), "--sequence", str(smoke_root), "--out", str(out)])
    with pytest.raises(CLIError, match="START:STOP"):
        run(["finetune", "--checkpoint", str(tiny_ckpt), "--sequence", str(smoke_root), "--out", str(tmp_path / "z"),
             "--frames", "7"])
    with pytest.raises(CLIError, match="unknown key"):
        run(["finetune", "--checkpoint", str(tiny_ckpt), "--sequence", str(smoke_root), "--out", str(tmp_path / "z"),
             "--set", "bogus=1"])


# -- pixel units and model selection --------------------------------------------------------------
def test_pixel_quantities_scale_with_resolution(open_model):
    from airpose_lib.finetune import pixel_settings, resolution_scales

    r = resolution_scales([(960, 540), (1920, 1080), (1280, 720)])
    np.testing.assert_allclose(r, [0.5, 1.0, 2 / 3])
    px = pixel_settings(r, threshold_px=100.0, w_j2d=0.01)
    np.testing.assert_allclose(px["threshold_px"], [50.0, 100.0, 200 / 3])
    np.testing.assert_allclose(px["w_j2d_per_px2"], [0.04, 0.01, 0.0225])
    # the agreement filter: a joint 70 px apart is a disagreement at half resolution, not at full
    op, ap = _agreeing_pair()
    op = np.repeat(op, 2, axis=1)
    ap = np.repeat(ap, 2, axis=1)
    j, c = _b("RWrist"), _c("RWrist")
    ap[:, :, c, 0] = op[:, :, j, 0] + 70.0
    m = agreement_masks(op, ap, threshold_px=100.0 * resolution_scales([(960, 540), (1920, 1080)]))
    assert m.disagree[:, 0, j].all() and m.kept[:, 1, j].all()
    with pytest.raises(ValueError, match="3 values for 2 views"):
        agreement_masks(op, ap, threshold_px=np.array([50.0, 60.0, 70.0]))
    # the 2D loss of a half-resolution view with pixel_scale 0.5 equals the full-resolution one
    loss = FineTuneLoss(finetune_loss_config("fullcam", w_vposer=0.0), body_model=open_model)
    pred = _random_pred()
    K_full = _K()
    K_half = K_full.clone()
    K_half[:, :2] *= 0.5
    uv = loss.project(pred, K_full)
    rng = torch.Generator().manual_seed(3)
    targets = torch.cat((uv + 8 * torch.randn(uv.shape, generator=rng, dtype=uv.dtype),
                         torch.rand(*uv.shape[:-1], 1, generator=rng, dtype=uv.dtype)), -1)
    half = targets.clone()
    half[..., :2] *= 0.5
    full = loss(pred, targets, K_full)["j2d"]
    torch.testing.assert_close(loss(pred, half, K_half, pixel_scale=torch.tensor([0.5, 0.5]))["j2d"], full)
    torch.testing.assert_close(loss(pred, half, K_half)["j2d"], full / 4)  # without: 4x weaker


def test_heldout_split():
    from airpose_lib.finetune.train import heldout_split

    tr, ho = heldout_split(10, 0.2)
    assert tr.tolist() == list(range(8)) and ho.tolist() == [8, 9]
    assert heldout_split(3, 0.2)[1].tolist() == [2] and heldout_split(5, 0.0)[1].size == 0


def _rows(selection: dict) -> list[dict]:
    """selection.csv as lists -> one mapping per selection point."""
    return [dict(zip(selection, values)) for values in zip(*selection.values())]


def _weighted_terms(loss: dict) -> list[str]:
    return [t for t in ("j2d", "beta", "vposer", "theta", "depth") if loss[f"w_{t}"] != 0]


def _point(step, **terms):
    """A selection row from ``term=(heldout, train)`` pairs."""
    row = {"step": step}
    for t, (h, tr) in terms.items():
        row[f"heldout_{t}"], row[f"train_{t}"] = h, tr
    return row


def test_selection_rules_on_hand_made_curves():
    """first_overfit keeps the point before the first weighted term whose held-out value rises
    while its training value falls; a term rising on both is a trade-off, not overfitting."""
    rows = [_point(0, j2d=(300, 310), beta=(1.0, 1.0)),
            _point(100, j2d=(130, 120), beta=(1.5, 1.6)),   # beta up on both: not overfitting
            _point(200, j2d=(126, 110), beta=(1.6, 1.7)),
            _point(300, j2d=(132, 100), beta=(1.6, 1.7)),   # j2d: held-out up, training down
            _point(400, j2d=(120, 95), beta=(1.6, 1.7))]
    sel = select_step(rows, "first_overfit", ["j2d", "beta"])
    assert (sel.step, sel.overfit_step, sel.overfit_terms) == (200, 300, ["j2d"])
    assert select_step(rows, "min_heldout_j2d", ["j2d"]).step == 400
    # beta held-out up with training down at 100: that term counts only if weighted
    rows[1] = _point(100, j2d=(130, 120), beta=(1.5, 0.9))
    assert select_step(rows, "first_overfit", ["j2d", "beta"]).overfit_step == 100
    assert select_step(rows, "first_overfit", ["j2d"]).step == 200
    # no term ever overfits: the last point; ties of the held-out minimum: the earliest
    flat = [_point(s, j2d=(100 - s / 100, 100 - s / 100)) for s in (0, 100, 200)]
    assert select_step(flat, "first_overfit", ["j2d"]) == Selection(200)
    tie = [_point(0, j2d=(5, 5)), _point(100, j2d=(4, 4)), _point(200, j2d=(4, 3))]
    assert select_step(tie, "min_heldout_j2d", ["j2d"]).step == 100 and select_step([], "first_overfit", []).step is None
    with pytest.raises(ValueError, match="unknown selection rule"):
        select_step(tie, "lowest", ["j2d"])
    with pytest.raises(ValueError, match="selection must be one of"):
        _cfg(selection="lowest")


def test_model_selection_never_reads_the_test_person(tiny_ckpt, smoke_root, tmp_path, body32, tiny_prior):
    """Selection on person 1's held-out frames; a test recording's errors are logged per checkpoint.
    With the test recording replaced by NaN the choice, the weights and the held-out losses are the same."""
    import types

    from airpose_lib.data.sequences.reader import load_sequence
    from airpose_lib.experiments.recording_diagnostic import ground_truth_diagnostic
    from airpose_lib.finetune.predict import sequence_features
    from airpose_lib.train import load_checkpoint

    model, _, _ = load_sized_network(tiny_ckpt)
    test = load_sequence(smoke_root, frames=range(40, 46), detectors=("openpose",))
    feats = sequence_features(model, test, input_size=S)
    nan = types.SimpleNamespace(root=test.root, K=test.K, num_views=test.num_views, image=test.image,
                                ground_truth={k: np.full_like(np.asarray(v, np.float64), np.nan)
                                              for k, v in test.ground_truth.items()})
    nan_feats = {k: (np.full_like(v, np.nan) if v.dtype.kind == "f" else v) for k, v in feats.items()}
    cfg = _cfg(steps=8, frames=[0, 10], holdout_fraction=0.3, checkpoint_every=2, lr=3e-4)
    kw = dict(prior=tiny_prior, body_model=body32)
    runs = {}
    for name, seq, f in (("real", test, feats), ("nan", nan, nan_feats)):
        diag = ground_truth_diagnostic(model, seq, input_size=S, features=f)
        runs[name] = finetune(tiny_ckpt, smoke_root, tmp_path / name, cfg, diagnostic=diag, **kw)
    a, b = runs["real"], runs["nan"]
    assert a.selection["step"] == [0, 2, 4, 6, 8] and a.heldout_frames == 3
    assert a.best_step == b.best_step and a.selection["heldout_j2d"] == b.selection["heldout_j2d"]
    assert a.best_step == select_step(_rows(a.selection), "first_overfit", _weighted_terms(a.loss)).step
    assert (a.overfit_step, a.overfit_terms) == (b.overfit_step, b.overfit_terms)
    assert np.isfinite(a.selection["diag_mpjpe_m"]).all() and np.isnan(b.selection["diag_mpjpe_m"]).all()
    assert len(set(a.selection["diag_mpjpe_m"])) > 1  # the diagnostic does see the changing weights
    for which in ("best_checkpoint", "checkpoint"):
        wa, wb = load_checkpoint(getattr(a, which))["model"], load_checkpoint(getattr(b, which))["model"]
        assert all(torch.equal(wa[k], wb[k]) for k in wa), which
    best = load_checkpoint(a.best_checkpoint)
    assert best["step"] == a.best_step and load_sized_network(a.best_checkpoint)[2] == S
    assert (tmp_path / "real" / "selection.csv").is_file()


# -- the true-keypoint control ----------------------------------------------------------------------
def test_true_targets_keep_what_a_perfect_detector_sees():
    from airpose_lib.finetune.keypoints import true_targets

    kp = np.array([[[[10.0, 20.0], [959.0, 539.0], [960.0, 5.0], [-1.0, 5.0], [np.nan, 3.0], [4.0, 4.0]],
                    [[10.0, 20.0], [959.0, 539.0], [960.0, 5.0], [-1.0, 5.0], [1.0, 3.0], [4.0, 4.0]]]])
    z = np.array([[[5.0, 5.0, 5.0, 5.0, 5.0, -0.5], [5.0, 5.0, 5.0, 5.0, 5.0, 5.0]]])
    out = true_targets(kp, z, np.array([[960, 540], [1920, 1080]]))
    assert out.shape == (1, 2, 6, 3) and out.dtype == np.float32
    # view 0 (960x540): inside, on the last pixel, right of it, left of it, NaN, behind the camera
    np.testing.assert_array_equal(out[0, 0, :, 2], [1, 1, 0, 0, 0, 0])
    np.testing.assert_array_equal(out[0, 1, :, 2], [1, 1, 1, 0, 1, 1])  # the 1920 px view sees x = 960
    np.testing.assert_array_equal(out[0, 0, 1], [959.0, 539.0, 1.0])
    np.testing.assert_array_equal(out[0, 0, 2], [0.0, 0.0, 0.0])  # unseen: exactly OpenPose's "missed"
    with pytest.raises(ValueError, match="kp2d"):
        true_targets(kp, z[..., :3], np.array([[960, 540], [1920, 1080]]))


def test_finetune_on_true_keypoints_uses_the_ground_truth(tiny_ckpt, smoke_root, tmp_path, body32, tiny_prior):
    from airpose_lib.data.sequences.reader import load_sequence
    from airpose_lib.finetune.keypoints import true_targets
    from airpose_lib.finetune.predict import image_sizes
    from airpose_lib.finetune.train import finetune_done

    kw = dict(prior=tiny_prior, body_model=body32)
    det = finetune(tiny_ckpt, smoke_root, tmp_path / "det", _cfg(steps=0), **kw)
    true = finetune(tiny_ckpt, smoke_root, tmp_path / "true", _cfg(steps=0, targets="ground_truth"), **kw)
    seq = load_sequence(smoke_root, frames=np.arange(6))
    gt = seq.ground_truth
    want = true_targets(gt["kp2d_body25"], gt["kp_depth_body25"], np.asarray(image_sizes(seq)))
    assert true.keypoints == {"targets": "ground_truth", "kept": int((want[..., 2] > 0).sum())}
    assert true.config["targets"] == "ground_truth" and "disagree" in det.keypoints
    # same network, frames and crops: only the targets differ, and the true ones are not the detections
    assert true.initial["j2d"] != det.initial["j2d"] and true.initial["beta"] == det.initial["beta"]
    # a changed target source is a different run, never a resumed one
    assert not finetune_done(tmp_path / "true", tiny_ckpt, smoke_root, _cfg(steps=0))
    assert finetune_done(tmp_path / "true", tiny_ckpt, smoke_root, _cfg(steps=0, targets="ground_truth"))
    with pytest.raises(ValueError, match="targets must be one of"):
        _cfg(targets="openpose")


def test_finetune_on_mediapipe_puts_it_in_openposes_place(tiny_ckpt, smoke_root, tmp_path, body32, tiny_prior):
    """targets="mediapipe": the agreement filter with MediaPipe's keypoints instead of OpenPose's.
    MediaPipe here: OpenPose's keypoints 40 px to the right (a linked copy of the recording)."""
    from airpose_lib.data.sequences.mediapipe_pose import write_body25
    from airpose_lib.data.sequences.reader import load_sequence
    from airpose_lib.finetune import resolution_scales
    from airpose_lib.finetune.keypoints import agreement_masks, agreement_summary
    from airpose_lib.finetune.predict import image_sizes

    root = tmp_path / "rec"
    root.mkdir()
    for item in smoke_root.iterdir():
        if not item.is_dir():
            (root / item.name).symlink_to(item)
    seq = load_sequence(smoke_root, detectors=("openpose", "alphapose"), ground_truth=False)
    mp = np.where(seq.keypoints["openpose"][..., 2:] > 0, seq.keypoints["openpose"] + [40.0, 0.0, 0.0], 0.0)
    for v in range(seq.num_views):
        (root / f"machine_{v + 1}").mkdir()
        for item in (smoke_root / f"machine_{v + 1}").iterdir():
            (root / f"machine_{v + 1}" / item.name).symlink_to(item)
        write_body25(root / f"machine_{v + 1}" / "mediapipe_res.pkl", seq.frames.tolist(), mp[:, v])
    kw = dict(prior=tiny_prior, body_model=body32)
    res = finetune(tiny_ckpt, root, tmp_path / "mp", _cfg(steps=0, targets="mediapipe", threshold_px=60.0), **kw)
    thr = 60.0 * resolution_scales(image_sizes(seq), 1920.0)
    ap = seq.keypoints["alphapose"][:6]
    want = agreement_summary(agreement_masks(mp[:6], ap, threshold_px=thr, min_confidence=0.05))
    assert res.keypoints == want and res.config["targets"] == "mediapipe"
    # the shift (20 px in these 960 px views; the threshold is 30 px here) moves joints across it
    openpose = agreement_summary(agreement_masks(seq.keypoints["openpose"][:6], ap, threshold_px=thr,
                                                 min_confidence=0.05))
    assert want["kept"] > 0 and want["disagree"] > openpose["disagree"]


def test_a_run_saved_before_an_option_existed_resumes_with_its_default():
    from airpose_lib.engine import StaleRunError
    from airpose_lib.finetune.train import _check_resume

    cfg = _cfg()
    old = {k: v for k, v in cfg.to_dict().items() if k != "targets"}  # written before `targets` existed
    saved = {"config": old, "base_fingerprint": "f", "data_fingerprint": "d"}
    _check_resume(saved, cfg, "f", "d")  # the default: same run
    with pytest.raises(StaleRunError, match="targets"):
        _check_resume(saved, cfg.replace(targets="ground_truth"), "f", "d")
    with pytest.raises(StaleRunError, match="base checkpoint"):
        _check_resume(saved, cfg, "g", "d")
    # a run saved before its recording was fingerprinted cannot show it was made on this one
    with pytest.raises(StaleRunError, match="recording"):
        _check_resume({"config": old, "base_fingerprint": "f"}, cfg, "f", "d")


def test_the_training_frames_are_evaluated_once_per_selection_point(tiny_ckpt, smoke_root, tmp_path, body32,
                                                                    tiny_prior, monkeypatch):
    import airpose_lib.finetune.train as T

    calls = []
    real = T.evaluate_finetune_loss

    def counting(model, loss_fn, features, *args, **kw):
        calls.append(int(features.shape[0]))
        return real(model, loss_fn, features, *args, **kw)

    monkeypatch.setattr(T, "evaluate_finetune_loss", counting)
    cfg = _cfg(frames=[0, 10], steps=4, batch_size=2, checkpoint_every=2, keep_checkpoints=1, holdout_fraction=0.2)
    res = finetune(tiny_ckpt, smoke_root, tmp_path / "ft", cfg, prior=tiny_prior, body_model=body32)
    rows = res.selection
    assert rows["step"] == [0, 2, 4]
    # selection points 0, 2, 4: held-out + training frames each; `initial` and `final` reuse them
    assert sorted(calls) == sorted([res.num_frames, res.heldout_frames] * 3)
    assert res.initial == {k[len("train_"):]: v[0] for k, v in rows.items() if k.startswith("train_")}
    assert res.final == {k[len("train_"):]: v[-1] for k, v in rows.items() if k.startswith("train_")}
