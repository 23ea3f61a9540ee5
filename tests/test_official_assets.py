"""Loaders of the official AirPose assets, on fixtures the kit writes in the official formats.

References are independent of the code under test: OpenCV's projectPoints / Rodrigues, roma,
hand-written crop formulas, the official key names and fc1 widths of the paper/official code.
"""
from __future__ import annotations

import argparse
import hashlib
import pickle
import re
import shutil
import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest
import roma
import torch
from official_fixtures import (
    AUTHOR_ROOT,
    write_official_real_fixture,
    write_official_synthetic_fixture,
)

from airpose_lib.data.official.real import (
    REAL_DATA_SPLITS,
    load_marker_poses,
    load_official_real,
    real_split_frames,
)
from airpose_lib.data.official.synthetic import (
    OfficialDataError,
    OfficialSyntheticDataset,
    official_split_files,
    read_official_sample,
    remap_official_path,
)
from airpose_lib.data.sequences.layout import SequenceFormatError
from airpose_lib.data.sequences.writer import OfficialLayoutWriter
from airpose_lib.data.still.dataset import PER_VIEW_KEYS, SAMPLE_KEYS, denormalize_images
from airpose_lib.model import AirPoseNet
from airpose_lib.model.official import (
    OfficialCheckpointError,
    detect_backbone,
    detect_variant,
    load_official_checkpoint,
    official_to_kit,
    read_official_checkpoint,
    to_official_state_dict,
    write_official_checkpoint,
)

S = 128  # crop side of the data tests
VARIANTS = ("baseline", "multiview", "fullcam", "airpose")

# The StillFrameDataset contract (airpose_lib/data/dataset.py docstring), V = 2 views.
CONTRACT = {
    "images": ((2, 3, S, S), torch.float32), "P": ((2, 3), torch.float32), "K": ((2, 3, 3), torch.float32),
    "bbox": ((2, 4), torch.float32), "R_cw": ((2, 3, 3), torch.float32), "t_cw": ((2, 3), torch.float32),
    "phi": ((2, 3, 3), torch.float32), "tau": ((2, 3), torch.float32), "theta": ((21, 3), torch.float32),
    "beta": ((10,), torch.float32), "gender": ((), torch.int64), "j2d": ((2, 22, 2), torch.float32),
    "kp2d": ((2, 25, 2), torch.float32), "kp_visible": ((2, 25), torch.bool),
    "j3d_cam": ((2, 22, 3), torch.float32), "index": ((), torch.int64),
}


def _tree_state(root: Path) -> dict:
    return {str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns,
                                       hashlib.sha256(p.read_bytes()).hexdigest())
            for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def synth(module_tmp, open_model_files):
    root = module_tmp("official_synth")
    # 5 subjects: 2 training, 2 validation (the last training subjects), 1 test
    info = write_official_synthetic_fixture(root, n_subjects=5, n_positions=2, n_cameras=2, seed=0)
    return info


def _sample(pkl: Path) -> dict:
    with open(pkl, "rb") as fh:
        return pickle.load(fh)


# -- synthetic data -------------------------------------------------------------------------------
@pytest.mark.parametrize("split", ["train", "test"])
def test_items_follow_the_still_frame_contract(synth, split):
    ds = OfficialSyntheticDataset(synth["root"], split, input_size=S)
    assert len(ds) == len(synth[split]) and ds.files == synth[split]
    item = ds[0]
    assert set(item) == set(SAMPLE_KEYS) and set(PER_VIEW_KEYS) <= set(item)
    for k, (shape, dtype) in CONTRACT.items():
        assert tuple(item[k].shape) == shape and item[k].dtype == dtype, k
    assert torch.isfinite(item["images"]).all() and torch.isfinite(item["j2d"]).all()
    # a batch collates like a StillFrameDataset batch
    batch = torch.utils.data.default_collate([ds[0], ds[1]])
    assert batch["images"].shape == (2, 2, 3, S, S)


