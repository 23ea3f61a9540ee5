"""The mean-body references of Table I: exact on their mean body, off by the stature ratio otherwise."""
import numpy as np
import pytest

from airpose_lib.eval.mean_body import (
    GENDERED_LABEL,
    NEUTRAL_LABEL,
    mean_body_per_view,
    mean_body_references,
    solve_translation,
)

K = np.array([[1400.0, 0.0, 960.0], [0.0, 1400.0, 540.0], [0.0, 0.0, 1.0]])


def _rotation(rng) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q * np.linalg.det(q)


def _scene(rng, n_views=4):
    X0 = rng.uniform([-0.3, -0.9, -0.15], [0.3, 0.8, 0.15], size=(22, 3))  # a person-sized cloud
    phi = np.stack([_rotation(rng) for _ in range(n_views)])
    tau = np.stack([rng.uniform([-2, -1, 8], [2, 1, 14]) for _ in range(n_views)])
    return X0, phi, tau


def _project(P, K):
    q = P @ K.T
    return q[..., :2] / q[..., 2:]


def test_translation_is_recovered_exactly_from_exact_pixels():
    X0, phi, tau = _scene(np.random.default_rng(0))
    X = np.einsum("vij,kj->vki", phi, X0)
    uv = _project(X + tau[:, None], K)
    np.testing.assert_allclose(solve_translation(X, uv, np.broadcast_to(K, (4, 3, 3))), tau, atol=1e-6)


def test_gauss_newton_lowers_the_pixel_error_of_the_linear_solution():
    X0, phi, tau = _scene(np.random.default_rng(1))
    X = np.einsum("vij,kj->vki", phi, X0)
    uv = _project(X + tau[:, None], K) + np.random.default_rng(2).normal(0, 3.0, size=(4, 22, 2))
    Ks = np.broadcast_to(K, (4, 3, 3))
    rms = lambda t: np.sqrt(((_project(X + t[:, None], K) - uv) ** 2).sum(-1).mean(-1))  # noqa: E731
    linear, refined = solve_translation(X, uv, Ks, 0), solve_translation(X, uv, Ks, 5)
    assert (rms(refined) <= rms(linear) + 1e-9).all() and (rms(refined) < rms(linear)).any()
    # at the optimum one more step changes nothing
    np.testing.assert_allclose(solve_translation(X, uv, Ks, 6), refined, atol=1e-9)


def test_a_taller_person_puts_the_reference_short_by_the_stature_ratio():
    # A body s times taller at tau projects like the mean body at tau / s: the reference lands there.
    X0, phi, tau = _scene(np.random.default_rng(3))
    s = 1.065  # one standard deviation of the kit's stature spread (6.5 %)
    X = np.einsum("vij,kj->vki", phi, X0)
    uv = _project(s * X + tau[:, None], K)
    est = solve_translation(X, uv, np.broadcast_to(K, (4, 3, 3)))
    np.testing.assert_allclose(est, tau / s, atol=1e-6)
    depth_error = est[:, 2] - tau[:, 2]
    np.testing.assert_allclose(depth_error, tau[:, 2] * (1 / s - 1), atol=1e-6)  # ~ -0.61 m at 10 m


def _arrays(model, s: float, n=3, V=2, gender=None):
    """A still-frame split whose ground truth is ``model``'s body with beta = 0, scaled by s, posed
    by smplx's own forward pass (independent of the reference's joints-only path). ``model`` may be a
    list, one per sample, with ``gender`` their codes."""
    import torch

    rng = np.random.default_rng(4)
    theta = rng.normal(0, 0.25, size=(n, 21, 3))
    z = lambda k: torch.zeros(1, k, dtype=torch.float64)  # noqa: E731
    J0 = []
    for i, m in enumerate(model if isinstance(model, list) else [model] * n):
        with torch.no_grad():  # as the data generator poses its subjects
            out = m(betas=z(10), body_pose=torch.as_tensor(theta[i]).reshape(1, 63), global_orient=z(3),
                    transl=z(3), jaw_pose=z(3), leye_pose=z(3), reye_pose=z(3), left_hand_pose=z(45),
                    right_hand_pose=z(45), expression=z(m.num_expression_coeffs))
        J0.append(s * out.joints[0, :22].numpy())
    J0 = np.stack(J0)
    phi = np.stack([[_rotation(rng) for _ in range(V)] for _ in range(n)])
    tau = rng.uniform([-2, -1, 8], [2, 1, 14], size=(n, V, 3))
    jc = np.einsum("nvij,nkj->nvki", phi, J0) + tau[:, :, None]
    return {"theta": theta, "phi": phi, "tau": tau, "j2d": _project(jc, K), "K": np.broadcast_to(K, (n, V, 3, 3)),
            "index": np.array([10, 11, 12]), "beta": np.zeros((n, 10)),
            "gender": np.zeros(n, np.int64) if gender is None else np.asarray(gender, np.int64)}


