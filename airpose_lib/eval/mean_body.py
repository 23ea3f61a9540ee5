"""Mean-body references of MPE on the kit's data: what a stature-blind estimate gets.

A single image fixes a person's position only up to the person's size: a body k times taller
at k times the distance projects to the same pixels. A mean-body reference knows the ground-truth
root orientation phi, body pose theta and 2D joints of each view, but not the shape: it poses a
*mean* body (beta = 0) and solves the translation tau that reprojects its 22 body joints onto the
ground-truth 2D joints. Its MPE against the ground-truth tau is what the stature spread of the
test subjects costs an estimate that reads everything but stature exactly. Two references:

* **neutral** (:data:`NEUTRAL_LABEL`): the neutral model's mean body for every subject;
* **true gender** (:data:`GENDERED_LABEL`): the mean body of the subject's own gender (the male or
  female model, beta = 0), what a stature-blind estimate of the right gender gets. Gender is
  visible in an image, so this is the nearer mark for a network.

Neither is a bound: within a gender, the body's proportions predict stature closely,
so a network may read stature from the pixels and beat both. A third reference measures how far
that can go:

* **stature from proportions** (:data:`PROPORTION_LABEL`): the subject's own body (true gender,
  true shape) scaled to the stature a linear model reads from its proportions alone, the 21
  scale-free bone-length ratios of its T-posed skeleton (:func:`bone_ratios`), fitted per gender
  on the training split's subjects (:func:`fit_stature_from_proportions`). Its only error is that
  model's residual: what an estimate gets that reads the pose, the gender and the proportions
  exactly and the stature no better than the proportions tell it. How well proportions tell
  stature is a property of the body model's shape space (the open body's or SMPL-X's), not
  necessarily of real people.

They are references for scale, not limits.

On a two-drone recording (:func:`mean_body_recording_estimate`) the neutral reference, frame by
frame and view by view, gives UAV2's position in UAV1 as well: two views do not fix the scale
either (the whole scene, cameras included, can grow by k with the same images), so a body of the
wrong size puts both drones k times too far and UAV2's position in UAV1 is off by ``|k - 1|``
times the drones' distance.

tau is solved in two steps per view: the algebraic (DLT-style) least-squares solution, linear in
tau, then a few Gauss-Newton steps on the pixel reprojection error.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pandas as pd
import torch

from airpose_lib.body import load_body_model
from airpose_lib.body.forward import BodyForward, axis_angle_rotations, rest_body
from airpose_lib.body.genders import GENDER_CODES, GENDER_NAMES
from airpose_lib.body.joint_sets import NUM_BODY_JOINTS, SMPLX_PARENTS
from airpose_lib.body.loader import stature
from airpose_lib.geometry import axis_angle_to_matrix

__all__ = ["NEUTRAL_LABEL", "GENDERED_LABEL", "PROPORTION_LABEL", "MEAN_BODY_LABELS", "STATURE_FIT_SUBJECTS",
           "solve_translation", "mean_body_joints", "mean_body_per_view", "bone_ratios", "rest_statures", "StatureModel",
           "fit_stature_from_proportions", "proportion_body_per_view", "mean_body_references",
           "mean_body_recording_estimate"]

#: Training subjects the stature-from-proportions model is fitted on (:func:`mean_body_references`).
STATURE_FIT_SUBJECTS = 4000
#: Row name of the neutral mean-body reference (Table I, the recordings' error tables).
NEUTRAL_LABEL = "Reference: neutral mean body (GT pose)"
#: Row name of the mean body of the subject's true gender.
GENDERED_LABEL = "Reference: true-gender mean body (GT pose)"
#: Row name of the subject's own body scaled to the stature its proportions predict.
PROPORTION_LABEL = "Reference: true body, stature from proportions (GT pose)"
#: The reference rows, in table order (the name is historical: the third is not a mean body).
MEAN_BODY_LABELS = (NEUTRAL_LABEL, GENDERED_LABEL, PROPORTION_LABEL)


def _project(P: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Pinhole projection of camera-frame points ``P (..., J, 3)`` with ``K (..., 3, 3)`` -> pixels."""
    q = np.einsum("...ij,...nj->...ni", K, P)
    return q[..., :2] / q[..., 2:3]


