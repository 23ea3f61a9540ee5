"""The same frames computed offline, in one process: the reference for the online runs.

:func:`offline_inputs` rebuilds each view's crop and P for given camera frames exactly as a
drone does (``data.network_input``: detections -> ``person_box`` -> ``crop_input``), or from the
boxes a drone recorded. :func:`offline_staged` runs one :class:`~.backends.StageModel` per view
in-process with a perfect exchange (every message of every other view, in view order, in the
wire dtype), optionally replaying the online run's fallbacks (which drones' messages each stage
actually used); with the same backend this is bit-for-bit what the drones compute.
:func:`offline_batched` is the batched ``AirPoseNet.forward`` of the same crops (torch). With
:func:`~.results.merge_views` this gives "online vs offline" on the frames the drones completed.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from airpose_lib.data.network_input import box_margin, crop_input, hold_boxes, person_box

from .backends import BackendSpec, StageModel, build_torch_model, fresh_copy, to_numpy
from .networks import make_stage_model
from .results import PARAM_KEYS, mask_to_ids
from .source import open_source

__all__ = ["offline_inputs", "offline_staged", "offline_batched", "max_abs_difference"]


def offline_inputs(source, frame_index: np.ndarray, input_size: int, boxes: np.ndarray | None = None,
                   min_confidence: float = 0.2, margin_px: float | None = None,
                   K_net: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Crops and crop vectors of the given frames.

    Args:
        source: an :func:`~.source.open_source` object or its spec string.
        frame_index: ``(F, V)`` camera frame of view v for row f.
        input_size: S.
        boxes: optional ``(F, V, 4)`` boxes to use (e.g. the drones' records); default: from the
            detections of each frame (``data.network_input.hold_boxes`` over the rows: a row
            without one keeps the previous row's box, and a row before the view's first
            detection is an error, since no drone made that crop).
        min_confidence, margin_px: the person box rule (``data.network_input.person_box``); a
            margin of None is ``network_box_margin`` of each view's K (as a drone's).
        K_net: the network's camera (``data.network_input.crop_input``; default ``network_camera()``).

    Returns:
        ``crops (F, V, 3, S, S)`` float32, ``P (F, V, 3)`` float32, ``boxes (F, V, 4)``.
    """
    src = open_source(source) if isinstance(source, str) else source
    F, V = frame_index.shape
    crops = np.zeros((F, V, 3, input_size, input_size), np.float32)
    P = np.zeros((F, V, 3), np.float32)
    out_boxes = np.zeros((F, V, 4), np.float64)
    for v in range(V):
        view = src.view(v)
        if boxes is None:
            view_boxes = _detected_boxes(view, v, frame_index[:, v], min_confidence,
                                         box_margin(margin_px, view.K, K_net))
        else:
            view_boxes = boxes[:, v]
        for f in range(F):
            i = int(frame_index[f, v])
            c, p = crop_input(view.image(i), view_boxes[f], view.K, input_size, K_net)
            crops[f, v], P[f, v], out_boxes[f, v] = c[0], p[0], view_boxes[f]
    return crops, P, out_boxes


def _detected_boxes(view, v: int, frames: np.ndarray, min_confidence: float, margin: float) -> np.ndarray:
    """``(F, 4)`` boxes of view v's camera ``frames (F,)`` by the previous-box rule; a frame
    before the first detection raises ``ValueError``. The image size (which clips the box) is the
    first frame's: a camera's frames share one size."""
    H, W = view.image(int(frames[0])).shape[:2]
    detected = [person_box(view.keypoints(int(i)), (W, H), min_confidence, margin) for i in frames]
    boxes, _ = hold_boxes(detected, leading="none")
    if np.isnan(boxes[0, 0]):  # leading frames without a box
        raise ValueError(f"view {v} frame {int(frames[0])}: no detection and no earlier box; pass the boxes")
    return boxes


def offline_staged(model: StageModel | BackendSpec, crops: np.ndarray, P: np.ndarray,
                   used: Sequence | None = None) -> dict[str, np.ndarray]:
    """Every view's staged computation in-process with the exchange the drones perform.

    Args:
        model: the prototype stage model (or the :class:`BackendSpec` the drones used).
        crops: ``(F, V, 3, S, S)``; P: ``(F, V, 3)``.
        used: optional ``(F, V, num_stages - 1)`` bit masks: which drones' (bit ``id - 1``; drone
            id = view + 1) stage ``j + 1`` messages view v used for stage ``j + 2`` (the
            ``used_s2, used_s3`` of :func:`~.results.merge_views`); default: all other views (no
            message lost).

    Returns:
        ``(F, V, ...)`` float32 arrays phi6d, theta6d, beta, tau or cam.
    """
    proto = make_stage_model(model) if isinstance(model, BackendSpec) else model
    F, V = crops.shape[:2]
    outs: dict[str, list] = {}
    for f in range(F):
        nodes = [fresh_copy(proto) for _ in range(V)]
        msgs = [nodes[v].stage1(crops[f, v][None], P[f, v][None]) for v in range(V)]
        for k in range(2, proto.num_stages + 1):
            new = []
            for v in range(V):
                if used is None:
                    senders = [u for u in range(V) if u != v]
                else:
                    senders = [d - 1 for d in mask_to_ids(used[f][v][k - 2])]
                new.append(nodes[v].stage(k, [msgs[u] for u in sorted(senders)]))
            msgs = new
        for v in range(V):
            res = nodes[v].result()
            for key in PARAM_KEYS:
                if key in res:
                    rows = outs.setdefault(key, [[None] * V for _ in range(F)])
                    rows[f][v] = to_numpy(res[key]).astype(np.float32)[0]
    return {k: np.stack([np.stack(row) for row in rows]) for k, rows in outs.items()}


def offline_batched(model, crops: np.ndarray, P: np.ndarray) -> dict[str, np.ndarray]:
    """``AirPoseNet.forward`` on all frames and views at once (torch backend only).

    Args:
        model: an :class:`~airpose_lib.model.AirPoseNet` (or the drones' :class:`BackendSpec`).
        crops: ``(F, V, 3, S, S)``; P: ``(F, V, 3)``.
    """
    import torch

    if isinstance(model, BackendSpec):
        model = build_torch_model(model)
    model.eval()
    with torch.no_grad():
        out = model(torch.from_numpy(crops), torch.from_numpy(P))
    return {k: out[k].numpy() for k in PARAM_KEYS if k in out}


def max_abs_difference(a: dict, b: dict, keys: Sequence[str] = PARAM_KEYS) -> dict[str, float]:
    """Largest absolute difference per parameter present in both dicts."""
    return {k: float(np.max(np.abs(np.asarray(a[k], np.float64) - np.asarray(b[k], np.float64))))
            for k in keys if k in a and k in b}
