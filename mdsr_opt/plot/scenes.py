"""Figures of scenes: regions, targets, and animations as GIFs."""

from __future__ import annotations

import os
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import to_rgba
from matplotlib.figure import Figure
from matplotlib.font_manager import findfont
from matplotlib import patheffects
from matplotlib.patches import PathPatch
import numpy as np
from matplotlib.collections import LineCollection
from PIL import Image, ImageDraw, ImageFont

from ..body.io import atomic_path
from .common import (LEGEND_OUTSIDE, axes_or_new, coordinate_axes, draw_obstacles, legend_below, mesh_paths, plot_mesh,
                     plot_muscles)
from .style import BODY, LIGHT, REGION_COLORS, REST_LINE, energy_label, layout_colors, muscle_label

__all__ = ['plot_scene', 'plot_target', 'save_animation']


# --- problem library and scenes (issue 6) ---
def plot_scene(mesh, regions=None, ax=None, title=None, markersize=4, units=None):
    """The rest mesh with its named node regions (``{name: node indices}``) marked in colour; axes in
    ``units`` (default ``"body units"``).

    Example
    -------
    >>> from mdsr_opt import Mesh
    >>> mesh = Mesh.rectangle(2.0, 1.0, 4, 2)
    >>> fig = plot_scene(mesh, {"left": [0, 5, 10]}, title="strip")
    >>> fig.axes[0].get_legend_handles_labels()[1]
    ['left']
    """
    fig, ax = axes_or_new(ax, figsize=(7, 4.5))
    plot_mesh(mesh, None, ax=ax, color=LIGHT["face"], edgecolor=LIGHT["edge"])
    for i, (name, idx) in enumerate((regions or {}).items()):
        p = mesh.points[np.asarray(idx, dtype=int)]
        ax.plot(p[:, 0], p[:, 1], "s", ms=markersize, color=REGION_COLORS[i % len(REGION_COLORS)], label=name)
    if regions:
        ax.legend(fontsize=7, **LEGEND_OUTSIDE)
    # y=1.0: the title's place given, not searched (the search lays the y axis out once more before the draw,
    # for an offset text a mesh's coordinates never have)
    ax.set_title(title or f"rest mesh: {mesh.n_nodes} nodes, {mesh.n_triangles} triangles", fontsize=9, y=1.0)
    coordinate_axes(ax, units)
    return fig


def plot_target(mesh, target, anchors=(), drag_nodes=(), drag_positions=None, muscles=(), values=None,
                ax=None, title=None, colorbar_label=None, units=None,
                ticks=True, obstacles=()):
    """A target shape over the rest outline: anchors (black), drag nodes (red, with their paths from rest).

    Parameters
    ----------
    mesh : the rest mesh; target : (n, 2) target positions.
    anchors, drag_nodes : node indices; drag_positions : (d, 2) where the drags go (default: ``target``).
    muscles : muscles to draw over the target (e.g. an internal-driving case's).
    values : per-triangle values to colour the target by (e.g. strain energy per area), with a colour bar
        the height of the axes, labelled ``colorbar_label`` (default :func:`~mdsr_opt.plot.style.energy_label`
        without a stress unit: units of ``E*t``).
    units : the coordinates' length unit, on the axes (default ``"body units"``); ticks : coordinate ticks
        (``False``: three a side).
    obstacles : rigid obstacles the target touches, drawn where they are (:func:`~mdsr_opt.plot.common.draw_obstacles`).
    """
    fig, ax = axes_or_new(ax, figsize=(7, 4.5))
    x = np.asarray(target, dtype=float)
    for loop in mesh.boundary_loops:
        p = mesh.points[np.append(loop, loop[0])]
        ax.plot(p[:, 0], p[:, 1], "-", color=REST_LINE, lw=0.8)
    label = energy_label(None, units) if colorbar_label is None else colorbar_label  # values: an energy map
    plot_mesh(mesh, x, ax=ax, values=values, colorbar_label=label if values is not None else None,
              alpha=0.9)
    anchors = np.asarray(anchors, dtype=int)
    dn = np.asarray(drag_nodes, dtype=int)
    if len(anchors):
        ax.plot(x[anchors, 0], x[anchors, 1], "s", color="k", ms=3, label="anchors")
    if len(dn):
        dp = x[dn] if drag_positions is None else np.asarray(drag_positions, dtype=float)
        segs = np.stack([mesh.points[dn], dp], axis=1)
        ax.add_collection(LineCollection(segs, colors="#d62728", linewidths=0.5, alpha=0.5))
        ax.plot(dp[:, 0], dp[:, 1], "o", color="#d62728", ms=3, label="drag points")
    if len(muscles):
        plot_muscles(x, muscles, ax=ax)
    ax.autoscale_view()
    if len(obstacles):
        draw_obstacles(ax, obstacles)
    if len(anchors) or len(dn) or len(muscles) or len(obstacles):
        # beside the axes unless the colour bar is there (it would cover the legend): then below them
        if values is None:
            ax.legend(fontsize=7, **LEGEND_OUTSIDE)
        else:
            legend_below(ax)
    coordinate_axes(ax, units, ticks)
    if title:
        ax.set_title(title, fontsize=9, y=1.0)  # placed, not searched: see plot_scene
    return fig


