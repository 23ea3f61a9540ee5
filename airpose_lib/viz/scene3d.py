"""A recording in 3D: ground, the person's mesh over time, both drones' cameras, each drone's
estimate of the person against the ground truth; interactive in JupyterLab, static elsewhere.

- :class:`RecordingScene` holds the world-frame geometry of a recording (built from a
  recording and one method's per-view estimates by
  :func:`airpose_lib.experiments.scene.recording_scene`: each view's camera-frame estimate is
  placed in the world with the ground-truth extrinsics, as the paper's Fig. 4 does).
- :func:`show_interactive` draws it with pyvista's ``trame`` Jupyter backend and an ipywidgets
  frame slider (JupyterLab, a live kernel).
- :func:`plot_static_frames` renders a few frames off-screen into a matplotlib figure: what
  papermill, CI and a kernel without trame show.
- :func:`interactive_available` says which of the two applies.

Colours follow the kit (``VIEW_COLORS``): the ground truth green, UAV1's camera and estimate red,
UAV2's blue. World frame: Y up, metres.
"""
from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from airpose_lib.progress import in_notebook

from .style import VIEW_COLORS

__all__ = ["RecordingScene", "camera_frustum", "interactive_available",
           "show_interactive", "plot_static_frames"]

#: Length (m) of the drawn camera frustums along the optical axis.
FRUSTUM_DEPTH_M = 1.5


@dataclass
class RecordingScene:
    """World-frame geometry of a recording, per frame.

    Attributes:
        frames: ``(F,)`` image numbers.
        time_s: ``(F,)`` seconds from the first frame.
        faces: ``(M, 3)`` triangles of the body meshes.
        ground_truth: ``(F, N, 3)`` vertices of the true body.
        estimates: ``(F, V, N, 3)`` vertices of each view's estimate, or None.
        method: name of the estimate (``"AirPose"``), or None.
        R_cw: ``(F, V, 3, 3)`` and ``t_cw`` ``(F, V, 3)``: world -> camera of each drone.
        K: ``(V, 3, 3)`` intrinsics; ``image_size``: ``(V, 2)`` width, height in pixels.
        person_path: ``(F, 3)`` the true pelvis in the world.
    """

    frames: np.ndarray
    time_s: np.ndarray
    faces: np.ndarray
    ground_truth: np.ndarray
    estimates: np.ndarray | None
    method: str | None
    R_cw: np.ndarray
    t_cw: np.ndarray
    K: np.ndarray
    image_size: np.ndarray
    person_path: np.ndarray

    @property
    def num_frames(self) -> int:
        return int(self.ground_truth.shape[0])

    @property
    def num_views(self) -> int:
        return int(self.R_cw.shape[1])

    def camera_centres(self) -> np.ndarray:
        """``(F, V, 3)`` drone camera centres, ``C = -R^T t``."""
        return -np.einsum("fvji,fvj->fvi", self.R_cw, self.t_cw)

    def to_world(self, points_cam: np.ndarray, view: int) -> np.ndarray:
        """``(F, N, 3)`` camera-``view`` points -> world, ``X_w = R^T (X_c - t)``."""
        return np.einsum("fji,fnj->fni", self.R_cw[:, view], points_cam - self.t_cw[:, view, None])


def camera_frustum(K: np.ndarray, image_size: Sequence[int], R_cw: np.ndarray, t_cw: np.ndarray,
                   depth: float = FRUSTUM_DEPTH_M) -> tuple[np.ndarray, np.ndarray]:
    """A pinhole camera as lines: ``points (5, 3)`` (centre, 4 image corners at ``depth``) in the
    world and ``lines (8, 2)`` index pairs."""
    W, H = float(image_size[0]), float(image_size[1])
    corners = np.array([[0, 0, 1], [W, 0, 1], [W, H, 1], [0, H, 1]], np.float64)
    rays = corners @ np.linalg.inv(K).T  # z = 1
    cam = np.vstack([np.zeros(3), depth * rays])
    world = (cam - t_cw) @ R_cw  # R^T (X - t) for row vectors
    lines = np.array([[0, 1], [0, 2], [0, 3], [0, 4], [1, 2], [2, 3], [3, 4], [4, 1]])
    return world, lines


