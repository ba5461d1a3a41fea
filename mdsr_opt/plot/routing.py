"""Figures of muscle routing across several targets: the paper's Figure 6 panels and convergence chart.

Three functions, each taking plain data (no scene or study objects), each returning a matplotlib figure:

- :func:`plot_layout_grid`: Figure 6a. One column per target; rows: the target (external driving, with
  anchors and drag nodes), the contraction graph, and one row per routing (e.g. a smaller and a larger
  ``K_a``) with the muscles over the target mesh.
- :func:`plot_design_grid`: Figure 6b. The target, then one row per layout with the driven state after
  the designed contractions drawn over the target.
- :func:`plot_convergence`: Figure 6c. The design's difference against the optimiser iteration, both
  layouts of each target in one panel.

This module sets no backend and imports no scene or study code.

Example
-------
>>> import numpy as np
>>> from mdsr_opt import Mesh
>>> from mdsr_opt.synthesis.routing import route_muscles
>>> mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
>>> t = mesh.points * [0.8, 1.0]
>>> col = {"title": "shorten", "mesh": mesh, "target": t, "layouts": [route_muscles(mesh, t)],
...        "row_labels": ["K_a = 4"]}
>>> fig = plot_layout_grid([col])
>>> len(fig.axes)
3
"""

from __future__ import annotations

import re

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection, PolyCollection

from matplotlib.lines import Line2D

from .common import legend_below, plain_log_ticks
from .style import (BODY, CONTRACTION_CMAP, TARGET, add_colorbar, axis_label, label_colors, layout_colors,
                    muscle_label, symmetric_limits, unit_label)

__all__ = ["plot_layout_grid", "plot_design_grid", "plot_convergence"]


def _mesh(ax, mesh, x, face="#e3e9f0", edge="#a9b6c4", alpha=1.0, lw=0.25):
    ax.add_collection(PolyCollection(np.asarray(x)[mesh.triangles], facecolors=face, edgecolors=edge,
                                     linewidths=lw, alpha=alpha))


def _muscles(ax, x, muscles, lw=2.4, labels=True, palette=None):
    """Muscles over ``x``; ``palette`` ({name: colour}, :func:`_row_palette`) colours a row's panels alike."""
    x = np.asarray(x)
    muscles = list(muscles)
    colors = layout_colors(muscles)
    if palette is not None:
        colors = [palette.get(muscle_label(m, i), c) for i, (m, c) in enumerate(zip(muscles, colors))]
    for i, m in enumerate(muscles):
        p = x[list(m.nodes)]
        ax.plot(p[:, 0], p[:, 1], "-", color=colors[i], lw=lw, solid_capstyle="round",
                label=muscle_label(m, i) if labels else None)
        ax.plot(p[[0, -1], 0], p[[0, -1], 1], "o", color="k", ms=2.5)


def _finish(ax):
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xticks([])
    ax.set_yticks([])


def _scale_bar(ax, x, units=None):
    """A scale bar under the lower right corner of a drawing without coordinate ticks: a round length near a quarter
    of the drawing's width, labelled with its unit (:func:`.style.unit_label`), so the panel's size reads
    as a labelled axis would give it."""
    from matplotlib.offsetbox import AnchoredOffsetbox, AuxTransformBox, HPacker, TextArea, VPacker
    from matplotlib.patches import Rectangle

    width = float(np.ptp(np.asarray(x, dtype=float)[:, 0])) or 1.0
    raw = 0.25 * width
    step = 10.0 ** np.floor(np.log10(raw))
    length = max(m * step for m in (1, 2, 5) if m * step <= raw)
    bar = AuxTransformBox(ax.transData)
    bar.add_artist(Rectangle((0, 0), length, 0, lw=1.6, edgecolor="k", facecolor="none"))
    text = TextArea(f"{length:g} {unit_label(units)}", textprops={"fontsize": 7})
    box = VPacker(children=[bar, HPacker(children=[text], align="center", pad=0, sep=0)], align="center",
                  pad=0, sep=2)
    # outside the axes, under their lower right corner: over no part of the drawing
    ax.add_artist(AnchoredOffsetbox(loc="upper right", child=box, pad=0.1, borderpad=0.1, frameon=False,
                                    bbox_to_anchor=(1.0, 0.0), bbox_transform=ax.transAxes))


def _row_legend(ax, palette):
    """The muscles' names and colours of a row of panels (``{name: colour}``), beside its last panel (over no
    drawing)."""
    if palette:
        handles = [Line2D([], [], color=c, lw=2.4) for c in palette.values()]
        ax.legend(handles, list(palette), fontsize=7, loc="upper left", bbox_to_anchor=(1.03, 1.0),
                  borderaxespad=0.0, handlelength=1.5)


