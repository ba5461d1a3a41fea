"""Study charts: accuracy against time, time against nodes, success maps, fidelity."""

from __future__ import annotations

from matplotlib.colors import ListedColormap
from matplotlib.patches import Patch
from matplotlib.ticker import NullFormatter
import matplotlib.pyplot as plt
import numpy as np

from ..core.stats import fit_slopes, pareto_front
from .common import LEGEND_OUTSIDE, axes_or_new, panel_axes, plain_log_ticks
from .style import axis_label

__all__ = ['plot_study_pareto', 'plot_study_scaling', 'plot_study_success', 'plot_fidelity',
           'plot_recommendation']


# --- solver comparison studies (issue 7) ---
_STUDY_FAILURE_COLORS = {"none": "#2ca02c", "no convergence": "#ff7f0e", "inverted elements": "#d62728",
                         "self-contact": "#e377c2", "iteration limit": "#bcbd22", "saddle": "#9467bd", "time-out": "#7f7f7f",
                         "error": "#111111"}


def _study_colors(methods):
    cyc = plt.rcParams["axes.prop_cycle"].by_key()["color"] + ["#393b79", "#8c6d31", "#843c39"]
    return {m: cyc[i % len(cyc)] for i, m in enumerate(methods)}


def _study_time(r):
    return max(r["build_time"] + r["solve_time"], 1e-4)


def _lost_time(r):
    """The time of a run that gave no result (a time-out's budget): its wall time when longer."""
    wall = r.get("wall_time", float("nan"))
    return max(_study_time(r), wall if np.isfinite(wall) else 0.0)


