"""Rendering of a simulated recording, frame by frame: the person's posed mesh in a fixed outdoor
scene (with ArUco markers on the ground when the recording's ``markers`` option is on), seen by
each drone's calibrated camera (non-square pixels, off-centre principal point), then, when the
recording's ``field`` option is on, the field camera pipeline (:mod:`.field`); the
``held_out`` option changes the clothing colours and the ground (:mod:`.held_out`)."""
from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from airpose_lib.body.forward import rest_body

from ..still.appearance import BodyPaint, sample_appearance
from ..still.scene import Distractor, EnvironmentSample
from .field import field_frame, field_rng, person_image_velocity
from .held_out import HELD_OUT_GROUND_PHOTOS, held_out_appearance, held_out_ground_photo
from .markers import MarkerLayout, marker_tile, tile_corners_world
from .simulate import SimulatedSequence, person_body_model

__all__ = ["SequenceRenderer", "render_sequence"]


def _scene_renderer_class():
    # Imported lazily: VTK/pyvista start-up is only paid when frames are rendered.
    from ..still.render import SceneRenderer

    class _Renderer(SceneRenderer):
        """SceneRenderer whose camera takes any pinhole K (fx != fy, off-centre principal point).

        The drones' calibrated cameras have non-square pixels, which a VTK view angle cannot
        express; the projection matrix is set explicitly instead (OpenGL clip space from K,
        the OpenCV pixel-centre convention and the near/far planes).
        """

        def _set_camera(self, K, R_cw, t_cw) -> None:
            W, H = self.image_size
            K = np.asarray(K, dtype=np.float64)
            if abs(K[0, 1]) > 1e-9:
                raise ValueError("skewed intrinsics (K[0, 1] != 0) are not supported")
            fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
            R = np.asarray(R_cw, dtype=np.float64)
            centre = -R.T @ np.asarray(t_cw, dtype=np.float64)
            cam = self._cam
            cam.SetPosition(*centre)
            cam.SetFocalPoint(*(centre + R[2]))
            cam.SetViewUp(*(-R[1]))
            n, f = self.near, self.far
            # View coordinates: x right, y up, camera looking down -z (VTK / OpenGL).
            # u = fx x/z + cx with OpenCV's x = x_v, y = -y_v, z = -z_v and NDC x = 2 (u + .5) / W - 1.
            P = np.array([
                [2 * fx / W, 0.0, 1.0 - 2.0 * (cx + 0.5) / W, 0.0],
                [0.0, 2 * fy / H, 2.0 * (cy + 0.5) / H - 1.0, 0.0],
                [0.0, 0.0, -(f + n) / (f - n), -2.0 * f * n / (f - n)],
                [0.0, 0.0, -1.0, 0.0],
            ])
            import vtk  # (lazily, as above)

            m = vtk.vtkMatrix4x4()
            for i in range(4):
                for j in range(4):
                    m.SetElement(i, j, float(P[i, j]))
            cam.SetExplicitProjectionTransformMatrix(m)
            cam.SetUseExplicitProjectionTransformMatrix(True)
            cam.SetClippingRange(n, f)
            self._pl.renderer.camera_set = True

        def add_markers(self, layout: MarkerLayout, ambient: float) -> None:
            """Printed ArUco markers lying on the ground: one textured quad each, lit as the
            ground (``ambient``). They float :data:`_MARKER_LIFT_M` above it so the depth test
            never mixes them with the ground quad; the markers' geometry keeps ``y = 0``."""
            import pyvista as pv  # (lazily, as above)

            corners = tile_corners_world(layout) + np.array([0.0, _MARKER_LIFT_M, 0.0])
            # pyvista puts image row 0 at the top (v = 1): TL, TR, BR, BL -> (0,1) (1,1) (1,0) (0,0)
            uv = np.array([[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]])
            for mid, quad in zip(layout.ids, corners):
                mesh = pv.PolyData.from_regular_faces(quad, np.array([[0, 3, 2, 1]]))  # normal up
                mesh.active_texture_coordinates = uv
                mesh.point_data["Normals"] = np.tile([0.0, 1.0, 0.0], (4, 1))
                mesh.point_data.active_normals = mesh.point_data["Normals"]
                tile = marker_tile(layout, mid, _MARKER_PX_PER_CELL)
                tex = pv.Texture(np.repeat(tile[..., None], 3, axis=-1))
                tex.interpolate = True
                tex.mipmap = True  # a few hundred texels shrunk to ~50 px: mip-mapped, not aliased
                self._pl.add_mesh(mesh, texture=tex, ambient=ambient, diffuse=0.75, specular=0.0,
                                  reset_camera=False, render=False, name=f"marker{mid}")

    return _Renderer


#: Height of the rendered markers above the ground quad, metres (depth-test separation only).
_MARKER_LIFT_M = 0.003
#: Texels per marker cell of the rendered markers' textures.
_MARKER_PX_PER_CELL = 16


