"""Mirror augmentation: one mirrored scene for every view (body forward, cameras, crops, P)."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from airpose_lib.body import BODY22_NAMES, BODY_25_FROM_SMPLX, BODY_25_NAMES, GENDER_NAMES, load_body_model
from airpose_lib.body.forward import axis_angle_rotations, cached_body
from airpose_lib.data.still.dataset import SAMPLE_KEYS, StillFrameDataset, swap_views
from airpose_lib.data.still.generate import GenerationConfig, generate_still_dataset
from airpose_lib.data.still.mirror import BODY22_MIRROR, BODY_25_MIRROR, mirror_sample
from airpose_lib.data.still.scene import SceneConfig
from airpose_lib.geometry import body_in_camera, full_to_crop_pixels, project_points

S = 48
CFG = GenerationConfig(num_samples=4, shard_size=4, crop_size=S, seed=11, scene=SceneConfig(num_distractors=(0, 1)))
M = np.diag([-1.0, 1.0, 1.0])


@pytest.fixture(scope="module")
def dataset(module_tmp):
    root = module_tmp("mirror") / "still"
    generate_still_dataset(CFG, root, workers=1, progress=False, label="test")
    return StillFrameDataset(root, "train", augment=False)  # one shard: all training data


@pytest.fixture(scope="module")
def models():
    return {g: load_body_model("open", g, dtype=torch.float64) for g in ("male", "female")}


def test_partner_tables_exchange_left_and_right_only():
    for perm, names in ((BODY22_MIRROR, BODY22_NAMES), (BODY_25_MIRROR, BODY_25_NAMES)):
        p = np.asarray(perm)
        assert (p[p] == np.arange(len(p))).all()
        for i, j in enumerate(p):
            a, b = names[i], names[j]
            if i == j:  # a joint on the midline
                assert not a.startswith(("left", "right")) and not (a[0] in "LR" and a[1].isupper()), a
            else:
                assert a.replace("left", "X").replace("right", "X") == b.replace("left", "X").replace("right", "X") \
                    or (a[0] + b[0] in ("LR", "RL") and a[1:] == b[1:])
    assert BODY22_MIRROR[1] == 2 and BODY22_MIRROR[20] == 21 and BODY22_MIRROR[12] == 12
    assert BODY_25_MIRROR[2] == 5 and BODY_25_MIRROR[19] == 22 and BODY_25_MIRROR[8] == 8


def test_mirroring_twice_gives_the_sample_back(dataset):
    for i in range(len(dataset)):
        item = dataset[i]
        once = mirror_sample(item, S)
        twice = mirror_sample(once, S)
        assert set(twice) == set(item) == set(SAMPLE_KEYS)
        for k in SAMPLE_KEYS:
            assert twice[k].dtype == item[k].dtype and twice[k].shape == item[k].shape, k
            if item[k].is_floating_point() and k != "images":
                assert torch.allclose(twice[k], item[k], rtol=1e-6, atol=1e-4, equal_nan=True), k
            else:
                assert torch.equal(twice[k], item[k]), k
        assert not torch.allclose(once["j2d"], item["j2d"])  # and once is not the identity


def test_mirrored_sample_is_the_mirrored_scene(dataset, models):
    """The mirrored pose, root and translation through the kit's body forward, seen by the mirrored
    cameras, give the mirrored 2D joints, keypoints and camera points; the cameras are the mirrored
    world's; labels land on the flipped crop columns; P is the mirrored box's (bx -> -bx + 1/(s cx))."""
    arrays = dataset.arrays
    for i in range(len(dataset)):
        item = dataset[i]
        m = {k: v.double() if v.is_floating_point() else v for k, v in mirror_sample(item, S).items()}
        x = {k: v.double() if v.is_floating_point() else v for k, v in item.items()}
        body = cached_body(models[GENDER_NAMES[int(item["gender"])]], mesh=False)
        j, _ = body(axis_angle_rotations(m["theta"]), m["beta"], m["phi"], m["tau"], vertices=False)  # (V, 76, 3)
        # the open body is left-right symmetric to < 0.3 mm at the joints (module docstring of data.still.mirror)
        assert torch.allclose(j[:, :22], m["j3d_cam"], atol=5e-4)
        assert torch.allclose(project_points(j[:, :22], m["K"]), m["j2d"], atol=0.1)
        kp = project_points(j[:, list(BODY_25_FROM_SMPLX)], m["K"])
        assert torch.allclose(kp, m["kp2d"], atol=0.5)
        # one mirrored world: the mirrored body pose in the world, seen by the mirrored extrinsics
        R_wb = torch.from_numpy(M @ arrays["R_wb"][i].astype(np.float64) @ M)
        t_wb = torch.from_numpy(M @ arrays["t_wb"][i].astype(np.float64))
        phi, tau = body_in_camera(R_wb, t_wb, m["R_cw"], m["t_cw"])
        assert torch.allclose(phi, m["phi"], atol=1e-5) and torch.allclose(tau, m["tau"], atol=1e-4)
        assert torch.allclose(torch.linalg.det(m["R_cw"]), torch.ones(2, dtype=torch.float64), atol=1e-5)
        assert torch.allclose(torch.linalg.det(m["phi"]), torch.ones(2, dtype=torch.float64), atol=1e-5)
        # in crop pixels a joint moves from column u to S - 1 - u: where the column flip moved its picture
        uv, uv_m = full_to_crop_pixels(x["j2d"], x["bbox"], S), full_to_crop_pixels(m["j2d"], m["bbox"], S)
        partner = list(BODY22_MIRROR)
        assert torch.allclose(uv_m[..., 0], S - 1 - uv[:, partner, 0], atol=1e-3)
        assert torch.allclose(uv_m[..., 1], uv[:, partner, 1], atol=1e-3)
        assert torch.equal(m["images"], item["images"].flip(-1).double())
        # P by hand: bx' = -bx + 1 / (s cx), by and s kept
        cx = x["K"][:, 0, 2]
        bx, by, s = x["P"].unbind(-1)
        assert torch.allclose(m["P"], torch.stack((-bx + 1.0 / (s * cx), by, s), -1), atol=1e-6)
        assert torch.allclose(m["bbox"][:, [1, 3]], x["bbox"][:, [1, 3]])
        for k in ("beta", "gender", "index", "K"):
            assert torch.equal(m[k], x[k]), k


def test_mirror_acts_only_as_training_augmentation(dataset):
    """``mirror=False`` (the default) keeps the view-swap augmentation and its RNG stream bit for
    bit; ``mirror=True`` mirrors some samples and leaves the rest and the swap as they were; without
    ``augment`` it changes nothing."""
    root = dataset.root
    plain = StillFrameDataset(root, "train", augment=False, mirror=True)
    off, on = (StillFrameDataset(root, "train", augment=True, mirror=f) for f in (False, True))
    assert not off.mirror and StillFrameDataset(root, "train").mirror is False
    mirrored = kept = 0
    for seed in range(8):
        i = seed % len(plain)
        torch.manual_seed(seed)
        ref = swap_views(plain[i])
        after_ref = torch.rand(3)
        torch.manual_seed(seed)
        a = off[i]
        assert torch.equal(torch.rand(3), after_ref)  # no extra draw
        for k in SAMPLE_KEYS:
            assert torch.equal(a[k], ref[k]), k
        torch.manual_seed(seed)
        b = on[i]
        flipped = not torch.equal(b["images"], ref["images"])
        want = mirror_sample(ref, S) if flipped else ref
        for k in SAMPLE_KEYS:
            assert torch.equal(b[k], want[k]), k
        mirrored += flipped
        kept += not flipped
    assert mirrored and kept
    item = plain[0]
    assert torch.equal(item["images"], dataset[0]["images"])
