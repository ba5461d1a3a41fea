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

Material: ``NeoHookean(E=1.0, nu=0.4)`` in plane strain, in units where E = 1 (E scales forces and energies
only: drag- and stroke-driven shapes do not depend on it). Plane strain at nu = 0.4 is the law the library's
results were made and checked with, kept so they stay comparable; a cast silicone robot is a thin, nearly
incompressible sheet (``NeoHookean(1.0, 0.5, plane="stress")`` or ``silicone(...)``), which moves no node of
these cases by more than 0.4 % of the largest motion (default resolution).

Run ``python problems/gecko.py --out out/gecko`` or ``mdsr run gecko --out out/gecko``.
"""

from __future__ import annotations

import numpy as np

from mdsr_opt import NeoHookean
from mdsr_opt.synthesis.gait import Gait
from mdsr_opt.scenes.scene import Animation, Case, Scene, mesh_polygon, resolve_resolution
from mdsr_opt.scenes.shapes import arc_map, arc_rigid
from mdsr_opt.scenes.select import nodes_in_box, nodes_near
from mdsr_opt.scenes.runscene import run_main

BEND = 0.55          # radians of bend on each side of the trunk's middle
MIDDLE = 5.5         # x of the anchored middle of the trunk

# the lower (right-hand, y < 0) half of the outline from tail tip to snout; the upper half is its mirror
_LOWER = [(0.0, -0.12), (1.5, -0.25), (3.0, -0.45), (3.6, -0.7),
          (3.8, -0.8), (3.0, -2.0), (2.8, -2.4), (3.3, -2.6), (3.55, -2.25), (4.4, -0.85),   # hind leg
          (5.5, -0.9),
          (6.6, -0.85), (7.2, -2.05), (7.05, -2.45), (7.55, -2.6), (7.75, -2.2), (7.2, -0.8),  # front leg
          (7.8, -0.55), (8.2, -0.5), (8.8, -0.7), (9.5, -0.55)]


def outline() -> np.ndarray:
    """The gecko's outline, counter-clockwise (right side first, from the blunt tail tip to the snout)."""
    lower = np.array(_LOWER)
    upper = lower[::-1] * [1.0, -1.0]
    return np.vstack([lower, [[10.0, 0.0]], upper])


def bent(points: np.ndarray, side: int, root: tuple[float, float] | None = None) -> np.ndarray:
    """The C-bend of the body, concave to the left (``side=+1``, +y) or right (``side=-1``).

    Without ``root`` every point follows the bent spine (``arc_map``); with ``root`` (a point on the
    body) the points move rigidly with the spine's frame there (``arc_rigid``): how a foot, the head or
    the tail tip is carried.
    """
    P = np.asarray(points, dtype=float)
    ref = P[:, 0] if root is None else np.full(len(P), float(root[0]))
    head = ref >= MIDDLE
    out = P.copy()
    for sel, d, L, a in ((head, (1.0, 0.0), 10.0 - MIDDLE, side * BEND),
                         (~head, (-1.0, 0.0), MIDDLE, -side * BEND)):
        if sel.any():
            out[sel] = (arc_map(P[sel], (MIDDLE, 0.0), d, L, a) if root is None
                        else arc_rigid(P[sel], root, (MIDDLE, 0.0), d, L, a))
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
    }
    # each group is carried rigidly by the spine's frame at its root (hip, shoulder, neck, tail)
    groups = [(regions["head"], (9.2, 0.0)), (regions["tail"], (0.8, 0.0))]
    for foot_y, hip_x, fx in ((-1, 4.1, 3.2), (-1, 6.9, 7.4), (1, 4.1, 3.2), (1, 6.9, 7.4)):
        foot = nodes_near(mesh, (fx, 2.35 * foot_y), 0.45)
        groups.append((foot, (hip_x, 0.0)))
    regions["feet"] = np.concatenate([g for g, _ in groups[2:]])
    driven = np.concatenate([g for g, _ in groups])
    cases = []
    for name, side in (("bend_left", 1), ("bend_right", -1)):
        pos = np.vstack([bent(P[g], side, root) for g, root in groups])
        cases.append(Case(name, anchors=regions["middle"], drag_nodes=driven, drag_positions=pos,
                          description=f"spine bent {'left' if side > 0 else 'right'} by {2 * BEND:.2f} rad"))
    gait = Animation("gait", (("rest", 0.0), ("bend_left", 1.0), ("rest", 0.0), ("bend_right", 1.0),
                              ("rest", 0.0)), frames_per_step=5)
    return Scene(
        name="gecko", title="Gecko (paper Figure 11a): left and right bending, alternating as a gait",
        description=__doc__.split("\n\n")[2].replace("\n", " "), mesh=mesh,
        material=NeoHookean(E=1.0, nu=0.4), cases=tuple(cases), regions=regions,
        routing_options={"K_a": 10.0, "K_b": 4.0, "max_muscles": 2},
        design_options={"method": "flattened", "a_max": 0.6}, animations=(gait,),
        expected={"n_muscles": {"bend_left": 2, "bend_right": 2}}, resolution=resolve_resolution(resolution),
        source=__file__, units="cm",
        # one muscle layout for both bends, alternated through the straight body (no co-contraction) (issue 16)
        gait=Gait("walk", ("bend_left", "rest", "bend_right", "rest"), frames_per_step=4, max_muscles=4))


if __name__ == "__main__":
    raise SystemExit(run_main(build))
