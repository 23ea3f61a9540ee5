"""Off-screen renderer against OpenCV's projection; skeleton and style helpers."""

import os

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

import cv2  # noqa: E402
import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
import pyvista as pv  # noqa: E402

pv.OFF_SCREEN = True

from airpose_lib.viz import (  # noqa: E402
    edges_from_parents,
    method_color,
    plot_keypoints_2d,
    plot_skeleton_3d,
    save_figure,
    use_kit_style,
)
from airpose_lib.viz.render import (  # noqa: E402
    OffscreenRenderer,
    RenderMesh,
    intrinsics_from_fov,
    look_at,
    render_turntable,
    render_views,
    set_vtk_camera,
    vtk_camera,
)
from airpose_lib.viz.skeleton import joint_side  # noqa: E402

W, H = 320, 240


def _sphere(center, radius=0.3, res=48):
    s = pv.Sphere(radius=radius, center=center, theta_resolution=res, phi_resolution=res)
    return np.asarray(s.points, dtype=np.float64), np.asarray(s.regular_faces)


def _box(center, half=0.25, seed=0):
    """A cube (8 corners, 12 triangles) turned by a random rotation, moved to ``center``."""
    b = pv.Box(bounds=(-half, half, -half, half, -half, half)).triangulate()
    rot, _ = cv2.Rodrigues(np.random.default_rng(seed).normal(size=3) * 0.6)
    v = np.asarray(b.points, dtype=np.float64) @ rot.T + np.asarray(center)
    return v, np.asarray(b.regular_faces)


def _silhouette(img, background=(0, 0, 0)):
    return np.any(img != np.asarray(background, dtype=np.uint8), axis=-1)


def _cv_project(v, K):
    uv, _ = cv2.projectPoints(v, np.zeros(3), np.zeros(3), K, None)
    return uv[:, 0]


@pytest.fixture(scope="module")
def renderer():
    r = OffscreenRenderer((W, H), background=(0, 0, 0), anti_aliasing=False)
    yield r
    r.close()


# Off-centre principal points and fx != fy, where a naive "view angle only" camera is wrong.
INTRINSICS = {
    "offcentre": np.array([[300.0, 0, 110.0], [0, 300.0, 150.0], [0, 0, 1]]),
    "centred": np.array([[250.0, 0, (W - 1) / 2], [0, 250.0, (H - 1) / 2], [0, 0, 1]]),
    "fx_ne_fy": np.array([[340.0, 0, 180.0], [0, 280.0, 100.0], [0, 0, 1]]),
}


@pytest.mark.parametrize("kname", list(INTRINSICS))
def test_box_silhouette_matches_opencv(renderer, kname):
    K = INTRINSICS[kname]
    v, f = _box((0.2, -0.1, 5.0))
    img = renderer.render(v, f, (1.0, 1.0, 1.0), K=K)
    assert img.shape == (H, W, 3) and img.dtype == np.uint8
    mask = _silhouette(img)
    ys, xs = np.nonzero(mask)
    uv = _cv_project(v, K)
    # A convex box: its silhouette is the convex hull of the projected corners. Compare the pixel
    # centroid and area with the hull polygon's exact moments (pixel centres at integers, as
    # OpenCV), and the extreme pixels with the extreme corners (a corner's wedge may cover no
    # pixel centre, hence 1.5 px).
    m = cv2.moments(cv2.convexHull(uv.astype(np.float32)))
    assert xs.mean() == pytest.approx(m["m10"] / m["m00"], abs=0.15)
    assert ys.mean() == pytest.approx(m["m01"] / m["m00"], abs=0.15)
    assert mask.sum() == pytest.approx(m["m00"], rel=0.02)
    got = np.array([xs.min(), xs.max(), ys.min(), ys.max()], dtype=float)
    want = np.array([uv[:, 0].min(), uv[:, 0].max(), uv[:, 1].min(), uv[:, 1].max()])
    np.testing.assert_allclose(got, want, atol=1.5)


