"""Still-frame dataset: reproducible shards, resumption, checksums, ground truth, Dataset items."""
from __future__ import annotations

import shutil

import numpy as np
import pytest
import torch

from airpose_lib.body import BODY_25_FROM_SMPLX, GENDER_NAMES, load_body_model
from airpose_lib.data.still.dataset import (
    PER_VIEW_KEYS,
    SAMPLE_KEYS,
    StillFrameDataset,
    decode_image,
    denormalize_images,
)
from airpose_lib.data.still.generate import GenerationConfig, generate_still_dataset
from airpose_lib.data.still.manifest import DatasetError, ShardIntegrityError, load_manifest
from airpose_lib.data.still.render import SceneRenderer
from airpose_lib.data.still.scene import SceneConfig
from airpose_lib.data.still.shards import read_shard, shard_name
from airpose_lib.errors import ConfigError
from airpose_lib.geometry import (
    body_in_camera,
    box_in_crop,
    crop_intrinsics,
    crop_vector,
    full_to_crop_pixels,
    project_points,
)

CFG = GenerationConfig(num_samples=12, shard_size=4, crop_size=64, seed=7, val_fraction=0.0,
                       scene=SceneConfig(num_distractors=(1, 2)))  # no validation split: see test_validation_split


def _generate(root, config=CFG, **kw):
    return generate_still_dataset(config, root, workers=1, progress=False, label="test", **kw)


def _shard_bytes(root, n=CFG.num_shards):
    return [(root / shard_name(k)).read_bytes() for k in range(n)]


@pytest.fixture(scope="module")
def reference(module_tmp):
    root = module_tmp("still") / "ref"
    manifest = _generate(root)
    return root, manifest


@pytest.fixture(scope="module")
def arrays(reference):
    root, manifest = reference
    parts = [read_shard(root / r["file"]) for r in manifest["shards"]]
    out = {k: np.concatenate([p[k] for p in parts]) for k in parts[0] if k not in ("meta", "images", "image_offsets")}
    out["split"] = np.concatenate([[p["meta"]["split"]] * len(p["index"]) for p in parts])
    return out


@pytest.fixture(scope="module")
def models():
    return {g: load_body_model("open", g, dtype=torch.float64) for g in ("male", "female")}


def _body(models, gender, beta, theta):
    m = models[GENDER_NAMES[int(gender)]]
    with torch.no_grad():
        out = m(betas=torch.as_tensor(beta)[None], body_pose=torch.as_tensor(theta).reshape(1, 63))
    return out.vertices[0].numpy(), out.joints[0].numpy(), np.asarray(m.faces, dtype=np.int64)


# -- files ----------------------------------------------------------------------------------------
def test_manifest_records_everything(reference):
    root, m = reference
    assert m["status"] == "complete" and m["seed"] == 7 and m["profile"] == "test"
    assert m["generator_version"] >= 1 and m["kit_version"]
    assert [r["index"] for r in m["shards"]] == [0, 1, 2] and m["splits"] == {"train": [0, 1], "val": [], "test": [2]}
    t = m["totals"]
    assert t["samples"] == 12 and t["train_samples"] == 8 and t["test_samples"] == 4
    assert t["attempts"] - t["samples"] == t["dropped"] == sum(r["dropped"] for r in m["shards"])
    assert all(len(r["sha256"]) == 64 for r in m["shards"])
    assert set(m["body_models"]["sha256"]) == {"male", "female"}
    assert load_manifest(root) == m


