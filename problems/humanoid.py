"""Humanoid figure: the third of the paper's three MDSR bodies, the one it built as a prototype.

The paper tests its muscle routing and contraction design on five deformations of three MDSR bodies made
by external driving (its Figure 6, Table 1) and builds the third body, "in a humanoid figure", in
silicone with sliding-rope muscles (its Figure 7). This scene is that figure in a T-pose: head, neck,
torso, two arms held out sideways and two legs, 8.2 units tall, with two of the five deformations:
``raise_arms`` (the torso anchored, both hands carried up round arcs about the shoulders by ``RAISE``
rad) and ``lean`` (the feet anchored, the head and both hands carried by the spine bent ``LEAN`` rad to
the right about the hips). ``four_muscles.py`` uses the same body for the paper's four-muscle experiment.

The shapes are drawn by the mdsr_opt authors from the paper's descriptions (it gives no geometry); they
are not the paper's meshes.

Material: ``NeoHookean(E=1.0, nu=0.4)`` in plane strain, in units where E = 1 (E scales forces and energies
only: drag- and stroke-driven shapes do not depend on it). Plane strain at nu = 0.4 is the law the library's
results were made and checked with, kept so they stay comparable; a cast silicone robot is a thin, nearly
incompressible sheet (``NeoHookean(1.0, 0.5, plane="stress")`` or ``silicone(...)``), which moves no node of
these cases by more than 0.5 % of the largest motion (default resolution).

Run ``python problems/humanoid.py --out out/humanoid`` or ``mdsr run humanoid --out out/humanoid``.
"""

from __future__ import annotations

import numpy as np

from mdsr_opt import NeoHookean
from mdsr_opt.scenes.scene import Case, Scene, mesh_polygon, resolve_resolution, seeds_for
from mdsr_opt.scenes.shapes import arc_rigid
from mdsr_opt.scenes.select import nodes_in_box
from mdsr_opt.scenes.runscene import run_main

RAISE = 0.9        # radians each arm is raised
LEAN = 0.35        # radians the spine bends to the right
HEAD_C, HEAD_R = (0.0, 4.3), 0.85
SHOULDER_Y = 2.85  # the arms' centre line


def outline(n_head: int = 20) -> np.ndarray:
    """The figure's outline, counter-clockwise from the left foot's outer corner."""
    right_half = [(0.15, -0.25), (0.2, -3.0), (1.0, -3.0), (1.0, 2.4), (3.5, 2.5), (3.5, 3.2), (1.0, 3.3),
                  (0.35, 3.4)]
    a0 = np.arcsin(0.35 / HEAD_R)              # where the neck meets the head
    th = np.linspace(-np.pi / 2 + a0, 3 * np.pi / 2 - a0, n_head)
    head = np.column_stack([HEAD_C[0] + HEAD_R * np.cos(th), HEAD_C[1] + HEAD_R * np.sin(th)])
    left_half = [(-x, y) for x, y in reversed(right_half)]
    pts = [(0.0, -0.15)] + right_half + head.tolist() + left_half
    # start at the left foot's outer corner so the outline reads foot, crotch, foot, arm, head, arm
    pts = np.array(pts)
    k = int(np.argmin(pts[:, 0] + 10 * pts[:, 1]))
    return np.roll(pts, -k, axis=0)


def body(resolution="medium"):
    """The figure's mesh and material (shared with ``four_muscles.py``)."""
    n = resolve_resolution(resolution)
    return mesh_polygon(outline(max(12, int(np.sqrt(n)))), resolution=n), NeoHookean(E=1.0, nu=0.4)


def build(resolution="medium") -> Scene:
    """The humanoid scene: cases ``raise_arms`` and ``lean`` (external driving, muscles routed)."""
    mesh, material = body(resolution)
    P = mesh.points
    regions = {
        "torso": nodes_in_box(mesh, -0.6, 0.6, 0.6, 2.0),
        "feet": nodes_in_box(mesh, ymax=-2.8),
        "head": nodes_in_box(mesh, ymin=HEAD_C[1] - 0.3),
        "right_hand": nodes_in_box(mesh, xmin=3.1),
        "left_hand": nodes_in_box(mesh, xmax=-3.1),
    }
    rh, lh = regions["right_hand"], regions["left_hand"]
    up_r = arc_rigid(P[rh], (3.1, SHOULDER_Y), (1.0, SHOULDER_Y), (1.0, 0.0), 2.1, RAISE)
    up_l = arc_rigid(P[lh], (-3.1, SHOULDER_Y), (-1.0, SHOULDER_Y), (-1.0, 0.0), 2.1, -RAISE)
    spine = dict(origin=(0.0, 0.0), direction=(0.0, 1.0), length=HEAD_C[1], angle=-LEAN)
    head = regions["head"]
    lean = np.vstack([arc_rigid(P[head], HEAD_C, **spine), arc_rigid(P[rh], (0.0, SHOULDER_Y), **spine),
                      arc_rigid(P[lh], (0.0, SHOULDER_Y), **spine)])
    cases = (
        Case("raise_arms", anchors=regions["torso"], drag_nodes=np.concatenate([rh, lh]),
             drag_positions=np.vstack([up_r, up_l]), description=f"torso anchored, both arms raised {RAISE} rad"),
        Case("lean", anchors=regions["feet"], drag_nodes=np.concatenate([head, rh, lh]), drag_positions=lean,
             description=f"feet anchored, upper body bent {LEAN} rad to the right"),
    )
    return Scene(
        name="humanoid", title="Humanoid figure (MDSR body 3 of 3, the paper's prototype): raise arms, lean",
        description=__doc__.split("\n\n")[1].replace("\n", " "), mesh=mesh, material=material, cases=cases,
        regions=regions, routing_options={"K_a": 10.0, "K_b": 4.0, "max_muscles": 4, "n_seeds": seeds_for(mesh)},
        design_options={"method": "flattened", "a_max": 0.6},
        expected={"max_muscles": 4}, resolution=resolve_resolution(resolution), source=__file__)


if __name__ == "__main__":
    raise SystemExit(run_main(build))