def test_geometry_against_opencv(synth):
    ds = OfficialSyntheticDataset(synth["root"], "test", input_size=S)  # no view swap, no jitter
    for i, pkl in enumerate(ds.files):
        s, item = _sample(pkl), ds[i]
        Jw = s["smpl_joints_wrt_origin"][0, :22].astype(np.float64)
        orient, trans = s["smplorient_rotmat_wrt_origin"][0].astype(np.float64), s["smpltrans"].reshape(3)
        assert item["gender"] == {"male": 1, "female": 2}[s["smplgender"]]
        np.testing.assert_allclose(item["theta"].numpy(), s["smplpose"].reshape(21, 3), atol=0)
        for v in range(2):
            E, K = s[f"cam{v}"]["extr"], s[f"cam{v}"]["intr"]
            rvec = cv2.Rodrigues(E[:3, :3])[0]
            uv = cv2.projectPoints(Jw, rvec, E[:3, 3], K, None)[0].reshape(-1, 2)
            np.testing.assert_allclose(item["j2d"][v].numpy(), uv, atol=2e-3)
            np.testing.assert_allclose(item["j3d_cam"][v].numpy(), Jw @ E[:3, :3].T + E[:3, 3], atol=1e-5)
            np.testing.assert_allclose(item["phi"][v].numpy(), E[:3, :3] @ orient, atol=1e-6)
            np.testing.assert_allclose(item["tau"][v].numpy(), E[:3, :3] @ trans + E[:3, 3], atol=1e-5)
            # test split: the tight box of the pkl, and P by the paper's formula
            (x0, y0), (x1, y1) = s[f"bb{v}"]
            np.testing.assert_allclose(item["bbox"][v].numpy(), [x0, y0, x1, y1])
            P = [(x0 + x1) / 2 / K[0, 2] - 1, (y0 + y1) / 2 / K[1, 2] - 1, S / max(x1 - x0, y1 - y0)]
            np.testing.assert_allclose(item["P"][v].numpy(), P, rtol=1e-6)
            np.testing.assert_allclose(item["j2d"][v, :22].numpy(), s[f"j2d{v}"][:22], atol=2e-3)


def test_rgb_and_arrays_for_match_the_items(synth):
    ds = OfficialSyntheticDataset(synth["root"], "test", input_size=S)
    arr, item = ds.arrays_for([0, 1]), ds[1]
    for k in ("P", "K", "bbox", "R_cw", "t_cw", "phi", "tau", "j2d", "j3d_cam", "theta", "beta"):
        np.testing.assert_allclose(arr[k][1], item[k].numpy(), rtol=1e-6, atol=1e-5, err_msg=k)
    np.testing.assert_array_equal(arr["bbox"], arr["bbox_tight"])
    np.testing.assert_array_equal(ds.rgb(1), denormalize_images(item["images"]))


def _disc_errors(item, colors, radius_full, j2d_full) -> list[float]:
    """Distance (crop px) between each isolated disc's centroid and where j2d says it is."""
    rgb = denormalize_images(item["images"]).astype(np.int16)
    errs = []
    for v in range(rgb.shape[0]):
        x0, y0, x1, y1 = item["bbox"][v].double().tolist()
        s = S / max(x1 - x0, y1 - y0)
        uv = j2d_full[v]
        pred = s * (uv - [(x0 + x1) / 2, (y0 + y1) / 2]) + S / 2  # hand-written crop map
        half = int(np.ceil(radius_full * s)) + 2  # window half-size, crop px
        for j in range(22):
            d = np.linalg.norm(uv - uv[j], axis=1) * s
            d[j] = np.inf
            if d.min() < half * 1.5 + radius_full * s + 2 or not (x0 + radius_full < uv[j, 0] < x1 - radius_full
                                                                  and y0 + radius_full < uv[j, 1] < y1 - radius_full):
                continue  # discs near others or cut by the box cannot be located
            # colour-weighted centroid in a window around the prediction (bilinear resampling
            # keeps it; the isolation test above keeps other discs out of the window)
            cx, cy = int(round(pred[j, 0])), int(round(pred[j, 1]))
            ys, xs = np.mgrid[max(cy - half, 0):min(cy + half + 1, S), max(cx - half, 0):min(cx + half + 1, S)]
            col = colors[j].astype(np.float64)
            w = np.clip(rgb[v, ys, xs] @ col / (col @ col), 0, 1)
            w[np.abs(rgb[v, ys, xs] - col * w[..., None]).max(-1) > 40] = 0  # other colours
            assert w.sum() > 1, f"disc of joint {j} not found in view {v}"
            errs.append(float(np.hypot((w * xs).sum() / w.sum() - pred[j, 0], (w * ys).sum() / w.sum() - pred[j, 1])))
    return errs


