"""Off-screen mesh rendering through a pinhole camera (pyvista / VTK, no X server).

The renderer draws triangle meshes given in *camera coordinates* (OpenCV: x right, y down,
z forward, metres) as seen by a camera with intrinsics ``K`` (3, 3) and image size ``(W, H)``
pixels, so that a vertex lands on the pixel ``cv2.projectPoints`` gives it. The VTK camera sits
at the origin looking along +z with view-up -y; the vertical view angle follows from ``fy`` and
``H``, and an off-centre principal point is applied with ``vtkCamera.SetWindowCenter`` (a shift
of the projection in normalised device coordinates, which keeps the pinhole model exact).

One ``pyvista.Plotter`` is kept for the renderer's lifetime and vertex buffers are updated in
place: re-creating a Plotter per frame is about three times slower.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

# Must be set before VTK creates its first render window: EGL renders without an X server and
# skips the X probe warning. A user's explicit setting wins.
os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

import pyvista as pv  # noqa: E402

from airpose_lib.viz.style import MESH_COLOR  # noqa: E402

pv.OFF_SCREEN = True

__all__ = [
    "RenderMesh",
    "CameraView",
    "OffscreenRenderer",
    "intrinsics_from_fov",
    "vtk_camera",
    "set_vtk_camera",
    "vertex_normals",
    "look_at",
    "project_points",
    "render_views",
    "render_turntable",
]

#: Default mesh colour (the kit's body colour), RGB in [0, 1].
DEFAULT_MESH_COLOR = MESH_COLOR
#: Default background, RGB in [0, 1].
DEFAULT_BACKGROUND = (1.0, 1.0, 1.0)
#: Default key-light direction in camera coordinates: the light travels forward (+z) and
#: down (+y), i.e. it comes from above and behind the camera, as a sun over the shoulder.
DEFAULT_LIGHT_DIR = (0.25, 0.6, 1.0)


@dataclass
class RenderMesh:
    """One triangle mesh to render.

    Attributes:
        vertices: (V, 3) positions in camera coordinates (OpenCV axes), metres.
        faces: (F, 3) integer vertex indices, counter-clockwise seen from outside.
        color: a single colour (3,) or per-vertex colours (V, 3); floats in [0, 1] or uint8.
            ``None`` uses :data:`DEFAULT_MESH_COLOR`.
        opacity: 0 (invisible) .. 1 (opaque).
    """

    vertices: np.ndarray
    faces: np.ndarray
    color: np.ndarray | tuple[float, float, float] | str | None = None
    opacity: float = 1.0


@dataclass
class CameraView:
    """A rendered view and the pinhole camera that made it.

    ``R``, ``t`` map world points into the camera frame: ``x_cam = R @ x_world + t`` (OpenCV
    axes), so ``project(points)`` gives the pixel where the renderer drew a world point.

    Attributes:
        image: (H, W, 3) uint8 RGB.
        K: (3, 3) intrinsics, pixels.
        R: (3, 3) world-to-camera rotation.
        t: (3,) world-to-camera translation, metres.
        depth: (H, W) depth along the optical axis in metres (``inf`` on background), or None.
        name: a label such as ``"front"``.
    """

    image: np.ndarray
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    depth: np.ndarray | None = None
    name: str = ""

    def to_camera(self, points: np.ndarray) -> np.ndarray:
        """World points (..., 3) -> camera coordinates (..., 3)."""
        return np.asarray(points, dtype=np.float64) @ self.R.T + self.t

    def project(self, points: np.ndarray) -> np.ndarray:
        """World points (..., 3) -> pixel coordinates (..., 2) in this view."""
        return project_points(self.to_camera(points), self.K)


def project_points(points_cam: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Pinhole projection of camera-frame points (..., 3) with intrinsics K (3, 3) -> (..., 2) px."""
    p = np.asarray(points_cam, dtype=np.float64) @ np.asarray(K, dtype=np.float64).T
    return p[..., :2] / p[..., 2:3]


def intrinsics_from_fov(image_size: tuple[int, int], fov_y_deg: float) -> np.ndarray:
    """Intrinsics K (3, 3) with square pixels, centred principal point and vertical FOV in degrees.

    ``image_size`` is (W, H) in pixels; the principal point is the image centre in OpenCV's pixel
    convention (pixel centres at integers), ((W - 1) / 2, (H - 1) / 2).
    """
    W, H = image_size
    f = 0.5 * H / math.tan(math.radians(fov_y_deg) / 2)
    return np.array([[f, 0.0, (W - 1) / 2], [0.0, f, (H - 1) / 2], [0.0, 0.0, 1.0]])


