"""The open SMPL-X-format model: file contents, smplx loading, anatomy and keypoints."""
from __future__ import annotations

import json

import numpy as np
import pytest
import smplx
import torch
import yaml
from PIL import Image

from airpose_lib.body import (
    EXTRA_JOINT_NAMES,
    SMPLX_JOINT_NAMES,
    SMPLX_PARENTS,
    joint_index,
    load_body_model,
    open_model_texture,
    stature,
)

J = joint_index


@pytest.fixture(scope="module")
def npz(open_model_files):
    with np.load(open_model_files["neutral"]) as data:
        return {k: data[k] for k in data.files}


def test_file_has_the_smplx_keys_and_sane_values(npz):
    V = npz["v_template"].shape[0]
    assert npz["f"].shape[1] == 3 and npz["f"].max() < V
    assert npz["shapedirs"].shape == (V, 3, 20)
    assert npz["posedirs"].shape == (V, 3, 486)
    assert npz["J_regressor"].shape == (55, V)
    assert npz["weights"].shape == (V, 55)
    for key in ("v_template", "shapedirs", "J_regressor", "weights"):
        assert np.isfinite(npz[key]).all(), key
    np.testing.assert_allclose(npz["weights"].sum(1), 1.0, atol=1e-9)
    assert npz["weights"].min() >= 0
    np.testing.assert_allclose(npz["J_regressor"].sum(1), 1.0, atol=1e-9)
    assert npz["J_regressor"].min() >= 0
    parents = npz["kintree_table"][0].astype(np.int64)
    assert list(parents[1:]) == list(SMPLX_PARENTS[1:])
    assert npz["extra_joint_vertex_ids"].shape == (len(EXTRA_JOINT_NAMES),)
    assert len(np.unique(npz["extra_joint_vertex_ids"])) == len(EXTRA_JOINT_NAMES)


def test_loads_through_plain_smplx_create(open_model_files):
    model = smplx.create(str(open_model_files["neutral"]), model_type="smplx", ext="npz")
    out = model()
    assert out.vertices.shape == (1, 13718, 3)
    assert out.joints.shape == (1, 76, 3)  # no face landmarks on the open model
    assert torch.isfinite(out.vertices).all()


def test_loader_installs_keypoint_vertices(open_model, npz):
    ids = open_model.vertex_joint_selector.extra_joints_idxs.numpy()
    np.testing.assert_array_equal(ids, npz["extra_joint_vertex_ids"])
    out = open_model()
    np.testing.assert_allclose(out.joints[0, 55:].detach(), out.vertices[0, ids].detach())


def _rest(model, betas=None):
    with torch.no_grad():
        out = model(betas=betas)
    return out.vertices[0].numpy(), out.joints[0].numpy()


def test_axes_and_t_pose(open_model):
    v, j = _rest(open_model)
    # Y up: head above pelvis above ankles; metres: a person is 1.5-2 m tall
    assert j[J("head"), 1] > j[J("pelvis"), 1] > j[J("left_ankle"), 1]
    assert 1.5 < stature(torch.as_tensor(v)).item() < 2.0
    # +X is the subject's left
    assert j[J("left_hip"), 0] > 0 > j[J("right_hip"), 0]
    assert j[J("left_wrist"), 0] > 0.5 > -0.5 > j[J("right_wrist"), 0]
    # faces +Z: nose and toes in front of the head and ankles
    assert j[J("nose"), 2] > j[J("head"), 2] + 0.05
    assert j[J("left_big_toe"), 2] > j[J("left_ankle"), 2] + 0.08
    # T-pose: shoulder -> wrist is horizontal and sideways (within 3 degrees)
    for side in ("left", "right"):
        arm = j[J(f"{side}_wrist")] - j[J(f"{side}_shoulder")]
        arm /= np.linalg.norm(arm)
        assert abs(arm[0]) > np.cos(np.radians(3)), (side, arm)


def test_left_right_symmetry(open_model):
    v, j = _rest(open_model)
    mirror = np.array([-1.0, 1.0, 1.0])
    for name in SMPLX_JOINT_NAMES + EXTRA_JOINT_NAMES:
        if name.startswith("left_"):
            other = "right_" + name[5:]
            np.testing.assert_allclose(j[J(name)] * mirror, j[J(other)], atol=0.01, err_msg=name)
    # the mesh itself: every vertex has a mirror image on the mesh within 1 cm
    from scipy.spatial import cKDTree

    dist, _ = cKDTree(v).query(v * mirror)
    assert np.percentile(dist, 99) < 0.01