@pytest.mark.parametrize("split", ["test", "train"])
def test_drawn_discs_land_where_j2d_says(synth, split):
    np.random.seed(3)  # the training crop jitter
    ds = OfficialSyntheticDataset(synth["root"], split, input_size=S, augment=False)
    errs = []
    for i in range(len(ds)):
        item = ds[i]
        errs += _disc_errors(item, synth["colors"], synth["disc_radius"], item["j2d"].double().numpy())
    # a half-pixel convention slip would give ~0.7 px
    assert len(errs) >= (10 if split == "test" else 5)
    assert max(errs) < (0.3 if split == "test" else 0.5), errs


def test_training_crops_are_jittered_within_200px(synth):
    ds = OfficialSyntheticDataset(synth["root"], "train", input_size=S, augment=False)
    grown = []
    for seed in range(4):
        np.random.seed(seed)
        item = ds[0]
        s = _sample(ds.files[0])
        for v in range(2):
            (x0, y0), (x1, y1) = s[f"bb{v}"]
            b = item["bbox"][v].double().numpy()
            g = np.array([x0 - b[0], y0 - b[1], b[2] - x1, b[3] - y1])
            assert (g >= -1e-4).all() and (g <= 200 + 1e-4).all()
            assert b[0] >= -0.5 and b[1] >= -0.5 and b[2] <= 1919.5 and b[3] <= 1079.5
            grown.append(g)
    assert np.std(np.concatenate(grown)) > 10  # really random


def test_full_frame_images_give_the_same_crops(tmp_path, open_model_files):
    a = write_official_synthetic_fixture(tmp_path / "cropped", n_subjects=1, n_positions=1, seed=5)
    b = write_official_synthetic_fixture(tmp_path / "full", n_subjects=1, n_positions=1, seed=5, cropped=False)
    assert cv2.imread(str(b["root"] / "data/rp_kit000_posed_001/MyCamera0_0.png")).shape == (1080, 1920, 3)
    ia = OfficialSyntheticDataset(a["root"], "test", input_size=S)[0]
    ib = OfficialSyntheticDataset(b["root"], "test", input_size=S)[0]
    for k in ia:
        assert torch.equal(ia[k], ib[k]), k


def test_model_joints_match_pkl_joints(synth):
    a = OfficialSyntheticDataset(synth["root"], "test", input_size=S, joints="model", body_source="open")[1]
    b = OfficialSyntheticDataset(synth["root"], "test", input_size=S)[1]
    torch.testing.assert_close(a["j3d_cam"], b["j3d_cam"], atol=1e-5, rtol=0)
    torch.testing.assert_close(a["kp2d"], b["kp2d"], atol=1e-3, rtol=0, equal_nan=True)


def test_training_loss_runs_on_official_items(synth):
    from airpose_lib.losses import SupervisedLoss, loss_config
    from airpose_lib.train.loop import forward_loss

    ds = OfficialSyntheticDataset(synth["root"], "train", input_size=64)
    batch = torch.utils.data.default_collate([ds[0], ds[1]])
    torch.manual_seed(0)
    model = AirPoseNet("airpose", backbone="resnet18").eval()
    terms = forward_loss(model, SupervisedLoss(loss_config("airpose"), source="open"), batch)
    assert torch.isfinite(terms["total"])


