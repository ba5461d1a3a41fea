"""Figure basics shared by every figure: axes, meshes, edges, muscles, atomic saving."""

from __future__ import annotations

import os
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import to_rgba
from matplotlib.layout_engine import PlaceHolderLayoutEngine
from matplotlib.path import Path
import matplotlib as mpl
import matplotlib.pyplot as plt
from matplotlib.transforms import Bbox
import numpy as np
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.patches import PathPatch

from ..body.io import atomic_path
from .style import BODY, ENERGY_CMAP, add_colorbar, figure_paths, label_coordinates, layout_colors, muscle_label

__all__ = ['plot_mesh', 'plot_edges', 'plot_muscles', 'save_figure', 'close_figure', 'hide_ticks',
           'coordinate_axes', 'mesh_paths', 'plain_log_ticks']


# Legends sit outside the axes, to the right (saved with bbox_inches="tight"): never over the drawing, and no
# loc="best" search, which re-runs on every draw and was 11-32 % of a scene's figure time.
LEGEND_OUTSIDE = {"loc": "upper left", "bbox_to_anchor": (1.01, 1.0), "borderaxespad": 0.0}


def legend_below(ax, ncol: int = 4, fontsize: float = 7, drop: float = 0.5):
    """A legend centred under ``ax``, ``drop`` inches below its bottom edge: clear of the x tick labels and
    axis label, of a colour bar beside the axes and of the drawing (also with an equal aspect ratio, where a
    place given in axes fractions moves with the drawn box)."""
    from matplotlib.transforms import ScaledTranslation

    below = ax.transAxes + ScaledTranslation(0.0, -drop, ax.figure.dpi_scale_trans)
    return ax.legend(fontsize=fontsize, loc="upper center", bbox_to_anchor=(0.5, 0.0), bbox_transform=below,
                     ncol=ncol, borderaxespad=0.0)


def plain_log_ticks(ax, which: str = "both") -> None:
    """Tick labels of ``ax``'s log axes (``"x"``, ``"y"`` or ``"both"``) as plain numbers (``0.06``, ``300``,
    not ``6 x 10^-2``, ``3 x 10^2``), on the ticks matplotlib would label (few minor ones: they never
    crowd)."""
    from matplotlib.ticker import LogFormatterSciNotation

    class Plain(LogFormatterSciNotation):
        def __call__(self, x, pos=None):
            return f"{x:.3g}" if super().__call__(x, pos) else ""

    for axis in ((ax.xaxis, ax.yaxis) if which == "both" else (ax.xaxis,) if which == "x" else (ax.yaxis,)):
        if axis.get_scale() == "log":
            axis.set_major_formatter(Plain(labelOnlyBase=False))
            axis.set_minor_formatter(Plain(labelOnlyBase=False))


def axes_or_new(ax=None, figsize=(6, 4)):
    if ax is None:
        fig, ax = plt.subplots(figsize=figsize)
    return ax.figure, ax


def panel_axes(fig, nrow, ncol, figsize):
    """``(fig, axes)`` with an (nrow, ncol) grid: in ``fig`` when given, else in a new figure."""
    if fig is None:
        return plt.subplots(nrow, ncol, figsize=figsize, squeeze=False)
    return fig, fig.subplots(nrow, ncol, squeeze=False)