def _winding_number(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Generalised winding number (Jacobson et al. 2013): ~1 inside a closed mesh, ~0 outside."""
    tri = vertices[faces]  # (F, 3, 3)
    out = []
    for p in points:
        a, b, c = (tri - p).transpose(1, 0, 2)
        la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
        num = np.einsum("ij,ij->i", a, np.cross(b, c))
        den = la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", b, c) * la
        den += np.einsum("ij,ij->i", c, a) * lb
        out.append(2 * np.arctan2(num, den).sum() / (4 * np.pi))
    return np.array(out)


@pytest.mark.parametrize("beta1", [-2.0, 0.0, 2.0])
def test_body_joints_lie_inside_the_mesh(open_model, beta1):
    betas = torch.zeros(1, 10, dtype=torch.float64)
    betas[0, 0] = beta1
    betas[0, 1] = -beta1 / 2  # a second component too, so both directions are exercised
    v, j = _rest(open_model, betas)
    w = _winding_number(j[:22], v, open_model.faces.astype(np.int64))
    inside = {name: round(float(x), 2) for name, x in zip(SMPLX_JOINT_NAMES[:22], w)}
    assert all(x > 0.5 for x in inside.values()), inside


def test_stature_range_along_first_shape_component(open_model):
    heights = {}
    for beta1 in (-2.0, 0.0, 2.0):
        betas = torch.zeros(1, 10, dtype=torch.float64)
        betas[0, 0] = beta1
        heights[beta1] = stature(_rest(open_model, betas)[0][None]).item()
    assert 1.45 < heights[-2.0] < 1.60, heights
    assert 1.65 < heights[0.0] < 1.80, heights
    assert 1.85 < heights[2.0] < 2.00, heights


def test_provenance_json(open_model_files):
    info = json.loads(open_model_files["neutral"].with_suffix(".json").read_text())
    assert info["gender"] == "neutral" and info["build_version"] >= 1
    assert info["shape_variance_explained"] > 0.99
    assert max(info["anny_bone_head_mean_distance_m"].values()) < 0.03


def test_gendered_variants(open_model_files):
    heights = {}
    for gender in ("male", "female"):
        model = load_body_model("open", gender, dtype=torch.float64)
        heights[gender] = stature(_rest(model)[0][None]).item()
    assert heights["male"] > heights["female"] + 0.03, heights


def _part_at_vertex(texture: dict, vertex: int, faces: np.ndarray) -> str:
    """Body part of anny's UV segmentation under a vertex (an independent label source)."""
    image = np.asarray(Image.open(texture["segmentation_png"]).convert("RGB"))
    colours = yaml.safe_load(texture["segmentation_yaml"].read_text())["colors"]
    f, corner = np.argwhere(faces == vertex)[0]
    u, v = texture["uv"][texture["faces_uv"][f, corner]]
    h, w = image.shape[:2]
    rgb = image[int(round((1 - v) * (h - 1))), int(round(u * (w - 1)))].astype(int)
    return min(colours, key=lambda name: np.abs(np.array(colours[name]) - rgb).sum())


def test_keypoint_vertices_land_on_the_right_body_parts(open_model, npz):
    texture = open_model_texture("neutral")
    ids = dict(zip(EXTRA_JOINT_NAMES, npz["extra_joint_vertex_ids"]))
    faces = npz["f"]
    expected = {"nose": {"head"}, "left_ear": {"head"}, "right_ear": {"head"}}
    for side, s in (("left", "L"), ("right", "R")):
        expected[f"{side}_eye"] = {f"eye_front.{s}", f"eye_back.{s}", "head"}
        for toe in ("big_toe", "small_toe", "heel"):
            expected[f"{side}_{toe}"] = {f"foot.{s}"}
        for finger in ("thumb", "index", "middle", "ring", "pinky"):
            expected[f"{side}_{finger}"] = {f"hand.{s}"}
    parts = {name: _part_at_vertex(texture, ids[name], faces) for name in expected}
    wrong = {n: p for n, p in parts.items() if p not in expected[n]}
    assert not wrong, wrong

    _, j = _rest(open_model)
    for side, sign in (("left", 1), ("right", -1)):
        assert sign * j[J(f"{side}_ear"), 0] > sign * j[J(f"{side}_eye"), 0]
        assert j[J(f"{side}_heel"), 2] < j[J(f"{side}_ankle"), 2]
        for finger in ("thumb", "index", "middle", "ring", "pinky"):
            assert sign * j[J(f"{side}_{finger}"), 0] > sign * j[J(f"{side}_wrist"), 0] + 0.05
    assert abs(j[J("nose"), 0]) < 0.01


def test_posing_bends_the_knee_backwards(open_model):
    body_pose = torch.zeros(1, 63, dtype=torch.float64)
    body_pose[0, (J("left_knee") - 1) * 3] = 1.2  # flexion about +X
    with torch.no_grad():
        j = open_model(body_pose=body_pose).joints[0]
    assert j[J("left_ankle"), 2] < j[J("left_knee"), 2] - 0.2  # shank swings behind
    assert j[J("right_ankle"), 2] == pytest.approx(_rest(open_model)[1][J("right_ankle"), 2], abs=1e-9)


# -- quiet start-up: anny's warp prints a no-driver warning on every CPU-only machine ---
def test_loading_anny_and_the_body_model_prints_nothing(open_model_files):
    """A fresh process that imports the body package, loads the model and imports anny (what the
    first build does) writes nothing on stdout or stderr: before the fix, warp's banner went to
    stdout and 'Warp CUDA warning: Could not find or load the NVIDIA CUDA driver' to stderr."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    code = ("import airpose_lib.body as body\n"
            "body.load_body_model()\n"
            "from airpose_lib.body.open_model import _load_anny\n"
            "_load_anny()\n")
    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stderr == "" and done.stdout == ""


def test_the_stderr_filter_drops_only_its_line(capfd):
    """Only lines starting with the prefix go; whatever else C code writes on fd 2 stays, in order."""
    import os

    from airpose_lib.body.open_model import _without_native_stderr_line

    with _without_native_stderr_line("Warp CUDA warning:"):
        os.write(2, b"first\nWarp CUDA warning: no driver\nlast error\n")
    assert capfd.readouterr().err == "first\nlast error\n"
