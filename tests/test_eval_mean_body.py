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


def _smplx_body(model, beta, theta):
    """smplx's own forward pass (independent of the kit's BodyForward): ``(joints (22, 3), vertices)``."""
    import torch

    z = lambda k: torch.zeros(1, k, dtype=torch.float64)  # noqa: E731
    with torch.no_grad():
        out = model(betas=torch.as_tensor(beta, dtype=torch.float64).reshape(1, -1),
                    body_pose=torch.as_tensor(theta, dtype=torch.float64).reshape(1, 63), global_orient=z(3),
                    transl=z(3), jaw_pose=z(3), leye_pose=z(3), reye_pose=z(3), left_hand_pose=z(45),
                    right_hand_pose=z(45), expression=z(model.num_expression_coeffs))
    return out.joints[0, :22].numpy(), out.vertices[0].numpy()


def _shaped_arrays(models, gender, seed=5, V=2):
    """A split of subjects with their own shapes (beta ~ N(0, 1)), posed by smplx's forward."""
    rng = np.random.default_rng(seed)
    n = len(gender)
    beta, theta = rng.normal(0, 1, size=(n, 10)), rng.normal(0, 0.25, size=(n, 21, 3))
    J0 = np.stack([_smplx_body(models[i], beta[i], theta[i])[0] for i in range(n)])
    phi = np.stack([[_rotation(rng) for _ in range(V)] for _ in range(n)])
    tau = rng.uniform([-2, -1, 8], [2, 1, 14], size=(n, V, 3))
    jc = np.einsum("nvij,nkj->nvki", phi, J0) + tau[:, :, None]
    return {"theta": theta, "phi": phi, "tau": tau, "j2d": _project(jc, K), "K": np.broadcast_to(K, (n, V, 3, 3)),
            "index": np.arange(n), "beta": beta, "gender": np.asarray(gender, np.int64)}


def test_bone_ratios_by_hand_and_free_of_scale():
    from airpose_lib.body.joint_sets import SMPLX_PARENTS
    from airpose_lib.eval.mean_body import bone_ratios

    J = np.random.default_rng(6).normal(size=(22, 3))
    r = bone_ratios(J)
    lengths = np.array([np.sqrt(((J[k] - J[SMPLX_PARENTS[k]]) ** 2).sum()) for k in range(1, 22)])
    np.testing.assert_allclose(r, lengths / lengths.sum(), rtol=1e-12)
    np.testing.assert_allclose(bone_ratios(np.stack([J, 2.5 * J])), np.stack([r, r]), rtol=1e-12)
    assert SMPLX_PARENTS[1:4] == (0, 0, 0) and r.shape == (21,)  # hips and spine leave the pelvis


def test_stature_fit_recovers_an_exact_linear_rule_per_gender():
    from airpose_lib.eval.mean_body import fit_stature_from_proportions

    rng = np.random.default_rng(7)
    ratios = rng.dirichlet(np.ones(21), size=200)
    gender = np.repeat([1, 2], 100)
    w = {1: rng.normal(size=21), 2: rng.normal(size=21)}
    height = np.where(gender == 1, 1.2 + ratios @ w[1], 0.9 + ratios @ w[2])
    fit = fit_stature_from_proportions(ratios, height, gender)
    np.testing.assert_allclose(fit.predict(ratios, gender), height, atol=1e-10)
    assert min(fit.r2.values()) > 1 - 1e-12 and max(fit.residual_sd.values()) < 1e-10
    new = rng.dirichlet(np.ones(21), size=5)  # subjects the fit never saw
    np.testing.assert_allclose(fit.predict(new, np.full(5, 2)), 0.9 + new @ w[2], atol=1e-10)