def body_panels(extents, *, height: float = 3.6, max_width: float = 5.0, min_width: float = 2.2,
                max_height: float = 5.5):
    """A new figure with one axes per body drawing, side by side, each as wide as its body's aspect ratio asks.

    Fixed figure sizes leave an equal-aspect drawing of a tall, narrow body in the middle of a wide axes box
    (two panels then sit at the figure's far edges with a blank gap between them); here each box has its
    drawing's width-to-height ratio, so the drawings fill their boxes and the panels sit a label's width apart.

    Parameters
    ----------
    extents : sequence of (width, height)
        Each panel's data extent (e.g. ``np.ptp(points, axis=0)``), in one length unit.
    height : float
        The panels' height in inches, before they are fitted: lowered so that the widest is at most
        ``max_width`` inches, raised (up to ``max_height``) so that the narrowest is at least ``min_width``
        (room for its title and ticks).

    Returns
    -------
    (Figure, list of Axes)
    """
    ratios = [max(float(w), 1e-12) / max(float(h), 1e-12) for w, h in extents]
    h = min(height, max_width / max(ratios))  # the widest fits
    if min(ratios) * h < min_width:  # the narrowest gets room for its title, up to max_height
        h = min(min_width / min(ratios), max_height)
    h = max(h, 1.0)
    widths = [min(h * r, max_width) for r in ratios]
    left, gap, right, bottom, top = 0.75, 1.0, 0.2, 0.6, 0.5  # inches: tick labels, axis labels, titles
    W, H = left + sum(widths) + gap * (len(widths) - 1) + right, bottom + h + top
    fig = plt.figure(figsize=(W, H))
    axes, x = [], left
    for w in widths:
        axes.append(fig.add_axes((x / W, bottom / H, w / W, h / H)))
        x += w + gap
    return fig, axes


def hide_ticks(*axes) -> None:
    """No tick marks or tick labels on ``axes`` (the frame stays): for drawings whose coordinates another
    figure of the same run already gives. Ticks are most of the cost of drawing an axes (each tick is a
    handful of artists, each label a laid-out text)."""
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])


def coordinate_axes(ax, units=None, ticks=True) -> None:
    """Label a drawing's axes ``x (unit)``, ``y (unit)`` (:func:`.style.label_coordinates`); with ``ticks``
    False, three ticks a side instead of matplotlib's many (a run's figures: ticks are most of the cost of
    drawing an axes, and the target figure of the same case has them all)."""
    from matplotlib.ticker import MaxNLocator

    label_coordinates(ax, units)
    ax.tick_params(labelsize=8)
    if not ticks:
        ax.xaxis.set_major_locator(MaxNLocator(3))
        ax.yaxis.set_major_locator(MaxNLocator(3))


#: how rigid obstacles are drawn: grey, hatched
OBSTACLE = {"face": "#d9d9d9", "edge": "#4d4d4d", "hatch": "///"}


def draw_obstacles(ax, obstacles) -> None:
    """Rigid obstacles (:class:`~mdsr_opt.Disk`, :class:`~mdsr_opt.HalfPlane`, :class:`~mdsr_opt.Obstacle`)
    drawn grey and hatched under the body, the first labelled "obstacle". A disk or polygon widens the view to
    hold it; a half-plane fills its solid side across the view as it is (call this last)."""
    from matplotlib.patches import Circle, Polygon

    style = {"facecolor": OBSTACLE["face"], "edgecolor": OBSTACLE["edge"], "hatch": OBSTACLE["hatch"],
             "lw": 0.8, "zorder": 0.5}
    obstacles = list(obstacles or ())
    label = ["obstacle"]  # the first drawn takes it

    def add(patch):
        patch.set(label=label.pop() if label else None, **style)
        ax.add_patch(patch)

    for ob in (o for o in obstacles if not hasattr(o, "normal")):
        add(Circle(tuple(np.asarray(ob.center, float)), float(ob.radius)) if hasattr(ob, "radius")
            else Polygon(np.asarray(ob.polygon, float), closed=True))
    ax.autoscale_view()  # the view widened to hold the disks and polygons
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    big = 4.0 * (abs(x1 - x0) + abs(y1 - y0) + 1.0)
    for ob in (o for o in obstacles if hasattr(o, "normal")):  # the side the normal points away from is solid
        p, n = np.asarray(ob.point, float), np.asarray(ob.normal, float)
        t = np.array([-n[1], n[0]])
        add(Polygon([p + big * t, p - big * t, p - big * t - big * n, p + big * t - big * n], closed=True))
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)


