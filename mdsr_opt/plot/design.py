"""Figures of routing and design: contraction graphs, routed muscles, designs, benchmarks, gait schedules."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection, PolyCollection

from ..body.fingerprint import check_same_mesh
from ..core.quantities import band_text
from .common import (LEGEND_OUTSIDE, axes_or_new, body_panels, coordinate_axes, draw_obstacles, plot_edges,
                     plot_mesh, plot_muscles)
from .style import (BODY, CONTRACTION_CMAP, LIGHT, TARGET, axis_label, commanded_achieved, label_colors,
                    symmetric_limits, unit_label)

__all__ = ['plot_contraction_graph', 'plot_routing', 'plot_routing_timings', 'plot_design', 'design_title',
           'plot_design_benchmark', 'plot_schedule']


# --- routing (issue 3) ---
def _edge_weights_of(mesh, graph):
    return np.array([graph.edges[int(a), int(b)]["weight"] for a, b in mesh.edges])


def plot_contraction_graph(mesh, target, graph=None, ax=None, cmap=CONTRACTION_CMAP, lw=1.5, title=None,
                           seeds=None, ticks=True, units=None, limit=None):
    """The contraction graph drawn over the target mesh, each edge coloured by its weight.

    Parameters
    ----------
    mesh : Mesh
        The rest mesh.
    target : (n, 2) array
        Target node positions.
    graph : networkx.Graph, optional
        From :func:`mdsr_opt.synthesis.routing.contraction_graph`; computed when omitted.
    ax : matplotlib Axes, optional
    cmap : str
        A diverging colormap, centred on 0: contraction (w > 0) at the top end, elongation below.
    seeds : sequence of (i, j), optional
        Seed edges to outline in black (the default title says so).
    ticks : bool, default True
        Coordinate ticks on the drawing (the colour bar keeps its own); ``False`` for a run's figures,
        whose coordinates the target figure gives: three ticks a side.
    units : str, optional
        The length unit of the coordinates, named on the axes (default ``"body units"``).
    limit : float, optional
        The colour scale runs from ``-limit`` to ``limit`` (panels to compare pass one:
        :func:`mdsr_opt.plot.style.symmetric_limits`); default the largest weight drawn.

    Returns
    -------
    matplotlib.figure.Figure

    Example
    -------
    >>> from mdsr_opt import Mesh
    >>> mesh = Mesh.rectangle(2.0, 1.0, 4, 2)
    >>> fig = plot_contraction_graph(mesh, mesh.points * [0.9, 1.0])
    """
    fig, ax = axes_or_new(ax)
    x = np.asarray(target, dtype=float)
    ax.add_collection(PolyCollection(x[mesh.triangles], facecolors="#eeeeee", edgecolors="none"))
    if graph is None:  # the graph's weights, (l0 - l) / l0 per mesh edge, without building the graph
        l0 = mesh.edge_lengths
        w = (l0 - np.linalg.norm(x[mesh.edges[:, 1]] - x[mesh.edges[:, 0]], axis=1)) / l0
    else:
        w = _edge_weights_of(mesh, graph)
    m = symmetric_limits(w)[1] if limit is None else float(limit)
    plot_edges(x, mesh.edges, w, ax=ax, cmap=cmap, lw=lw, vmin=-m, vmax=m,
               label=axis_label("relative contraction $(l_0 - l)/l_0$", "1"))
    if seeds is not None and len(seeds):
        ax.add_collection(LineCollection(x[np.asarray(seeds)], colors="k", linewidths=lw * 2.2, zorder=3))
    seeded = ";\nblack: seed edges, where the routing starts muscles" if seeds is not None and len(seeds) else ""
    ax.set_title(title or f"contraction graph (red: shortens, blue: stretches{seeded})", fontsize=10)
    ax.autoscale_view()
    coordinate_axes(ax, units, ticks)
    return fig


def plot_routing(mesh, target, result, axes=None, title=None, ticks=True, units=None):
    """Routed muscles over the rest mesh (left) and the target mesh (right).

    Parameters
    ----------
    mesh : Mesh
        The rest mesh.
    target : (n, 2) array
        Target node positions.
    result : RoutingResult or sequence of Muscle
        From :func:`mdsr_opt.synthesis.routing.route_muscles`.
    axes : pair of matplotlib Axes, optional
    ticks : bool, default True
        Coordinate ticks on both panels (``False``: a run's figures, see :func:`plot_contraction_graph`).
    units : str, optional
        The length unit of the coordinates (default ``"body units"``).

    Returns
    -------
    matplotlib.figure.Figure

    Example
    -------
    >>> from mdsr_opt import Mesh
    >>> from mdsr_opt.synthesis.routing import route_muscles
    >>> mesh = Mesh.rectangle(2.0, 1.0, 8, 4)
    >>> fig = plot_routing(mesh, mesh.points * [0.8, 1.0], route_muscles(mesh, mesh.points * [0.8, 1.0]))
    """
    x = np.asarray(target, dtype=float)
    if axes is None:  # each panel as wide as its body: no blank gap beside a tall, narrow one
        fig, axes = body_panels([np.ptp(mesh.points, axis=0), np.ptp(x, axis=0)])
    fig = axes[0].figure
    muscles = list(result)
    for ax, pos, name in ((axes[0], mesh.points, "rest"), (axes[1], x, "target")):
        plot_mesh(mesh, pos, ax=ax, color=LIGHT["face"], edgecolor=LIGHT["edge"])
        if muscles:
            plot_muscles(pos, muscles, ax=ax)
            for m in muscles:
                ends = pos[[m.nodes[0], m.nodes[-1]]]
                ax.plot(ends[:, 0], ends[:, 1], "o", color="k", ms=3)
        ax.set_title(f"{len(muscles)} muscle(s) over the {name} mesh", fontsize=10)
    if muscles and len(muscles) <= 10:
        axes[1].legend(fontsize=7, **LEGEND_OUTSIDE)
    if title:
        fig.suptitle(title)
    for ax in axes:
        coordinate_axes(ax, units, ticks)
    return fig


def plot_routing_timings(series, budget=None, budget_nodes=None, ax=None):
    """Routing time against mesh size (log-log), one line per series, with an optional budget.

    ``series`` maps a name to ``(nodes, seconds)``; names ending in ``"cold"`` are drawn dashed.
    ``budget`` (seconds) and ``budget_nodes`` draw the budget as a horizontal and a vertical line.
    """
    fig, ax = axes_or_new(ax, figsize=(7, 4.5))
    for name, (nodes, t) in series.items():
        ax.loglog(nodes, t, "o--" if name.endswith("cold") else "s-", label=name,
                  alpha=0.6 if name.endswith("cold") else 1.0)
    if budget is not None:
        ax.axhline(budget, color="r", ls="--", lw=1, label=f"budget {budget:g} s")
    if budget_nodes is not None:
        ax.axvline(budget_nodes, color="0.5", ls=":", lw=1)
    ax.set_xlabel(axis_label("mesh nodes", "count"))
    ax.set_ylabel(axis_label("routing time", "s"))
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, **LEGEND_OUTSIDE)  # beside the axes: over no line (and no "best" search)
    ax.set_title("muscle routing time")
    return fig


def plot_design(mesh, result, target, muscles=(), ax=None, title=None, ticks=True, units=None, obstacles=()):
    """Overlay a design's driven state (moved onto the target) on the target, with the muscles.

    The title gives, per muscle (named and coloured as in every figure: :mod:`mdsr_opt.plot.style`), the
    commanded contraction and the one the muscle reached (``1 - L/L0`` along its path), and the difference
    to the target in the coordinates' unit.

    Parameters
    ----------
    mesh : the rest mesh.
    result : ``DesignResult`` (``mdsr_opt.synthesis.results``); its ``x_aligned`` is drawn.
    target : (n, 2) target positions.
    muscles : muscles to draw over the driven state.
    ticks : coordinate ticks (``False``: a run's figures, see :func:`plot_contraction_graph`).
    units : the coordinates' length unit, on the axes and the difference (default ``"body units"``).
    obstacles : rigid obstacles the design touched, drawn where they are (:func:`~mdsr_opt.plot.common.draw_obstacles`).

    Example
    -------
    >>> import numpy as np
    >>> from mdsr_opt import Mesh, Muscle, NeoHookean, solve_internal
    >>> from mdsr_opt.synthesis.contractions import design_contractions
    >>> mesh, mat, mus = Mesh.rectangle(4.0, 1.0, 16, 4), NeoHookean(1.0, 0.3), [Muscle(range(1, 16))]
    >>> target = solve_internal(mesh, mat, mus, [0.15]).x
    >>> fig = plot_design(mesh, design_contractions(mesh, mat, mus, target), target, mus)
    >>> title = fig.axes[0].get_title()
    >>> "difference D = " in title and "M1 0.150 \u2192 0.150" in title and "largest node error" in title
    True
    """
    check_same_mesh(mesh, getattr(result, "rest_mesh", None), "the design")  # drawn on the body it was made on
    fig, ax = axes_or_new(ax)
    plot_mesh(mesh, np.asarray(target), ax=ax, color=TARGET["face"], edgecolor=TARGET["edge"], alpha=0.6,
              label="target")
    plot_mesh(mesh, result.x_aligned, ax=ax, color=BODY["face"], edgecolor=BODY["edge"], alpha=0.45,
              label="driven (aligned)")
    if len(muscles):
        plot_muscles(result.x_aligned, muscles, ax=ax)
    err = np.linalg.norm(np.asarray(result.x_aligned) - np.asarray(target, dtype=float), axis=1)
    worst = None
    if err.size and np.isfinite(err).all():  # where the design misses the pose most
        k = int(np.argmax(err))
        worst = float(err[k])
        pts = np.array([result.x_aligned[k], np.asarray(target, dtype=float)[k]])
        ax.plot(pts[:, 0], pts[:, 1], color="k", lw=1.0, marker="x", ms=5, zorder=5,
                label=f"largest node error {worst:.3g} {unit_label(units)}")
    ax.set_title(title or design_title(result, muscles, units, max_error=worst), fontsize=9)
    if len(obstacles):
        draw_obstacles(ax, obstacles)
    ax.legend(fontsize=7, **LEGEND_OUTSIDE)
    coordinate_axes(ax, units, ticks)
    return fig


def design_title(result, muscles=(), units=None, per_line: int = 3, max_error: float | None = None) -> str:
    """A design's title: method, difference (the weighted RMS the verdict judges) with its unit and the
    largest node error after the same alignment (``max_error`` when given, as measured against the drawn
    target, else the result's ``max_error``), then per muscle the commanded contraction and the achieved one (``M1 0.150 -> 0.148``): on
    the same line for one or two muscles, else ``per_line`` muscles to a line under a heading line (the title
    stays about as wide as the drawing)."""
    from .style import muscle_label, muscle_name

    a = np.asarray(result.contractions, dtype=float)
    reached = np.asarray(getattr(result, "achieved", ()), dtype=float)
    names = [muscle_label(m, i) for i, m in enumerate(muscles)] if len(muscles) == a.size else None
    names = names or [muscle_name(i) for i in range(a.size)]
    text = commanded_achieved(a, reached if reached.size == a.size else None, names)
    parts = text.split(", ") if text else []
    ok = "" if result.success else "  [FAILED]"
    worst = float(getattr(result, "max_error", float("nan")) if max_error is None else max_error)
    most = f", largest node error {worst:.3g} {unit_label(units)}" if np.isfinite(worst) else ""
    head = f"{result.method}: difference D = {result.difference:.3g} {unit_label(units)} (RMS){most}{ok}"
    what = "contraction commanded \u2192 achieved:" if reached.size == a.size else "contraction commanded:"
    # a stroke with its uncertainty band (synthesis.bands) when the design carries one
    band = np.asarray(getattr(result, "stroke_band", ()), dtype=float).reshape(-1, 2)
    strokes = np.asarray(getattr(result, "stroke", ()), dtype=float).reshape(-1)
    tail = []
    if len(band) and len(band) == len(strokes) == len(names):
        sat = np.asarray(getattr(result, "saturated", np.zeros(len(band), bool)), dtype=bool).reshape(-1)
        sat = sat if sat.shape == (len(band),) else np.zeros(len(band), dtype=bool)
        cells = [f"{n} {v:.3g} {band_text(lo, hi, at, 3)}" for n, v, (lo, hi), at in zip(names, strokes, band, sat)]
        tail = [f"stroke {unit_label(units)} [band]:"] + [", ".join(cells[k:k + per_line])
                                                         for k in range(0, len(cells), per_line)]
    if len(parts) <= 2:
        return "\n".join([f"{head}\n{what} {', '.join(parts) or 'none'}"] + tail)
    rows = [", ".join(parts[k:k + per_line]) for k in range(0, len(parts), per_line)]
    return "\n".join([head, what] + rows + tail)


def plot_design_benchmark(rows, traces=None, ax=None):
    """Difference against time for the design methods (``tests/benchmarks/bench_design.py``).

    ``rows``: dicts with ``method``, ``mesh``, ``muscles``, ``solve_time``, ``difference`` (one marker per run:
    colour = method, marker = mesh size, size = muscle count). ``traces``: optional
    ``{(mesh, muscles, method): [(t, difference), ...]}``; the best difference so far of the outer loops is
    drawn as lines for the largest case present.
    """
    fig, ax = axes_or_new(ax, figsize=(7.5, 5))
    colors = {"flattened": "#d62728", "nested": "#1f77b4", "derivative-free": "#2ca02c"}
    markers = ["o", "s", "^", "D", "v"]
    meshes = list(dict.fromkeys(r["mesh"] for r in rows))
    floor = 1e-14
    for r in rows:
        ax.scatter(max(r["solve_time"], 1e-3), max(r["difference"], floor), color=colors.get(r["method"], "k"),
                   marker=markers[meshes.index(r["mesh"]) % len(markers)], s=18 + 10 * r["muscles"],
                   edgecolors="k" if r.get("success", True) else "none", linewidths=0.4, alpha=0.85)
    if traces:
        big = max(rows, key=lambda r: (r["nodes"], r["muscles"]))
        for method, c in colors.items():
            tr = traces.get((big["mesh"], big["muscles"], method))
            if tr and len(tr) > 1:
                t, d = np.array(tr).T
                ax.plot(np.maximum(t, 1e-3), np.maximum(d, floor), "-", color=c, lw=0.8, alpha=0.6)
        ax.text(0.01, 0.01, f"lines: progress on {big['mesh']} nodes, {big['muscles']} muscles",
                transform=ax.transAxes, fontsize=7)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(axis_label("solve time", "s"))
    ax.set_ylabel(axis_label("final difference D", None))
    for method, c in colors.items():
        ax.scatter([], [], color=c, label=method)
    for i, mname in enumerate(meshes):
        ax.scatter([], [], color="grey", marker=markers[i % len(markers)], label=f"{mname} nodes")
    ax.legend(fontsize=7, **LEGEND_OUTSIDE)  # beside the axes: over no marker
    ax.set_title("contraction design: difference against time (marker size ~ muscle count)", fontsize=10)
    ax.grid(True, which="major", alpha=0.3)
    return fig


# --- gait schedules (synthesis.gait) ---
def plot_schedule(schedule, ax=None, title: str | None = None):
    """Chart of a gait's strokes over time: one line per muscle (commanded solid, achieved dotted), named and
    coloured as in every figure (:mod:`mdsr_opt.plot.style`), the keyframes marked with their poses.
    ``schedule`` is a :class:`~mdsr_opt.synthesis.gait.GaitSchedule` (its fields are read; nothing of the
    synthesis stage is imported). Returns the figure."""
    if ax is None:
        fig, ax = plt.subplots(figsize=(7.5, 3.8))
    else:
        fig = ax.figure
    t = schedule.times
    colors = label_colors(schedule.muscle_names)
    for i, n in enumerate(schedule.muscle_names):
        c = colors[i]
        L0 = float(schedule.rest_lengths[i])
        length = f"{L0:.0f}" if abs(L0) >= 100 else f"{L0:.3g}"  # 1650 mm, not 1.65e+03 mm beside 705 mm
        ax.plot(t, schedule.strokes[:, i], "-o", color=c, ms=3, lw=1.8, label=f"{n} (L0 = {length} {schedule.units})")
        if np.isfinite(schedule.achieved[:, i]).any():
            ax.plot(t, schedule.achieved[:, i], ":", color=c, lw=1.2)
    top = float(np.nanmax(schedule.strokes)) if schedule.strokes.size else 1.0
    for k in schedule.keyframes:
        ax.axvline(t[k], color="0.75", lw=0.8, zorder=0)
        ax.text(t[k], top * 1.04 if top > 0 else 0.02, schedule.labels[k], ha="center", va="bottom", fontsize=8)
    if np.isfinite(schedule.achieved).any():  # how to read the two kinds of line, in the legend too
        ax.plot([], [], "-", color="0.35", lw=1.8, label="commanded")
        ax.plot([], [], ":", color="0.35", lw=1.2, label="achieved")
    bad = ~np.asarray(schedule.frame_success, bool)
    if bad.any():
        ax.plot(t[bad], np.zeros(bad.sum()), "rx", ms=8, label="frame solve failed")
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"stroke ({schedule.units}; < 0: rope paid out)")
    low = min(0.0, float(np.nanmin(schedule.strokes)))
    ax.set_ylim(bottom=low - 0.08 * (top - low), top=top * 1.15 if top > 0 else 1.0)
    ax.axhline(0.0, color="0.5", lw=0.6, zorder=0)
    ax.set_title(title or f"actuation schedule: {' -> '.join(schedule.sequence)} "
                 f"({schedule.n_frames} frames; dotted: achieved)", fontsize=9)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    # no tight_layout: it lays every text out once more (40 % of the chart's time), and the PNG is cropped
    # to what is drawn anyway (mdsr_opt.plot.common.save_figure)
    return fig