def interactive_available() -> bool:
    """True in a live Jupyter kernel with pyvista's trame backend installed, unless the run is
    headless: papermill under ``airpose reproduce`` (``AIRPOSE_INTERACTIVE=0``) or CI (``CI``)."""
    if os.environ.get("AIRPOSE_INTERACTIVE", "1") == "0" or os.environ.get("CI"):
        return False
    if not in_notebook():
        return False
    try:
        import ipywidgets  # noqa: F401
        import trame  # noqa: F401
        import trame_vtk  # noqa: F401
    except ImportError:
        return False
    return True


# -- drawing ----------------------------------------------------------------------------------------
def _faces_pv(faces: np.ndarray) -> np.ndarray:
    return np.hstack([np.full((len(faces), 1), 3, np.int64), faces]).ravel()


def _lines_pv(lines: np.ndarray) -> np.ndarray:
    return np.hstack([np.full((len(lines), 1), 2, np.int64), lines]).ravel()


def _hex_rgb(color: str) -> tuple[float, float, float]:
    c = color.lstrip("#")
    return tuple(int(c[i:i + 2], 16) / 255 for i in (0, 2, 4))


def _ground_extent(scene: RecordingScene) -> tuple[np.ndarray, float]:
    pts = np.concatenate([scene.person_path, scene.camera_centres().reshape(-1, 3)])
    centre = 0.5 * (pts.min(0) + pts.max(0))
    size = float(max(np.ptp(pts[:, 0]), np.ptp(pts[:, 2]))) + 2.0
    return np.array([centre[0], 0.0, centre[2]]), size


def _populate(plotter, scene: RecordingScene, i: int) -> dict:
    """Add ground, path, meshes and cameras of frame ``i``; returns the updatable datasets."""
    import pyvista as pv

    centre, size = _ground_extent(scene)
    plotter.add_mesh(pv.Plane(center=centre, direction=(0, 1, 0), i_size=size, j_size=size,
                              i_resolution=int(size), j_resolution=int(size)),
                     color=(0.86, 0.86, 0.82), show_edges=True, edge_color=(0.7, 0.7, 0.66), opacity=1.0)
    plotter.add_mesh(pv.lines_from_points(scene.person_path), color=_hex_rgb(VIEW_COLORS["ground truth"]),
                     line_width=2)
    data = {"gt": pv.PolyData(scene.ground_truth[i].copy(), _faces_pv(scene.faces))}
    plotter.add_mesh(data["gt"], color=_hex_rgb(VIEW_COLORS["ground truth"]), smooth_shading=True)
    for v in range(scene.num_views):
        colour = _hex_rgb(VIEW_COLORS[f"camera {v + 1}"])
        pts, lines = camera_frustum(scene.K[v], scene.image_size[v], scene.R_cw[i, v], scene.t_cw[i, v])
        data[f"cam{v}"] = pv.PolyData(pts, lines=_lines_pv(lines))
        plotter.add_mesh(data[f"cam{v}"], color=colour, line_width=3)
        plotter.add_mesh(pv.lines_from_points(scene.camera_centres()[:, v]), color=colour, line_width=1,
                         opacity=0.5)
        if scene.estimates is not None:
            data[f"est{v}"] = pv.PolyData(scene.estimates[i, v].copy(), _faces_pv(scene.faces))
            plotter.add_mesh(data[f"est{v}"], color=colour, opacity=0.55, smooth_shading=True)
    return data


def _legend_entries(scene: RecordingScene) -> list[tuple[str, str]]:
    """(label, colour) of everything drawn."""
    entries = [("true body and path", VIEW_COLORS["ground truth"])]
    for v in range(scene.num_views):
        entries.append((f"UAV{v + 1} camera" + (f" and its {scene.method} estimate" if scene.estimates is not None
                                                 else ""), VIEW_COLORS[f"camera {v + 1}"]))
    return entries


def _update(data: dict, scene: RecordingScene, i: int) -> None:
    data["gt"].points = scene.ground_truth[i]
    for v in range(scene.num_views):
        data[f"cam{v}"].points = camera_frustum(scene.K[v], scene.image_size[v], scene.R_cw[i, v],
                                                scene.t_cw[i, v])[0]
        if scene.estimates is not None:
            data[f"est{v}"].points = scene.estimates[i, v]


