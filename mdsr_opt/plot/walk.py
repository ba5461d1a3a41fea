"""Chart of a walk on the table: the body's displacement against the gait cycle."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from .style import axis_label

__all__ = ["plot_walk", "plot_walk_refinement"]


def plot_walk(result, ax=None, title: str | None = None):
    """The centroid's displacement (x, y and the distance from the start) and the body's rotation against the
    cycle, every frame drawn as a fraction of its cycle and every cycle's end marked; the frames that failed
    marked red. ``result`` is a :class:`~mdsr_opt.synthesis.walk.WalkResult` (its fields are read; nothing of
    the synthesis stage is imported). Returns the figure."""
    if ax is None:
        fig, ax = plt.subplots(figsize=(7.0, 3.8))
    else:
        fig = ax.figure
    S = np.asarray(result.states, dtype=float)
    # frame k >= 1 is frame (k - 1) of the cycles; the cycles start at frame 1 (the cycle's first frame)
    t = np.concatenate([[0.0], np.arange(S.shape[0] - 1) / result.cycle_frames])
    d = np.asarray(result.centroids, dtype=float)
    dist = np.hypot(*d.T)
    for y, lab, col in ((d[:, 0], "x", "#1f77b4"), (d[:, 1], "y", "#2ca02c"), (dist, "distance", "#333333")):
        ax.plot(t[1:], y[1:], "-", color=col, lw=1.0, alpha=0.6)
        ends = np.arange(1, S.shape[0], result.cycle_frames)
        ax.plot(t[ends], y[ends], "o", color=col, ms=5, label=f"centroid {lab}")
    bad = ~np.asarray(result.frame_success, bool)
    if bad.any():
        ax.plot(t[bad], d[bad, 0], "rx", ms=8, label="frame solve failed")
    ax.axhline(0.0, color="0.6", lw=0.6, zorder=0)
    ax.set_xlabel(axis_label("gait cycle", "1"))
    ax.set_ylabel(axis_label("displacement", result.units))
    rot = np.degrees(np.asarray(result.turns, dtype=float))[1:]
    ax2 = ax.twinx()
    ax2.plot(t[1:], rot, "--", color="#d62728", lw=1.0, label="rotation")
    ax2.set_ylabel(axis_label("rotation", "deg"), color="#d62728")
    per = np.asarray(result.displacement).mean(0) if len(result.displacement) else np.zeros(2)
    ax.set_title(title or f"walk on the table, mu = {result.mu:g}: {np.hypot(*per):.4g} {result.units} per cycle, "
                 f"{np.degrees(np.mean(result.rotation)):.3g} deg per cycle", fontsize=9)
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, fontsize=7, loc="upper left", bbox_to_anchor=(1.12, 1.0), borderaxespad=0.0)
    fig.tight_layout()
    return fig


def plot_walk_refinement(levels, ax=None, title: str | None = None, estimate: dict | None = None):
    """A walk's refinement study: the distance per cycle (the last cycle, and every cycle as small marks)
    against the number of nodes, one point per mesh. ``levels`` is a sequence of ``(n_nodes, WalkResult)``
    (coarsest first; e.g. from :func:`~mdsr_opt.synthesis.walkstudy.walk_refinement`, its meshes' node counts).
    ``estimate``, if given, is :func:`~mdsr_opt.synthesis.walkstudy.richardson` of the last cycles: its
    extrapolated limit is drawn as a dashed line in a band of its error. Returns the figure."""
    if ax is None:
        fig, ax = plt.subplots(figsize=(5.5, 3.6))
    else:
        fig = ax.figure
    n = np.array([int(k) for k, _ in levels], dtype=float)
    last = np.array([float(r.distance[-1]) if r.cycles else np.nan for _, r in levels])
    for k, (_, r) in zip(n, levels):
        ax.plot(np.full(r.cycles, k), r.distance, "_", color="0.5", ms=10)
    ax.plot(n, last, "o-", color="#1f77b4", label="last cycle")
    if estimate is not None and estimate.get("extrapolated") is not None:
        v, e = float(estimate["extrapolated"]), float(estimate["error"])
        ax.axhspan(v - e, v + e, color="#1f77b4", alpha=0.12, lw=0)
        order = estimate.get("order")
        ax.axhline(v, color="#1f77b4", ls="--", lw=1, label=f"limit {v:.4g} ± {e:.2g}"
                   + (f" (Richardson, order {order:.2g})" if order is not None else " (last change)"))
    bad = np.array([not r.success for _, r in levels])
    if bad.any():
        ax.plot(n[bad], last[bad], "rx", ms=9, label="a frame failed")
    ax.set_xscale("log")
    ax.set_xticks(n, [str(int(k)) for k in n])
    ax.xaxis.set_minor_locator(plt.NullLocator())
    ax.set_xlabel("nodes")
    units = levels[0][1].units if len(levels) else ""
    ax.set_ylabel(axis_label("distance per cycle", units))
    ax.set_title(title or "walk: distance per cycle under mesh refinement (same layout)", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig
