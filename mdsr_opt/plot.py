"""Figures (matplotlib; the only module that imports it).

Conventions: every function draws into an ``ax`` (or ``axes`` / ``fig`` for multi-panel figures) that you
pass, or into a new figure, and returns the matplotlib ``Figure``. Importing this module leaves the
matplotlib backend alone: scripts and notebooks keep theirs (the ``mdsr`` command picks the non-interactive
``Agg`` itself). :func:`save_figure` writes a figure atomically and closes it only when asked
(``close=True``), so a figure you own stays open.

Example
-------
>>> import matplotlib.pyplot as plt
>>> from mdsr_opt import Mesh
>>> fig, ax = plt.subplots()
>>> plot_mesh(Mesh.rectangle(2.0, 1.0, 4, 2), ax=ax) is fig
True
>>> plt.close(fig)
"""

from __future__ import annotations

import os

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection, PolyCollection

from .io import atomic_path

# Legends sit outside the axes, to the right (saved with bbox_inches="tight"): never over the drawing, and no
# loc="best" search, which re-runs on every draw and was 11-32 % of a scene's figure time.
_LEGEND_OUTSIDE = {"loc": "upper left", "bbox_to_anchor": (1.01, 1.0), "borderaxespad": 0.0}


def _axes(ax=None, figsize=(6, 4)):
    if ax is None:
        fig, ax = plt.subplots(figsize=figsize)
    return ax.figure, ax


def _panels(fig, nrow, ncol, figsize):
    """``(fig, axes)`` with an (nrow, ncol) grid: in ``fig`` when given, else in a new figure."""
    if fig is None:
        return plt.subplots(nrow, ncol, figsize=figsize, squeeze=False)
    return fig, fig.subplots(nrow, ncol, squeeze=False)


def plot_mesh(mesh, x=None, ax=None, color="#8fb3d9", edgecolor="#335577", alpha=1.0, values=None,
              cmap="viridis", label=None, nodes=None, node_color="k", title=None, colorbar_label=None):
    """Draw ``mesh`` in configuration ``x`` (default: rest). ``values`` colours the triangles (per triangle)."""
    fig, ax = _axes(ax)
    x = mesh.points if x is None else np.asarray(x)
    polys = x[mesh.triangles]
    pc = PolyCollection(polys, facecolors=color, edgecolors=edgecolor, linewidths=0.3, alpha=alpha, label=label)
    if values is not None:
        pc.set_array(np.asarray(values))
        pc.set_cmap(cmap)
        fig.colorbar(pc, ax=ax, label=colorbar_label)
    ax.add_collection(pc)
    if nodes is not None and len(nodes):
        ax.plot(x[nodes, 0], x[nodes, 1], "o", color=node_color, ms=3)
    ax.set_aspect("equal")
    ax.autoscale_view()
    if title:
        ax.set_title(title)
    return fig


def plot_edges(x, edges, values, ax=None, cmap="coolwarm", lw=1.5, label=None, vmin=None, vmax=None):
    """Draw edges (k, 2) of configuration ``x`` coloured by ``values``; returns the figure (the edges are
    ``ax.collections[-1]``)."""
    fig, ax = _axes(ax)
    lc = LineCollection(np.asarray(x)[np.asarray(edges)], cmap=cmap, linewidths=lw)
    lc.set_array(np.asarray(values))
    if vmin is not None or vmax is not None:
        lc.set_clim(vmin, vmax)
    ax.add_collection(lc)
    if label:
        fig.colorbar(lc, ax=ax, label=label)
    ax.set_aspect("equal")
    ax.autoscale_view()
    return fig


def plot_muscles(x, muscles, ax=None, colors=None, lw=2.5, labels=True):
    """Draw muscle paths over configuration ``x``."""
    fig, ax = _axes(ax)
    x = np.asarray(x)
    cyc = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, m in enumerate(muscles):
        c = (colors[i] if colors is not None else cyc[i % len(cyc)])
        p = x[list(m.nodes)]
        ax.plot(p[:, 0], p[:, 1], "-", color=c, lw=lw, label=(m.name or f"muscle {i}") if labels else None)
    ax.set_aspect("equal")
    return fig