def test_shard_splits():
    """train | val | test in shard order; each split keeps at least one shard; small datasets
    have no room for a validation split."""
    cfg = GenerationConfig(num_samples=35200, shard_size=200)  # the cpu profile's sizes
    splits = [cfg.shard_split(k) for k in range(cfg.num_shards)]
    assert splits == ["train"] * 140 + ["val"] * 18 + ["test"] * 18
    assert [GenerationConfig(num_samples=n, shard_size=1).num_val_shards for n in (1, 2, 3, 4, 30)] == [0, 0, 1, 1, 3]
    assert [GenerationConfig(num_samples=3, shard_size=1).shard_split(k) for k in range(3)] == ["train", "val", "test"]
    assert GenerationConfig(num_samples=30, shard_size=1, val_fraction=0.0).num_val_shards == 0
    assert GenerationConfig(num_samples=10, shard_size=1, val_fraction=0.5, test_fraction=0.4).num_val_shards == 5
    with pytest.raises(ConfigError, match="val_fraction"):
        GenerationConfig(val_fraction=0.9, test_fraction=0.1)


def test_validation_split(tmp_path):
    """The validation shards are made like the test shards (test-protocol and tight crops, their own
    seeds), recorded in the manifest, and read by StillFrameDataset("val")."""
    from airpose_lib.data.still.dataset import StillFrameDataset

    cfg = GenerationConfig(num_samples=6, shard_size=2, crop_size=32, seed=3, val_fraction=0.3)
    m = _generate(tmp_path / "d", cfg)
    assert m["splits"] == {"train": [0], "val": [1], "test": [2]}
    assert (m["totals"]["train_samples"], m["totals"]["val_samples"], m["totals"]["test_samples"]) == (2, 2, 2)
    val = StillFrameDataset(tmp_path / "d", "val")
    assert len(val) == 2 and not val.augment
    assert len(StillFrameDataset(tmp_path / "d", "val", crops="tight")) == 2  # like the test shards
    assert "images_tight" not in read_shard(tmp_path / "d" / shard_name(0))
    indices = {s: set(StillFrameDataset(tmp_path / "d", s).arrays["index"].tolist()) for s in ("train", "val", "test")}
    assert not (indices["val"] & indices["train"]) and not (indices["val"] & indices["test"])


def test_same_seed_gives_identical_bytes(reference, tmp_path):
    root, m = reference
    again = _generate(tmp_path / "again")
    assert _shard_bytes(tmp_path / "again") == _shard_bytes(root)
    assert again["shards"] == m["shards"]
    other = _generate(tmp_path / "other", CFG.replace(seed=8), stop_after_shards=1)
    assert (tmp_path / "other" / shard_name(0)).read_bytes() != (root / shard_name(0)).read_bytes()
    assert other["status"] == "incomplete"


def test_a_larger_dataset_begins_with_the_smaller_ones_training_shards(reference, tmp_path):
    """Shard k depends on (seed, k) only: a profile's dataset can grow and an earlier pretraining
    stage, pinned to the smaller size, still names the samples it was trained on (cpu.yaml)."""
    root, _ = reference
    larger = _generate(tmp_path / "larger", CFG.replace(num_samples=20))
    assert larger["splits"]["test"] == [4]  # the smaller one's test shard (2) is training data now
    for k in (0, 1):  # the same arrays; only the file's record of the dataset's fingerprint differs
        a, b = read_shard(root / shard_name(k)), read_shard(tmp_path / "larger" / shard_name(k))
        assert a.keys() == b.keys()
        assert all(np.array_equal(a[x], b[x]) for x in a if x != "meta")
        assert a["meta"]["fingerprint"] != b["meta"]["fingerprint"]


def test_interrupted_generation_resumes_to_the_same_dataset(reference, tmp_path):
    root = tmp_path / "resumed"
    part = _generate(root, stop_after_shards=1)
    assert part["status"] == "incomplete" and [r["index"] for r in part["shards"]] == [0]
    with pytest.raises(DatasetError, match=r"incomplete \(1 of 3 shards\).*airpose data generate"):
        StillFrameDataset(root)
    first = (root / shard_name(0)).stat().st_mtime_ns
    # What a crash leaves behind: a worker's temporary file, and a shard written without its
    # manifest entry (here garbage, so that keeping it would be noticed).
    (root / ".shard_00001.npz.x1.tmp").write_bytes(b"partial")
    (root / shard_name(2)).write_bytes(b"not a shard")
    done = _generate(root)
    assert done["status"] == "complete"
    assert _shard_bytes(root) == _shard_bytes(reference[0])
    assert done["shards"] == reference[1]["shards"]
    assert (root / shard_name(0)).stat().st_mtime_ns == first  # finished shard kept, not rebuilt
    assert not list(root.glob(".shard_*.tmp"))
    assert len(StillFrameDataset(root, "train")) == 8


