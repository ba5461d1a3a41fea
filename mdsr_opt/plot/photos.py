"""The photograph overlay: a simulated mesh drawn over a photograph with its contour metrics."""

from __future__ import annotations

import numpy as np
from matplotlib.collections import PolyCollection

from .common import axes_or_new, hide_ticks, legend_below
from .style import CONTOUR, CONTOUR_EDGE, DISTANCE_CMAP, add_colorbar, axis_label

__all__ = ['plot_overlay']


def plot_overlay(image, mesh, x, comparison, ax=None, synthetic=False, title=None, mesh_color="#1f77b4",
                 contour_color=CONTOUR, cmap=DISTANCE_CMAP, ticks=True):
    """Draw the simulated mesh over the photograph it was compared with (``mdsr_opt.photos``).

    Parameters
    ----------
    image : (H, W) or (H, W, 3) uint8 array (RGB), e.g. from ``evaluate.load_image``.
    mesh, x : the mesh and its simulated state (simulation coordinates).
    comparison : ``ContourComparison``; its ``transform`` maps ``x`` into the image's pixels.
    synthetic : mark the figure as made from a synthetic (rendered) photograph.
    ticks : pixel coordinates on the photograph's axes (the colour bar keeps its own); a run's figures
        leave them out (the distances are in the colour bar and the title; ticks were a third of the
        figure's drawing time).

    The mesh is drawn as triangle edges, the measured contour as a bright line on a black rim (visible on
    grey, white and black) and the simulated boundary nodes coloured by their distance to it (pixels), with
    a colour bar the height of the photograph and the legend below it.

    Example
    -------
    >>> from mdsr_opt import Mesh
    >>> from mdsr_opt.photos.camera import render_photo; from mdsr_opt.photos.compare import evaluate_image
    >>> mesh = Mesh.rectangle(3.0, 1.0, 6, 2)
    >>> photo = render_photo(mesh, image_size=(300, 200))
    >>> fig = plot_overlay(photo.image, mesh, mesh.points, evaluate_image(photo.image, mesh), synthetic=True)
    >>> fig.axes[0].get_title().endswith("(SYNTHETIC photograph)")
    True
    """
    fig, ax = axes_or_new(ax, figsize=(6, 6 * image.shape[0] / max(image.shape[1], 1)))
    img = np.asarray(image)
    ax.imshow(img, cmap="gray" if img.ndim == 2 else None, origin="upper", interpolation="nearest")
    P = comparison.to_pixels(np.asarray(x))
    ax.add_collection(PolyCollection(P[mesh.triangles], facecolors="none", edgecolors=mesh_color,
                                     linewidths=0.4, alpha=0.9))
    m = np.vstack([comparison.measured_px, comparison.measured_px[:1]])
    from matplotlib import patheffects

    rim = [patheffects.Stroke(linewidth=3.2, foreground=CONTOUR_EDGE), patheffects.Normal()]
    ax.plot(m[:, 0], m[:, 1], "-", color=contour_color, lw=1.6, label="measured contour", path_effects=rim)
    s = comparison.simulated_px
    sc = ax.scatter(s[:, 0], s[:, 1], c=comparison.distances_px, cmap=cmap, s=10, zorder=3,
                    label="simulated boundary nodes")
    add_colorbar(ax, sc, axis_label("distance to contour", "px"))
    ax.set_xlim(-0.5, img.shape[1] - 0.5)
    ax.set_ylim(img.shape[0] - 0.5, -0.5)
    ax.set_aspect("equal")
    ax.set_xlabel(axis_label("image x", "px"), fontsize=8)
    ax.set_ylabel(axis_label("image y", "px"), fontsize=8)
    legend_below(ax, ncol=2, drop=0.5 if ticks else 0.3)
    head = f"{title}: " if title else ""
    text = f"{head}outline d = {comparison.mean_px:.2f} px, sd = {comparison.std_px:.2f} px"  # the loop drawn
    if synthetic:
        text += " (SYNTHETIC photograph)"
    ax.set_title(text, fontsize=9, y=1.0)  # placed, not searched (see plot_scene): pixels have no offset text
    if not ticks:
        hide_ticks(ax)
    return fig