def save_figure(fig, path, *, close: bool = False, dpi: float = 130) -> str:
    """Write ``fig`` to ``path`` through a temporary file, so no partial file is left.

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

    Returns
    -------
    str
        The path written.
    """
    path = os.fspath(path)
    try:
        with atomic_path(path, suffix=os.path.splitext(path)[1] or ".png") as tmp:
            fig.savefig(tmp, dpi=dpi, bbox_inches="tight")
    finally:
        if close:
            plt.close(fig)
    return path


def close_figure(fig) -> None:
    """Close ``fig`` (release it from pyplot); the counterpart of ``save_figure(..., close=True)``."""
    plt.close(fig)

# --- figures added by later modules go below this line ---


# --- routing (issue 3) ---
def _edge_weights_of(mesh, graph):
    return np.array([graph.edges[int(a), int(b)]["weight"] for a, b in mesh.edges])


def plot_contraction_graph(mesh, target, graph=None, ax=None, cmap="coolwarm", lw=1.5, title=None,
                           seeds=None):
    """The contraction graph drawn over the target mesh, each edge coloured by its weight.

    Parameters
    ----------
    mesh : Mesh
        The rest mesh.
    target : (n, 2) array
        Target node positions.
    graph : networkx.Graph, optional
        From :func:`mdsr_opt.routing.contraction_graph`; computed when omitted.
    ax : matplotlib Axes, optional
    cmap : str
        A diverging colormap, centred on 0: contraction (w > 0) at the top end, elongation below.
    seeds : sequence of (i, j), optional
        Seed edges to outline in black.

    Returns
    -------
    matplotlib.figure.Figure

    Example
    -------
    >>> from mdsr_opt import Mesh
    >>> mesh = Mesh.rectangle(2.0, 1.0, 4, 2)
    >>> fig = plot_contraction_graph(mesh, mesh.points * [0.9, 1.0])
    """
    fig, ax = _axes(ax)
    x = np.asarray(target, dtype=float)
    ax.add_collection(PolyCollection(x[mesh.triangles], facecolors="#eeeeee", edgecolors="none"))
    if graph is None:  # the graph's weights, (l0 - l) / l0 per mesh edge, without building the graph
        l0 = mesh.edge_lengths
        w = (l0 - np.linalg.norm(x[mesh.edges[:, 1]] - x[mesh.edges[:, 0]], axis=1)) / l0
    else:
        w = _edge_weights_of(mesh, graph)
    m = float(np.abs(w).max()) or 1.0
    plot_edges(x, mesh.edges, w, ax=ax, cmap=cmap, lw=lw, vmin=-m, vmax=m,
               label="relative contraction $(l_0 - l)/l_0$")
    if seeds is not None and len(seeds):
        ax.add_collection(LineCollection(x[np.asarray(seeds)], colors="k", linewidths=lw * 2.2, zorder=3))
    ax.set_title(title or "contraction graph (red: shortens, blue: stretches)", fontsize=10)
    ax.autoscale_view()
    return fig


def plot_routing(mesh, target, result, axes=None, title=None):
    """Routed muscles over the rest mesh (left) and the target mesh (right).

    Parameters
    ----------
    mesh : Mesh
        The rest mesh.
    target : (n, 2) array
        Target node positions.
    result : RoutingResult or sequence of Muscle
        From :func:`mdsr_opt.routing.route_muscles`.
    axes : pair of matplotlib Axes, optional

    Returns
    -------
    matplotlib.figure.Figure

    Example
    -------
    >>> from mdsr_opt import Mesh
    >>> from mdsr_opt.routing import route_muscles
    >>> mesh = Mesh.rectangle(2.0, 1.0, 8, 4)
    >>> fig = plot_routing(mesh, mesh.points * [0.8, 1.0], route_muscles(mesh, mesh.points * [0.8, 1.0]))
    """
    if axes is None:
        fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    fig = axes[0].figure
    muscles = list(result)
    x = np.asarray(target, dtype=float)
    for ax, pos, name in ((axes[0], mesh.points, "rest"), (axes[1], x, "target")):
        plot_mesh(mesh, pos, ax=ax, color="#dde6f0", edgecolor="#9aaabb")
        if muscles:
            plot_muscles(pos, muscles, ax=ax)
            for m in muscles:
                ends = pos[[m.nodes[0], m.nodes[-1]]]
                ax.plot(ends[:, 0], ends[:, 1], "o", color="k", ms=3)
        ax.set_title(f"{len(muscles)} muscle(s) over the {name} mesh")
    if muscles and len(muscles) <= 10:
        axes[1].legend(fontsize=7, **_LEGEND_OUTSIDE)
    if title:
        fig.suptitle(title)
    return fig


def plot_routing_timings(series, budget=None, budget_nodes=None, ax=None):
    """Routing time against mesh size (log-log), one line per series, with an optional budget.

    ``series`` maps a name to ``(nodes, seconds)``; names ending in ``"cold"`` are drawn dashed.
    ``budget`` (seconds) and ``budget_nodes`` draw the budget as a horizontal and a vertical line.
    """
    fig, ax = _axes(ax, figsize=(7, 4.5))
    for name, (nodes, t) in series.items():
        ax.loglog(nodes, t, "o--" if name.endswith("cold") else "s-", label=name,
                  alpha=0.6 if name.endswith("cold") else 1.0)
    if budget is not None:
        ax.axhline(budget, color="r", ls="--", lw=1, label=f"budget {budget:g} s")
    if budget_nodes is not None:
        ax.axvline(budget_nodes, color="0.5", ls=":", lw=1)
    ax.set_xlabel("mesh nodes")
    ax.set_ylabel("seconds")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2, loc="upper left")  # explicit: "best" searches
    ax.set_title("muscle routing time")
    return fig


def plot_overlay(image, mesh, x, comparison, ax=None, synthetic=False, title=None, mesh_color="#1f77b4",
                 contour_color="#ffd400", cmap="magma_r"):
    """Draw the simulated mesh over the photograph it was compared with (``mdsr_opt.evaluate``).

    Parameters
    ----------
    image : (H, W) or (H, W, 3) uint8 array (RGB), e.g. from ``evaluate.load_image``.
    mesh, x : the mesh and its simulated state (simulation coordinates).
    comparison : ``ContourComparison``; its ``transform`` maps ``x`` into the image's pixels.
    synthetic : mark the figure as made from a synthetic (rendered) photograph.

    The mesh is drawn as triangle edges, the measured contour as a line and the simulated boundary
    nodes coloured by their distance to it (pixels).

    Example
    -------
    >>> from mdsr_opt import Mesh
    >>> from mdsr_opt.evaluate import render_photo, evaluate_image
    >>> mesh = Mesh.rectangle(3.0, 1.0, 6, 2)
    >>> photo = render_photo(mesh, resolution=(300, 200))
    >>> fig = plot_overlay(photo.image, mesh, mesh.points, evaluate_image(photo.image, mesh), synthetic=True)
    >>> fig.axes[0].get_title().endswith("(SYNTHETIC photograph)")
    True
    """
    fig, ax = _axes(ax, figsize=(6, 6 * image.shape[0] / max(image.shape[1], 1)))
    img = np.asarray(image)
    ax.imshow(img, cmap="gray" if img.ndim == 2 else None, origin="upper", interpolation="nearest")
    P = comparison.to_pixels(np.asarray(x))
    ax.add_collection(PolyCollection(P[mesh.triangles], facecolors="none", edgecolors=mesh_color,
                                     linewidths=0.4, alpha=0.9))
    m = np.vstack([comparison.measured_px, comparison.measured_px[:1]])
    ax.plot(m[:, 0], m[:, 1], "-", color=contour_color, lw=1.2, label="measured contour")
    s = comparison.simulated_px
    sc = ax.scatter(s[:, 0], s[:, 1], c=comparison.distances_px, cmap=cmap, s=10, zorder=3,
                    label="simulated boundary nodes")
    fig.colorbar(sc, ax=ax, shrink=0.7, label="distance to contour (px)")
    ax.set_xlim(-0.5, img.shape[1] - 0.5)
    ax.set_ylim(img.shape[0] - 0.5, -0.5)
    ax.set_aspect("equal")
    ax.legend(fontsize=7, loc="upper right")
    head = f"{title}: " if title else ""
    text = f"{head}d = {comparison.mean_px:.2f} px, sd = {comparison.std_px:.2f} px"
    if synthetic:
        text += " (SYNTHETIC photograph)"
    ax.set_title(text, fontsize=9)
    return fig


def plot_design(mesh, result, target, muscles=(), ax=None, title=None):
    """Overlay a design's driven state (moved onto the target) on the target, with the muscles.

    Parameters
    ----------
    mesh : the rest mesh.
    result : ``DesignResult`` (``mdsr_opt.design``); its ``x_aligned`` is drawn.
    target : (n, 2) target positions.
    muscles : muscles to draw over the driven state.

    Example
    -------
    >>> import numpy as np
    >>> from mdsr_opt import Mesh, Muscle, NeoHookean, solve_internal
    >>> from mdsr_opt.design import design_contractions
    >>> mesh, mat, mus = Mesh.rectangle(4.0, 1.0, 16, 4), NeoHookean(1.0, 0.3), [Muscle(range(1, 16))]
    >>> target = solve_internal(mesh, mat, mus, [0.15]).x
    >>> fig = plot_design(mesh, design_contractions(mesh, mat, mus, target), target, mus)
    >>> "difference" in fig.axes[0].get_title()
    True
    """
    fig, ax = _axes(ax)
    plot_mesh(mesh, np.asarray(target), ax=ax, color="#cccccc", edgecolor="#999999", alpha=0.6, label="target")
    plot_mesh(mesh, result.x_aligned, ax=ax, color="#8fb3d9", edgecolor="#335577", alpha=0.45,
              label="driven (aligned)")
    if len(muscles):
        plot_muscles(result.x_aligned, muscles, ax=ax)
    a = ", ".join(f"{c:.3f}" for c in result.contractions)
    ok = "" if result.success else "  [FAILED]"
    ax.set_title(title or f"{result.method}: a = [{a}], difference {result.difference:.3g}{ok}", fontsize=9)
    ax.legend(fontsize=7, **_LEGEND_OUTSIDE)
    return fig


def plot_design_benchmark(rows, traces=None, ax=None):
    """Difference against time for the design methods (``tests/benchmarks/bench_design.py``).

    ``rows``: dicts with ``method``, ``mesh``, ``muscles``, ``solve_time``, ``difference`` (one marker per run:
    colour = method, marker = mesh size, size = muscle count). ``traces``: optional
    ``{(mesh, muscles, method): [(t, difference), ...]}``; the best difference so far of the outer loops is
    drawn as lines for the largest case present.
    """
    fig, ax = _axes(ax, figsize=(7.5, 5))
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
    ax.set_xlabel("solve time (s)")
    ax.set_ylabel("final difference (length)")
    for method, c in colors.items():
        ax.scatter([], [], color=c, label=method)
    for i, mname in enumerate(meshes):
        ax.scatter([], [], color="grey", marker=markers[i % len(markers)], label=f"{mname} nodes")
    ax.legend(fontsize=7, loc="upper right")
    ax.set_title("contraction design: difference against time (marker size ~ muscle count)")
    ax.grid(True, which="major", alpha=0.3)
    return fig