def look_at(eye: Sequence[float], target: Sequence[float], up: Sequence[float] = (0.0, 1.0, 0.0)
            ) -> tuple[np.ndarray, np.ndarray]:
    """World-to-camera (R (3, 3), t (3,)) of an OpenCV camera at ``eye`` looking at ``target``.

    ``up`` is the world direction that should appear upwards in the image (world Y for SMPL-X).
    Camera axes: z towards the target, y = image down, x = image right.
    """
    eye = np.asarray(eye, dtype=np.float64)
    z = np.asarray(target, dtype=np.float64) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, dtype=np.float64))  # image right = forward x up (y ~ -up)
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("look_at: viewing direction is parallel to `up`; pick another up vector")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])  # rows: camera axes in world coordinates
    return R, -R @ eye


def vtk_camera(K: np.ndarray, image_size: tuple[int, int], R_cw: np.ndarray | None = None,
               t_cw: np.ndarray | None = None) -> dict:
    """The VTK camera of an OpenCV camera: a world point X lands on the pixel ``K (R_cw X + t_cw)``.

    VTK has one focal length, that of ``fy``; a caller with ``fx != fy`` stretches x by ``fx / fy``.

    Args:
        K: ``(3, 3)`` intrinsics in pixels, no skew (OpenCV pixel centres at integers).
        image_size: ``(W, H)`` in pixels.
        R_cw, t_cw: ``(3, 3)``, ``(3,)`` world -> OpenCV camera (x right, y down, z forward);
            None: the world is the camera frame.

    Returns:
        ``position``, ``focal_point``, ``view_up`` (each ``(3,)``), ``view_angle`` (vertical,
        degrees) and ``window_center`` (``(2,)``, normalised device coordinates).
    """
    W, H = image_size
    K = np.asarray(K, dtype=np.float64)
    if abs(K[0, 1]) > 1e-9:
        raise ValueError("skewed intrinsics (K[0, 1] != 0) are not supported")
    fy, cx, cy = K[1, 1], K[0, 2], K[1, 2]
    if R_cw is None:
        position, focal_point, view_up = (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, -1.0, 0.0)
    else:
        R = np.asarray(R_cw, dtype=np.float64)
        position = -R.T @ np.asarray(t_cw, dtype=np.float64)
        focal_point = position + R[2]  # the optical axis is the camera's third row
        view_up = -R[1]  # image up = -y of the OpenCV camera
    # OpenCV pixel u spans [u - 0.5, u + 0.5]; VTK's viewport spans [0, W] in NDC [-1, 1]. The
    # principal point must land at NDC (2 (cx + .5) / W - 1, 1 - 2 (cy + .5) / H); the window
    # centre shifts the image the opposite way, hence the signs.
    return {"position": tuple(position), "focal_point": tuple(focal_point), "view_up": tuple(view_up),
            "view_angle": math.degrees(2.0 * math.atan(0.5 * H / fy)),
            "window_center": (1.0 - 2.0 * (cx + 0.5) / W, 2.0 * (cy + 0.5) / H - 1.0)}


def set_vtk_camera(camera, settings: dict, near: float, far: float) -> None:
    """Give a ``vtkCamera`` the :func:`vtk_camera` settings and the clipping planes (metres)."""
    camera.SetPosition(*settings["position"])
    camera.SetFocalPoint(*settings["focal_point"])
    camera.SetViewUp(*settings["view_up"])
    camera.SetViewAngle(settings["view_angle"])
    camera.SetWindowCenter(*settings["window_center"])
    camera.SetClippingRange(near, far)