def gif_frame(rgb: np.ndarray):
    """An (h, w, 3) uint8 frame as a 256-colour PIL image for a GIF: Pillow's fast octree quantiser (a tenth
    of the time of its default median cut) and one Lloyd step that moves every palette colour to the mean of
    the pixels it stands for (so the white background and the flat fills keep their exact colours)."""
    rgb = np.ascontiguousarray(rgb)
    q = Image.fromarray(rgb).quantize(256, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE)
    idx = np.asarray(q).ravel()
    src = rgb.reshape(-1, 3)
    n = np.bincount(idx, minlength=256)
    used = n > 0
    pal = np.zeros((256, 3))
    old = np.asarray(q.getpalette() or [], dtype=float)[:768]
    pal.ravel()[:len(old)] = old
    for c in range(3):
        pal[used, c] = np.bincount(idx, weights=src[:, c], minlength=256)[used] / n[used]
    q.putpalette(np.clip(np.round(pal), 0, 255).astype(np.uint8).ravel().tolist())
    return q


def gif_palette(frames, n_sample: int = 6):
    """One 256-colour palette for all the (h, w, 3) uint8 ``frames`` of an animation, as a ``P`` image for
    ``Image.quantize(palette=...)``: :func:`gif_frame`'s palette of up to ``n_sample`` frames spread over the
    animation, stacked. Mapping a frame to a fixed palette costs a twentieth of quantising it, and one
    palette for every frame keeps flat colours from flickering between frames."""
    frames = list(frames)
    if not frames:
        raise ValueError("gif_palette needs at least one frame")
    pick = np.unique(np.linspace(0, len(frames) - 1, min(n_sample, len(frames))).round().astype(int))
    # every second pixel of every second row of a frame (a quarter of the pixels: a quarter of the time);
    # the first frame whole, so each of its colours (the flat fills, the background) is a palette colour
    pixels = [np.asarray(frames[pick[0]]).reshape(-1, 3)] + [np.asarray(frames[k])[::2, ::2].reshape(-1, 3)
                                                             for k in pick[1:]]
    return gif_frame(np.concatenate(pixels)[:, None, :])  # one column of pixels: the palette ignores layout


def wrap_title(text: str, width: int) -> str:
    """``text`` on as few lines of at most ``width`` characters as its ``", "``-separated parts allow."""
    if len(text) <= width:
        return text
    lines, line = [], ""
    for part in text.split(", "):
        piece = part if not line else f"{line}, {part}"
        if len(piece) > width and line:
            lines.append(line + ",")
            line = part
        else:
            line = piece
    return "\n".join(lines + [line])