# --- problem library and scenes (issue 6) ---
def plot_scene(mesh, regions=None, ax=None, title=None, markersize=4):
    """The rest mesh with its named node regions (``{name: node indices}``) marked in colour.

    Example
    -------
    >>> from mdsr_opt import Mesh
    >>> mesh = Mesh.rectangle(2.0, 1.0, 4, 2)
    >>> fig = plot_scene(mesh, {"left": [0, 5, 10]}, title="strip")
    >>> fig.axes[0].get_legend_handles_labels()[1]
    ['left']
    """
    fig, ax = _axes(ax, figsize=(7, 4.5))
    plot_mesh(mesh, None, ax=ax, color="#dde6f0", edgecolor="#9aaabb")
    cyc = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, (name, idx) in enumerate((regions or {}).items()):
        p = mesh.points[np.asarray(idx, dtype=int)]
        ax.plot(p[:, 0], p[:, 1], "o", ms=markersize, color=cyc[i % len(cyc)], label=name)
    if regions:
        ax.legend(fontsize=7, **_LEGEND_OUTSIDE)
    ax.set_title(title or f"rest mesh: {mesh.n_nodes} nodes, {mesh.n_triangles} triangles", fontsize=9)
    return fig


def plot_target(mesh, target, anchors=(), drag_nodes=(), drag_positions=None, muscles=(), values=None,
                ax=None, title=None, colorbar_label="strain energy density"):
    """A target shape over the rest outline: anchors (black), drag nodes (red, with their paths from rest).

    Parameters
    ----------
    mesh : the rest mesh; target : (n, 2) target positions.
    anchors, drag_nodes : node indices; drag_positions : (d, 2) where the drags go (default: ``target``).
    muscles : muscles to draw over the target (e.g. an internal-driving case's).
    values : per-triangle values to colour the target by (e.g. strain energy density).
    """
    fig, ax = _axes(ax, figsize=(7, 4.5))
    x = np.asarray(target, dtype=float)
    for loop in mesh.boundary_loops:
        p = mesh.points[np.append(loop, loop[0])]
        ax.plot(p[:, 0], p[:, 1], "-", color="#aaaaaa", lw=0.8)
    plot_mesh(mesh, x, ax=ax, values=values, colorbar_label=colorbar_label if values is not None else None,
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
    if len(anchors) or len(dn) or len(muscles):
        ax.legend(fontsize=7, **_LEGEND_OUTSIDE)
    ax.autoscale_view()
    if title:
        ax.set_title(title, fontsize=9)
    return fig


def save_animation(mesh, states, path, muscles=(), activations=None, titles=None, fps=8.0, rest=True,
                   figsize=(6, 4), dpi=90) -> str:
    """Write a sequence of states as an animated GIF (matplotlib's PillowWriter), atomically.

    Parameters
    ----------
    mesh : the rest mesh; states : sequence of (n, 2) states, one per frame.
    muscles : muscles drawn over every frame; activations : (frames, m) values in [0, 1] that set each
        muscle's line width and opacity (e.g. contraction / a_max).
    titles : one title per frame; fps : frames per second.
    rest : draw the rest outline in grey behind every frame.

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
    from matplotlib.animation import FuncAnimation, PillowWriter

    states = [np.asarray(s, dtype=float) for s in states]
    if not states:
        raise ValueError("an animation needs at least one state")
    for i, s in enumerate(states):
        if s.shape != (mesh.n_nodes, 2):
            raise ValueError(f"states[{i}] must have shape ({mesh.n_nodes}, 2), got {s.shape}")
    muscles = list(muscles)
    act = None if activations is None else np.asarray(activations, dtype=float).reshape(len(states), -1)
    allp = np.vstack(states + ([mesh.points] if rest else []))
    lo, hi = allp.min(0), allp.max(0)
    pad = 0.05 * float((hi - lo).max())
    fig, ax = plt.subplots(figsize=figsize)
    cyc = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    # the artists are made once and updated per frame (clearing the axes and redrawing everything made the
    # GIFs the slowest part of a scene's figures)
    if rest:
        for loop in mesh.boundary_loops:
            p = mesh.points[np.append(loop, loop[0])]
            ax.plot(p[:, 0], p[:, 1], "-", color="#bbbbbb", lw=0.8)
    body = PolyCollection(states[0][mesh.triangles], facecolors="#8fb3d9", edgecolors="#335577", linewidths=0.25)
    ax.add_collection(body)
    lines = [ax.plot([], [], "-", color=cyc[i % len(cyc)])[0] for i in range(len(muscles))]
    paths = [list(m.nodes) for m in muscles]
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    title = ax.set_title("", fontsize=9)

    def draw(k):
        x = states[k]
        body.set_verts(x[mesh.triangles])
        for i, (line, p) in enumerate(zip(lines, paths)):
            a = 1.0 if act is None else float(np.clip(act[k, i], 0.0, 1.0))
            line.set_data(x[p, 0], x[p, 1])
            line.set_linewidth(0.8 + 2.5 * a)
            line.set_alpha(0.35 + 0.65 * a)
        title.set_text(titles[k] if titles is not None else f"frame {k + 1}/{len(states)}")
        return []

    path = os.fspath(path)
    try:
        with atomic_path(path, suffix=".gif") as tmp:
            FuncAnimation(fig, draw, frames=len(states), blit=False).save(
                tmp, writer=PillowWriter(fps=fps), dpi=dpi)
    finally:
        plt.close(fig)
    return path


# --- solver comparison studies (issue 7) ---
_STUDY_FAILURE_COLORS = {"none": "#2ca02c", "no convergence": "#ff7f0e", "inverted elements": "#d62728",
                         "self-overlap": "#e377c2", "saddle": "#9467bd", "time-out": "#7f7f7f",
                         "error": "#111111"}


def _study_colors(methods):
    cyc = plt.rcParams["axes.prop_cycle"].by_key()["color"] + ["#393b79", "#8c6d31", "#843c39"]
    return {m: cyc[i % len(cyc)] for i, m in enumerate(methods)}


def _study_time(r):
    return max(r["build_time"] + r["solve_time"], 1e-4)


def plot_study_pareto(rows, axes=None, title=None, floor=1e-14):
    """Accuracy against time for a study's runs, with the Pareto front of each method.

    One panel per kind present: equilibrium runs (state error over body size, against the reference) and
    design runs (largest contraction error). Filled markers are successful runs, crosses failed ones (their
    last state). The line of each method joins its non-dominated successful runs: no faster run of that
    method is more accurate. Time is build plus solve time, log scale; errors below ``floor`` are drawn at it.

    Parameters
    ----------
    rows : list of dict
        Rows of :class:`mdsr_opt.study.StudyResult`.
    axes : sequence of Axes, optional
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    from .study import pareto_front

    kinds = [k for k in ("equilibrium", "design") if any(r["kind"] == k for r in rows)]
    if axes is None:
        fig, axes = plt.subplots(1, len(kinds), figsize=(6.5 * len(kinds), 4.8), squeeze=False)
        axes = axes[0]
    fig = axes[0].figure
    colors = _study_colors(list(dict.fromkeys(r["method"] for r in rows)))
    ylabels = {"equilibrium": "max node error / body size (vs reference)", "design": "max contraction error"}
    for ax, kind in zip(axes, kinds):
        rs = [r for r in rows if r["kind"] == kind and np.isfinite(r["error"])]
        for m in dict.fromkeys(r["method"] for r in rs):
            mr = [r for r in rs if r["method"] == m]
            ok = [r for r in mr if r["success"]]
            bad = [r for r in mr if not r["success"]]
            c = colors[m]
            if ok:
                t = np.array([_study_time(r) for r in ok])
                e = np.maximum([r["error"] for r in ok], floor)
                ax.scatter(t, e, color=c, s=16, alpha=0.75, label=m)
                f = pareto_front(t, e)
                ax.step(t[f], e[f], where="post", color=c, lw=1.2)
            if bad:
                ax.scatter([_study_time(r) for r in bad], np.maximum([r["error"] for r in bad], floor),
                           color=c, marker="x", s=18, alpha=0.6, label=None if ok else f"{m} (failed)")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("build + solve time (s)")
        ax.set_ylabel(ylabels[kind])
        ax.set_title(f"{kind}: accuracy against time (x = failed run)", fontsize=9)
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=7, **_LEGEND_OUTSIDE)
    if title:
        fig.suptitle(f"study {title}", fontsize=10)
    return fig


