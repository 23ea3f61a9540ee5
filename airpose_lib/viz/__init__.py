"""Figures for the kit: one style, off-screen mesh renders, skeletons and keypoints.

``render`` pulls in pyvista/VTK (and selects the EGL window) on import; import it where needed
(``from airpose_lib.viz.render import OffscreenRenderer``) rather than through this package.
"""

from airpose_lib.viz.skeleton import (
    edges_from_parents,
    plot_keypoints_2d,
    plot_skeleton_3d,
)
from airpose_lib.viz.style import (
    METHOD_COLORS,
    SIDE_COLORS,
    VIEW_COLORS,
    method_color,
    save_figure,
    use_kit_style,
)

__all__ = [
    "edges_from_parents",
    "plot_keypoints_2d",
    "plot_skeleton_3d",
    "METHOD_COLORS",
    "SIDE_COLORS",
    "VIEW_COLORS",
    "method_color",
    "save_figure",
    "use_kit_style",
]