def _as_rgb(color, n: int | None = None) -> np.ndarray:
    """Colour(s) -> float RGB in [0, 1]: (3,) for one colour or (n, 3) per vertex."""
    if color is None:
        return np.asarray(DEFAULT_MESH_COLOR, dtype=np.float64)
    if isinstance(color, str):
        return np.asarray(pv.Color(color).float_rgb, dtype=np.float64)
    c = np.asarray(color)
    scale = 255.0 if np.issubdtype(c.dtype, np.integer) else 1.0
    c = c.astype(np.float64) / scale
    if c.shape == (3,) or (n is not None and c.shape == (n, 3)):
        return np.clip(c, 0.0, 1.0)
    raise ValueError(f"colour must be (3,) or (V, 3) with V={n}, got shape {c.shape}")


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals (V, 3) of a triangle mesh (V, 3), (F, 3)."""
    tri = vertices[faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # length = 2 * area
    # Each face adds its normal to its three corners; bincount is ~2x faster than np.add.at.
    idx, w = faces.reshape(-1), np.repeat(fn, 3, axis=0)
    vn = np.stack([np.bincount(idx, weights=w[:, c], minlength=len(vertices)) for c in range(3)], 1)
    norm = np.linalg.norm(vn, axis=1, keepdims=True)
    return vn / np.where(norm > 0, norm, 1.0)


@dataclass
class _Slot:
    """A mesh actor kept between frames so that a new frame only rewrites its buffers."""

    poly: pv.PolyData
    actor: object
    faces: np.ndarray
    per_vertex: bool


class OffscreenRenderer:
    """Renders meshes in camera coordinates through an OpenCV pinhole camera, off-screen.

    Example::

        r = OffscreenRenderer((640, 480), K)
        rgb = r.render(vertices_cam, faces)                    # (480, 640, 3) uint8
        rgb, depth = r.render(vertices_cam, faces, return_depth=True)

    Args:
        image_size: (W, H) in pixels.
        K: (3, 3) intrinsics; defaults to a 40 degree vertical FOV with centred principal point.
        background: RGB in [0, 1] (or a colour name).
        light_dir: (3,) direction the key light travels, in camera coordinates.
        ambient, diffuse, specular: material lighting coefficients.
        anti_aliasing: MSAA on silhouettes (off gives hard, exactly binary edges).
    """

    def __init__(
        self,
        image_size: tuple[int, int] = (512, 512),
        K: np.ndarray | None = None,
        *,
        background=DEFAULT_BACKGROUND,
        light_dir: Sequence[float] = DEFAULT_LIGHT_DIR,
        ambient: float = 0.3,
        diffuse: float = 0.75,
        specular: float = 0.1,
        anti_aliasing: bool = True,
    ) -> None:
        self.image_size = (int(image_size[0]), int(image_size[1]))
        self.K = np.asarray(K if K is not None else intrinsics_from_fov(self.image_size, 40.0),
                            dtype=np.float64)
        self.material = dict(ambient=ambient, diffuse=diffuse, specular=specular)
        self._plotter = pv.Plotter(off_screen=True, window_size=list(self.image_size),
                                   lighting="none")
        if not anti_aliasing:
            self._plotter.disable_anti_aliasing()
        self._slots: list[_Slot] = []
        self._light = pv.Light(light_type="scene light")
        self._light.positional = False
        self._fill = pv.Light(light_type="scene light", intensity=0.35)
        self._fill.positional = False
        self._plotter.add_light(self._light)
        self._plotter.add_light(self._fill)
        self.set_background(background)
        self.set_light(light_dir)
        self._clip = (0.01, 100.0)

    # -- configuration ------------------------------------------------------------------------
    def set_background(self, color) -> None:
        """Background colour, RGB in [0, 1] or a colour name."""
        self._plotter.set_background(tuple(_as_rgb(color)))

    def set_light(self, direction: Sequence[float]) -> None:
        """Key-light direction (3,) in camera coordinates (where the light travels to)."""
        d = np.asarray(direction, dtype=np.float64)
        d = d / np.linalg.norm(d)
        # A directional VTK light shines from `position` towards `focal_point`.
        self._light.position = tuple(-d)
        self._light.focal_point = (0.0, 0.0, 0.0)
        # A weak fill from the opposite side keeps shadowed limbs readable.
        fill = np.array([-d[0], -abs(d[1]) * 0.3, d[2]])
        self._fill.position = tuple(-fill / np.linalg.norm(fill))
        self._fill.focal_point = (0.0, 0.0, 0.0)

    def _fit_camera(self, K: np.ndarray, near: float, far: float) -> tuple[float, float]:
        """Point the VTK camera so that it reproduces the pinhole K (3, 3); returns x scale."""
        set_vtk_camera(self._plotter.renderer.GetActiveCamera(), vtk_camera(K, self.image_size), near, far)
        self._plotter.renderer.camera_set = True  # keep pyvista from resetting the camera
        self._clip = (near, far)
        # VTK has one focal length; fx != fy is reproduced by stretching x by fx / fy.
        return K[0, 0] / K[1, 1]

    # -- rendering ----------------------------------------------------------------------------
    def render(
        self,
        vertices: np.ndarray,
        faces: np.ndarray,
        color=None,
        *,
        K: np.ndarray | None = None,
        return_depth: bool = False,
    ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Render one mesh.

        Args:
            vertices: (V, 3) in camera coordinates (OpenCV axes), metres.
            faces: (F, 3) int.
            color: (3,) or per-vertex (V, 3) colour, floats in [0, 1] or uint8; None = default.
            K: (3, 3) intrinsics for this frame (default: the renderer's).
            return_depth: also return the (H, W) depth along +z, ``inf`` where nothing was hit.

        Returns:
            (H, W, 3) uint8 RGB, and the depth map if ``return_depth``.
        """
        return self.render_meshes([RenderMesh(vertices, faces, color)], K=K,
                                  return_depth=return_depth)

    def render_meshes(
        self,
        meshes: Sequence[RenderMesh],
        *,
        K: np.ndarray | None = None,
        return_depth: bool = False,
    ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Render several meshes into one image; see :meth:`render` for arguments and outputs."""
        if K is not None:
            self.K = np.asarray(K, dtype=np.float64)
        zs = [np.asarray(m.vertices)[:, 2] for m in meshes if len(m.vertices)]
        zmin = min((float(z.min()) for z in zs), default=1.0)
        zmax = max((float(z.max()) for z in zs), default=10.0)
        # Tight clipping planes keep the depth buffer precise; geometry behind the camera is cut.
        near = max(zmin * 0.9, 1e-3)
        far = max(zmax * 1.1, near * 2.0)
        sx = self._fit_camera(self.K, near, far)

        for i, m in enumerate(meshes):
            v = np.asarray(m.vertices, dtype=np.float64)
            if sx != 1.0:
                v = v * np.array([sx, 1.0, 1.0])
            self._update_slot(i, v, np.asarray(m.faces), m.color, m.opacity)
        for slot in self._slots[len(meshes):]:  # hide meshes left over from earlier frames
            slot.actor.SetVisibility(False)

        # render() before reading back: without it screenshot() returns the previous frame.
        self._plotter.render()
        rgb = np.asarray(self._plotter.screenshot(return_img=True), dtype=np.uint8)[..., :3].copy()
        if not return_depth:
            return rgb
        z = -np.asarray(self._plotter.get_image_depth(fill_value=np.nan,
                                                      reset_camera_clipping_range=False))
        return rgb, np.where(np.isfinite(z), z, np.inf)

    def _update_slot(self, i: int, v: np.ndarray, faces: np.ndarray, color, opacity: float) -> None:
        rgb = _as_rgb(color, len(v))
        per_vertex = rgb.ndim == 2
        normals = vertex_normals(v, faces)
        slot = self._slots[i] if i < len(self._slots) else None
        same_topology = (slot is not None and slot.per_vertex == per_vertex
                         and slot.poly.n_points == len(v) and slot.faces.shape == faces.shape
                         and np.array_equal(slot.faces, faces))
        if same_topology:
            slot.poly.points[:] = v  # in-place: the mapper re-uploads only the changed buffers
            slot.poly.point_data["Normals"][:] = normals
            slot.poly.point_data.active_normals = slot.poly.point_data["Normals"]
            if per_vertex:
                slot.poly.point_data["rgb"][:] = (rgb * 255).astype(np.uint8)
            slot.poly.Modified()
        else:
            if slot is not None:
                self._plotter.remove_actor(slot.actor, render=False)
            poly = pv.PolyData.from_regular_faces(v.copy(), faces.astype(np.int64))
            poly.point_data["Normals"] = normals
            poly.point_data.active_normals = poly.point_data["Normals"]
            kw = dict(self.material, specular_power=20.0, reset_camera=False, render=False,
                      opacity=opacity, name=f"mesh{i}")
            if per_vertex:
                poly.point_data["rgb"] = (rgb * 255).astype(np.uint8)
                actor = self._plotter.add_mesh(poly, scalars="rgb", rgb=True, **kw)
            else:
                actor = self._plotter.add_mesh(poly, color=tuple(rgb), **kw)
            slot = _Slot(poly, actor, faces.copy(), per_vertex)
            if i < len(self._slots):
                self._slots[i] = slot
            else:
                self._slots.append(slot)
        if not per_vertex:
            slot.actor.prop.color = tuple(rgb)
        slot.actor.prop.opacity = opacity
        slot.actor.SetVisibility(True)

    # -- lifetime -----------------------------------------------------------------------------
    def close(self) -> None:
        """Release the render window (the renderer cannot be used afterwards)."""
        self._plotter.close()

    def __enter__(self) -> OffscreenRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


# -- views of a mesh in world coordinates ----------------------------------------------------------
_NAMED_AZIMUTHS = {"front": 0.0, "left": 90.0, "side": 90.0, "back": 180.0, "right": -90.0}


def _view_camera(vertices: np.ndarray, azimuth_deg: float, elevation_deg: float,
                 distance: float | None, target: Sequence[float] | None,
                 image_size: tuple[int, int], fov_y_deg: float, margin: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Camera (K, R, t) on a sphere around the mesh; azimuth 0 looks at the model's front (+Z)."""
    lo, hi = vertices.min(0), vertices.max(0)
    centre = (lo + hi) / 2 if target is None else np.asarray(target, dtype=np.float64)
    if distance is None:
        # Far enough that the bounding sphere fills (1 - margin) of the shorter image side.
        W, H = image_size
        fov_short = 2 * math.atan(math.tan(math.radians(fov_y_deg) / 2) * min(W, H) / H)
        radius = 0.5 * float(np.linalg.norm(hi - lo))
        distance = radius / math.sin(fov_short / 2) / (1.0 - margin)
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    # World: Y up, the model faces +Z, +X is the subject's left; azimuth turns towards +X.
    offset = distance * np.array([math.cos(el) * math.sin(az), math.sin(el),
                                  math.cos(el) * math.cos(az)])
    R, t = look_at(centre + offset, centre, up=(0.0, 1.0, 0.0))
    return intrinsics_from_fov(image_size, fov_y_deg), R, t


def render_views(
    vertices: np.ndarray,
    faces: np.ndarray,
    views: Sequence[str | float] = ("front", "side"),
    *,
    image_size: int | tuple[int, int] = 512,
    color=None,
    elevation_deg: float = 0.0,
    distance: float | None = None,
    target: Sequence[float] | None = None,
    fov_y_deg: float = 30.0,
    margin: float = 0.05,
    background=DEFAULT_BACKGROUND,
    light_dir: Sequence[float] = DEFAULT_LIGHT_DIR,
    return_depth: bool = False,
    renderer: OffscreenRenderer | None = None,
) -> list[CameraView]:
    """Render a world-frame mesh (Y up, facing +Z, as SMPL-X) from named or numeric azimuths.

    Args:
        vertices: (V, 3) world coordinates, metres.
        faces: (F, 3) int.
        views: names (``front``, ``side``/``left``, ``back``, ``right``) or azimuths in degrees
            (0 = in front of the model, 90 = on the model's left, +X).
        image_size: W = H (int) or (W, H), pixels.
        color: (3,) or (V, 3) colour.
        elevation_deg: camera height angle above the target, degrees.
        distance: camera distance to the target in metres; None fits the mesh in the image.
        target: the point looked at (3,); None = the centre of the bounding box. Fix it together
            with ``distance`` to compare meshes at the same scale.
        fov_y_deg: vertical field of view, degrees.
        margin: fraction of the image left free around the mesh when ``distance`` is None.
        renderer: reuse an existing renderer (its image size is kept).

    Returns:
        One :class:`CameraView` per view; ``view.project(points_world)`` gives pixels.
    """
    v = np.asarray(vertices, dtype=np.float64)
    size = (image_size, image_size) if isinstance(image_size, int) else tuple(image_size)
    own = renderer is None
    r = renderer or OffscreenRenderer(size, background=background, light_dir=light_dir)
    size = r.image_size
    out = []
    try:
        for view in views:
            az = _NAMED_AZIMUTHS[view] if isinstance(view, str) else float(view)
            K, R, t = _view_camera(v, az, elevation_deg, distance, target, size, fov_y_deg, margin)
            res = r.render(v @ R.T + t, faces, color, K=K, return_depth=return_depth)
            img, depth = res if return_depth else (res, None)
            out.append(CameraView(img, K, R, t, depth, name=str(view)))
    finally:
        if own:
            r.close()
    return out


def render_turntable(
    vertices: np.ndarray,
    faces: np.ndarray,
    n_frames: int = 8,
    **kwargs,
) -> list[CameraView]:
    """``n_frames`` views at evenly spaced azimuths (0 = front); kwargs as :func:`render_views`.

    The distance is fixed over the turn (fitted to the bounding sphere unless given), so the
    frames can be played as an animation.
    """
    return render_views(vertices, faces, [360.0 * k / n_frames for k in range(n_frames)], **kwargs)

