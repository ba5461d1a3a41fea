"""Estimated run times of a scene run's jobs, by kind and size: the order in which a pool's free worker
takes them (:class:`~mdsr_opt.core.jobs.Jobs`, costliest first): scene runs and the gait runner.

Only the order matters: the figures are rough CPU seconds of one core, fitted to the jobs of ``mdsr run
all``, and a job's estimate grows with what makes it long (the nodes of the mesh solved, the frames drawn,
the muscles the virtual prototype pulls). A wrong estimate changes when a job starts, never what it
writes.
"""

from __future__ import annotations

__all__ = ["figure_cost", "shapes_cost", "photo_cost", "animation_cost", "gif_cost"]

#: one figure drawn and written (a PNG)
FIGURE = 0.2
#: one frame of a GIF drawn and quantised
GIF_FRAME = 0.04
#: one forward solve of an animation's frame, per node of the design mesh
FRAME_SOLVE_PER_NODE = 2e-4
#: the virtual prototype's solve, per node of its mesh and per muscle pulled (plus half a muscle: the
#: external driving's solve)
PROTOTYPE_PER_NODE = 5e-4
#: a synthetic photograph rendered, its contours compared, its overlay drawn
PHOTO = 0.6


def figure_cost(n: int = 1) -> float:
    """``n`` figures."""
    return FIGURE * n


def shapes_cost() -> float:
    """A case's shape figures (target, graph, muscles, design) and its two meshes."""
    return 4.5 * FIGURE


def photo_cost(prototype_nodes: int = 0, muscles: int = 0) -> float:
    """A case's photograph stage: the synthetic photograph and, with a virtual prototype of
    ``prototype_nodes`` nodes (0: none), its solves for ``muscles`` muscles."""
    return PHOTO + PROTOTYPE_PER_NODE * prototype_nodes * (muscles + 0.5)


def animation_cost(frames: int, nodes: int, gif: bool = True) -> float:
    """An animation of ``frames`` frames on a mesh of ``nodes`` nodes: its forward solves (a gait goes out
    and back: about half of its frames are solved) and, with ``gif``, its GIF."""
    return frames * (0.5 * FRAME_SOLVE_PER_NODE * nodes + (GIF_FRAME if gif else 0.0))


def gif_cost(frames: int) -> float:
    """A GIF of ``frames`` frames whose states are known."""
    return frames * GIF_FRAME