def _row_palette(layouts) -> dict:
    """``{name: colour}`` of every muscle drawn in a row of panels, each name once (numbered ones in their
    number's order): every panel of the row draws a muscle of that name in that colour and the row's
    legend lists them all (the face's expressions each pull another subset of one layout)."""
    names = list(dict.fromkeys(muscle_label(m, i) for lay in layouts for i, m in enumerate(lay)))
    names.sort(key=lambda n: (0, int(n[1:])) if re.fullmatch(r"M[1-9][0-9]*", n) else (1, 0))
    return dict(zip(names, label_colors(names)))


def plot_layout_grid(columns, title=None):
    """Figure 6a: targets, contraction graphs and routed layouts, one column per target.

    Parameters
    ----------
    columns : sequence of dict
        Each with ``title`` (str), ``mesh`` (Mesh), ``target`` ((n, 2) array), ``layouts`` (sequence of
        RoutingResult or of muscle lists, one per layout row), ``row_labels`` (one str per layout), and
        optionally ``anchors`` and ``drag_nodes`` (node indices, drawn on the target) and ``weights``
        (per-edge contraction, computed from the target when omitted). Row B shares one colour scale
        across the columns, with its colour bar beside the last panel; muscles are named and coloured as in
        every figure (:mod:`mdsr_opt.plot.style`).
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
        ``2 + len(layouts)`` rows of axes per column (row A target, B contraction graph, then layouts).
    """
    columns = list(columns)
    if not columns:
        raise ValueError("plot_layout_grid needs at least one column")
    n_lay = max(len(c["layouts"]) for c in columns)
    rows = 2 + n_lay
    fig, axes = plt.subplots(rows, len(columns), figsize=(3.2 * len(columns) + 0.6, 2.6 * rows), squeeze=False)
    weights = []
    for c in columns:
        w = c.get("weights")
        if w is None:
            x = np.asarray(c["target"], dtype=float)
            E, l0 = c["mesh"].edges, c["mesh"].edge_lengths
            w = (l0 - np.linalg.norm(x[E[:, 1]] - x[E[:, 0]], axis=1)) / l0
        weights.append(np.asarray(w, dtype=float))
    lo, hi = symmetric_limits(*weights)  # one scale for the row: the columns compare
    palettes = [_row_palette([list(c["layouts"][i]) for c in columns if i < len(c["layouts"])])
                for i in range(n_lay)]
    lc = None
    for j, c in enumerate(columns):
        mesh, x = c["mesh"], np.asarray(c["target"], dtype=float)
        ax = axes[0, j]
        _mesh(ax, mesh, x)
        for key, mark, col, what in (("anchors", "s", "k", "anchors"), ("drag_nodes", "o", "#d62728", "drag points")):
            idx = np.asarray(c.get(key, ()), dtype=int)
            if len(idx):
                ax.plot(x[idx, 0], x[idx, 1], mark, color=col, ms=2.0, label=what)
        ax.set_title(c["title"], fontsize=9)
        _finish(ax)
        _scale_bar(ax, x, c.get("units"))
        ax = axes[1, j]
        lc = LineCollection(x[mesh.edges], cmap=CONTRACTION_CMAP, linewidths=0.9)
        lc.set_array(weights[j])
        lc.set_clim(lo, hi)
        ax.add_collection(lc)
        _finish(ax)
        for i, (lay, label) in enumerate(zip(c["layouts"], c["row_labels"])):
            ax = axes[2 + i, j]
            _mesh(ax, mesh, x, alpha=0.8)
            mus = list(lay)
            _muscles(ax, x, mus, labels=False, palette=palettes[i])
            ax.set_title(f"{label}: {len(mus)} muscle(s)", fontsize=8)
            _finish(ax)
    for i, name in enumerate(["A target", "B contraction graph"] + [f"{chr(67 + k)} layout" for k in range(n_lay)]):
        axes[i, 0].set_ylabel(name, fontsize=9)
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    # after the layout (an inset is not laid out): the row's colour bar beside its last panel
    add_colorbar(axes[1, -1], lc, axis_label("$(l_0 - l)/l_0$", "1"), width=0.05)
    # one legend per layout row, beside its last panel: over no drawing, the muscles' names and colours
    # as in every figure (a name the columns do not share is the muscle's place, M<k>)
    for i in range(n_lay):
        _row_legend(axes[2 + i, -1], palettes[i])
    # row A's marks: anchors and drag points, beside its last panel
    marks = {}
    for ax in axes[0]:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            marks.setdefault(lab, Line2D([], [], ls="none", marker=h.get_marker(), color=h.get_color(), ms=4))
    if marks:
        axes[0, -1].legend(list(marks.values()), list(marks), fontsize=7, loc="upper left",
                           bbox_to_anchor=(1.03, 1.0), borderaxespad=0.0, handlelength=1.0)
    return fig


