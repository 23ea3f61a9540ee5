"""Off-screen renderer of the synthetic scenes: textured ground, sky, clutter, lights and a body.

``viz.render.OffscreenRenderer`` draws meshes in camera coordinates with per-vertex or single
colours; a dataset scene also needs a textured ground plane and a handful of objects that stay in
the world while the camera moves. :class:`SceneRenderer` therefore keeps every actor in *world*
coordinates and moves the VTK camera instead: one body upload serves all views of a sample, and
a view only costs a camera update and a draw.

The camera is :func:`airpose_lib.viz.render.vtk_camera` (OpenCV ``K, R_cw, t_cw`` to VTK), so a
world point lands on the pixel that ``K (R_cw X + t_cw)`` gives.

Crops are rendered directly at the network input size with the crop's intrinsics
(:func:`airpose_lib.geometry.crop_intrinsics`); :func:`airpose_lib.geometry.pad_outside_box` then
blacks out what lies outside the person box, as the paper's aspect-preserving resize with black
padding does (the rule every crop of the kit shares).
"""
from __future__ import annotations

import math

import numpy as np
import pyvista as pv  # noqa: E402
from vtkmodules.vtkCommonMath import vtkMatrix4x4  # noqa: E402  (not `import vtk`: 1.5 s saved)
from vtkmodules.vtkRenderingCore import vtkTexture  # noqa: E402

# Importing viz.render selects the EGL window (no X server) and sets pyvista off-screen before
# VTK creates a window; keep this import first.
from airpose_lib.viz.render import set_vtk_camera, vertex_normals, vtk_camera  # noqa: E402

from .scene import EnvironmentSample  # noqa: E402

__all__ = ["ground_textures", "TRAINING_GROUND_PHOTOS", "photo_texture", "SceneRenderer"]

_GROUND_HALF_SIZE = 150.0  # metres; far enough that the horizon is ground, not void
_MAX_DISTRACTORS = 8


# -- textures -------------------------------------------------------------------------------------
def _periodic_noise(rng: np.random.Generator, size: int, beta: float) -> np.ndarray:
    """Seamless (periodic) 1/f^beta noise ``(size, size)`` scaled to [0, 1]."""
    f = np.fft.fftfreq(size)
    r = np.hypot(*np.meshgrid(f, f, indexing="ij"))
    r[0, 0] = 1.0
    spec = (rng.standard_normal((size, size)) + 1j * rng.standard_normal((size, size))) / r ** beta
    spec[0, 0] = 0.0
    img = np.real(np.fft.ifft2(spec))
    return (img - img.min()) / (img.max() - img.min())