# -- paths and splits -----------------------------------------------------------------------------
def test_path_remapping(tmp_path, synth):
    root = tmp_path
    assert remap_official_path(f"{AUTHOR_ROOT}/dataset/pkls/a_b/a_b_3.pkl", root) == root / "dataset/pkls/a_b/a_b_3.pkl"
    assert remap_official_path(r"C:\data\x\dataset\pkls\s\f.pkl", root) == root / "dataset/pkls/s/f.pkl"
    assert remap_official_path("dataset/pkls/s/f.pkl", root) == root / "dataset/pkls/s/f.pkl"
    assert remap_official_path("/x/dataset/y/dataset/pkls/s/f.pkl", root) == root / "dataset/pkls/s/f.pkl"
    with pytest.raises(OfficialDataError, match="no 'dataset/'"):
        remap_official_path("/home/x/pkls/s/f.pkl", root)
    # the fixture's list files hold the author's absolute paths
    with open(synth["root"] / "dataset/train_pkls.pkl", "rb") as fh:
        assert all(e.startswith(AUTHOR_ROOT) for e in pickle.load(fh))
    ds = OfficialSyntheticDataset(synth["root"], "test", input_size=S)
    pkl = ds.files[0]
    want = synth["root"] / "data" / pkl.parent.name / "MyCamera1_0.png"
    assert ds.image_path(pkl, f"/home/author/x/data/{pkl.parent.name}/MyCamera1_0.png", 1) == want
    assert ds.image_path(pkl, "renamed/elsewhere.png", 1) == want  # the release's naming


def test_split_by_subjects_matches_the_lists(synth, tmp_path):
    for split in ("train", "val", "test"):
        assert official_split_files(synth["root"], split, "subjects", num_test_subjects=1) == synth[split]
        assert official_split_files(synth["root"], split, "lists") == synth[split]
    assert len(synth["train"]) == len(synth["val"]) == 4 and not set(synth["train"]) & set(synth["val"])
    everything = official_split_files(synth["root"], "train", "lists", num_val_subjects=0)
    assert everything == synth["train"] + synth["val"]  # the authors' whole training split
    # without list files the subject rule is used
    shutil.copytree(synth["root"] / "dataset", tmp_path / "dataset")
    for f in ("train_pkls.pkl", "test_pkls.pkl"):
        (tmp_path / "dataset" / f).unlink()
    rel = lambda fs, r: [f.relative_to(r) for f in fs]  # noqa: E731
    got = official_split_files(tmp_path, "test", num_test_subjects=1)
    assert rel(got, tmp_path) == rel(synth["test"], synth["root"])
    # the official preprocessing bug: test list == train list
    (tmp_path / "dataset/train_pkls.pkl").write_bytes(pickle.dumps([str(f) for f in synth["train"]]))
    (tmp_path / "dataset/test_pkls.pkl").write_bytes(pickle.dumps([str(f) for f in synth["train"]]))
    with pytest.raises(OfficialDataError, match="split_by='subjects'"):
        official_split_files(tmp_path, "test")


# -- errors and read-only -------------------------------------------------------------------------
def _copy(synth, tmp_path) -> Path:
    dst = tmp_path / "copy"
    shutil.copytree(synth["root"], dst)
    return dst


def test_missing_dataset_folder(tmp_path):
    with pytest.raises(OfficialDataError, match="no dataset/ folder"):
        OfficialSyntheticDataset(tmp_path, "train")