def mesh_paths(mesh):
    """(fill, edges) path builders for ``mesh`` in a state ``x``: the triangles as one compound path (drawn
    in one pass, no seams) and each mesh edge once as a second one. A PolyCollection fills and strokes
    every triangle on its own (each inner edge twice): twice the drawing time of these two paths."""
    tri, edges = np.asarray(mesh.triangles), np.asarray(mesh.edges)
    tri_codes = np.tile(np.array([Path.MOVETO, Path.LINETO, Path.LINETO, Path.CLOSEPOLY], dtype=Path.code_type),
                        len(tri))
    edge_codes = np.tile(np.array([Path.MOVETO, Path.LINETO], dtype=Path.code_type), len(edges))
    closed = np.concatenate([tri, tri[:, :1]], axis=1)

    def fill(x):
        return Path(x[closed].reshape(-1, 2), tri_codes)

    def edge(x):
        return Path(x[edges].reshape(-1, 2), edge_codes)

    return fill, edge


def plot_mesh(mesh, x=None, ax=None, color=BODY["face"], edgecolor=BODY["edge"], alpha=1.0, values=None,
              cmap=ENERGY_CMAP, label=None, nodes=None, node_color="k", title=None, colorbar_label=None,
              vmin=None, vmax=None):
    """Draw ``mesh`` in configuration ``x`` (default: rest). ``values`` colours the triangles (per triangle),
    on the scale ``vmin``..``vmax`` when given (panels to compare share one: :func:`.style.shared_limits`),
    with a colour bar the height of the axes (:func:`.style.add_colorbar`)."""
    fig, ax = axes_or_new(ax)
    x = mesh.points if x is None else np.asarray(x)
    if values is not None:  # a colour per triangle: a collection
        pc = PolyCollection(x[mesh.triangles], facecolors=color, edgecolors=edgecolor, linewidths=0.3, alpha=alpha,
                            label=label)
        pc.set_array(np.asarray(values))
        pc.set_cmap(cmap)
        if vmin is not None or vmax is not None:
            pc.set_clim(vmin, vmax)
        add_colorbar(ax, pc, colorbar_label)
        ax.add_collection(pc)
    else:  # one colour: two compound paths (mesh_paths), half the drawing time of a collection
        fill, edges = mesh_paths(mesh)
        ax.add_artist(PathPatch(fill(x), facecolor=color, edgecolor="none", alpha=alpha, label=label))
        if edgecolor is not None and not (isinstance(edgecolor, str) and edgecolor.lower() == "none"):
            # each edge drawn once (a collection strokes inner edges twice): 0.34 pt keeps the tone of 0.3
            ax.add_artist(PathPatch(edges(x), facecolor="none", edgecolor=edgecolor, linewidth=0.34, alpha=alpha))
        ax.update_datalim(x)  # add_artist leaves the data limits alone (add_patch would walk every segment)
    if nodes is not None and len(nodes):
        ax.plot(x[nodes, 0], x[nodes, 1], "o", color=node_color, ms=3)
    ax.set_aspect("equal")
    ax.autoscale_view()
    if title:
        ax.set_title(title, fontsize=10)
    return fig


def plot_edges(x, edges, values, ax=None, cmap="coolwarm", lw=1.5, label=None, vmin=None, vmax=None):
    """Draw edges (k, 2) of configuration ``x`` coloured by ``values``; returns the figure (the edges are
    ``ax.collections[-1]``)."""
    fig, ax = axes_or_new(ax)
    lc = LineCollection(np.asarray(x)[np.asarray(edges)], cmap=cmap, linewidths=lw)
    lc.set_array(np.asarray(values))
    if vmin is not None or vmax is not None:
        lc.set_clim(vmin, vmax)
    ax.add_collection(lc)
    if label:
        add_colorbar(ax, lc, label)
    ax.set_aspect("equal")
    ax.autoscale_view()
    return fig