def test_damaged_shards_are_detected_and_repaired(reference, tmp_path):
    root = tmp_path / "damaged"
    shutil.copytree(reference[0], root)
    path = root / shard_name(1)
    good = path.read_bytes()
    path.write_bytes(good[: len(good) // 2])
    with pytest.raises(ShardIntegrityError, match=r"shard_00001\.npz.*truncated.*airpose data generate --profile test"):
        StillFrameDataset(root, "train")
    StillFrameDataset(root, "test")  # the other split's shards are fine
    flipped = bytearray(good)
    flipped[len(good) // 2] ^= 0xFF
    path.write_bytes(bytes(flipped))
    with pytest.raises(ShardIntegrityError, match=r"shard_00001\.npz.*SHA-256"):
        StillFrameDataset(root, "train")
    path.unlink()
    with pytest.raises(ShardIntegrityError, match=r"shard_00001\.npz is missing"):
        StillFrameDataset(root, "train")
    path.write_bytes(bytes(flipped))
    _generate(root)  # the fix the message names: rebuilds just that shard
    assert path.read_bytes() == good
    with pytest.raises(DatasetError, match="other settings"):
        _generate(root, CFG.replace(seed=1))


# -- ground truth ---------------------------------------------------------------------------------
def test_projections_crop_vector_and_crop_intrinsics_agree(arrays):
    a = {k: torch.from_numpy(v) for k, v in arrays.items() if k != "split"}
    S = CFG.crop_size
    assert torch.allclose(project_points(a["j3d_cam"], a["K"]), a["j2d"], atol=1e-9)
    assert torch.allclose(crop_vector(a["bbox"], a["K"], S), a["P"], atol=1e-12)
    Kc = crop_intrinsics(a["K"], a["bbox"], S)
    in_crop = project_points(a["j3d_cam"], Kc)
    assert torch.allclose(in_crop, full_to_crop_pixels(a["j2d"], a["bbox"], S), atol=0.5)
    assert torch.allclose(in_crop, full_to_crop_pixels(a["j2d"], a["bbox"], S), atol=1e-6)  # in fact exact
    phi, tau = body_in_camera(a["R_wb"][:, None], a["t_wb"][:, None], a["R_cw"], a["t_cw"])
    assert torch.allclose(phi, a["phi"], atol=1e-12) and torch.allclose(tau, a["tau"], atol=1e-12)
    assert torch.allclose(a["K"][..., 0, 0], torch.tensor(1475.0, dtype=torch.float64))


def test_ground_truth_matches_an_independent_body_evaluation(arrays, models):
    """phi, tau and the model-origin convention: X_c = phi X_0 + tau with X_0 from the gendered
    model (identity root, zero translation); the body stands on the ground; boxes contain it."""
    body25 = np.asarray(BODY_25_FROM_SMPLX)
    for i in range(len(arrays["index"])):
        v0, j0, _ = _body(models, arrays["gender"][i], arrays["beta"][i], arrays["theta"][i])
        jc = np.einsum("cij,nj->cni", arrays["phi"][i], j0) + arrays["tau"][i][:, None]
        assert np.allclose(jc[:, :22], arrays["j3d_cam"][i], atol=2e-5)
        kp = jc[:, body25] @ arrays["K"][i].transpose(0, 2, 1)
        assert np.allclose(kp[..., :2] / kp[..., 2:], arrays["kp2d"][i], atol=1e-3)
        vw = v0 @ arrays["R_wb"][i].T + arrays["t_wb"][i]
        assert vw[:, 1].min() == pytest.approx(0.0, abs=1e-5)
        assert np.all(np.abs(arrays["t_wb"][i][[0, 2]]) <= 2.75)
        vc = np.einsum("cij,nj->cni", arrays["phi"][i], v0) + arrays["tau"][i][:, None]
        uv = vc @ arrays["K"][i].transpose(0, 2, 1)
        uv = uv[..., :2] / uv[..., 2:]
        assert uv.min() >= -0.5 and uv[..., 0].max() <= 1919.5 and uv[..., 1].max() <= 1079.5
        tight, box = arrays["bbox_tight"][i], arrays["bbox"][i]
        j2d = arrays["j2d"][i]
        assert np.all(tight[:, :2] <= j2d.min(1) - 20 + 1e-6) and np.all(tight[:, 2:] >= j2d.max(1) + 20 - 1e-6)
        clipped = np.clip(tight, -0.5, [1919.5, 1079.5, 1919.5, 1079.5])
        assert np.all(box[:, :2] <= clipped[:, :2] + 1e-9) and np.all(box[:, 2:] >= clipped[:, 2:] - 1e-9)
        # test crops are enlarged like training crops (official protocol); their tight boxes are
        # checked in test_tight_crops_are_the_same_samples
    assert arrays["kp_visible"].all()
    pitch = np.degrees(arrays["cam_pitch"])
    assert pitch.min() >= 0 and pitch.max() <= 45
    assert set(np.unique(arrays["gender"])) <= {1, 2}


def test_rendered_person_covers_its_projected_joints(reference, arrays, models):
    import cv2

    root, _ = reference
    S = CFG.crop_size
    ds = StillFrameDataset(root, "all", augment=False)
    hits, total = 0, 0
    with SceneRenderer(S) as r:
        for i in range(0, len(ds), 2):
            v0, _, faces = _body(models, arrays["gender"][i], arrays["beta"][i], arrays["theta"][i])
            r.set_body(v0 @ arrays["R_wb"][i].T + arrays["t_wb"][i], faces, np.full((len(v0), 3), 255, np.uint8))
            stored = ds.rgb(i)
            for c in range(CFG.scene.num_views):
                K, box = arrays["K"][i, c], arrays["bbox"][i, c]
                Kc = crop_intrinsics(torch.from_numpy(K), torch.from_numpy(box), S).numpy()
                mask = r.render(Kc, arrays["R_cw"][i, c], arrays["t_cw"][i, c], body_only=True).sum(-1) > 0
                mask = cv2.dilate(mask.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
                uv = full_to_crop_pixels(torch.from_numpy(arrays["j2d"][i, c]), torch.from_numpy(box), S).numpy()
                px = np.round(uv).astype(int)
                ok = (px >= 0).all(1) & (px < S).all(1)
                hits += int(mask[px[ok, 1], px[ok, 0]].sum())
                total += int(ok.sum())
                # The stored crop: black padding outside the box (away from JPEG ringing), picture inside.
                u0, v0_, u1, v1 = box_in_crop(box, S)
                cols, rows = np.arange(S), np.arange(S)
                far_out = (cols[None, :] < u0 - 2) | (cols[None, :] > u1 + 2) | (rows[:, None] < v0_ - 2) | (rows[:, None] > v1 + 2)
                inside = (cols[None, :] > u0 + 2) & (cols[None, :] < u1 - 2) & (rows[:, None] > v0_ + 2) & (rows[:, None] < v1 - 2)
                img = stored[c].astype(float).sum(-1)
                if far_out.any():
                    assert img[far_out].mean() < 6
                assert np.mean(img[inside] > 30) > 0.95
                # and the person is where the silhouette says (it differs from the background)
                assert mask.sum() > 20
    assert total >= 22 * CFG.scene.num_views * 5 and hits / total >= 0.99


# -- Dataset --------------------------------------------------------------------------------------
CONTRACT = {  # key: (shape without V/S, dtype)
    "images": ((2, 3, 64, 64), torch.float32), "P": ((2, 3), torch.float32),
    "K": ((2, 3, 3), torch.float32), "bbox": ((2, 4), torch.float32),
    "R_cw": ((2, 3, 3), torch.float32), "t_cw": ((2, 3), torch.float32),
    "phi": ((2, 3, 3), torch.float32), "tau": ((2, 3), torch.float32),
    "theta": ((21, 3), torch.float32), "beta": ((10,), torch.float32),
    "gender": ((), torch.int64), "j2d": ((2, 22, 2), torch.float32),
    "kp2d": ((2, 25, 2), torch.float32), "kp_visible": ((2, 25), torch.bool),
    "j3d_cam": ((2, 22, 3), torch.float32), "index": ((), torch.int64),
}


def test_dataset_items_match_the_contract(reference, arrays):
    root, _ = reference
    train, test = StillFrameDataset(root, "train"), StillFrameDataset(root, "test")
    assert (len(train), len(test)) == (8, 4) and train.augment and not test.augment
    assert set(CONTRACT) == set(SAMPLE_KEYS)
    item = test[1]
    assert set(item) == set(CONTRACT)
    for k, (shape, dtype) in CONTRACT.items():
        assert tuple(item[k].shape) == shape and item[k].dtype == dtype, k
    i = int(item["index"])
    assert i == 9 and np.allclose(item["tau"].numpy(), arrays["tau"][i], atol=1e-5)
    rgb = test.rgb(1)
    assert np.abs(denormalize_images(item["images"]).astype(int) - rgb).max() <= 1
    # ImageNet normalisation: the black padding (there is some: tight boxes are far from square) is -mean/std
    black = torch.tensor([-0.485 / 0.229, -0.456 / 0.224, -0.406 / 0.225])
    item = StillFrameDataset(root, "test", crops="tight")[1]
    u0, v0, u1, v1 = box_in_crop(item["bbox"][0].double().numpy(), 64)
    assert u0 > 3 or v0 > 3
    pad = item["images"][0, :, 32, 0] if u0 > 3 else item["images"][0, :, 0, 32]
    assert torch.allclose(pad, black, atol=0.1)
    batch = next(iter(torch.utils.data.DataLoader(test, batch_size=4)))
    assert batch["images"].shape == (4, 2, 3, 64, 64) and batch["gender"].shape == (4,)
    assert decode_image(test._images[0].get(0)).shape == (64, 64, 3)


def test_view_swap_keeps_the_views_consistent(reference):
    root, _ = reference
    plain = StillFrameDataset(root, "train", augment=False)
    aug = StillFrameDataset(root, "train", augment=True)
    swapped = kept = 0
    torch.manual_seed(0)
    for _ in range(12):
        a, p = aug[3], plain[3]
        same = torch.equal(a["tau"], p["tau"])
        for k in PER_VIEW_KEYS:
            assert torch.equal(a[k], p[k] if same else p[k].flip(0)), k
        for k in ("theta", "beta", "gender", "index"):
            assert torch.equal(a[k], p[k])
        assert torch.allclose(project_points(a["j3d_cam"].double(), a["K"].double()), a["j2d"].double(), atol=1e-2)
        swapped += not same
        kept += same
    assert swapped and kept


def test_cli_offers_data_generate():
    from airpose_lib.cli import build_parser

    args = build_parser().parse_args(["data", "generate", "--profile", "smoke", "--workers", "2", "--out", "x"])
    assert args.profile == "smoke" and args.workers == 2 and str(args.out) == "x"


@pytest.mark.slow
def test_worker_count_does_not_change_the_bytes(reference, tmp_path):
    root = tmp_path / "two_workers"
    generate_still_dataset(CFG, root, workers=2, progress=False, label="test")
    assert _shard_bytes(root) == _shard_bytes(reference[0])


def test_a_render_worker_that_dies_costs_only_its_shard(reference, tmp_path, monkeypatch, capsys):
    """A worker killed by SIGSEGV mid-run: the workers start again for the unfinished shards, and
    the dataset is the one a single process makes, byte for byte."""
    import crashing_worker

    import airpose_lib.data.still.generate as G

    monkeypatch.setenv("AIRPOSE_TEST_CRASH_FLAG", str(tmp_path / "crashed"))
    monkeypatch.setattr(G, "_worker_shard", crashing_worker.crash_once)  # the workers are given this one
    root = tmp_path / "two_workers"
    manifest = generate_still_dataset(CFG, root, workers=2, progress=False, label="test")
    assert (tmp_path / "crashed").exists(), "no worker died: the test tested nothing"
    assert "a render worker died" in capsys.readouterr().err
    assert manifest["status"] == "complete" and _shard_bytes(root) == _shard_bytes(reference[0])


# -- test crops (the official protocol: jittered like the training crops) --------------------------
@pytest.fixture(scope="module")
def crop_protocol(module_tmp):
    cfg = GenerationConfig(num_samples=40, shard_size=10, crop_size=16, seed=3)
    root = module_tmp("crops") / "ds"
    generate_still_dataset(cfg, root, workers=1, progress=False, label="test")
    return root


def test_test_crops_are_jittered_like_training_crops(crop_protocol):
    """The crop scale s of the test split lies inside the training distribution; the tight boxes of
    the paper's text lie above it (copenet/dsets/aerialpeople.py jitters both splits)."""
    s_train = StillFrameDataset(crop_protocol, "train").arrays["P"][..., 2].ravel()
    s_test = StillFrameDataset(crop_protocol, "test").arrays["P"][..., 2].ravel()
    s_tight = StillFrameDataset(crop_protocol, "test", crops="tight").arrays["P"][..., 2].ravel()
    lo, hi = np.quantile(s_train, [0.1, 0.9])
    assert lo <= np.median(s_test) <= hi
    assert np.median(s_tight) > hi
    assert np.all(s_tight >= s_test - 1e-6)  # a tight box is never larger than its enlargement


def test_split_arrays_reads_only_the_shards_of_the_first_samples(crop_protocol, monkeypatch):
    """The first 13 training samples' arrays, as the dataset types them, from 2 of the 3 training
    shards (10 samples each); a name that is not a stored array is refused."""
    import airpose_lib.data.still.dataset as ds

    full = StillFrameDataset(crop_protocol, "train").arrays
    read = []
    monkeypatch.setattr(ds, "read_shard", lambda path, names=None: read.append(path) or read_shard(path, names))
    part = ds.split_arrays(crop_protocol, "train", ("beta", "gender", "P"), 13)
    assert len(read) == 2
    for k in ("beta", "gender", "P"):
        assert part[k].dtype == full[k].dtype
        np.testing.assert_array_equal(part[k], full[k][:13])
    whole = ds.split_arrays(crop_protocol, "test", ["index"])
    np.testing.assert_array_equal(whole["index"], StillFrameDataset(crop_protocol, "test").arrays["index"])
    with pytest.raises(ConfigError, match="images"):
        ds.split_arrays(crop_protocol, "train", ("beta", "images"))


def test_tight_crops_are_the_same_samples(crop_protocol):
    test = StillFrameDataset(crop_protocol, "test")
    tight = StillFrameDataset(crop_protocol, "test", crops="tight")
    a, b = test.arrays, tight.arrays
    for k in ("theta", "beta", "phi", "tau", "j2d", "index"):
        np.testing.assert_array_equal(a[k], b[k])
    np.testing.assert_allclose(b["bbox"], np.clip(a["bbox_tight"], -0.5, [1919.5, 1079.5, 1919.5, 1079.5]),
                               atol=1e-4)
    item = tight[0]
    assert item["images"].shape == test[0]["images"].shape
    assert not torch.equal(item["images"], test[0]["images"])
    np.testing.assert_allclose(item["P"].numpy(), crop_vector(torch.from_numpy(b["bbox"][0]).double(),
                                                              torch.from_numpy(b["K"][0]).double(), 16).numpy(),
                               atol=1e-5)
    with pytest.raises(ValueError, match="tight-box crops"):
        StillFrameDataset(crop_protocol, "train", crops="tight")