def plot_design_grid(columns, title=None, row_names=None):
    """Figure 6b: the target, then each layout's driven state (designed contractions) over it.

    Parameters
    ----------
    columns : sequence of dict
        Each with ``title``, ``mesh``, ``target``, ``designs`` (one per layout: a dict with ``x`` the
        driven state moved onto the target, ``muscles``, ``difference``, ``success``) and ``row_labels``
        (one per design, heading its panel); optionally ``units``, the coordinates' length unit (default
        ``"body units"``).
    title : str, optional
    row_names : sequence of str, optional
        The rows' names beside the first column: the target row's, then one per design row. Default
        ``"target"``, then ``"driven"`` (one design row) or ``"driven, layout 1"``, ``"driven, layout 2"``...

    Returns
    -------
    matplotlib.figure.Figure
    """
    columns = list(columns)
    if not columns:
        raise ValueError("plot_design_grid needs at least one column")
    n_lay = max(len(c["designs"]) for c in columns)
    rows = 1 + n_lay
    if row_names is None:
        row_names = ["target"] + (["driven"] if n_lay == 1 else [f"driven, layout {k + 1}" for k in range(n_lay)])
    row_names = [str(n) for n in row_names]
    if len(row_names) != rows:
        raise ValueError(f"plot_design_grid: {len(row_names)} row names for {rows} rows (the target's, then one "
                         f"per design row)")
    fig, axes = plt.subplots(rows, len(columns), figsize=(3.2 * len(columns), 2.6 * rows), squeeze=False)
    palettes = [_row_palette([list(c["designs"][i]["muscles"]) for c in columns if i < len(c["designs"])])
                for i in range(n_lay)]
    for j, c in enumerate(columns):
        mesh, y = c["mesh"], np.asarray(c["target"], dtype=float)
        ax = axes[0, j]
        _mesh(ax, mesh, y, face="#bbbbbb", edge="#888888")
        ax.set_title(c["title"], fontsize=9)
        _finish(ax)
        _scale_bar(ax, y, c.get("units"))
        for i, (d, label) in enumerate(zip(c["designs"], c["row_labels"])):
            ax = axes[1 + i, j]
            _mesh(ax, mesh, y, face=TARGET["face"], edge="none", alpha=0.45)
            _mesh(ax, mesh, d["x"], face=BODY["face"], edge=BODY["edge"], alpha=0.45, lw=0.2)
            _muscles(ax, d["x"], d["muscles"], lw=1.8, labels=False, palette=palettes[i])
            flag = "" if d["success"] else " FAILED"
            # a long label (the muscles an expression pulls) keeps its own line: titles never run into the
            # next panel's
            what = f"D = {d['difference']:.3g} {unit_label(c.get('units'))}{flag}"
            ax.set_title(f"{label}: {what}" if len(label) + len(what) <= 42 else f"{label}:\n{what}", fontsize=8)
            _finish(ax)
    for i, name in enumerate(row_names):
        axes[i, 0].set_ylabel(name, fontsize=9)
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    # after the layout: per design row the muscles' names and colours beside its last panel (as in 6a)
    for i in range(n_lay):
        _row_legend(axes[1 + i, -1], palettes[i])
    return fig


def plot_convergence(panels, title=None, log=True):
    """Figure 6c: the design's difference against the optimiser iteration, one panel per target.

    Parameters
    ----------
    panels : sequence of dict
        Each with ``title`` and ``traces``: a list of ``(label, iterations, differences)``; ``iterations``
        and ``differences`` are equal-length sequences; optionally ``units``, the length unit of the
        differences (default ``"body units"``). Panels in one unit share the first panel's axis label;
        panels in different units each label their own.
    log : bool
        Logarithmic difference axis.

    Returns
    -------
    matplotlib.figure.Figure
    """
    panels = list(panels)
    if not panels:
        raise ValueError("plot_convergence needs at least one panel")
    fig, axes = plt.subplots(1, len(panels), figsize=(3.3 * len(panels), 3.0), squeeze=False)
    for ax, p in zip(axes[0], panels):
        for i, (label, it, d) in enumerate(p["traces"]):
            it, d = np.asarray(it, dtype=float), np.asarray(d, dtype=float)
            if len(it) != len(d):
                raise ValueError(f"{p['title']}, {label}: {len(it)} iterations but {len(d)} differences")
            # layouts, not muscles: greys and markers (the muscle colours name muscles only)
            ax.plot(it, d, "-" + "osD^v"[i % 5], ms=2.5, lw=1.3, color=("#222222", "#888888", "#555555")[i % 3],
                    label=f"{label} ({int(it[-1]) if len(it) else 0} it.)")
        if log:
            ax.set_yscale("log")
            plain_log_ticks(ax, "y")
        ax.set_title(p["title"], fontsize=9)
        ax.set_xlabel(axis_label("IPOPT iteration", "count"))
        ax.grid(alpha=0.3)
        legend_below(ax, ncol=1, drop=0.45)  # under the panel: never over a trace
    units = [unit_label(p.get("units")) for p in panels]
    for ax, u in zip(axes[0], units) if len(set(units)) > 1 else [(axes[0, 0], units[0])]:
        ax.set_ylabel(axis_label("difference D", u))
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    return fig