def _set_view(plotter, scene: RecordingScene) -> None:
    """One fixed view of the whole recording: from the side of the line between the drones,
    raised 35 degrees, far enough to see both drones and the person (Y up)."""
    centres = scene.camera_centres()
    target = scene.person_path.mean(0)
    across = (centres[:, 0] - centres[:, 1]).mean(0)
    side = np.cross(across, [0.0, 1.0, 0.0])
    side[1] = 0.0
    side = side / (np.linalg.norm(side) + 1e-9)
    extent = float(np.ptp(np.concatenate([centres.reshape(-1, 3), scene.person_path]), axis=0).max())
    dist = 1.25 * extent + 4.0
    elev = np.deg2rad(35.0)
    eye = target + dist * (np.cos(elev) * side + np.array([0.0, np.sin(elev), 0.0]))
    plotter.camera_position = [tuple(eye), tuple(target), (0.0, 1.0, 0.0)]
    pts = np.concatenate([centres.reshape(-1, 3), scene.person_path, np.zeros((1, 3)) + target * [1, 0, 1]])
    lo, hi = pts.min(0) - 1.0, pts.max(0) + 1.0  # frame the drones and the person, not the whole ground
    plotter.reset_camera(bounds=(lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]))
    plotter.camera.zoom(1.7)  # reset_camera fits the bounding sphere: generous for a flat scene


def show_interactive(scene: RecordingScene, window_size: tuple[int, int] = (900, 600)):
    """A pyvista (trame) view with a frame slider, for JupyterLab; returns the ipywidgets box."""
    import ipywidgets as widgets
    import pyvista as pv

    from .render import DEFAULT_BACKGROUND  # noqa: F401 - EGL window: trame renders on the server, no X needed

    pv.set_jupyter_backend("trame")
    plotter = pv.Plotter(notebook=True, off_screen=True, window_size=list(window_size))
    data = _populate(plotter, scene, 0)
    _set_view(plotter, scene)
    # The legend is HTML under the view: VTK's legend box clipped its labels at this window size.
    legend = widgets.HTML(" &nbsp; ".join(f'<span style="color:{colour}">&#9632; {label}</span>'
                                          for label, colour in _legend_entries(scene)))
    slider = widgets.IntSlider(value=0, min=0, max=scene.num_frames - 1, step=1, description="frame",
                               continuous_update=False, layout=widgets.Layout(width="60%"))
    label = widgets.Label()

    def on_change(change=None) -> None:
        i = int(slider.value)
        _update(data, scene, i)
        label.value = f"image {int(scene.frames[i])}, t = {scene.time_s[i]:.2f} s"
        plotter.render()

    slider.observe(on_change, names="value")
    on_change()
    viewer = plotter.show(jupyter_backend="trame", return_viewer=True)
    return widgets.VBox([widgets.HBox([slider, label]), viewer, legend])


def plot_static_frames(scene: RecordingScene, n_frames: int = 3, image_size: tuple[int, int] = (640, 440),
                       title: str = ""):
    """Off-screen renders of ``n_frames`` frames spread over the recording, side by side."""
    import matplotlib.pyplot as plt
    import pyvista as pv

    from .render import DEFAULT_BACKGROUND  # noqa: F401 - selects the EGL window before VTK starts

    idx = np.linspace(0, scene.num_frames - 1, n_frames).round().astype(int)
    fig, axes = plt.subplots(1, n_frames, figsize=(3.6 * n_frames, 3.3), squeeze=False, layout="constrained")
    plotter = pv.Plotter(off_screen=True, window_size=list(image_size))
    try:
        data = _populate(plotter, scene, int(idx[0]))
        _set_view(plotter, scene)
        for ax, i in zip(axes[0], idx):
            _update(data, scene, int(i))
            ax.imshow(plotter.screenshot(return_img=True))
            ax.set_title(f"image {int(scene.frames[i])} ({scene.time_s[i]:.1f} s)")
            ax.set_axis_off()
    finally:
        plotter.close()
    from matplotlib.patches import Patch

    fig.legend(handles=[Patch(color=c, label=lab) for lab, c in _legend_entries(scene)],
               loc="outside lower center", ncol=scene.num_views + 1)
    if title:
        fig.suptitle(title)
    return fig

