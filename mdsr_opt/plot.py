"""Figures (matplotlib; the only module that imports it). Every function takes an optional ``ax`` and
returns the matplotlib ``Figure``; ``save_figure`` writes a PNG atomically."""

from __future__ import annotations

import os
import tempfile

import numpy as np

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.collections import LineCollection, PolyCollection  # noqa: E402


def _axes(ax=None, figsize=(6, 4)):
    if ax is None:
        fig, ax = plt.subplots(figsize=figsize)
    return ax.figure, ax


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
    """Draw edges (k, 2) of configuration ``x`` coloured by ``values``; returns the LineCollection."""
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
    return lc


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


def save_figure(fig, path) -> str:
    """Write ``fig`` to ``path`` (PNG by extension) via a temporary file, so no partial file is left."""
    path = os.fspath(path)
    d = os.path.dirname(os.path.abspath(path))
    os.makedirs(d, exist_ok=True)
    suffix = os.path.splitext(path)[1] or ".png"
    fd, tmp = tempfile.mkstemp(suffix=suffix, dir=d)
    os.close(fd)
    try:
        fig.savefig(tmp, dpi=130, bbox_inches="tight")
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
        plt.close(fig)
    return path

# --- figures added by later modules go below this line ---