def plot_muscles(x, muscles, ax=None, colors=None, lw=2.5, labels=True):
    """Draw muscle paths over configuration ``x``: each in its colour (:func:`.style.layout_colors`: its
    number's for ``M<k>``, else the first colour no other muscle drawn takes),
    labelled :func:`.style.muscle_label` (its name, else ``M<i+1>``), as in every figure and drawing."""
    fig, ax = axes_or_new(ax)
    x = np.asarray(x)
    muscles = list(muscles)
    own = layout_colors(muscles)
    for i, m in enumerate(muscles):
        c = (colors[i] if colors is not None else own[i])
        p = x[list(m.nodes)]
        ax.plot(p[:, 0], p[:, 1], "-", color=c, lw=lw, solid_capstyle="round",
                label=muscle_label(m, i) if labels else None)
    ax.set_aspect("equal")
    return fig


def save_figure(fig, path, *, close: bool = False, dpi: float = 130, vector=None) -> str:
    """Write ``fig`` to ``path`` through a temporary file, so no partial file is left; with ``vector``, a
    vector copy beside it (same name, ``.pdf`` or ``.svg``) for papers.
    An existing file of either name is replaced, without a warning (``mdsr run`` refuses to without ``--overwrite``).

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    path : str or path-like
        The format follows the extension (``.png``, ``.svg``, ``.pdf``, ...).
    close : bool, default False
        Also close the figure (release it from pyplot), even when writing fails. Code that makes many
        figures in a loop passes ``True``; a figure you still want to show stays open by default.
    dpi : float
        Resolution of raster formats.
    vector : bool, str or sequence of str, optional
        Also write the figure in these vector formats beside ``path`` (:func:`.style.figure_formats`:
        ``True`` is PDF; ``"svg"``, ``"pdf"`` or both). :func:`.style.figure_paths` names every file written.

    Returns
    -------
    str
        The path written (the first; the vector copies follow :func:`.style.figure_paths`).
    """
    path = os.fspath(path)
    extra = figure_paths(path, vector)[1:]  # checked before anything is written
    try:
        for other in extra:
            with atomic_path(other, suffix=os.path.splitext(other)[1]) as tmp:
                fig.savefig(tmp, dpi=dpi, bbox_inches="tight", format=os.path.splitext(other)[1][1:])
        ext = os.path.splitext(path)[1] or ".png"
        png = ext.lower() == ".png"
        # PNG (drawn by Agg): drawn once on a canvas with a margin, cropped to its drawn pixels (see
        # render_cropped) and encoded losslessly at zlib level 1 (see _write_png). Vector formats measure
        # their text with their own renderer: "tight".
        rgba = _render_crop(fig, dpi) if png else None
        with atomic_path(path, suffix=ext) as tmp:
            if rgba is not None:
                _write_png(rgba, tmp)
            elif png:  # a figure render_cropped cannot handle: the tight box measured once, then savefig
                fig.savefig(tmp, dpi=dpi, bbox_inches=tight_bbox(fig, dpi), pil_kwargs={"compress_level": 1})
            else:
                fig.savefig(tmp, dpi=dpi, bbox_inches="tight")
    finally:
        if close:
            plt.close(fig)
    return path


class _Grab:
    """A file for ``savefig(format="rgba")``: keeps the renderer's (h, w, 4) buffer as an array."""

    array = None

    def write(self, data):
        self.array = np.asarray(data)  # a view of the renderer's buffer (nothing draws on it until cropped)
        return len(data)

    def seek(self, *args):  # pragma: no cover - matplotlib only checks that a file handle can seek
        return 0


#: the canvas margins :func:`render_cropped` draws with, in inches beyond the farthest text, legend or axes
#: placed outside the figure (:func:`_reach`), the next tried when the drawing (with ``savefig.pad_inches``)
#: reaches the canvas's edge: the figures of ``mdsr run all`` reach at most 0.6 in past their box (a legend
#: beside the axes), and a 1 in margin drew them in about 80 % of the time of a 2 in one (fewer pixels to
#: clear, scan and page in)
MARGINS = (1.0, 4.0)