def test_truncated_sample_pkl(synth, tmp_path):
    root = _copy(synth, tmp_path)
    ds = OfficialSyntheticDataset(root, "test", input_size=S)
    data = ds.files[0].read_bytes()
    ds.files[0].write_bytes(data[: len(data) // 2])
    with pytest.raises(OfficialDataError, match="truncated") as e:
        ds[0]
    assert str(ds.files[0]) in str(e.value) and "re-extract" in str(e.value)


def test_truncated_list_and_missing_listed_sample(synth, tmp_path):
    root = _copy(synth, tmp_path)
    lst = root / "dataset/test_pkls.pkl"
    lst.write_bytes(lst.read_bytes()[:10])
    with pytest.raises(OfficialDataError, match=f"{re.escape(str(lst))}.*truncated"):
        OfficialSyntheticDataset(root, "test")
    root2 = _copy(synth, tmp_path / "b")
    victim = root2 / synth["train"][1].relative_to(synth["root"])
    victim.unlink()
    with pytest.raises(OfficialDataError, match="1 of the 4 'train' samples listed are missing") as e:
        OfficialSyntheticDataset(root2, "train")
    assert str(victim) in str(e.value)


def test_missing_and_wrong_size_images(synth, tmp_path):
    root = _copy(synth, tmp_path)
    ds = OfficialSyntheticDataset(root, "test", input_size=S)
    img = root / "data" / ds.files[0].parent.name / "MyCamera1_0.png"
    img.unlink()
    with pytest.raises(OfficialDataError, match="missing image for camera 1") as e:
        ds[0]
    assert str(img) in str(e.value)
    cv2.imwrite(str(img), np.zeros((50, 60, 3), np.uint8))
    with pytest.raises(OfficialDataError, match=r"is 60x50 px; expected the full 1920x1080 frame or the official "
                                                r"pre-cropped") as e:
        ds[0]
    assert str(img) in str(e.value)


def test_user_files_are_never_modified(synth):
    before = _tree_state(synth["root"])
    for split in ("train", "test", "all"):
        ds = OfficialSyntheticDataset(synth["root"], split, input_size=32)
        for i in range(len(ds)):
            ds[i]
    assert _tree_state(synth["root"]) == before


# -- real data ------------------------------------------------------------------------------------
def test_real_release_splits_and_detections(tmp_path):
    frames = [0, 1, 6999, 7000, 7999, 8000, 8001]
    missing = {"openpose": [(1, 1)], "alphapose": [(0, 8000)], "marker": [(0, 8001)]}
    truth = write_official_real_fixture(tmp_path, frames=frames, missing=missing)
    before = _tree_state(tmp_path)
    assert real_split_frames("train") == range(0, 7000) == REAL_DATA_SPLITS["train"]
    assert real_split_frames(person=2) == range(8000, 15000)
    for person, want in ((1, [0, 1, 6999]), (2, [8000, 8001])):
        seq = load_official_real(tmp_path, person=person)
        assert seq.frames.tolist() == want and seq.num_views == 2
        rows = [frames.index(i) for i in want]
        np.testing.assert_array_equal(seq.keypoints["openpose"], truth["openpose"][rows])
        np.testing.assert_allclose(seq.keypoints["alphapose"], truth["alphapose"][rows])
        np.testing.assert_allclose(seq.K, truth["K"])
        assert seq.meta["detector_formats"] == {"openpose": "official", "alphapose": "official"}
        assert [p.name for p in seq.images[1].paths] == [f"{i:06d}.jpg" for i in want]
    assert load_official_real(tmp_path, person=1).info["openpose"]["missing_frames"] == 1
    assert load_official_real(tmp_path, split="test").info["alphapose"]["missing_frames"] == 1
    with pytest.raises(ValueError, match="person 1 is the 'train' split"):
        load_official_real(tmp_path, person=1, split="test")
    mp = load_marker_poses(tmp_path, [8000, 8001])
    rows = [frames.index(8000), frames.index(8001)]
    assert mp.valid.tolist() == [[True, True], [False, True]]
    R_ref = roma.rotvec_to_rotmat(torch.as_tensor(truth["rvec"][rows])).numpy()
    np.testing.assert_allclose(mp.R_cm[0], R_ref[0], atol=1e-12)
    np.testing.assert_allclose(mp.R_cm[1, 1], R_ref[1, 1], atol=1e-12)
    np.testing.assert_allclose(mp.R_cm[1, 0], np.eye(3))
    np.testing.assert_allclose(mp.t_cm[0], truth["tvec"][rows[0]])
    assert _tree_state(tmp_path) == before


def test_real_loader_reads_kit_format_and_reports_bad_files(tmp_path):
    rng = np.random.default_rng(1)
    w = OfficialLayoutWriter(tmp_path / "kit", num_views=2)
    for i in (8000, 8001):
        w.write_frame(i, [np.zeros((8, 8, 3), np.uint8)] * 2)
    op = np.concatenate([rng.uniform(0, 8, (2, 2, 25, 2)), rng.uniform(0.2, 1, (2, 2, 25, 1))], -1)
    ap = np.concatenate([rng.uniform(0, 8, (2, 2, 18, 2)), rng.uniform(0.2, 1, (2, 2, 18, 1))], -1)
    w.finish(np.stack([np.eye(3)] * 2), {"openpose": op, "alphapose": ap})
    seq = load_official_real(tmp_path / "kit", split="test")
    assert seq.meta["detector_formats"] == {"openpose": "kit", "alphapose": "kit"}
    np.testing.assert_allclose(seq.keypoints["openpose"], op.astype(np.float32), atol=1e-5)
    np.testing.assert_allclose(seq.keypoints["alphapose"], ap, atol=1e-3)
    with pytest.raises(SequenceFormatError, match="none of frames 0-6999"):
        load_official_real(tmp_path / "kit", person=1)
    write_official_real_fixture(tmp_path / "rel", n_frames=2)
    bad = tmp_path / "rel/machine_2/markerposes_corrected_all.pkl"
    bad.write_bytes(bad.read_bytes()[:20])
    with pytest.raises(SequenceFormatError, match="truncated") as e:
        load_marker_poses(tmp_path / "rel", [0, 1])
    assert str(bad) in str(e.value)


# -- checkpoints ----------------------------------------------------------------------------------
def _random_model(variant: str, seed: int = 0) -> AirPoseNet:
    """A resnet18 network with every tensor (BN statistics and mean buffers too) randomised."""
    torch.manual_seed(seed)
    m = AirPoseNet(variant, backbone="resnet18")
    with torch.no_grad():
        for name, t in m.state_dict().items():
            if t.is_floating_point() and not name.startswith("init_tau_n"):
                t.copy_(t + 0.05 * torch.randn_like(t) if "running_var" not in name else t.abs() + 0.5)
    return m.eval()


def _official_keys_besides_backbone(variant: str) -> set[str]:
    # model_hmr.py / model_muhmr.py / model_copenet_singleview.py / model_copenet.py attributes
    keys = {f"model.{l}.{p}" for l in ("fc1", "fc2", "decpose", "decshape", "deccam") for p in ("weight", "bias")}
    keys |= {"model.init_pose", "model.init_shape", "body_only_mask"}
    keys.add("model.init_position" if variant == "fullcam" else "model.init_cam")
    return keys


@pytest.mark.parametrize("variant", VARIANTS)
def test_official_checkpoint_round_trip(tmp_path, variant):
    m = _random_model(variant, seed=VARIANTS.index(variant))
    sd = to_official_state_dict(m)
    assert {k for k in sd if not k.startswith(("model.conv1", "model.bn1", "model.layer"))} == \
        _official_keys_besides_backbone(variant)
    path = write_official_checkpoint(m, tmp_path / f"{variant}.ckpt",
                                     extra={"hyper_parameters": argparse.Namespace(lr=5e-5, model="x")})
    raw = read_official_checkpoint(path)
    assert not isinstance(raw["hyper_parameters"], argparse.Namespace)  # placeholder, no foreign class built
    # agrees with the kit's earlier, simpler converter on every tensor that one maps
    from airpose_lib.model import convert_official_state_dict

    conv = official_to_kit(raw, variant, backbone="resnet18")
    for k, v in convert_official_state_dict(raw["state_dict"], variant).items():
        assert torch.equal(conv.state_dict[k], v.to(conv.state_dict[k].dtype)), k
    m2 = load_official_checkpoint(path, backbone="resnet18")
    assert m2.variant == variant and not m2.official_conversion.unused
    x = torch.randn(2, 2, 3, 64, 64)
    P = torch.tensor([0.1, -0.2, 0.4]) + 0.05 * torch.randn(2, 2, 3)
    with torch.no_grad():
        a, b = m(x, P), m2(x, P)
    for k in ("phi6d", "theta6d", "beta", "tau" if m.spec.fullcam else "cam"):
        assert torch.equal(a[k], b[k]), k
    # back to the kit's own checkpoint format
    from airpose_lib.train.evaluate import load_trained_model
    from airpose_lib.train.official import save_kit_checkpoint

    kit = save_kit_checkpoint(m2, tmp_path / f"{variant}_kit.pt", source=path)
    m3, cfg = load_trained_model(kit)
    assert cfg.variant == variant and cfg.backbone == "resnet18"
    with torch.no_grad():
        c = m3(x, P)
    assert all(torch.equal(a[k], c[k]) for k in ("phi6d", "theta6d", "beta"))


def test_wrong_variant_backbone_and_unused_keys(tmp_path):
    m = _random_model("airpose")
    path = write_official_checkpoint(m, tmp_path / "a.ckpt")
    with pytest.raises(OfficialCheckpointError, match=r"is a copenet_twoview network .*not hmr"):
        load_official_checkpoint(path, variant="baseline", backbone="resnet18")
    with pytest.raises(OfficialCheckpointError, match=r"is a copenet_twoview network .*not copenet_singleview"):
        load_official_checkpoint(path, variant="copenet_singleview", backbone=None)
    with pytest.raises(OfficialCheckpointError, match="holds a resnet18 backbone, not resnet50"):
        load_official_checkpoint(path)  # default: the official resnet50
    assert load_official_checkpoint(path, variant="copenet_twoview", backbone=None).variant == "airpose"

    ckpt = torch.load(path, weights_only=True)
    ckpt["state_dict"]["model.spare_head.weight"] = torch.zeros(2)
    ckpt["state_dict"]["teacher.weight"] = torch.zeros(2)
    torch.save(ckpt, tmp_path / "b.ckpt")
    with pytest.raises(OfficialCheckpointError, match=r"2 tensor\(s\) neither loaded.*model.spare_head.weight"):
        load_official_checkpoint(tmp_path / "b.ckpt", backbone=None)
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        model = load_official_checkpoint(tmp_path / "b.ckpt", backbone=None, strict=False)
    assert sorted(model.official_conversion.unused) == ["model.spare_head.weight", "teacher.weight"]
    assert any("neither loaded" in str(w.message) for w in rec)
    ignored = model.official_conversion.ignored
    assert set(ignored) == {"body_only_mask", "model.deccam.weight", "model.deccam.bias", "model.init_cam"}

    del ckpt["state_dict"]["model.decshape.bias"]
    torch.save(ckpt, tmp_path / "c.ckpt")
    with pytest.raises(OfficialCheckpointError, match="not filled.*regressor.decshape.bias"):
        load_official_checkpoint(tmp_path / "c.ckpt", backbone=None, strict=False)
    (tmp_path / "d.ckpt").write_bytes(path.read_bytes()[:1000])
    with pytest.raises(OfficialCheckpointError, match="truncated"):
        load_official_checkpoint(tmp_path / "d.ckpt")


def test_variant_detection_from_fc1_width():
    # ResNet-50 layout (bottleneck blocks [3, 4, 6, 3]) with the paper's fc1 widths.
    net = {f"layer{s}.{b}.conv3.weight": torch.zeros(1) for s, n in zip(range(1, 5), (3, 4, 6, 3)) for b in range(n)}
    assert detect_backbone(net) == "resnet50"
    for width, pose, variant in ((2193, 132, "baseline"), (2329, 132, "multiview"), (2196, 135, "fullcam"),
                                 (2332, 135, "airpose")):
        net.update({"fc1.weight": torch.zeros(1024, width), "decpose.weight": torch.zeros(pose, 1024)})
        assert detect_variant(net) == variant
    net["fc1.weight"] = torch.zeros(1024, 2200)
    with pytest.raises(OfficialCheckpointError, match="no AirPose variant"):
        detect_variant(net)
    net.update({"fc1.weight": torch.zeros(1024, 2332), "decpose.weight": torch.zeros(132, 1024)})
    with pytest.raises(OfficialCheckpointError, match="decpose gives 132"):
        detect_variant(net)


def test_conversion_reads_spin_mean_buffers():
    """init_pose (1, 144) float64 as in SPIN's file: root, 21 body joints, then 2 ignored joints."""
    m = _random_model("baseline")
    sd = to_official_state_dict(m)
    pose = torch.randn(1, 144, dtype=torch.float64)
    sd["model.init_pose"], sd["model.init_cam"] = pose, torch.tensor([[0.9, 0.1, -0.1]], dtype=torch.float64)
    conv = official_to_kit({"state_dict": sd})
    assert conv.state_dict["init_phi6d"].dtype == torch.float32
    torch.testing.assert_close(conv.state_dict["init_phi6d"], pose[0, :6].float())
    torch.testing.assert_close(conv.state_dict["init_theta6d"], pose[0, 6:132].float())
    torch.testing.assert_close(conv.state_dict["init_cam"], torch.tensor([0.9, 0.1, -0.1]))


def test_test_crops_follow_the_official_jitter(synth):
    """The official loader (copenet/dsets/aerialpeople.py, HEAD): each side keeps m - randint(m)
    pixels of its margin m (200 px, less at the frame edge), i.e. a whole number uniform on 1..m.
    Seeded draws of the test crops (jitter_seed) reproduce; the growth matches that distribution."""
    from scipy import stats

    ds = OfficialSyntheticDataset(synth["root"], "test", input_size=S, augment=False, jitter=True, jitter_seed=0)
    s = _sample(ds.files[0])
    tight = np.array([*s["bb0"][0], *s["bb0"][1]], np.float64)
    a, b = ds[0], OfficialSyntheticDataset(synth["root"], "test", input_size=S, jitter=True, jitter_seed=0)[0]
    assert torch.equal(a["bbox"], b["bbox"]) and torch.equal(a["images"], b["images"])  # seeded: reproducible
    c = OfficialSyntheticDataset(synth["root"], "test", input_size=S, jitter=True, jitter_seed=1)[0]
    assert not torch.equal(a["bbox"], c["bbox"])
    g0 = np.array([tight[0] - a["bbox"][0, 0], tight[1] - a["bbox"][0, 1], a["bbox"][0, 2] - tight[2],
                   a["bbox"][0, 3] - tight[3]], np.float64)
    assert np.allclose(g0, np.round(g0), atol=1e-3) and (g0 >= 1).all()  # whole pixels, at least 1

    # the distribution, on the stored image of that view (margins up to 200 px, clipped at the frame)
    img, offset = ds.load_image(ds.files[0], read_official_sample(ds.files[0], ds.views), 0)
    room = np.r_[tight[:2] - (np.array(offset) - 0.5), (np.array(offset) - 0.5 + [img.shape[1], img.shape[0]])
                 - tight[2:]]
    margins = np.minimum(np.floor(room + 1e-9), 200).astype(int)
    draws = np.array([ds.crop_box(tight, offset, img.shape, np.random.default_rng(k)) for k in range(3000)])
    growth = np.round(np.c_[tight[:2] - draws[:, :2], draws[:, 2:] - tight[2:]]).astype(int)
    for side, m in enumerate(margins):
        g = growth[:, side]
        if m == 0:
            assert (g == 0).all()
            continue
        assert g.min() >= 1 and g.max() <= m
        # the official draw with numpy's legacy RNG, as an independent reference sample
        ref = m - np.random.RandomState(side).randint(m, size=3000)
        assert stats.ks_2samp(g, ref).pvalue > 0.001
        assert abs(g.mean() - (m + 1) / 2) < 4 * np.sqrt((m * m - 1) / 12 / len(g))
    assert (margins == 200).any()  # the fixture has at least one full 200-px margin