def test_reference_is_exact_when_the_subject_is_the_mean_body(open_model):
    t = mean_body_per_view(_arrays(open_model, 1.0), body_model=open_model)
    assert list(t["sample"]) == [10, 10, 11, 11, 12, 12] and list(t["view"]) == [0, 1] * 3
    assert (t["method"] == NEUTRAL_LABEL).all()
    assert t["mpe_m"].max() < 1e-6 and t["reproj_px"].max() < 1e-6


def test_reference_error_on_a_taller_subject_is_the_stature_ratio(open_model):
    s = 1.1
    arrays = _arrays(open_model, s)
    t = mean_body_per_view(arrays, body_model=open_model)
    expected = np.linalg.norm(arrays["tau"], axis=-1).reshape(-1) * (1 - 1 / s)
    np.testing.assert_allclose(t["mpe_m"], expected, atol=1e-6)
    np.testing.assert_allclose(t["err_z_m"], arrays["tau"][..., 2].reshape(-1) * (1 / s - 1), atol=1e-6)
    assert t["mpe_m"].min() > 0.5  # 10 % taller at 8-14 m: the error is metres-scale, not noise


def test_recording_reference_puts_uav2_off_by_the_stature_ratio_of_the_drones_distance(open_model):
    """Two views do not fix the scale: both drones come out 1/s as far, so UAV2 in UAV1 is off by
    (1 - 1/s) of their distance."""
    from airpose_lib.eval.mean_body import mean_body_recording_estimate
    from airpose_lib.eval.recordings import relative_camera_positions

    s = 1.1
    a = _arrays(open_model, s)
    gt = {"theta_view": np.broadcast_to(a["theta"][:, None], (3, 2, 21, 3)), "phi": a["phi"], "tau": a["tau"],
          "j2d": a["j2d"], "K": np.broadcast_to(K, (2, 3, 3))}
    est = mean_body_recording_estimate(gt, body_model=open_model)
    assert est["theta"].shape == (3, 2, 21, 3, 3) and not est["beta"].any() and est["valid"].all()
    np.testing.assert_allclose(est["tau"], a["tau"] / s, atol=1e-6)
    R_gt, t_gt = relative_camera_positions(gt)
    R_est, t_est = relative_camera_positions(est)
    np.testing.assert_allclose(R_est, R_gt, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(t_est - t_gt, axis=-1), (1 - 1 / s) * np.linalg.norm(t_gt, axis=-1),
                               atol=1e-6)


@pytest.fixture(scope="module")
def gendered_models(open_model_files):
    import torch

    from airpose_lib.body import load_body_model

    return {g: load_body_model("open", g, dtype=torch.float64) for g in ("male", "female")}


def test_gendered_reference_is_exact_when_the_subject_is_their_genders_mean_body(open_model, gendered_models):
    """Hand-made case: a man, a woman and a man, each exactly the mean body (beta = 0) of their
    gender's model. The true-gender reference poses that very body, so it lands on tau; the neutral
    one poses another body, whose stature differs, and misses by a stature ratio times ~10 m."""
    male, female = gendered_models["male"], gendered_models["female"]
    arrays = _arrays([male, female, male], 1.0, gender=[1, 2, 1])  # body.genders codes: 1 male, 2 female
    g = mean_body_per_view(arrays, gendered=True, body_models=gendered_models)
    assert (g["method"] == GENDERED_LABEL).all() and list(g["sample"]) == [10, 10, 11, 11, 12, 12]
    assert g["mpe_m"].max() < 1e-6 and g["reproj_px"].max() < 1e-6
    n = mean_body_per_view(arrays, body_model=open_model)
    assert n["mpe_m"].min() > 0.05
    # both, neutral rows first, as Table I's reference rows
    both = mean_body_references(arrays, body_models={"neutral": open_model, **gendered_models})
    assert list(both["method"]) == [NEUTRAL_LABEL] * 6 + [GENDERED_LABEL] * 6
    np.testing.assert_allclose(both["mpe_m"], np.concatenate([n["mpe_m"], g["mpe_m"]]))


def test_a_wrong_gender_is_not_exact(gendered_models):
    """The same subjects with their genders swapped: the reference poses the other mean body and
    misses (the gender is read from ``arrays["gender"]``, not from anything else)."""
    male, female = gendered_models["male"], gendered_models["female"]
    arrays = _arrays([male, female, male], 1.0, gender=[2, 1, 2])
    assert mean_body_per_view(arrays, gendered=True, body_models=gendered_models)["mpe_m"].min() > 0.05