class SequenceRenderer:
    """Renders a :class:`SimulatedSequence` frame by frame, one renderer per view size.

    Args:
        sim: the simulated sequence.
        body_model: the person's model (default: the open model of the person's gender).
        anti_aliasing: MSAA on edges (default: the sequence config's setting).
    """

    def __init__(self, sim: SimulatedSequence, body_model=None, anti_aliasing: bool | None = None) -> None:
        self.sim = sim
        person = sim.config.person_spec
        self.model = body_model if body_model is not None else person_body_model(person.gender)
        self.faces = np.asarray(self.model.faces, dtype=np.int64)
        held = sim.config.held_out
        look = sample_appearance(np.random.default_rng(person.appearance_seed))
        self.colors = BodyPaint.from_model(self.model).colors(
            held_out_appearance(look, held, person.appearance_seed))
        cls = _scene_renderer_class()
        if anti_aliasing is None:
            anti_aliasing = sim.config.anti_aliasing
        sizes = [tuple(int(x) for x in s) for s in sim.gt["image_size"]]
        # The held-out ground is the renderers' one texture; off, the default bank as before.
        ground = held.enabled and held.ground is not None
        textures = [(held.ground, held_out_ground_photo(held.ground))] if ground else None
        self._renderers = {s: cls(s, anti_aliasing=anti_aliasing, textures=textures) for s in dict.fromkeys(sizes)}
        self._size_of_view = sizes
        # One fixed environment for the whole recording: a grass field, a clear sky, the sun,
        # and a few objects beyond the orbit (they never come between a drone and the person).
        rng = np.random.default_rng([sim.config.seed, 31337])
        first = next(iter(self._renderers.values()))
        tex = first.texture_names.index("grass") if "grass" in first.texture_names else 0
        centre = np.asarray(sim.script.start_xz)
        dist = []
        for _ in range(8):
            a, r = rng.uniform(-np.pi, np.pi), rng.uniform(16.0, 35.0)
            kind = "box" if rng.random() < 0.5 else "cylinder"
            size = np.array([rng.uniform(0.5, 3.0), rng.uniform(0.5, 3.0), rng.uniform(0.5, 3.0)])
            if kind == "cylinder":
                size[2] = size[0]
            dist.append(Distractor(kind, centre + r * np.array([np.sin(a), np.cos(a)]), size,
                                   float(rng.uniform(0, np.pi)), rng.uniform(0.2, 0.8, 3)))
        elev, az = np.deg2rad(rng.uniform(35, 65)), rng.uniform(-np.pi, np.pi)
        self.environment = EnvironmentSample(
            ground_texture=tex, ground_tile=3.0, ground_rotation=float(rng.uniform(0, np.pi)),
            ground_offset=rng.uniform(0, 1, 2), ground_tint=np.array([0.55, 0.72, 0.40]),
            sky_color=np.array([0.68, 0.80, 0.92]),
            light_dir=-np.array([np.cos(elev) * np.sin(az), np.sin(elev), np.cos(elev) * np.cos(az)]),
            light_intensity=0.9, ambient=0.35, distractors=dist)
        if ground:  # after every draw above: the rest of the scene stays the clean one's
            self.environment.ground_texture = 0
            self.environment.ground_tile = HELD_OUT_GROUND_PHOTOS[held.ground] * textures[0][1].shape[0]
            self.environment.ground_tint = np.asarray(held.ground_tint, dtype=np.float64)
        for r in self._renderers.values():
            r.set_environment(self.environment)
            if sim.config.markers is not None:  # off: no actor added, the scene as before
                r.add_markers(sim.config.markers, self.environment.ambient)
        # The field pipeline's motion blur follows the person's image motion (the drone's and
        # the person's together); computed only when the option is on.
        self._field = sim.config.field
        # per video frame: the shutter is open for a share of one (a recording that keeps every
        # k-th video frame moves k times as far between its frames)
        self._velocity = (person_image_velocity(sim.gt["j2d"]) / sim.config.frame_step
                          if self._field.enabled else None)

    def render_frames(self, frames=None, chunk: int = 32) -> Iterator[tuple[int, list[np.ndarray]]]:
        """Yield ``(frame_index, [image (H, W, 3) uint8 RGB per view])`` in order (after the field
        pipeline when the recording's ``field`` option is on)."""
        gt = self.sim.gt
        F, V = self.sim.num_frames, self.sim.num_views
        frames = np.arange(F) if frames is None else np.asarray(list(frames), dtype=np.int64)
        betas = gt["betas"]
        for a in range(0, len(frames), chunk):
            idx = frames[a:a + chunk]
            theta = gt["theta_view"][idx].reshape(-1, 21, 3)
            v0, _ = rest_body(self.model, np.broadcast_to(betas, (len(theta), 10)), theta)
            v0 = v0.reshape(len(idx), V, -1, 3)
            for k, i in enumerate(idx):
                images = []
                for v in range(V):
                    R_wb, t_wb = gt["R_wb"][i, v], gt["t_wb"][i, v]
                    r = self._renderers[self._size_of_view[v]]
                    r.set_body(v0[k, v] @ R_wb.T + t_wb, self.faces, self.colors)
                    img = r.render(gt["K"][v], gt["R_cw"][i, v], gt["t_cw"][i, v])
                    if self._field.enabled:  # off: the rendered frame itself, byte for byte
                        img = field_frame(img, self._field, field_rng(self.sim.config.seed, i, v),
                                          K=gt["K"][v], velocity_px=self._velocity[i, v])
                    images.append(img)
                yield int(i), images

    def close(self) -> None:
        for r in self._renderers.values():
            r.close()

    def __enter__(self) -> SequenceRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def render_sequence(sim: SimulatedSequence, frames=None, body_model=None) -> list[list[np.ndarray]]:
    """All (or the given) frames in memory: ``[[image per view] per frame]``; for previews."""
    with SequenceRenderer(sim, body_model) as r:
        return [imgs for _, imgs in r.render_frames(frames)]

