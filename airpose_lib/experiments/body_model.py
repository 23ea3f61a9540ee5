"""Notebook 00's shape-space sweep: the mean body with one shape component varied at a time,
its stature and a render from one fixed camera."""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from airpose_lib.body import pose_at_origin, stature
from airpose_lib.viz.render import render_views

__all__ = ["beta_sweep"]


def beta_sweep(model, faces: np.ndarray, beta_values: Sequence[float], components: Sequence[int] = (0, 1, 2),
               renderer=None, distance: float = 4.3) -> tuple[pd.DataFrame, dict]:
    """Vary ``betas[k]`` over ``beta_values`` for each component ``k``, all else at zero.

    One camera for the whole sweep, ``distance`` metres away (4.3 m fits ~2.2 m) and looking at
    the rest-pose centre, so renders compare in size.

    Returns:
        statures (index ``beta_<k + 1>``, columns the values, metres) and the front renders
        ``(k, value) -> (H, W, 3)``.
    """
    v_rest, _ = pose_at_origin(model)
    target = (v_rest.min(0) + v_rest.max(0)) / 2
    rows, images = [], {}
    for k in components:
        for b in beta_values:
            betas = np.zeros(10)
            betas[k] = b
            v, _ = pose_at_origin(model, betas=betas)
            height = float(stature(v))
            rows.append({"component": f"beta_{k + 1}", "value": b, "stature_m": height})
            print(f"beta_{k + 1} = {b:+.1f}: stature {height:.3f} m")
            images[k, b] = render_views(v, faces, ("front",), distance=distance, target=target,
                                        renderer=renderer)[0].image
    return pd.DataFrame(rows).pivot(index="component", columns="value", values="stature_m"), images