def plot_study_pareto(rows, axes=None, title=None, floor=1e-14):
    """Accuracy against time for a study's runs, with the Pareto front of each method.

    One panel per kind present: equilibrium runs (state error over body size, against the reference) and
    design runs (largest contraction error). Filled markers are successful runs, crosses failed ones (their
    last state); a failed run without an error (a time-out) is a cross at the top edge, at its time (its wall
    time when longer), and the panel's title counts them. The line of each method joins its non-dominated successful runs: no faster run of that
    method is more accurate. Time is build plus solve time, log scale; errors below ``floor`` are drawn at it.

    Parameters
    ----------
    rows : list of dict
        Rows of :class:`mdsr_opt.studies.study.StudyResult`.
    axes : sequence of Axes, optional
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    kinds = [k for k in ("equilibrium", "design") if any(r["kind"] == k for r in rows)]
    if axes is None:
        # wspace: room between the panels for the left panel's legend (placed beside its axes)
        fig, axes = plt.subplots(1, len(kinds), figsize=(7.5 * len(kinds), 4.8), squeeze=False,
                                 gridspec_kw={"wspace": 0.9})
        axes = axes[0]
    fig = axes[0].figure
    colors = _study_colors(list(dict.fromkeys(r["method"] for r in rows)))
    ylabels = {"equilibrium": "max node error / body size (-)", "design": "max contraction error (-)"}
    for ax, kind in zip(axes, kinds):
        rs = [r for r in rows if r["kind"] == kind and np.isfinite(r["error"])]
        lost = [r for r in rows if r["kind"] == kind and not np.isfinite(r["error"])]
        for m in dict.fromkeys(r["method"] for r in lost):  # no error to draw (a time-out ...): at the top edge
            t = [_lost_time(r) for r in lost if r["method"] == m]
            ax.scatter(t, np.ones(len(t)), transform=ax.get_xaxis_transform(), color=colors[m], marker="x",
                       s=28, clip_on=False, label=f"{m} (no result: {len(t)})")
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
        plain_log_ticks(ax)
        ax.xaxis.set_minor_formatter(NullFormatter())  # labelled minor ticks overlap on a short range
        ax.set_xlabel("build + solve time (s)")
        ax.set_ylabel(ylabels[kind])
        if lost:  # the top edge's crosses are in axes coordinates: the time axis must reach them
            t_all = [_study_time(r) for r in rs] + [_lost_time(r) for r in lost]
            ax.set_xlim(min(t_all) / 1.5, max(t_all) * 1.5)
            if not rs:
                ax.set_ylim(floor, 1.0)
        ax.set_title(f"{kind}: accuracy against time (x = failed run" + (
            f"; {len(lost)} with no result: x on the top edge)" if lost else ")"),
            fontsize=9)
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=7, **LEGEND_OUTSIDE)
    if title:
        fig.suptitle(f"study {title}", fontsize=10)
    return fig


def plot_study_scaling(rows, slopes=None, ax=None, title=None):
    """Time against node count on log-log axes, one colour per method, with the fitted power law.

    ``slopes``: ``{method: (slope, intercept, n)}`` from :func:`mdsr_opt.core.stats.fit_slopes` (computed when
    omitted); the legend gives each slope. Only successful runs are drawn.
    """
    fig, ax = axes_or_new(ax, figsize=(7, 5))
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
    ax.set_xlabel(axis_label("mesh nodes", "count"))
    ax.set_ylabel("build + solve time (s)")
    plain_log_ticks(ax)
    ax.set_title(f"study {title}: time against nodes (fitted time ~ nodes^slope)" if title else
                 "time against nodes (fitted time ~ nodes^slope)", fontsize=9)
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(fontsize=7, **LEGEND_OUTSIDE)  # beside the axes: over no run
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
    fig, axes = panel_axes(fig, nrow, ncol, size)
    codes = {f: i for i, f in enumerate(_STUDY_FAILURE_COLORS)}

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
    fig, axes = panel_axes(fig, nrow, ncol, (4.4 * ncol, 3.6 * nrow))
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
        ax.set_xlabel(axis_label("mesh nodes", "count"))
        ax.set_ylabel(axis_label("max node error / body size", "1"))
        plain_log_ticks(ax)
        ax.set_title(f"{p}, load {load:g}", fontsize=9)
        ax.grid(True, which="major", alpha=0.3)
    for ax in axes.ravel()[len(scenes):]:
        ax.axis("off")
    fig.suptitle(title or "fidelity: error against the finest model (x = failed; circles = chosen)", fontsize=10)
    # one legend for every panel (the material models are the same), under the panels: over no curve
    handles = [plt.Line2D([], [], color=colors[m], marker="o", ms=4, label=m) for m in mats]
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=7, frameon=False)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    return fig


def plot_recommendation(rows, rec, ax=None, floor=1e-8):
    """One scene's recommendation chart: for every backend (colour) and mesh (label: nodes), the worst error
    over the scene's cases against the summed build + solve time, the tolerance as a dashed line and the
    recommendation circled. A combination with a failed case is a cross labelled with its failure reasons.

    ``rows``: the scene's run rows (``method``, ``resolution``, ``nodes``, ``error``, ``success``,
    ``failure``, ``build_time``, ``solve_time``); ``rec``: the recommendation as a dict (``scene``, ``tol``,
    ``met``, ``method``, ``resolution``). Returns the figure.
    """
    fig, ax = axes_or_new(ax, figsize=(7.5, 4.8))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    colors = _study_colors(methods)
    groups = {}
    for r in rows:
        groups.setdefault((r["method"], r["resolution"]), []).append(r)
    for (m, res), g in groups.items():
        t = max(sum(r["build_time"] + r["solve_time"] for r in g), 1e-4)
        errs = [r["error"] for r in g if np.isfinite(r["error"])]
        e = max(max(errs) if errs else 1.0, floor)
        nodes = max(r["nodes"] for r in g)
        fails = sorted({r["failure"] for r in g if not r["success"]})
        if fails:
            ax.scatter([t], [e], marker="x", s=40, color=colors[m])
            ax.annotate(f"{nodes}: {', '.join(fails)}", (t, e), fontsize=6, xytext=(4, -8),
                        textcoords="offset points", color=colors[m])
        else:
            ax.scatter([t], [e], s=28, color=colors[m])
            ax.annotate(str(nodes), (t, e), fontsize=6, xytext=(4, 3), textcoords="offset points")
        if (m, res) == (rec["method"], rec["resolution"]):
            ax.scatter([t], [e], s=200, facecolors="none", edgecolors="k", linewidths=1.4)
    for m in methods:
        ax.scatter([], [], color=colors[m], s=28, label=m)
    ax.axhline(rec["tol"], ls="--", color="grey", lw=0.9, label=f"tolerance {rec['tol']:g}")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("build + solve time summed over the cases (s)")
    ax.set_ylabel(axis_label("worst node error / body size, finer-mesh reference", "1"))
    pick = (f"recommended {rec['method']} at {rec['resolution']} (circled)" if rec["met"] else
            "no backend and mesh met the tolerance (closest circled)")
    ax.set_title(f"{rec['scene']}: {pick}; labels: nodes; x = a case failed", fontsize=9)
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=7, **LEGEND_OUTSIDE)
    fig.tight_layout()
    return fig