def plot_study_scaling(rows, slopes=None, ax=None, title=None):
    """Time against node count on log-log axes, one colour per method, with the fitted power law.

    ``slopes``: ``{method: (slope, intercept, n)}`` from :func:`mdsr_opt.study.fit_slopes` (computed when
    omitted); the legend gives each slope. Only successful runs are drawn.
    """
    from .study import fit_slopes

    fig, ax = _axes(ax, figsize=(7, 5))
    slopes = fit_slopes(rows) if slopes is None else slopes
    methods = list(dict.fromkeys(r["method"] for r in rows))
    colors = _study_colors(methods)
    for m in methods:
        ok = [r for r in rows if r["method"] == m and r["success"]]
        if not ok:
            continue
        n = np.array([r["nodes"] for r in ok], dtype=float)
        t = np.array([_study_time(r) for r in ok])
        fit = slopes.get(m)
        lab = f"{m}: slope {fit[0]:.2f}" if fit else f"{m}: one size"
        ax.scatter(n, t, color=colors[m], s=14, alpha=0.7, label=lab)
        if fit:
            xs = np.array([n.min(), n.max()])
            ax.plot(xs, 10 ** (fit[1] + fit[0] * np.log10(xs)), "-", color=colors[m], lw=1.2)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("mesh nodes")
    ax.set_ylabel("build + solve time (s)")
    ax.set_title(f"study {title}: time against nodes (fitted time ~ nodes^slope)" if title else
                 "time against nodes (fitted time ~ nodes^slope)", fontsize=9)
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(fontsize=7, loc="upper left")
    return fig


