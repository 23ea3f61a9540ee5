"""Issue 31, a measurement (no choice): how much of each field recording's person box the ArUco
markers on the ground cover, from the simulated cameras and keypoints (no rendering).

    python results/cpu/selection/field_marker_exposure.py [PROFILE] > field_marker_exposure.txt

For each field recording of PROFILE (default cpu) and each view: whether any printed marker (its
white margin included) falls inside the person box, and the share of the box it covers, for two
boxes: the drones' (the joints +- the network's margin, what the crop shows: everything outside it
is black) and the joints' own box (margin 0: the markers under and beside the body). Also the
ground distance from the pelvis to the nearest marker centre. Polygons are the projected tile
corners (pinhole, the recording's K; the field preset's lens distortion is left out).
"""
import sys

import cv2
import numpy as np

from airpose_lib.data.network_input import network_box_margin, person_box
from airpose_lib.data.sequences.markers import tile_corners_world
from airpose_lib.data.sequences.presets import profile_field_sequences
from airpose_lib.data.sequences.simulate import simulate_sequence


def exposure(gt: dict, tiles: np.ndarray, margin: float | None) -> tuple[np.ndarray, np.ndarray]:
    """``inside (F, V)`` bool and ``share (F, V)`` of the person box covered by the markers
    (``margin``: None for the drones' box, else pixels around the joints)."""
    F, V = gt["R_cw"].shape[:2]
    share = np.zeros((F, V))
    for f in range(F):
        for v in range(V):
            K, R, t = gt["K"][v], gt["R_cw"][f, v], gt["t_cw"][f, v]
            kp = np.concatenate([gt["kp2d_body25"][f, v], np.ones((25, 1))], 1)
            box = person_box(kp, tuple(int(x) for x in gt["image_size"][v]),
                             margin_px=network_box_margin(K) if margin is None else margin)
            x0, y0, x1, y1 = (int(round(c)) for c in box)
            mask = np.zeros((y1 - y0 + 1, x1 - x0 + 1), np.uint8)
            for quad in tiles:
                px = (quad @ R.T + t) @ K.T
                cv2.fillConvexPoly(mask, np.round(px[:, :2] / px[:, 2:] - [x0, y0]).astype(np.int32), 1)
            share[f, v] = mask.mean()
    return share > 0, share


profile = sys.argv[1] if len(sys.argv) > 1 else "cpu"
print("recording | box | views with a marker in the box [%] (view 1, view 2) | mean share of the box "
      "covered [%] | pelvis to the nearest marker centre, median (min) [m]")
for name, cfg in profile_field_sequences(profile).items():
    gt = simulate_sequence(cfg).gt
    tiles = tile_corners_world(cfg.markers)
    pelvis = gt["pelvis_world"][:, 0][:, [0, 2]]
    dist = np.linalg.norm(tiles[:, :, [0, 2]].mean(1)[None] - pelvis[:, None], axis=-1).min(1)
    for label, margin in (("drones' box", None), ("joints' box", 0.0)):
        inside, share = exposure(gt, tiles, margin)
        print(f"{name} | {label} | {100 * inside.mean():.1f} ({100 * inside[:, 0].mean():.1f}, "
              f"{100 * inside[:, 1].mean():.1f}) | {100 * share.mean():.2f} | {np.median(dist):.2f} ({dist.min():.2f})")
