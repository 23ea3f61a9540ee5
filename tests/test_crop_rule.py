"""One crop rule: the training crops and the inference crop of the same box are the same array.

Training crops: the still-frame generator renders the crop and calls ``geometry.pad_outside_box``
(here: the same crop made by ``cv2.warpAffine`` of a full image, then padded), and the official
loader's ``data.official.synthetic.crop_image``. Inference: ``data.network_input.crop_input`` (the
drones' and fine-tuning's). Reference for the edge: hand-computed columns.
"""
from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from airpose_lib.data.network_input import IMAGENET_MEAN, IMAGENET_STD, crop_input, network_camera
from airpose_lib.data.official.synthetic import crop_image
from airpose_lib.geometry import box_in_crop, crop_affine_matrix, pad_outside_box

S = 64


def _normalise(crop: np.ndarray) -> np.ndarray:
    """``(S, S, 3)`` uint8 -> ``(1, 3, S, S)`` as ``crop_input`` normalises."""
    x = (crop.astype(np.float32) / 255.0 - IMAGENET_MEAN) / IMAGENET_STD
    return np.ascontiguousarray(x.transpose(2, 0, 1)[None])


def _training_crop(image: np.ndarray, bbox: np.ndarray) -> np.ndarray:
    """The generator's crop of a full image: warp by the crop map, then its padding call."""
    A = crop_affine_matrix(torch.as_tensor(bbox, dtype=torch.float64), S).numpy()
    crop = cv2.warpAffine(image, A[:2], (S, S), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                          borderValue=0)
    return pad_outside_box(crop, bbox)


def _boxes(rng: np.random.Generator, n: int, W: int, H: int) -> list[np.ndarray]:
    out = []
    for i in range(n):
        x0, y0 = rng.uniform(0, W - 300), rng.uniform(0, H - 300)
        box = np.array([x0, y0, x0 + rng.uniform(20, 300), y0 + rng.uniform(20, 300)])
        if i % 3 == 1:
            box = np.round(box)  # integer edges
        elif i % 3 == 2:
            box = np.floor(box) + 0.5  # edges at x.5
        out.append(box)
    return out


def test_training_and_inference_crops_of_a_box_are_identical():
    K = network_camera()  # the same camera for both: the virtual camera is the real one
    W, H = int(round(2 * K[0, 2] + 1)), int(round(2 * K[1, 2] + 1))
    rng = np.random.default_rng(7)
    image = rng.integers(1, 256, size=(H, W, 3), dtype=np.uint8)  # no black pixel of its own
    for bbox in _boxes(rng, 120, W, H):
        train = _training_crop(image, bbox)
        official = crop_image(image, (0.0, 0.0), bbox, S)
        crop, _ = crop_input(image, bbox, K, S)
        assert np.array_equal(official, train), bbox
        assert np.array_equal(crop, _normalise(train)), bbox


@pytest.mark.parametrize("bbox, kept", [
    # w 5, h 10 in a 10 px crop: s = 1, ccx = 12.5, so u0 = 10 - 12.5 + 5 = 2.5 and u1 = 7.5:
    # columns 3..7 are inside (centre >= 2.5 and <= 7.5); rounding the edge would keep 3..8.
    (np.array([10.0, 20.0, 15.0, 30.0]), range(3, 8)),
    # the same box shifted by half a pixel: u0 = 2.5, u1 = 7.5 again (the crop follows the box).
    (np.array([10.5, 20.0, 15.5, 30.0]), range(3, 8)),
])
def test_edge_at_half_pixel(bbox, kept):
    size = 10
    u0, v0, u1, v1 = box_in_crop(bbox, size)
    assert (u0, v0, u1, v1) == (2.5, 0.0, 7.5, 10.0)
    expected = np.zeros(size, bool)
    expected[list(kept)] = True
    padded = pad_outside_box(np.full((size, size, 3), 200, np.uint8), bbox)
    assert np.array_equal(padded[..., 0] > 0, np.broadcast_to(expected, (size, size)))
    K = np.array([[100.0, 0.0, 19.5], [0.0, 100.0, 24.5], [0.0, 0.0, 1.0]])
    image = np.full((50, 40, 3), 255, np.uint8)
    crop, _ = crop_input(image, bbox, K, size, K_net=K)
    lit = crop[0, 0] > 0  # (S, S): white is > 0 after normalising, black < 0
    assert np.array_equal(lit, np.broadcast_to(expected, (size, size)))
    assert np.array_equal(crop_image(image, (0.0, 0.0), bbox, size) > 0, padded > 0)