def save_animation(mesh, states, path, muscles=(), activations=None, titles=None, fps=8.0, rest=True,
                   figsize=(8.0, 5.0), dpi=110, units=None) -> str:
    """Write a sequence of states as an animated GIF (looping, Pillow), atomically.

    An existing file of that name is replaced, without a warning (``mdsr run`` refuses to without
    ``--overwrite``).

    Parameters
    ----------
    mesh : the rest mesh; states : sequence of (n, 2) states, one per frame.
    muscles : muscles drawn over every frame, named and coloured as in every figure (a legend beside the
        drawing; :mod:`mdsr_opt.plot.style`); activations : (frames, m) values in [0, 1] that set each
        muscle's line width (e.g. contraction / a_max): an idle muscle stays drawn, thin and opaque.
    titles : one title per frame; fps : frames per second.
    rest : draw the rest outline in grey behind every frame.
    figsize, dpi : the frame size in inches and its resolution (pixels = figsize * dpi; by default
        880 x 550).
    units : the coordinates' length unit, on the axes (default ``"body units"``).

    Returns the path. The GIF is written to a temporary file in the same folder and renamed.

    Example
    -------
    >>> import os, tempfile
    >>> from mdsr_opt import Mesh
    >>> mesh = Mesh.rectangle(2.0, 1.0, 4, 2)
    >>> with tempfile.TemporaryDirectory() as d:
    ...     p = save_animation(mesh, [mesh.points, mesh.points * 1.1], os.path.join(d, "a.gif"))
    ...     os.path.getsize(p) > 0
    True
    """
    states = [np.asarray(s, dtype=float) for s in states]
    if not states:
        raise ValueError("an animation needs at least one state")
    for i, s in enumerate(states):
        if s.shape != (mesh.n_nodes, 2):
            raise ValueError(f"states[{i}] must have shape ({mesh.n_nodes}, 2), got {s.shape}")
    muscles = list(muscles)
    act = None if activations is None else np.asarray(activations, dtype=float).reshape(len(states), -1)
    if titles is not None and len(titles) != len(states):
        raise ValueError(f"titles: {len(titles)} title(s) for {len(states)} frame(s)")
    allp = np.vstack(states + ([mesh.points] if rest else []))
    lo, hi = allp.min(0), allp.max(0)
    pad = 0.05 * float((hi - lo).max())
    # an Agg figure of its own (no pyplot: nothing to close, whatever the interactive backend)
    fig = Figure(figsize=figsize, dpi=dpi)
    canvas = FigureCanvasAgg(fig)
    # room on the right for the muscles' legend, as wide as its longest name (9 pt text beside a 3 pt line)
    longest = max((len(muscle_label(m, i)) for i, m in enumerate(muscles)), default=0)
    right = min(0.84, 0.97 - (34.0 + 5.6 * longest) / (72.0 * figsize[0])) if muscles else 0.97
    fig.subplots_adjust(left=0.09, right=max(right, 0.6), bottom=0.12, top=0.88)
    ax = fig.subplots()
    # Blitting: the axes, ticks and labels are drawn once; per frame only the moving artists are drawn over
    # a copy of that background (a full draw per frame, twice through FuncAnimation + PillowWriter, made
    # the GIFs the slowest part of a run). The moving artists are drawn in the order a full draw uses.
    moving = []
    if rest:
        for loop in mesh.boundary_loops:
            p = mesh.points[np.append(loop, loop[0])]
            moving += ax.plot(p[:, 0], p[:, 1], "-", color=REST_LINE, lw=0.9)
    fill_path, edge_path = mesh_paths(mesh)
    # the body: fill and edges as two compound paths (see common.mesh_paths); the edges, drawn once each rather
    # than twice, are 0.28 pt wide instead of 0.25 to keep the mesh's tone
    body = PathPatch(fill_path(states[0]), facecolor=BODY["face"], edgecolor="none")
    edges = PathPatch(edge_path(states[0]), facecolor="none", edgecolor=BODY["edge"], linewidth=0.28)
    for p in (body, edges):
        ax.add_artist(p)  # not add_patch: its data-limit update walks every segment; the limits are set below
    moving += [body, edges]
    colors = layout_colors(muscles)
    lines = [ax.plot([], [], "-", color=c, solid_capstyle="round", zorder=3)[0] for c in colors]
    moving += lines
    if muscles:  # the legend is drawn once, with the background: proxies, not the moving lines
        from matplotlib.lines import Line2D

        ax.legend([Line2D([], [], color=c, lw=3) for c in colors],
                  [muscle_label(m, i) for i, m in enumerate(muscles)], fontsize=9, **LEGEND_OUTSIDE)
    paths = [list(m.nodes) for m in muscles]
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    coordinate_axes(ax, units)
    ax.tick_params(labelsize=8)
    names = titles if titles is not None else [f"frame {k + 1}/{len(states)}" for k in range(len(states))]
    # a title longer than the frame is wide (many muscles, long names) goes on two lines, broken at a comma
    names = [wrap_title(t, int(72.0 * figsize[0] / 7.5)) for t in names]
    title = ax.set_title(names[0], fontsize=12)
    title.set_animated(True)  # placed by matplotlib, drawn per frame by Pillow (see below)
    for a in moving:
        a.set_animated(True)
    moving.sort(key=lambda a: a.get_zorder())  # stable, as Axes.draw sorts its children
    canvas.draw()
    background = canvas.copy_from_bbox(fig.bbox)
    # The titles: matplotlib's text drawing (laying out and rendering every glyph, twice per frame) was a
    # quarter of a frame's time; Pillow draws them with the same font file and size, centred on the same
    # bottom edge as matplotlib placed the first frame's title (above the axes, clear of them also when a
    # title wraps to two lines: the lines grow upwards), in a tenth of that.
    size_px = title.get_fontsize() * fig.dpi / 72.0
    font = ImageFont.truetype(findfont(title.get_fontproperties()), size_px)
    tx, _ = title.get_transform().transform(title.get_position())
    bottom = title.get_window_extent(canvas.get_renderer()).y0
    anchor = (float(tx), canvas.get_width_height()[1] - float(bottom) - 1.0)  # Agg sets text 1 px higher
    spacing = 0.2 * size_px  # matplotlib's line spacing (1.2)
    ink = tuple(round(255 * c) for c in to_rgba(title.get_color())[:3])

    drawn: dict = {}  # an animation goes out and back: a frame drawn before (same state, same widths) is copied

    def frame(k):
        key = states[k].tobytes() + (b"" if act is None else act[k].tobytes())
        if key not in drawn:
            drawn[key] = draw(k)
        im = drawn[key].copy()
        title.set_text(names[k])  # the figure's own title follows the frame (for anyone drawing it)
        ImageDraw.Draw(im).multiline_text(anchor, names[k], font=font, fill=ink, anchor="md", align="center",
                                          spacing=spacing)
        return im

    def draw(k):  # the frame without its title
        x = states[k]
        body.set_path(fill_path(x))
        edges.set_path(edge_path(x))
        for i, (line, p) in enumerate(zip(lines, paths)):
            a = 1.0 if act is None else float(np.clip(act[k, i], 0.0, 1.0))
            line.set_data(x[p, 0], x[p, 1])
            w = 2.2 + 2.6 * a  # idle: thinner, but in full colour on a white rim, clear on the body's blue
            line.set_linewidth(w)
            line.set_path_effects([patheffects.Stroke(linewidth=w + 1.6, foreground="white"), patheffects.Normal()])
        canvas.restore_region(background)
        for a in moving:
            ax.draw_artist(a)
        buf = canvas.buffer_rgba()
        return Image.frombuffer("RGBA", (buf.shape[1], buf.shape[0]), buf, "raw", "RGBA", 0, 1).convert("RGB")

    rgb = [frame(k) for k in range(len(states))]  # RGB copies: the canvas is drawn over for the next frame
    palette = gif_palette([np.asarray(f) for f in rgb])
    images = [f.quantize(palette=palette, dither=Image.Dither.NONE) for f in rgb]
    path = os.fspath(path)
    with atomic_path(path, suffix=".gif") as tmp:
        images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:], duration=int(1000 / fps),
                       loop=0)
    return path