def test_rest_statures_match_smplx_forward(gendered_models):
    from airpose_lib.body.loader import stature
    from airpose_lib.eval.mean_body import bone_ratios, rest_statures

    male, female = gendered_models["male"], gendered_models["female"]
    rng = np.random.default_rng(8)
    beta, gender = rng.normal(0, 1, size=(3, 10)), np.array([1, 2, 1])
    height, ratios = rest_statures(beta, gender, body_models=gendered_models)
    for i, m in enumerate([male, female, male]):
        J, verts = _smplx_body(m, beta[i], np.zeros((21, 3)))
        assert height[i] == pytest.approx(stature(verts), abs=1e-9)
        np.testing.assert_allclose(ratios[i], bone_ratios(J), atol=1e-9)
    assert 1.3 < height.min() and height.max() < 2.2  # adults, in metres


def test_proportion_reference_is_off_by_its_stature_ratio(gendered_models):
    """A stature model that always says c: each subject's body is scaled by c / (its stature) and
    lands that many times too far, exactly; with c its own stature it lands on tau."""
    from airpose_lib.eval.mean_body import PROPORTION_LABEL, StatureModel, proportion_body_per_view, rest_statures

    male, female = gendered_models["male"], gendered_models["female"]
    gender = [1, 2, 1]
    arrays = _shaped_arrays([male, female, male], gender)
    height, _ = rest_statures(arrays["beta"], arrays["gender"], body_models=gendered_models)
    c = 1.75
    const = StatureModel({1: np.r_[c, np.zeros(21)], 2: np.r_[c, np.zeros(21)]}, {}, {})
    t = proportion_body_per_view(arrays, const, body_models=gendered_models)
    assert (t["method"] == PROPORTION_LABEL).all() and t["reproj_px"].max() < 1e-6
    k = np.repeat(c / height, 2)  # per view
    np.testing.assert_allclose(t["mpe_m"], np.abs(k - 1) * np.linalg.norm(arrays["tau"], axis=-1).reshape(-1),
                               atol=1e-6)
    own = StatureModel({1: np.r_[height[0], np.zeros(21)], 2: np.r_[height[1], np.zeros(21)]}, {}, {})
    exact = proportion_body_per_view({k_: v[:2] for k_, v in arrays.items()}, own, body_models=gendered_models)
    assert exact["mpe_m"].max() < 1e-6


def test_references_add_the_proportion_rows_with_a_training_split(open_model, gendered_models):
    from airpose_lib.eval.mean_body import MEAN_BODY_LABELS

    male, female = gendered_models["male"], gendered_models["female"]
    test = _shaped_arrays([male, female, male], [1, 2, 1], seed=9)
    train = _shaped_arrays([male, female] * 40, [1, 2] * 40, seed=10)
    models = {"neutral": open_model, **gendered_models}
    both = mean_body_references(test, body_models=models)
    three = mean_body_references(test, body_models=models, train_arrays=train)
    assert list(three["method"].unique()) == list(MEAN_BODY_LABELS)
    np.testing.assert_allclose(three["mpe_m"][: len(both)], both["mpe_m"])
    # 40 subjects per gender fit the open body's stature from its proportions to centimetres, so
    # this reference lands far closer than the true-gender mean body
    per = three.groupby("method", sort=False)["mpe_m"].mean()
    assert per[MEAN_BODY_LABELS[2]] < 0.5 * per[GENDERED_LABEL]


def test_references_load_each_body_model_once(monkeypatch, open_model, gendered_models):
    """With no models given, the three references share one load per gender (a load builds a whole
    mesh's blend shapes); the rows are those of the given models."""
    import airpose_lib.eval.mean_body as mb

    models = {"neutral": open_model, **gendered_models}
    loads = []
    monkeypatch.setattr(mb, "load_body_model", lambda source, gender, dtype=None: loads.append(gender) or models[gender])
    male, female = gendered_models["male"], gendered_models["female"]
    test = _shaped_arrays([male, female, male], [1, 2, 1], seed=9)
    train = _shaped_arrays([male, female] * 20, [1, 2] * 20, seed=10)
    loaded = mb.mean_body_references(test, train_arrays=train)
    assert sorted(loads) == ["female", "male", "neutral"]
    np.testing.assert_allclose(loaded["mpe_m"],
                               mb.mean_body_references(test, body_models=models, train_arrays=train)["mpe_m"])
