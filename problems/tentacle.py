"""Tentacle: the first of the paper's three MDSR bodies, a tapered finger with two target deformations.

The paper tests its muscle routing and contraction design on five deformations of three MDSR bodies made
by external driving (its Figure 6, Table 1); the third body is a humanoid figure (``humanoid.py``), and
the paper does not draw the other two in words. This scene is our first body: a tapered finger, 6 units
long, 1.2 wide at its base and 0.5 at its rounded tip, with two of the five deformations, ``curl`` (the tip
carried round an arc through 1.8 rad) and ``s_curve`` (the middle bent one way, the tip back the other).
``one_muscle.py`` uses the same body for the paper's one-muscle experiment.

The shapes are drawn by the mdsr_opt authors from the paper's descriptions (it gives no geometry); they
are not the paper's meshes. The base (x = 0) is anchored; the dragged nodes are carried rigidly by the
bent centre line's frame (``arc_rigid``).

Material: ``NeoHookean(E=1.0, nu=0.4)`` in plane strain, in units where E = 1 (E scales forces and energies
only: drag- and stroke-driven shapes do not depend on it). Plane strain at nu = 0.4 is the law the library's
results were made and checked with, kept so they stay comparable; a cast silicone robot is a thin, nearly
incompressible sheet (``NeoHookean(1.0, 0.5, plane="stress")`` or ``silicone(...)``), which moves no node of
these cases by more than 0.3 % of the largest motion (default resolution).

Run ``python problems/tentacle.py --out out/tentacle`` or ``mdsr run tentacle --out out/tentacle``.
"""

from __future__ import annotations

import numpy as np

from mdsr_opt import NeoHookean
from mdsr_opt.scenes.scene import Case, Scene, mesh_polygon, resolve_resolution, seeds_for
from mdsr_opt.scenes.shapes import arc_rigid, rigid_motion
from mdsr_opt.scenes.select import nodes_in_box
from mdsr_opt.scenes.runscene import run_main

LENGTH = 6.0       # base to tip
CURL = 1.8         # radians of the curl
S_BEND = 0.8       # radians of each half of the S


def half_width(x):
    """Half width of the finger at ``x`` (straight taper from 0.6 at the base to 0.25 at the tip)."""
    return 0.6 - 0.35 * np.asarray(x, dtype=float) / LENGTH


def outline(n_tip: int = 9) -> np.ndarray:
    """The finger's outline, counter-clockwise, its centre line on y = 0 from (0, 0) to the tip."""
    r = float(half_width(LENGTH))
    arc = np.linspace(-np.pi / 2, np.pi / 2, n_tip)
    tip = np.column_stack([LENGTH + r * np.cos(arc), r * np.sin(arc)])
    return np.vstack([[0.0, -0.6], tip, [0.0, 0.6]])


def body(resolution="medium"):
    """The tapered finger's mesh and material (shared with ``one_muscle.py``)."""
    return mesh_polygon(outline(), resolution=resolution), NeoHookean(E=1.0, nu=0.4)


def build(resolution="medium") -> Scene:
    """The tentacle scene: cases ``curl`` and ``s_curve`` (external driving, muscles routed)."""
    mesh, material = body(resolution)
    P = mesh.points
    h = float(mesh.edge_lengths.mean())
    base = nodes_in_box(mesh, xmax=0.0)
    tip = nodes_in_box(mesh, xmin=LENGTH - 0.4)
    mid = nodes_in_box(mesh, xmin=3.0 - 0.6 * h, xmax=3.0 + 0.6 * h)
    # curl: the tip follows the centre line bent through CURL
    curl = arc_rigid(P[tip], (LENGTH - 0.4, 0.0), (0.0, 0.0), (1.0, 0.0), LENGTH - 0.4, CURL)
    # S: the first half bends left by S_BEND, the second half right by S_BEND (the tip ends parallel)
    first = dict(origin=(0.0, 0.0), direction=(1.0, 0.0), length=3.0, angle=S_BEND)
    mid_pos = arc_rigid(P[mid], (3.0, 0.0), **first)
    c1 = arc_rigid(np.array([[3.0, 0.0]]), (3.0, 0.0), **first)[0]
    second = arc_rigid(P[tip], (LENGTH - 0.4, 0.0), (3.0, 0.0), (1.0, 0.0), LENGTH - 3.4, -S_BEND)
    tip_pos = rigid_motion(second, S_BEND, (3.0, 0.0), c1 - (3.0, 0.0))
    cases = (
        Case("curl", anchors=base, drag_nodes=tip, drag_positions=curl,
             description=f"base anchored, tip carried round an arc through {CURL} rad"),
        Case("s_curve", anchors=base, drag_nodes=np.concatenate([mid, tip]),
             drag_positions=np.vstack([mid_pos, tip_pos]),
             description=f"middle bent left and tip bent back right, {S_BEND} rad each"),
    )
    return Scene(
        name="tentacle", title="Tentacle (MDSR body 1 of 3): curl and S-curve by external driving",
        description=__doc__.split("\n\n")[1].replace("\n", " "), mesh=mesh, material=material, cases=cases,
        regions={"base": base, "middle": mid, "tip": tip},
        # K_a = 1: fewer, longer ropes. With ropes inside the body (a channel and its wall from the outline)
        # K_a = 10 left the curl one short rope, 5.9 % of the size from its target; K_a = 1 splices two,
        # 3.7 % (s_curve 1.8 % either way; medium resolution)
        routing_options={"K_a": 1.0, "K_b": 4.0, "max_muscles": 3, "n_seeds": seeds_for(mesh)},
        design_options={"method": "flattened", "a_max": 0.6},
        expected={"max_muscles": 3}, resolution=resolve_resolution(resolution), source=__file__)


if __name__ == "__main__":
    raise SystemExit(run_main(build))