def test_sphere_centroid_and_depth(renderer):
    K = INTRINSICS["offcentre"]
    centre = np.array([0.4, -0.2, 5.0])
    v, f = _sphere(centre)
    img, depth = renderer.render(v, f, (1.0, 1.0, 1.0), K=K, return_depth=True)
    mask = _silhouette(img)
    ys, xs = np.nonzero(mask)
    cu, cv = _cv_project(centre[None], K)[0]
    assert abs(xs.mean() - cu) < 1.0 and abs(ys.mean() - cv) < 1.0
    # Depth along +z: the sphere's nearest point is at z = 5 - r, the background is inf.
    assert depth.shape == (H, W)
    assert np.isinf(depth[~mask]).all()
    assert depth[int(round(cv)), int(round(cu))] == pytest.approx(4.7, abs=0.01)
    assert depth[mask].max() <= 5.0 + 1e-2


def test_no_stale_frame(renderer):
    """Moving the vertices must change the next image (render() before screenshot())."""
    K = INTRINSICS["offcentre"]
    v, f = _sphere((0.0, 0.0, 5.0))
    a = renderer.render(v, f, K=K)
    b = renderer.render(v + [0.5, 0.0, 0.0], f, K=K)
    assert (a != b).any()
    ya, xa = np.nonzero(_silhouette(a))
    yb, xb = np.nonzero(_silhouette(b))
    assert xb.mean() - xa.mean() == pytest.approx(300.0 * 0.5 / 5.0, abs=1.0)
    # The reused window gives the same pixels as a fresh renderer for the same frame.
    with OffscreenRenderer((W, H), background=(0, 0, 0), anti_aliasing=False) as fresh:
        c = fresh.render(v + [0.5, 0.0, 0.0], f, K=K)
    assert np.abs(c.astype(int) - b.astype(int)).max() <= 2


