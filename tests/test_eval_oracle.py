"""The mean-body oracle of Table I: exact on the mean body, off by the stature ratio otherwise."""
import numpy as np

from airpose_lib.eval.oracle import ORACLE_LABEL, oracle_per_view, solve_translation

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


def test_a_taller_person_puts_the_oracle_short_by_the_stature_ratio():
    # A body s times taller at tau projects like the mean body at tau / s: the oracle lands there.
    X0, phi, tau = _scene(np.random.default_rng(3))
    s = 1.065  # one standard deviation of the kit's stature spread (6.5 %)
    X = np.einsum("vij,kj->vki", phi, X0)
    uv = _project(s * X + tau[:, None], K)
    est = solve_translation(X, uv, np.broadcast_to(K, (4, 3, 3)))
    np.testing.assert_allclose(est, tau / s, atol=1e-6)
    depth_error = est[:, 2] - tau[:, 2]
    np.testing.assert_allclose(depth_error, tau[:, 2] * (1 / s - 1), atol=1e-6)  # ~ -0.61 m at 10 m


def _arrays(model, s: float, n=3, V=2):
    """A still-frame split whose ground truth is the neutral body with beta = 0, scaled by s,
    posed by smplx's own forward pass (independent of the oracle's joints-only path)."""
    import torch

    rng = np.random.default_rng(4)
    theta = rng.normal(0, 0.25, size=(n, 21, 3))
    z = lambda k: torch.zeros(n, k, dtype=torch.float64)  # noqa: E731
    with torch.no_grad():  # as the data generator poses its subjects
        out = model(betas=z(10), body_pose=torch.as_tensor(theta).reshape(n, 63), global_orient=z(3), transl=z(3),
                    jaw_pose=z(3), leye_pose=z(3), reye_pose=z(3), left_hand_pose=z(45), right_hand_pose=z(45),
                    expression=z(model.num_expression_coeffs))
    J0 = s * out.joints[:, :22].numpy()
    phi = np.stack([[_rotation(rng) for _ in range(V)] for _ in range(n)])
    tau = rng.uniform([-2, -1, 8], [2, 1, 14], size=(n, V, 3))
    jc = np.einsum("nvij,nkj->nvki", phi, J0) + tau[:, :, None]
    return {"theta": theta, "phi": phi, "tau": tau, "j2d": _project(jc, K), "K": np.broadcast_to(K, (n, V, 3, 3)),
            "index": np.array([10, 11, 12]), "beta": np.zeros((n, 10)), "gender": np.zeros(n, np.int64)}


def test_oracle_is_exact_when_the_subject_is_the_mean_body(open_model):
    t = oracle_per_view(_arrays(open_model, 1.0), body_model=open_model)
    assert list(t["sample"]) == [10, 10, 11, 11, 12, 12] and list(t["view"]) == [0, 1] * 3
    assert (t["method"] == ORACLE_LABEL).all()
    assert t["mpe_m"].max() < 1e-6 and t["reproj_px"].max() < 1e-6


def test_oracle_error_on_a_taller_subject_is_the_stature_ratio(open_model):
    s = 1.1
    arrays = _arrays(open_model, s)
    t = oracle_per_view(arrays, body_model=open_model)
    expected = np.linalg.norm(arrays["tau"], axis=-1).reshape(-1) * (1 - 1 / s)
    np.testing.assert_allclose(t["mpe_m"], expected, atol=1e-6)
    np.testing.assert_allclose(t["err_z_m"], arrays["tau"][..., 2].reshape(-1) * (1 / s - 1), atol=1e-6)
    assert t["mpe_m"].min() > 0.5  # 10 % taller at 8-14 m: the floor is metres-scale, not noise


def test_recording_oracle_puts_uav2_off_by_the_stature_ratio_of_the_drones_distance(open_model):
    """Two views do not fix the scale: both drones come out 1/s as far, so UAV2 in UAV1 is off by
    (1 - 1/s) of their distance."""
    from airpose_lib.eval.oracle import oracle_recording_estimate
    from airpose_lib.eval.recordings import relative_camera_positions

    s = 1.1
    a = _arrays(open_model, s)
    gt = {"theta_view": np.broadcast_to(a["theta"][:, None], (3, 2, 21, 3)), "phi": a["phi"], "tau": a["tau"],
          "j2d": a["j2d"], "K": np.broadcast_to(K, (2, 3, 3))}
    est = oracle_recording_estimate(gt, body_model=open_model)
    assert est["theta"].shape == (3, 2, 21, 3, 3) and not est["beta"].any() and est["valid"].all()
    np.testing.assert_allclose(est["tau"], a["tau"] / s, atol=1e-6)
    R_gt, t_gt = relative_camera_positions(gt)
    R_est, t_est = relative_camera_positions(est)
    np.testing.assert_allclose(R_est, R_gt, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(t_est - t_gt, axis=-1), (1 - 1 / s) * np.linalg.norm(t_gt, axis=-1),
                               atol=1e-6)