#: what :func:`_draw_crop` returns when the drawing reaches the canvas's edge
_TOO_SMALL = object()


def render_cropped(fig, dpi: float, margin: float | None = None):
    """``fig`` drawn once by Agg at ``dpi`` and cropped as ``savefig(bbox_inches="tight")`` crops it: an
    (h, w, 3) uint8 RGB array, or None for a figure this cannot handle (another canvas, a layout engine, a
    see-through background, nothing drawn, or a drawing reaching past the last of the margins).

    ``bbox_inches="tight"`` lays the figure out twice (once to measure every tick label, title and legend,
    once to draw), which was 40 % of a figure's saving time. Here the figure is drawn once on a canvas
    ``margin`` inches larger on every side (whole pixels, so every pixel lies where a plain draw puts it;
    default: :data:`MARGINS` beyond the farthest text, legend or axes placed outside the figure, in turn,
    the next only when the drawing reached the edge of the canvas), the drawing's box is read from the
    pixels that differ from the background and padded by ``savefig.pad_inches``. The crop can differ from
    the text-box crop of ``"tight"`` by the few blank pixels a text box reserves beyond its glyphs
    (descenders, line gap), and the margin never changes it. What is not seen: a line or patch drawn
    unclipped wholly beyond the margin (a given ``margin`` is taken as it is), which ``"tight"`` would keep.
    """
    crop = _render_crop(fig, dpi, margin)
    return None if crop is None else np.ascontiguousarray(crop[..., :3])


def _render_crop(fig, dpi: float, margin: float | None = None):
    """:func:`render_cropped`'s crop as an (h, w, 4) RGBA view of the renderer's buffer, or None."""
    if margin is None:
        reach = _reach(fig)
        margins = tuple(m + reach for m in MARGINS)
    else:
        margins = (margin,)
    for m in margins:
        crop = _draw_crop(fig, dpi, m)
        if crop is not _TOO_SMALL:
            return crop
    return None


def _reach(fig) -> float:
    """How far, in inches, the farthest anchor of a text (a suptitle, an axes' title or text), of a legend
    (its ``bbox_to_anchor``) or an axes lies outside the figure's box; 0 when all lie inside. A drawing
    whose pieces each start inside the canvas and run on to its edge is caught by that edge; one placed
    wholly outside is not, unless the margin starts beyond its anchor. Affine transforms only: no layout."""
    w, h = fig.get_size_inches()
    to_inches = fig.dpi_scale_trans.inverted()
    points = [fig.bbox.p0, fig.bbox.p1]
    texts = list(fig.texts)
    boxes = [lg.get_bbox_to_anchor() for lg in fig.legends]
    for ax in fig.axes:
        boxes.append(ax.bbox)
        texts += list(ax.texts) + [ax.title, ax._left_title, ax._right_title]
        if ax.get_legend() is not None:
            boxes.append(ax.get_legend().get_bbox_to_anchor())
    for t in texts:
        if t.get_visible() and t.get_text():
            points.append(t.get_transform().transform(t.get_position()))
    for b in boxes:
        points += [b.p0, b.p1]
    q = to_inches.transform(np.asarray(points, dtype=float))
    if not np.all(np.isfinite(q)):
        return 0.0
    return float(max(0.0, -q[:, 0].min(), -q[:, 1].min(), q[:, 0].max() - w, q[:, 1].max() - h))