def _study_cell_label(r, varying):
    parts = []
    for k in varying:
        v = r[k]
        if k == "load":
            parts.append(f"{v:g}")
        elif k == "resolution":
            parts.append(f"n{r['nodes']}")
        elif k == "material":
            parts.append({"neo-hookean": "NH", "linear": "lin"}.get(v, v))
        else:
            parts.append(str(v))
    return " ".join(parts)


def plot_study_success(rows, title=None, max_cols=2, fig=None):
    """The success map: for each problem a grid of methods (rows) against the other varying settings (load,
    first guess, mesh, material; columns), each cell coloured by its failure reason and labelled with the
    iteration count. Empty cells were not run (a node cap, or a design method on an equilibrium problem).
    ``fig``: an empty figure to draw the panels into (default: a new one). Returns the figure."""
    from matplotlib.patches import Patch

    problems = list(dict.fromkeys(r["problem"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    keys = ("load", "guess", "resolution", "material")
    varying = [k for k in keys if len({r[k] for r in rows}) > 1]
    ncol = min(max_cols, len(problems))
    nrow = int(np.ceil(len(problems) / ncol))
    widths = []
    cols_of = {}
    for p in problems:
        rs = [r for r in rows if r["problem"] == p]
        cols = list(dict.fromkeys(tuple(r[k] for k in varying) for r in rs))
        cols_of[p] = cols
        widths.append(max(len(cols), 1))
    w = max(widths)
    size = (max(4.0, 0.42 * w + 2.2) * ncol, 0.38 * len(methods) * nrow + 2.4)
    fig, axes = _panels(fig, nrow, ncol, size)
    codes = {f: i for i, f in enumerate(_STUDY_FAILURE_COLORS)}
    from matplotlib.colors import ListedColormap

    cmap = ListedColormap(list(_STUDY_FAILURE_COLORS.values())).with_extremes(bad="#f3f3f3")
    for ax, p in zip(axes.ravel(), problems):
        cols = cols_of[p]
        grid = np.full((len(methods), len(cols)), np.nan)
        text = {}
        labels = [""] * len(cols)
        for r in rows:
            if r["problem"] != p:
                continue
            j = cols.index(tuple(r[k] for k in varying))
            i = methods.index(r["method"])
            grid[i, j] = codes.get(r["failure"], codes["error"])
            text[(i, j)] = str(r["iterations"])
            labels[j] = _study_cell_label(r, varying)
        ax.imshow(np.ma.masked_invalid(grid), cmap=cmap, vmin=-0.5, vmax=len(codes) - 0.5, aspect="auto",
                  interpolation="nearest")
        for (i, j), s in text.items():
            ax.text(j, i, s, ha="center", va="center", fontsize=5.5,
                    color="white" if grid[i, j] in (codes["error"], codes["saddle"], codes["inverted elements"])
                    else "black")
        ax.set_yticks(range(len(methods)))
        ax.set_yticklabels(methods, fontsize=7)
        ax.set_xticks(range(len(cols)))
        ax.set_xticklabels(labels, rotation=90, fontsize=6)
        ax.set_title(p, fontsize=9)
        ax.set_xticks(np.arange(-0.5, len(cols), 1), minor=True)
        ax.set_yticks(np.arange(-0.5, len(methods), 1), minor=True)
        ax.grid(which="minor", color="white", lw=0.8)
        ax.tick_params(which="minor", length=0)
    for ax in axes.ravel()[len(problems):]:
        ax.axis("off")
    handles = [Patch(color=c, label=f) for f, c in _STUDY_FAILURE_COLORS.items()]
    handles.append(Patch(color="#f3f3f3", label="not run"))
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=7, frameon=False)
    head = "columns: " + ", ".join(varying) if varying else ""
    fig.suptitle(f"study {title}: failure reason per run (numbers: iterations); {head}" if title else
                 f"failure reason per run (numbers: iterations); {head}", fontsize=9)
    fig.tight_layout(rect=(0, 0.06, 1, 0.95))
    return fig


def plot_fidelity(rows, choices, title=None, max_cols=3, fig=None):
    """Fidelity: per scene, error against mesh nodes for each material model, the tolerances as dashed lines
    and the helper's choice for each tolerance circled.

    ``rows``: study rows of the candidates (``problem``, ``load``, ``material``, ``nodes``, ``error``,
    ``success``); ``choices``: dicts with ``problem``, ``load``, ``tol``, ``nodes``, ``material``, ``error``,
    ``met``. ``fig``: an empty figure to draw the panels into (default: a new one). Returns the figure.
    """
    scenes = list(dict.fromkeys((r["problem"], r["load"]) for r in rows))
    ncol = min(max_cols, len(scenes))
    nrow = int(np.ceil(len(scenes) / ncol))
    fig, axes = _panels(fig, nrow, ncol, (4.4 * ncol, 3.6 * nrow))
    mats = list(dict.fromkeys(r["material"] for r in rows))
    colors = _study_colors(mats)
    for ax, (p, load) in zip(axes.ravel(), scenes):
        for m in mats:
            rs = sorted((r for r in rows if r["problem"] == p and r["load"] == load and r["material"] == m),
                        key=lambda r: r["nodes"])
            if not rs:
                continue
            n = [r["nodes"] for r in rs]
            e = [max(r["error"], 1e-12) if np.isfinite(r["error"]) else np.nan for r in rs]
            ax.plot(n, e, "-o", color=colors[m], ms=4, label=m)
            bad = [(a, b) for a, b, r in zip(n, e, rs) if not r["success"]]
            if bad:
                ax.plot(*zip(*bad), "x", color="k", ms=7, label=None)
        picked = {}
        for c in choices:
            if c["problem"] == p and c["load"] == load:
                ax.axhline(c["tol"], ls="--", color="grey", lw=0.8)
                if c["met"]:
                    picked.setdefault((c["nodes"], c["material"], max(c["error"], 1e-12)), []).append(c["tol"])
        for (nodes, mat, err), tols in picked.items():
            ax.plot(nodes, err, "o", mfc="none", mec="k", ms=11, mew=1.3)
            ax.annotate(f"tol {', '.join(f'{t:g}' for t in tols)}: {mat}, {nodes} nodes", (nodes, err),
                        fontsize=6, xytext=(4, 4), textcoords="offset points")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("mesh nodes")
        ax.set_ylabel("max node error / body size")
        ax.set_title(f"{p}, load {load:g}", fontsize=9)
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=7, loc="upper right")
    for ax in axes.ravel()[len(scenes):]:
        ax.axis("off")
    fig.suptitle(title or "fidelity: error against the finest model (x = failed; circles = chosen)", fontsize=10)
    fig.tight_layout()
    return fig