def test_topology_change_and_multiple_meshes(renderer):
    K = INTRINSICS["centred"]
    vs, fs = _sphere((-0.5, 0.0, 5.0), res=16)
    vb, fb = _box((0.5, 0.0, 5.0))
    img = renderer.render_meshes([RenderMesh(vs, fs, (255, 0, 0)), RenderMesh(vb, fb, (0, 0, 255))],
                                 K=K)
    left, right = img[:, : W // 2], img[:, W // 2:]
    assert left[..., 0].max() > 100 and left[..., 2].max() < 60  # red sphere on the left
    assert right[..., 2].max() > 100 and right[..., 0].max() < 60  # blue box on the right
    # Fewer meshes next frame: the box must disappear.
    img2 = renderer.render(vs, fs, (255, 0, 0), K=K)
    assert img2[:, W // 2 + 10:].max() == 0


def test_per_vertex_colours(renderer):
    K = INTRINSICS["centred"]
    v, f = _sphere((0.0, 0.0, 4.0))
    colors = np.where(v[:, :1] < 0, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])  # left red, right green
    img = renderer.render(v, f, colors, K=K)
    row = img[H // 2]
    assert row[W // 2 - 10, 0] > 2 * row[W // 2 - 10, 1] + 20  # sphere radius ~19 px
    assert row[W // 2 + 10, 1] > 2 * row[W // 2 + 10, 0] + 20


def test_look_at_and_intrinsics():
    R, t = look_at(eye=(1.0, 2.0, 3.0), target=(0.0, 1.0, 0.0))
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(R @ np.array([1.0, 2.0, 3.0]) + t, 0.0, atol=1e-12)
    target_cam = R @ np.array([0.0, 1.0, 0.0]) + t
    np.testing.assert_allclose(target_cam[:2], 0.0, atol=1e-12)
    assert target_cam[2] > 0
    # World up appears upwards in the image (negative camera y).
    assert (R @ np.array([0.0, 1.0, 0.0]))[1] < 0
    K = intrinsics_from_fov((200, 100), 90.0)
    assert K[1, 1] == pytest.approx(50.0) and K[0, 2] == pytest.approx(99.5)


def test_render_views_project_matches_render():
    """view.project(world points) lands on the rendered silhouette, in every view."""
    v, f = _box((0.3, 0.9, -0.2), half=0.3, seed=3)
    views = render_views(v, f, ("front", "side", 45.0), image_size=(200, 160), background=(0, 0, 0),
                         elevation_deg=15.0)
    assert [vw.name for vw in views] == ["front", "side", "45.0"]
    for view in views:
        ys, xs = np.nonzero(_silhouette(view.image))
        uv = view.project(v)
        np.testing.assert_allclose([xs.min(), xs.max(), ys.min(), ys.max()],
                                   [uv[:, 0].min(), uv[:, 0].max(), uv[:, 1].min(), uv[:, 1].max()],
                                   atol=1.5)
    # Front view: the camera is on +Z; the subject's left (+X) appears on the image's right.
    front = views[0]
    a, b = front.project(np.array([[0.0, 0.9, -0.2], [0.2, 0.9, -0.2]]))
    assert b[0] > a[0]


def test_turntable_shares_distance():
    v, f = _sphere((0.0, 1.0, 0.0), res=12)
    views = render_turntable(v, f, n_frames=4, image_size=64)
    assert len(views) == 4
    dists = [np.linalg.norm(-vw.R.T @ vw.t - [0.0, 1.0, 0.0]) for vw in views]
    np.testing.assert_allclose(dists, dists[0], rtol=1e-9)


def test_skeleton_helpers():
    parents = [-1, 0, 1, 0, 3]
    assert edges_from_parents(parents) == [(0, 1), (1, 2), (0, 3), (3, 4)]
    assert joint_side("left_knee") == "left" and joint_side("LKnee") == "left"
    assert joint_side("RHeel") == "right" and joint_side("right_wrist") == "right"
    assert joint_side("Neck") == "centre" and joint_side("pelvis") == "centre"
    joints = np.array([[0, 0, 0], [0.1, 0.5, 0], [0.1, 1.0, 0], [-0.1, 0.5, 0], [-0.1, 1.0, 0.1]])
    fig = plt.figure()
    ax = fig.add_subplot(projection="3d")
    plot_skeleton_3d(ax, joints, parents, names=["root", "left_a", "left_b", "right_a", "right_b"])
    assert len(ax.lines) == 4
    ax2 = fig.add_subplot(1, 2, 1)
    kp = np.array([[10, 10], [20, 30], [np.nan, np.nan], [40, 50], [60, 70]], dtype=float)
    plot_keypoints_2d(ax2, kp, [(0, 1), (1, 2), (0, 3), (3, 4)], image=np.zeros((80, 90, 3), np.uint8),
                      visible=[1, 1, 1, 0, 1])
    assert len(ax2.lines) == 1  # (0, 1) only: 2 is NaN, 3 is hidden
    assert ax2.get_xlim() == (-0.5, 89.5)
    with pytest.raises(ValueError):
        plot_skeleton_3d(ax, joints)
    plt.close(fig)


def test_style_and_save_figure(tmp_path):
    from PIL import Image

    use_kit_style()
    assert matplotlib.rcParams["savefig.dpi"] == 150
    assert method_color("airpose+") == method_color("AirPose+") != method_color("AirPose")
    assert method_color("GT") == method_color("Ground truth")
    with pytest.raises(KeyError):
        method_color("SPIN")
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    path = save_figure(fig, tmp_path / "sub" / "f.png", params={"image_size": 64}, show=False)
    meta = Image.open(path).text
    assert meta["Software"].startswith("airpose_lib ")
    assert '"image_size": 64' in meta["Description"]
    assert not plt.fignum_exists(fig.number)


def test_vertex_normals_point_outwards():
    from airpose_lib.viz.render import vertex_normals

    centre = np.array([0.1, -0.2, 3.0])
    v, f = _sphere(centre, radius=0.5, res=24)
    n = vertex_normals(v, f)
    radial = (v - centre) / np.linalg.norm(v - centre, axis=1, keepdims=True)
    assert np.einsum("ij,ij->i", n, radial).min() > 0.98


def test_light_direction(renderer):
    """A light travelling down the image (+y) lights the top of a sphere, and vice versa."""
    K = INTRINSICS["centred"]
    v, f = _sphere((0.0, 0.0, 4.0), radius=0.6)
    means = []
    for d in ((0.0, 1.0, 0.3), (0.0, -1.0, 0.3)):
        renderer.set_light(d)
        img = renderer.render(v, f, (1.0, 1.0, 1.0), K=K).astype(float).mean(-1)
        means.append((img[: H // 2].sum(), img[H // 2:].sum()))
    renderer.set_light((0.25, 0.6, 1.0))
    (top_a, bottom_a), (top_b, bottom_b) = means
    assert top_a > 1.2 * bottom_a and bottom_b > 1.2 * top_b


def _vtk_pixels(settings: dict, image_size, X: np.ndarray) -> np.ndarray:
    """World points ``(N, 3)`` -> ``(N, 2)`` pixels through a bare ``vtkCamera`` (no rendering):
    its world -> NDC matrix, then NDC [-1, 1] to OpenCV pixels (centres at integers, v down)."""
    from vtkmodules.vtkRenderingCore import vtkCamera

    W, H = image_size
    cam = vtkCamera()
    set_vtk_camera(cam, settings, 0.1, 100.0)
    m = cam.GetCompositeProjectionTransformMatrix(W / H, -1.0, 1.0)
    M = np.array([[m.GetElement(i, j) for j in range(4)] for i in range(4)])
    h = np.c_[X, np.ones(len(X))] @ M.T
    ndc = h[:, :2] / h[:, 3:]
    return np.c_[(ndc[:, 0] + 1.0) * W / 2.0 - 0.5, (1.0 - ndc[:, 1]) * H / 2.0 - 0.5]


def test_vtk_camera_projects_as_opencv():
    """The OpenCV -> VTK camera rule against cv2.projectPoints: a turned, moved camera with an
    off-centre principal point puts every point on OpenCV's pixel."""
    size = (320, 200)
    K = np.array([[300.0, 0, 170.3], [0, 300.0, 88.7], [0, 0, 1]])
    rng = np.random.default_rng(3)
    R, _ = cv2.Rodrigues(rng.normal(size=3) * 0.5)
    t = np.array([0.3, -0.2, 6.0])
    X = (rng.uniform(-1, 1, (20, 3)) - t) @ R  # points about 6 m in front of the camera
    uv, _ = cv2.projectPoints(X.reshape(-1, 1, 3), cv2.Rodrigues(R)[0], t, K, None)
    assert np.abs(_vtk_pixels(vtk_camera(K, size, R, t), size, X) - uv[:, 0]).max() < 1e-6


def test_vtk_camera_by_hand():
    """Camera frame as world: view angle 2 atan(H / 2 fy), window centre from the principal point."""
    s = vtk_camera(np.array([[500.0, 0, 159.5], [0, 500.0, 99.5], [0, 0, 1]]), (320, 200))
    assert s["position"] == (0.0, 0.0, 0.0) and s["focal_point"] == (0.0, 0.0, 1.0)
    assert s["view_up"] == (0.0, -1.0, 0.0)
    assert s["view_angle"] == pytest.approx(np.degrees(2 * np.arctan(100 / 500)))
    assert s["window_center"] == pytest.approx((0.0, 0.0))  # centred principal point: no shift
    s = vtk_camera(np.array([[500.0, 0, 79.5], [0, 500.0, 149.5], [0, 0, 1]]), (320, 200))
    assert s["window_center"] == pytest.approx((0.5, 0.5))  # 80 px left, 50 px down of the centre
    with pytest.raises(ValueError, match="skew"):
        vtk_camera(np.array([[500.0, 1.0, 79.5], [0, 500.0, 149.5], [0, 0, 1]]), (320, 200))
