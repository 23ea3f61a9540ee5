"""The network input's one previous-box rule and one normalisation (``data.network_input``).

References: hand-made detections with the expected boxes written out, and the training
samples' former torch normalisation (``(x / 255 - mean) / std`` in float32) on every value.
"""
from __future__ import annotations

import numpy as np
import pytest
import torch

from airpose_lib.data.network_input import hold_boxes, keep_previous_box, normalize
from airpose_lib.data.still.dataset import normalize_images

A = np.array([10.0, 20.0, 110.0, 220.0])
B = np.array([12.0, 22.0, 112.0, 222.0])
C = np.array([30.0, 40.0, 130.0, 240.0])
NAN = np.full(4, np.nan)


def test_keep_previous_box():
    assert keep_previous_box(None, None) is None
    assert keep_previous_box(None, A) is A
    assert keep_previous_box(B, A) is B


@pytest.mark.parametrize("leading, first_two", [("first", [A, A]), ("none", [NAN, NAN])])
def test_leading_missing_frames_and_a_gap(leading, first_two):
    detected = [None, None, A, B, None, None, C, None]
    boxes, valid = hold_boxes(detected, leading=leading)
    expected = np.stack(first_two + [A, B, B, B, C, C])
    np.testing.assert_array_equal(boxes, expected)  # NaN == NaN for assert_array_equal
    assert valid.tolist() == [False, False, True, True, False, False, True, False]


@pytest.mark.parametrize("leading", ["first", "none"])
def test_nothing_leading(leading):
    boxes, valid = hold_boxes([A, None, B], leading=leading)
    np.testing.assert_array_equal(boxes, np.stack([A, A, B]))
    assert valid.tolist() == [True, False, True]


@pytest.mark.parametrize("leading", ["first", "none"])
def test_all_missing(leading):
    boxes, valid = hold_boxes([None] * 3, leading=leading)
    assert np.isnan(boxes).all() and boxes.shape == (3, 4) and not valid.any()


def test_unknown_policy():
    with pytest.raises(ValueError, match="leading"):
        hold_boxes([A], leading="last")


def test_one_normalisation_for_crops_and_training_samples():
    """Every uint8 value of every channel: the numpy rule gives the bits of the training
    samples' former torch code, and ``normalize_images`` is that rule."""
    rgb = np.repeat(np.arange(256, dtype=np.uint8)[:, None], 3, 1).reshape(16, 16, 3)
    x = torch.from_numpy(rgb).float().div_(255.0).movedim(-1, -3)
    ref = ((x - torch.tensor((0.485, 0.456, 0.406)).view(3, 1, 1))
           / torch.tensor((0.229, 0.224, 0.225)).view(3, 1, 1)).numpy()
    np.testing.assert_array_equal(normalize(rgb), ref)
    np.testing.assert_array_equal(normalize_images(rgb).numpy(), ref)
    assert normalize(rgb).dtype == np.float32 and normalize(rgb).shape == (3, 16, 16)
