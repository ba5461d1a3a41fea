"""Gecko: a sprawling lizard that walks by bending its spine left and right.

The paper (its Figure 11a) defines two deformations of a gecko-shaped body by dragging the body and feet
(external driving), bending to the left and to the right; routing yields one muscle bundle per side
([L1] and [R1]), and alternating the two contractions makes the crawling gait (its Supplementary Video).

The shapes are drawn by the mdsr_opt authors from the paper's descriptions (it gives no geometry); they
are not the paper's meshes. The body is 10 units from tail tip (x = 0) to snout (x = 10), mirror-symmetric
about the spine (y = 0), with four legs and feet. A target is the whole body bent into a C about the
middle of the trunk: the spine maps onto circular arcs (``arc_map``) of total angle ``2 * BEND``; the
middle of the trunk is anchored, and the head, the tail and the four feet are dragged to where that
bend puts them.

Run ``python problems/gecko.py --out out/gecko`` or ``mdsr run gecko --out out/gecko``.
"""

from __future__ import annotations

import numpy as np

from mdsr_opt import NeoHookean
from mdsr_opt.scenes import (Animation, Case, Scene, arc_map, mesh_polygon, nodes_in_box, nodes_near,
                             resolve_resolution, run_main)

BEND = 0.55          # radians of bend on each side of the trunk's middle
MIDDLE = 5.5         # x of the anchored middle of the trunk

# the lower (right-hand, y < 0) half of the outline from tail tip to snout; the upper half is its mirror
_LOWER = [(0.0, 0.0), (1.5, -0.2), (3.0, -0.45), (3.6, -0.7),
          (3.8, -0.8), (3.0, -2.0), (2.8, -2.4), (3.3, -2.6), (3.55, -2.25), (4.4, -0.85),   # hind leg
          (5.5, -0.9),
          (6.6, -0.85), (7.2, -2.05), (7.05, -2.45), (7.55, -2.6), (7.75, -2.2), (7.2, -0.8),  # front leg
          (7.8, -0.55), (8.2, -0.5), (8.8, -0.7), (9.5, -0.55)]


def outline() -> np.ndarray:
    """The gecko's outline, counter-clockwise (right side first, from the tail tip to the snout)."""
    lower = np.array(_LOWER)
    upper = lower[1:][::-1] * [1.0, -1.0]
    return np.vstack([lower, [[10.0, 0.0]], upper])


def bent(points: np.ndarray, side: int) -> np.ndarray:
    """The C-bend of the whole body, concave to the left (``side=+1``, +y) or right (``side=-1``)."""
    P = np.asarray(points, dtype=float)
    out = P.copy()
    head = P[:, 0] >= MIDDLE
    out[head] = arc_map(P[head], (MIDDLE, 0.0), (1.0, 0.0), 10.0 - MIDDLE, side * BEND)
    out[~head] = arc_map(P[~head], (MIDDLE, 0.0), (-1.0, 0.0), MIDDLE, -side * BEND)
    return out


def build(resolution="medium") -> Scene:
    """The gecko scene: cases ``bend_left`` and ``bend_right``, animation ``gait``."""
    mesh = mesh_polygon(outline(), resolution=resolution)
    P = mesh.points
    h = float(mesh.edge_lengths.mean())
    regions = {
        "middle": nodes_near(mesh, (MIDDLE, 0.0), max(0.3, 1.1 * h)),
        "head": nodes_in_box(mesh, xmin=9.2),
        "tail": nodes_in_box(mesh, xmax=0.8),
        "feet": np.concatenate([nodes_in_box(mesh, ymax=-2.15), nodes_in_box(mesh, ymin=2.15)]),
    }
    driven = np.concatenate([regions["head"], regions["tail"], regions["feet"]])
    cases = tuple(Case(name, anchors=regions["middle"], drag_nodes=driven, drag_positions=bent(P, side)[driven],
                       description=f"spine bent {'left' if side > 0 else 'right'} by {2 * BEND:.2f} rad")
                  for name, side in (("bend_left", 1), ("bend_right", -1)))
    gait = Animation("gait", (("rest", 0.0), ("bend_left", 1.0), ("rest", 0.0), ("bend_right", 1.0),
                              ("rest", 0.0)), frames_per_step=5)
    return Scene(
        name="gecko", title="Gecko (paper Figure 11a): left and right bending, alternating as a gait",
        description=__doc__.split("\n\n")[2].replace("\n", " "), mesh=mesh,
        material=NeoHookean(E=1.0, nu=0.4), cases=cases, regions=regions,
        routing_options={"K_a": 10.0, "K_b": 4.0, "max_muscles": 2},
        design_options={"method": "flattened", "a_max": 0.6}, animations=(gait,),
        expected={"n_muscles": {"bend_left": 2, "bend_right": 2}}, resolution=resolve_resolution(resolution),
        source=__file__)


if __name__ == "__main__":
    raise SystemExit(run_main(build))