def _procedural_textures(size: int) -> list[tuple[str, np.ndarray]]:
    rng = np.random.default_rng(20220101)  # fixed: every worker builds the same bank
    out = []
    dirt = 0.55 * _periodic_noise(rng, size, 1.2) + 0.45 * _periodic_noise(rng, size, 0.6)
    out.append(("dirt", dirt))
    asphalt = 0.35 + 0.3 * _periodic_noise(rng, size, 0.3) + 0.15 * _periodic_noise(rng, size, 1.4)
    out.append(("asphalt", asphalt))
    # Paving slabs: a grid of grout lines over per-slab brightness and fine noise.
    n = 4
    cell = size // n
    yy, xx = np.mgrid[0:size, 0:size]
    slab = rng.uniform(0.55, 0.85, size=(n, n))[yy // cell % n, xx // cell % n]
    grout = ((yy % cell) < 3) | ((xx % cell) < 3)
    tiles = np.where(grout, 0.3, slab) * (0.85 + 0.3 * _periodic_noise(rng, size, 0.8))
    out.append(("paving", tiles))
    sand = 0.6 + 0.25 * _periodic_noise(rng, size, 1.6) + 0.15 * _periodic_noise(rng, size, 0.2)
    out.append(("sand", sand))
    return [(name, np.clip(img * 255.0, 0, 255).astype(np.uint8)) for name, img in out]


def photo_texture(img: np.ndarray, size: int | None) -> np.ndarray:
    """A photograph as a grey ground texture ``(size, size) uint8`` (``size`` None: its own
    size), stretched to a common brightness so the scene's tint alone sets the colour."""
    img = np.asarray(img, dtype=np.float64)
    if img.ndim == 3:
        img = img[..., :3].mean(-1)
    if size is not None and (img.shape[0] != size or img.shape[1] != size):
        import cv2

        img = cv2.resize(img, (size, size), interpolation=cv2.INTER_AREA)
    img = (img - img.mean()) / (img.std() + 1e-6) * 0.18 + 0.55
    return np.clip(img * 255.0, 0, 255).astype(np.uint8)


#: The photographs of :func:`ground_textures` (the still frames' texture bank).
TRAINING_GROUND_PHOTOS: tuple[str, ...] = ("grass", "gravel", "brick")


def ground_textures(size: int = 256) -> list[tuple[str, np.ndarray]]:
    """Grey ground textures ``(name, (size, size) uint8)``: three photographs shipped with
    scikit-image (grass, gravel, brick) and four seamless procedural ones (dirt, asphalt, paving,
    sand). The scene's tint colours them."""
    out = []
    try:
        from skimage import data as skdata

        for name in TRAINING_GROUND_PHOTOS:
            out.append((name, photo_texture(getattr(skdata, name)(), size)))
    except ImportError:  # scikit-image is optional: the procedural ones still vary the ground
        pass
    return out + _procedural_textures(size)


# -- renderer -------------------------------------------------------------------------------------
class SceneRenderer:
    """Renders one sample's scene (ground, sky, distractors, body) from any pinhole camera.

    Example::

        r = SceneRenderer(224)
        r.set_environment(env)                      # EnvironmentSample
        r.set_body(vertices_world, faces, colors)   # (V, 3), (F, 3), (V, 3) uint8
        rgb = r.render(K_crop, R_cw, t_cw)          # (224, 224, 3) uint8

    Args:
        size: output side in pixels (square crops) or ``(W, H)``.
        textures: ground textures ``(name, (h, w) uint8)``; default :func:`ground_textures`.
        anti_aliasing: multi-sample anti-aliasing of edges (about 4x slower with Mesa's
            software rasteriser; the generator blurs slightly instead).
        mipmaps: trilinear, mip-mapped ground textures (about 2x slower in software; the
            default textures are small enough that plain bilinear filtering barely aliases).
        near, far: clipping planes in metres (the scene spans a few metres to the horizon).
    """

    def __init__(self, size: int | tuple[int, int] = 224, *,
                 textures: list[tuple[str, np.ndarray]] | None = None,
                 anti_aliasing: bool = False, mipmaps: bool = False,
                 near: float = 0.5, far: float = 400.0) -> None:
        self.image_size = (size, size) if isinstance(size, int) else (int(size[0]), int(size[1]))
        self.near, self.far = near, far
        self._pl = pv.Plotter(off_screen=True, window_size=list(self.image_size), lighting="none")
        if anti_aliasing:
            self._pl.enable_anti_aliasing("msaa")
        else:
            self._pl.disable_anti_aliasing()
        self._cam = self._pl.renderer.GetActiveCamera()

        # Ground: one large quad; the texture placement is set through its texture coordinates.
        L = _GROUND_HALF_SIZE
        pts = np.array([[-L, 0.0, -L], [L, 0.0, -L], [L, 0.0, L], [-L, 0.0, L]])
        self._ground = pv.PolyData.from_regular_faces(pts, np.array([[0, 3, 2, 1]]))
        self._ground.active_texture_coordinates = np.zeros((4, 2))
        self._ground.point_data["Normals"] = np.tile([0.0, 1.0, 0.0], (4, 1))
        self._ground.point_data.active_normals = self._ground.point_data["Normals"]
        self.texture_names = []
        self._textures = []
        for name, img in (textures if textures is not None else ground_textures()):
            rgb = np.repeat(np.asarray(img, dtype=np.uint8)[..., None], 3, axis=-1)
            tex = pv.Texture(rgb)
            tex.interpolate = True
            tex.mipmap = mipmaps
            tex.SetWrap(vtkTexture.MirroredRepeat)  # photos are not seamless; mirroring is
            self.texture_names.append(name)
            self._textures.append(tex)
        if not self._textures:
            raise ValueError("SceneRenderer needs at least one ground texture")
        # One ground actor per texture, only the sample's one visible: switching an actor's
        # texture re-uploads it (and rebuilds its mipmaps) on every change, toggling does not.
        self._ground_actors = []
        for i, tex in enumerate(self._textures):
            a = self._pl.add_mesh(self._ground, texture=tex, ambient=0.35, diffuse=0.75, specular=0.0,
                                  reset_camera=False, render=False, name=f"ground{i}")
            a.SetVisibility(i == 0)
            self._ground_actors.append(a)
        self._ground_actor = self._ground_actors[0]

        # Distractor pool: unit shapes, placed per sample through a user matrix.
        box = pv.Box(bounds=(-0.5, 0.5, 0.0, 1.0, -0.5, 0.5)).triangulate().compute_normals(
            split_vertices=True, auto_orient_normals=True)
        cyl = pv.Cylinder(center=(0.0, 0.5, 0.0), direction=(0.0, 1.0, 0.0), radius=0.5, height=1.0,
                          resolution=24, capping=True).triangulate().compute_normals(
            split_vertices=True, auto_orient_normals=True, feature_angle=45.0)
        self._distractors = {"box": [], "cylinder": []}
        for kind, mesh in (("box", box), ("cylinder", cyl)):
            for i in range(_MAX_DISTRACTORS):
                a = self._pl.add_mesh(mesh.copy(), color=(0.5, 0.5, 0.5), ambient=0.35, diffuse=0.7,
                                      specular=0.05, reset_camera=False, render=False,
                                      name=f"{kind}{i}")
                a.SetVisibility(False)
                self._distractors[kind].append(a)

        self._body = None
        self._body_actor = None
        self._body_faces = None

        # A sun (world-fixed directional light) and a weak fill that travels with the camera.
        self._sun = pv.Light(light_type="scene light")
        self._sun.positional = False
        self._fill = pv.Light(light_type="camera light", intensity=0.3)
        self._fill.positional = False
        self._pl.add_light(self._sun)
        self._pl.add_light(self._fill)
        self._ambient = 0.35
        self._pl.set_background((0.7, 0.8, 0.9))

    # -- scene content --------------------------------------------------------------------------
    def set_environment(self, env: EnvironmentSample) -> None:
        """Ground texture and placement, sky colour, light and distractor objects."""
        if not 0 <= env.ground_texture < len(self._textures):
            raise ValueError(f"ground_texture {env.ground_texture} not in the bank of {len(self._textures)}")
        self._ground_actor.SetVisibility(False)
        self._ground_actor = self._ground_actors[env.ground_texture]
        self._ground_actor.SetVisibility(True)
        # World (x, z) -> texture (u, v): scale by the tile size, rotate, offset.
        c, s = math.cos(env.ground_rotation), math.sin(env.ground_rotation)
        xz = self._ground.points[:, [0, 2]] / env.ground_tile
        uv = xz @ np.array([[c, -s], [s, c]]).T + np.asarray(env.ground_offset)
        self._ground.active_texture_coordinates[:] = uv
        self._ground.Modified()
        self._ground_actor.GetProperty().SetColor(*np.asarray(env.ground_tint, dtype=float))
        self._ground_actor.GetProperty().SetAmbient(env.ambient)
        self._ambient = env.ambient
        self._pl.set_background(tuple(float(v) for v in env.sky_color))
        d = np.asarray(env.light_dir, dtype=np.float64)
        d = d / np.linalg.norm(d)
        self._sun.position = tuple(-d)  # a directional light shines from position to focal point
        self._sun.focal_point = (0.0, 0.0, 0.0)
        self._sun.intensity = float(env.light_intensity)

        used = {"box": 0, "cylinder": 0}
        for dist in env.distractors[: 2 * _MAX_DISTRACTORS]:
            pool = self._distractors[dist.kind]
            if used[dist.kind] >= len(pool):
                continue
            a = pool[used[dist.kind]]
            used[dist.kind] += 1
            cy, sy = math.cos(dist.yaw), math.sin(dist.yaw)
            w, h, dd = (float(v) for v in dist.size)
            m = vtkMatrix4x4()
            rows = [[cy * w, 0.0, sy * dd, dist.position[0]], [0.0, h, 0.0, 0.0],
                    [-sy * w, 0.0, cy * dd, dist.position[1]], [0.0, 0.0, 0.0, 1.0]]
            for i, row in enumerate(rows):
                for j, v in enumerate(row):
                    m.SetElement(i, j, float(v))
            a.SetUserMatrix(m)
            a.GetProperty().SetColor(*(float(v) for v in dist.color))
            a.GetProperty().SetAmbient(env.ambient)
            a.SetVisibility(True)
        for kind, pool in self._distractors.items():
            for a in pool[used[kind]:]:
                a.SetVisibility(False)
        if self._body_actor is not None:
            self._body_actor.GetProperty().SetAmbient(env.ambient)

    def set_body(self, vertices: np.ndarray, faces: np.ndarray, colors: np.ndarray) -> None:
        """The person: world vertices ``(V, 3)``, faces ``(F, 3)``, vertex colours ``(V, 3)`` uint8."""
        v = np.asarray(vertices, dtype=np.float64)
        f = np.asarray(faces, dtype=np.int64)
        normals = vertex_normals(v, f)
        rgb = np.asarray(colors, dtype=np.uint8)
        same = (self._body is not None and self._body.n_points == len(v)
                and self._body_faces.shape == f.shape and np.array_equal(self._body_faces, f))
        if same:
            self._body.points[:] = v  # in place: only the changed buffers are re-uploaded
            self._body.point_data["Normals"][:] = normals
            self._body.point_data["rgb"][:] = rgb
            self._body.Modified()
        else:
            if self._body_actor is not None:
                self._pl.remove_actor(self._body_actor, render=False)
            poly = pv.PolyData.from_regular_faces(v.copy(), f)
            poly.point_data["Normals"] = normals
            poly.point_data.active_normals = poly.point_data["Normals"]
            poly.point_data["rgb"] = rgb.copy()
            self._body_actor = self._pl.add_mesh(poly, scalars="rgb", rgb=True, ambient=self._ambient,
                                                 diffuse=0.75, specular=0.08, specular_power=15.0,
                                                 reset_camera=False, render=False, name="body")
            self._body, self._body_faces = poly, f.copy()
        self._body_actor.SetVisibility(True)

    # -- camera and drawing ---------------------------------------------------------------------
    def _set_camera(self, K: np.ndarray, R_cw: np.ndarray, t_cw: np.ndarray) -> None:
        K = np.asarray(K, dtype=np.float64)
        if abs(K[0, 1]) > 1e-9 or abs(K[0, 0] - K[1, 1]) > 1e-6 * abs(K[1, 1]):
            # the world's meshes cannot be stretched per view as viz.render's camera-frame meshes are
            raise ValueError("SceneRenderer: needs square pixels (fx == fy) and no skew")
        set_vtk_camera(self._cam, vtk_camera(K, self.image_size, R_cw, t_cw), self.near, self.far)
        self._pl.renderer.camera_set = True  # keep pyvista from resetting the camera

    def render(self, K: np.ndarray, R_cw: np.ndarray, t_cw: np.ndarray, *,
               body_only: bool = False) -> np.ndarray:
        """Draw the scene seen by the camera ``K (3, 3)``, ``R_cw (3, 3)``, ``t_cw (3,)``.

        Args:
            body_only: draw just the body on black (a silhouette / mask render).
        Returns:
            ``(H, W, 3)`` uint8 RGB.
        """
        self._set_camera(K, R_cw, t_cw)
        hidden = []
        if body_only:
            for a in [self._ground_actor, *self._distractors["box"], *self._distractors["cylinder"]]:
                if a.GetVisibility():
                    hidden.append(a)
                    a.SetVisibility(False)
            background = self._pl.renderer.background_color
            self._pl.set_background((0.0, 0.0, 0.0))
        try:
            # render() before reading back: without it screenshot() returns the previous frame.
            self._pl.render()
            img = np.asarray(self._pl.screenshot(return_img=True), dtype=np.uint8)[..., :3].copy()
        finally:
            if body_only:
                for a in hidden:
                    a.SetVisibility(True)
                self._pl.set_background(background)
        return img

    def close(self) -> None:
        """Release the render window."""
        self._pl.close()

    def __enter__(self) -> SceneRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