def _solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Batched ``A (..., 3, 3) x = b (..., 3)`` (numpy >= 2 needs b as a column)."""
    return np.linalg.solve(A, b[..., None])[..., 0]


def solve_translation(X: np.ndarray, uv: np.ndarray, K: np.ndarray, gauss_newton_steps: int = 5) -> np.ndarray:
    """The translation tau that puts rotated model-frame points ``X`` onto the pixels ``uv``.

    Args:
        X: ``(..., J, 3)`` points in camera axes about the model origin (``phi X0``).
        uv: ``(..., J, 2)`` observed pixels of ``X + tau``.
        K: ``(..., 3, 3)`` intrinsics (third row ``[0, 0, 1]``).
        gauss_newton_steps: refinement steps on the pixel error after the linear solution.
    Returns:
        ``(..., 3)`` tau, float64.
    """
    X, uv, K = (np.asarray(a, dtype=np.float64) for a in (X, uv, K))
    # Algebraic error: with normalised coordinates (x, y, 1) = K^-1 (u, v, 1), a point on the ray
    # satisfies (X + tx) - x (Z + tz) = 0 and (Y + ty) - y (Z + tz) = 0: two linear equations in tau.
    ones = np.ones(uv.shape[:-1] + (1,))
    xy = np.einsum("...ij,...nj->...ni", np.linalg.inv(K), np.concatenate([uv, ones], axis=-1))
    x, y = xy[..., 0] / xy[..., 2], xy[..., 1] / xy[..., 2]  # (..., J)
    zeros, one = np.zeros_like(x), np.ones_like(x)
    A = np.concatenate([np.stack([one, zeros, -x], axis=-1), np.stack([zeros, one, -y], axis=-1)], axis=-2)
    b = np.concatenate([x * X[..., 2] - X[..., 0], y * X[..., 2] - X[..., 1]], axis=-1)
    tau = _solve(np.einsum("...ji,...jk->...ik", A, A), np.einsum("...ji,...j->...i", A, b))
    for _ in range(gauss_newton_steps):
        P = X + tau[..., None, :]
        q = np.einsum("...ij,...nj->...ni", K, P)
        z = q[..., 2]
        r = (q[..., :2] / z[..., None] - uv).reshape(*uv.shape[:-2], -1)  # (..., 2J)
        # d(q_a / z)/dP = (K_a - (q_a / z) e_z) / z for a = u, v (rows of K; K's third row is e_z)
        proj = q[..., :2] / z[..., None]
        J_u = (K[..., None, 0, :] - proj[..., 0:1] * K[..., None, 2, :]) / z[..., None]
        J_v = (K[..., None, 1, :] - proj[..., 1:2] * K[..., None, 2, :]) / z[..., None]
        Jac = np.stack([J_u, J_v], axis=-2).reshape(*uv.shape[:-2], -1, 3)  # (..., 2J, 3), d/dtau = d/dP
        JtJ = np.einsum("...ji,...jk->...ik", Jac, Jac)
        tau = tau - _solve(JtJ, np.einsum("...ji,...j->...i", Jac, r))
    return tau


def mean_body_joints(theta: np.ndarray, body_model=None, body_source: str = "open",
                     gender: str = "neutral") -> np.ndarray:
    """The 22 body joints of a mean body (beta = 0) in its model frame.

    Args:
        theta: ``(N, 21, 3)`` axis-angle body pose.
        body_model: an ``smplx.SMPLX`` (default: ``load_body_model(body_source, gender)``).
        gender: the model whose mean body is posed when ``body_model`` is None.
    Returns:
        ``(N, 22, 3)`` joints with identity root orientation, zero translation (the paper's
        ``X0``: ``X = phi X0 + tau``), float64.
    """
    if body_model is None:
        body_model = load_body_model(body_source, gender, dtype=torch.float64)
    body = BodyForward(body_model, vertices=None).double()  # float64 whatever the model's dtype
    theta = torch.as_tensor(np.asarray(theta), dtype=torch.float64)
    with torch.no_grad():
        joints, _ = body(axis_angle_rotations(theta), torch.zeros(1, body.num_betas, dtype=torch.float64))
    return joints.numpy()


def _gendered_joints(theta: np.ndarray, gender: np.ndarray, body_models: Mapping | None,
                     body_source: str) -> np.ndarray:
    """:func:`mean_body_joints` of each sample's own gender: ``theta (N, 21, 3)``, ``gender (N,)``
    codes (``body.genders``) -> ``(N, 22, 3)``."""
    X0 = np.empty((len(theta), 22, 3))
    models: dict = {}
    for code in np.unique(gender):
        rows = gender == code
        X0[rows] = mean_body_joints(theta[rows], _gender_model(code, body_models, body_source, models))
    return X0


def mean_body_per_view(arrays: Mapping[str, np.ndarray], body_model=None, body_source: str = "open",
                       gauss_newton_steps: int = 5, max_samples: int | None = None, gendered: bool = False,
                       body_models: Mapping | None = None) -> pd.DataFrame:
    """Per-view MPE of a mean-body reference on a still-frame split.

    Args:
        arrays: ``StillFrameDataset.arrays``: ``theta (N, 21, 3)``, ``phi (N, V, 3, 3)``,
            ``tau (N, V, 3)``, ``j2d (N, V, 22, 2)`` (full-frame pixels), ``K (N, V, 3, 3)``;
            ``index (N,)`` sample ids if present; with ``gendered``, ``gender (N,)`` codes.
        body_model, body_source: the neutral body posed with beta = 0 (:func:`mean_body_joints`).
        max_samples: only the first this many samples (the networks' ``eval_max_samples``).
        gendered: pose the mean body of each subject's true gender (:data:`GENDERED_LABEL`)
            instead of the neutral one (:data:`NEUTRAL_LABEL`).
        body_models: gender name -> ``smplx.SMPLX`` for ``gendered`` (a missing one is loaded
            from ``body_source``).
    Returns:
        columns ``method, sample, view, mpe_m, err_x_m, err_y_m, err_z_m, reproj_px`` (the RMS pixel
        residual of the fit), one row per (sample, view), like :func:`airpose_lib.eval.per_view_table`.
    """
    arrays = {k: np.asarray(v)[:max_samples] for k, v in arrays.items()}
    if gendered:
        X0 = _gendered_joints(arrays["theta"], np.asarray(arrays["gender"]), body_models, body_source)
    else:
        X0 = mean_body_joints(arrays["theta"], body_model, body_source)  # (N, 22, 3)
    return _placed_rows(arrays, X0, GENDERED_LABEL if gendered else NEUTRAL_LABEL, gauss_newton_steps)


def _placed_rows(arrays: Mapping[str, np.ndarray], X0: np.ndarray, label: str,
                 gauss_newton_steps: int) -> pd.DataFrame:
    """Per-view rows of a reference that poses the model-frame joints ``X0 (N, 22, 3)`` with the
    ground-truth root rotation and solves tau from the ground-truth 2D joints."""
    phi = np.asarray(arrays["phi"], dtype=np.float64)
    N, V = phi.shape[:2]
    X = np.einsum("nvij,nkj->nvki", phi, X0)  # phi X0, (N, V, 22, 3)
    uv = np.asarray(arrays["j2d"], dtype=np.float64)
    K = np.asarray(arrays["K"], dtype=np.float64)
    tau = solve_translation(X, uv, K, gauss_newton_steps)
    err = tau - np.asarray(arrays["tau"], dtype=np.float64)
    reproj = np.sqrt(((_project(X + tau[..., None, :], K) - uv) ** 2).sum(-1).mean(-1))
    ids = np.asarray(arrays["index"]) if "index" in arrays else np.arange(N)
    return pd.DataFrame({
        "method": label, "sample": np.repeat(ids, V),
        "view": np.tile(np.arange(V), N),
        "mpe_m": np.linalg.norm(err, axis=-1).reshape(-1),
        "err_x_m": err[..., 0].reshape(-1), "err_y_m": err[..., 1].reshape(-1), "err_z_m": err[..., 2].reshape(-1),
        "reproj_px": reproj.reshape(-1),
    })


def bone_ratios(joints: np.ndarray) -> np.ndarray:
    """Scale-free proportions of a skeleton: its 21 bone lengths over their sum.

    Args:
        joints: ``(..., 22, 3)`` the body joints (SMPL-X order; bone k joins joint k + 1 to its
            parent in ``body.joint_sets.SMPLX_PARENTS``).
    Returns:
        ``(..., 21)``, summing to 1; unchanged by a uniform scaling of the body.
    """
    joints = np.asarray(joints, dtype=np.float64)
    parents = list(SMPLX_PARENTS[1:NUM_BODY_JOINTS])
    lengths = np.linalg.norm(joints[..., 1:NUM_BODY_JOINTS, :] - joints[..., parents, :], axis=-1)
    return lengths / lengths.sum(-1, keepdims=True)


def _gender_model(code: int, body_models: Mapping | None, body_source: str, cache: dict):
    """The body model of gender ``code``: ``body_models``' own, else loaded once into ``cache``."""
    name = GENDER_NAMES[int(code)]
    if name not in cache:
        model = (body_models or {}).get(name)
        cache[name] = model if model is not None else load_body_model(body_source, name, dtype=torch.float64)
    return cache[name]


def rest_statures(beta: np.ndarray, gender: np.ndarray, body_models: Mapping | None = None,
                  body_source: str = "open", chunk: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """Stature and proportions of each subject's T-posed body (its gender's model, its beta).

    Args:
        beta: ``(N, S)`` shape coefficients. gender: ``(N,)`` codes (``body.genders``).
        body_models: gender name -> ``smplx.SMPLX`` (a missing one is loaded from ``body_source``).
        chunk: bodies per forward pass (each holds a whole mesh).
    Returns:
        ``stature (N,)`` in metres (``body.loader.stature``) and ``ratios (N, 21)``
        (:func:`bone_ratios`), float64.
    """
    beta, gender = np.asarray(beta, dtype=np.float64), np.asarray(gender)
    height, ratios = np.empty(len(beta)), np.empty((len(beta), NUM_BODY_JOINTS - 1))
    models: dict = {}
    for code in np.unique(gender):
        rows = np.flatnonzero(gender == code)
        model = _gender_model(code, body_models, body_source, models)
        for start in range(0, len(rows), chunk):
            r = rows[start:start + chunk]
            vertices, joints = rest_body(model, beta[r], np.zeros((len(r), 21, 3)))
            height[r], ratios[r] = stature(vertices), bone_ratios(joints[:, :NUM_BODY_JOINTS])
    return height, ratios


@dataclass(frozen=True)
class StatureModel:
    """Per gender, stature = ``coef[0] + coef[1:] . ratios`` (:func:`fit_stature_from_proportions`).

    Attributes:
        coef: gender code -> ``(22,)`` intercept and weights of the 21 bone ratios.
        r2: gender code -> R^2 of the fit on its training subjects.
        residual_sd: gender code -> standard deviation of the fit's residual (metres).
    """

    coef: dict
    r2: dict
    residual_sd: dict

    def predict(self, ratios: np.ndarray, gender: np.ndarray) -> np.ndarray:
        """``ratios (N, 21)``, ``gender (N,)`` codes -> statures ``(N,)``; a gender the fit never
        saw raises KeyError (a bug in the caller's split, not a user's input)."""
        ratios, gender = np.asarray(ratios, dtype=np.float64), np.asarray(gender)
        out = np.empty(len(ratios))
        for code in np.unique(gender):
            rows = gender == code
            c = self.coef[int(code)]
            out[rows] = c[0] + ratios[rows] @ c[1:]
        return out


def fit_stature_from_proportions(ratios: np.ndarray, height: np.ndarray, gender: np.ndarray) -> StatureModel:
    """Least squares of stature on the bone ratios, one linear model per gender.

    The ratios sum to 1, so with the intercept the system is rank deficient by one;
    ``np.linalg.lstsq`` returns its minimum-norm solution, whose predictions are the same.

    Args:
        ratios: ``(N, 21)`` (:func:`bone_ratios`). height: ``(N,)`` metres. gender: ``(N,)`` codes.
    """
    ratios, height, gender = np.asarray(ratios, np.float64), np.asarray(height, np.float64), np.asarray(gender)
    coef, r2, sd = {}, {}, {}
    for code in np.unique(gender):
        rows = gender == code
        A = np.concatenate([np.ones((int(rows.sum()), 1)), ratios[rows]], axis=1)
        c = np.linalg.lstsq(A, height[rows], rcond=None)[0]
        resid = height[rows] - A @ c
        coef[int(code)] = c
        spread = height[rows].var()
        r2[int(code)] = float(1.0 - resid.var() / spread) if spread > 0 else float("nan")  # one subject
        sd[int(code)] = float(resid.std())
    return StatureModel(coef, r2, sd)


def proportion_body_per_view(arrays: Mapping[str, np.ndarray], stature_model: StatureModel,
                             body_models: Mapping | None = None, body_source: str = "open",
                             gauss_newton_steps: int = 5, max_samples: int | None = None) -> pd.DataFrame:
    """Per-view MPE of the stature-from-proportions reference (:data:`PROPORTION_LABEL`).

    Each subject's own body (gender, beta, theta of the ground truth), scaled by
    ``predicted stature / true stature``, posed with the ground-truth root rotation and placed on
    the ground-truth 2D joints (:func:`solve_translation`). A body k times too tall lands k times
    too far: the error is the stature model's residual times the distance.

    Args:
        arrays: as :func:`mean_body_per_view`, with ``beta (N, S)`` and ``gender (N,)``.
        stature_model: :func:`fit_stature_from_proportions` on *other* subjects (the training split).
    Returns:
        :func:`mean_body_per_view`'s columns.
    """
    arrays = {k: np.asarray(v)[:max_samples] for k, v in arrays.items()}
    beta, gender = np.asarray(arrays["beta"], np.float64), np.asarray(arrays["gender"])
    height, ratios = rest_statures(beta, gender, body_models, body_source)
    scale = stature_model.predict(ratios, gender) / height  # (N,)
    theta = torch.as_tensor(np.asarray(arrays["theta"], dtype=np.float64))
    X0 = np.empty((len(beta), NUM_BODY_JOINTS, 3))
    models: dict = {}
    for code in np.unique(gender):
        rows = gender == code
        body = BodyForward(_gender_model(code, body_models, body_source, models), vertices=None).double()
        with torch.no_grad():
            b = torch.as_tensor(beta[rows][:, :body.num_betas])
            X0[rows] = body(axis_angle_rotations(theta[torch.as_tensor(rows)]), b)[0].numpy()
    return _placed_rows(arrays, scale[:, None, None] * X0, PROPORTION_LABEL, gauss_newton_steps)


def mean_body_references(arrays: Mapping[str, np.ndarray], body_source: str = "open", gauss_newton_steps: int = 5,
                         max_samples: int | None = None, body_models: Mapping | None = None,
                         train_arrays: Mapping[str, np.ndarray] | None = None,
                         max_train: int = STATURE_FIT_SUBJECTS) -> pd.DataFrame:
    """The references of a still-frame split in table order (:data:`MEAN_BODY_LABELS`).

    Args:
        body_models: gender name -> ``smplx.SMPLX`` (a missing one is loaded from ``body_source``).
        train_arrays: the training split's ``beta`` and ``gender``: with them the stature-from-
            proportions rows are added, the stature model fitted on its first ``max_train``
            subjects (None: the two mean-body references only).
    """
    # each model once for all three references (a load builds a whole mesh's blend shapes)
    models = dict(body_models or {})
    genders = [GENDER_CODES["neutral"], *np.asarray(arrays["gender"])]
    if train_arrays is not None:
        genders += list(np.asarray(train_arrays["gender"])[:max_train])
    for code in np.unique(genders):
        _gender_model(code, models, body_source, models)
    parts = [mean_body_per_view(arrays, models.get("neutral"), body_source, gauss_newton_steps, max_samples),
             mean_body_per_view(arrays, None, body_source, gauss_newton_steps, max_samples, gendered=True,
                                body_models=models)]
    if train_arrays is not None:
        height, ratios = rest_statures(np.asarray(train_arrays["beta"])[:max_train],
                                       np.asarray(train_arrays["gender"])[:max_train], models, body_source)
        fit = fit_stature_from_proportions(ratios, height, np.asarray(train_arrays["gender"])[:max_train])
        parts.append(proportion_body_per_view(arrays, fit, models, body_source, gauss_newton_steps, max_samples))
    return pd.concat(parts, ignore_index=True)


def mean_body_recording_estimate(ground_truth: Mapping[str, np.ndarray], body_model=None, body_source: str = "open",
                                 gauss_newton_steps: int = 5) -> dict[str, np.ndarray]:
    """The neutral mean-body reference over a recording, as an estimate of :mod:`airpose_lib.eval.recordings`.

    Args:
        ground_truth: a recording's ``ground_truth.npz``: ``theta_view (F, V, 21, 3)`` axis-angle,
            ``phi (F, V, 3, 3)``, ``j2d (F, V, 22, 2)`` pixels of the rendered images, ``K (V, 3, 3)``
            (or ``(F, V, 3, 3)``) their intrinsics.
        body_model, body_source: the body posed with beta = 0 (:func:`mean_body_joints`).
    Returns:
        ``phi`` (the ground truth's), ``tau (F, V, 3)`` (solved), ``theta (F, V, 21, 3, 3)``,
        ``beta (F, V, 10)`` zeros and ``valid (F, V)`` all true; float64.
    """
    theta = np.array(ground_truth["theta_view"], dtype=np.float64)  # a copy: the input may be read-only
    F, V = theta.shape[:2]
    X0 = mean_body_joints(theta.reshape(F * V, 21, 3), body_model, body_source).reshape(F, V, 22, 3)
    phi = np.asarray(ground_truth["phi"], dtype=np.float64)
    K = np.broadcast_to(np.asarray(ground_truth["K"], dtype=np.float64), (F, V, 3, 3))
    tau = solve_translation(np.einsum("fvij,fvkj->fvki", phi, X0), ground_truth["j2d"], K, gauss_newton_steps)
    return {"phi": phi, "tau": tau, "theta": axis_angle_to_matrix(torch.as_tensor(theta)).numpy(),
            "beta": np.zeros((F, V, 10)), "valid": np.ones((F, V), dtype=bool)}