def _draw_crop(fig, dpi: float, margin: float):
    """One try of :func:`_render_crop` with ``margin``: the crop, None, or :data:`_TOO_SMALL`."""
    if not isinstance(fig.canvas, FigureCanvasAgg) or _has_layout_engine(fig):
        return None
    face = mpl.rcParams["savefig.facecolor"]
    face = to_rgba(fig.get_facecolor() if isinstance(face, str) and face == "auto" else face)
    if face[3] < 1.0 or mpl.rcParams["savefig.transparent"]:
        return None
    m = int(np.ceil(margin * dpi)) / dpi  # whole pixels
    w, h = fig.get_size_inches()
    grab = _Grab()
    fig.savefig(grab, format="rgba", dpi=dpi, bbox_inches=Bbox.from_extents(-m, -m, w + m, h + m),
                facecolor=face, edgecolor=fig.get_edgecolor())
    img = grab.array
    if img is None or img.ndim != 3:  # pragma: no cover - a matplotlib that writes the buffer otherwise
        return None
    bg = np.array([round(255 * c) for c in face], dtype=np.uint8).view(np.uint32)[0]
    drawn = np.ascontiguousarray(img).view(np.uint32)[..., 0] != bg  # a contiguous buffer: no copy
    rows, cols = np.flatnonzero(drawn.any(axis=1)), np.flatnonzero(drawn.any(axis=0))
    if not len(rows):
        return None
    pad = round(mpl.rcParams["savefig.pad_inches"] * dpi)
    r0, r1, c0, c1 = rows[0] - pad, rows[-1] + 1 + pad, cols[0] - pad, cols[-1] + 1 + pad
    # the drawing and its padding must lie inside the canvas, off its edge row and column (a drawing cut
    # by the canvas would end there): else a larger margin
    if r0 <= 0 or c0 <= 0 or r1 >= img.shape[0] or c1 >= img.shape[1]:
        return _TOO_SMALL
    return img[r0:r1, c0:c1]


def _write_png(rgba, path) -> None:
    """Write an (h, w, 4) uint8 RGBA array (opaque) as an RGB PNG (lossless) with OpenCV: zlib level 1 with
    the run-length strategy and the Paeth filter on every row. Against Pillow at level 1 (adaptive filters):
    a figure in 40 % and a photograph overlay in half the time, files as large (figures) or 10 % smaller
    (overlay); trying every filter per row (libpng's default) doubled a figure's encoding time for 0.3 %."""
    import cv2

    bgr = cv2.cvtColor(rgba, cv2.COLOR_RGBA2BGR)
    params = [cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_RLE]
    if hasattr(cv2, "IMWRITE_PNG_FILTER"):  # OpenCV >= 4.11
        params += [cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_PAETH]
    ok, buf = cv2.imencode(".png", bgr, params)
    if not ok:  # pragma: no cover - OpenCV reports no reason
        raise OSError(f"could not encode a {rgba.shape[1]}x{rgba.shape[0]} PNG for {path}")
    with open(path, "wb") as fh:
        fh.write(buf.tobytes())


def tight_bbox(fig, dpi: float):
    """The region ``savefig(bbox_inches="tight")`` saves (the tight box padded by ``savefig.pad_inches``),
    measured with an Agg renderer at ``dpi``; ``"tight"`` itself for a figure this cannot measure (another
    canvas, a layout engine). Given as a box, ``savefig`` draws the figure once instead of twice: for
    "tight" it first draws it without rendering to place every text, which ``get_tightbbox`` does too."""
    if not isinstance(fig.canvas, FigureCanvasAgg) or _has_layout_engine(fig):
        return "tight"
    pad = mpl.rcParams["savefig.pad_inches"]
    old = fig.dpi
    try:
        fig.dpi = dpi
        box = fig.get_tightbbox(fig.canvas.get_renderer())
    except Exception:  # pragma: no cover - any artist that cannot be measured so: let savefig do it
        return "tight"
    finally:
        fig.dpi = old
    return box.padded(pad, pad)


def _has_layout_engine(fig) -> bool:
    """Whether a layout engine would move the axes when the figure is drawn (``fig.tight_layout()`` leaves a
    placeholder engine behind that does nothing)."""
    engine = fig.get_layout_engine()
    return engine is not None and not isinstance(engine, PlaceHolderLayoutEngine)


def close_figure(fig) -> None:
    """Close ``fig`` (release it from pyplot); the counterpart of ``save_figure(..., close=True)``."""
    plt.close(fig)
