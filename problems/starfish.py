"""Starfish: five arms about a central disc, curling one arm and all five (a pinwheel).

The paper (its Figure 11b) defines deformations of a starfish-shaped soft robot by external driving,
routes and optimises its muscles, and simulates its motion "in a similar manner" to the gecko. It gives
neither the deformations nor the shape; ours: a disc of radius 1 with five tapered arms reaching 3.6
from the centre, and two targets, each with the central disc anchored: ``curl`` (arm 0, pointing up,
carried round an arc through ``CURL`` rad to its left) and ``pinwheel`` (every arm bent ``SWIRL`` rad
anticlockwise, the stroke of a swimming or crawling motion). The animation ``swim`` plays rest,
pinwheel, rest.

The shapes are drawn by the mdsr_opt authors from the paper's descriptions (it gives no geometry); they
are not the paper's meshes.

Material: ``NeoHookean(E=1.0, nu=0.4)`` in plane strain, in units where E = 1 (E scales forces and energies
only: drag- and stroke-driven shapes do not depend on it). Plane strain at nu = 0.4 is the law the library's
results were made and checked with, kept so they stay comparable; a cast silicone robot is a thin, nearly
incompressible sheet (``NeoHookean(1.0, 0.5, plane="stress")`` or ``silicone(...)``), which moves no node of
these cases by more than 0.7 % of the largest motion (default resolution).

Run ``python problems/starfish.py --out out/starfish`` or ``mdsr run starfish --out out/starfish``.
"""

from __future__ import annotations

import numpy as np

from mdsr_opt import NeoHookean
from mdsr_opt.synthesis.gait import Gait
from mdsr_opt.scenes.scene import Animation, Case, Scene, mesh_polygon, resolve_resolution, seeds_for
from mdsr_opt.scenes.shapes import arc_rigid
from mdsr_opt.scenes.select import nodes_near
from mdsr_opt.scenes.runscene import run_main

ARMS = 5
R_DISC, R_TIP = 1.0, 3.6      # disc radius; distance of the arm tips from the centre
W_ROOT, W_TIP = 0.55, 0.2     # half widths of an arm at its root and at its rounded tip
CURL, SWIRL = 1.3, 0.6


def arm_angle(k: int) -> float:
    """Direction of arm ``k`` (arm 0 points up)."""
    return np.pi / 2 + 2 * np.pi * k / ARMS


def outline(n_tip: int = 7) -> np.ndarray:
    """The starfish's outline, counter-clockwise; between arms the disc's rim is a concave arc."""
    pts = []
    for k in range(ARMS):
        a = arm_angle(k)
        d, nrm = np.array([np.cos(a), np.sin(a)]), np.array([-np.sin(a), np.cos(a)])
        root = R_DISC * 0.9 * d
        tipc = (R_TIP - W_TIP) * d
        # right side out, round tip, left side in
        pts.append(root - W_ROOT * nrm)
        t = np.linspace(-np.pi / 2, np.pi / 2, n_tip)
        pts += [tipc + W_TIP * (np.cos(s) * d + np.sin(s) * nrm) for s in t]
        pts.append(root + W_ROOT * nrm)
        # the rim between this arm and the next
        a_next = arm_angle(k + 1)
        mid = (a + a_next) / 2
        pts.append(R_DISC * np.array([np.cos(mid), np.sin(mid)]))
    return np.array(pts)


def build(resolution="medium") -> Scene:
    """The starfish scene: cases ``curl`` and ``pinwheel``, animation ``swim``."""
    n = resolve_resolution(resolution)
    mesh = mesh_polygon(outline(max(5, int(np.sqrt(n) / 3))), resolution=n)
    P = mesh.points
    regions = {"disc": nodes_near(mesh, (0.0, 0.0), 0.55)}
    tips, moved_curl, moved_swirl = [], None, []
    for k in range(ARMS):
        a = arm_angle(k)
        d = np.array([np.cos(a), np.sin(a)])
        tip = nodes_near(mesh, (R_TIP - 0.35) * d, 0.45)
        regions[f"tip{k}"] = tip
        tips.append(tip)
        arm = dict(root=(R_TIP - 0.45) * d, origin=0.8 * d, direction=d, length=R_TIP - 1.25)
        moved_swirl.append(arc_rigid(P[tip], angle=SWIRL, **arm))
        if k == 0:
            moved_curl = arc_rigid(P[tip], angle=CURL, **arm)
    cases = (
        Case("curl", anchors=regions["disc"], drag_nodes=tips[0], drag_positions=moved_curl,
             description=f"disc anchored, arm 0 curled {CURL} rad to its left"),
        Case("pinwheel", anchors=regions["disc"], drag_nodes=np.concatenate(tips),
             drag_positions=np.vstack(moved_swirl), description=f"disc anchored, every arm bent {SWIRL} rad "
             "anticlockwise"),
    )
    return Scene(
        name="starfish", title="Starfish (paper Figure 11b): one arm curled, all five swirled",
        description=__doc__.split("\n\n")[1].replace("\n", " "), mesh=mesh, material=NeoHookean(E=1.0, nu=0.4),
        cases=cases, regions=regions,
        routing_options={"K_a": 10.0, "K_b": 4.0, "max_muscles": 5, "n_seeds": max(10, seeds_for(mesh))},
        # short arm muscles: end patches of 0.1 (the default 0.04 x diameter = 0.29 covers too much of them)
        design_options={"method": "flattened", "a_max": 0.6, "anchor_radius": 0.1},
        animations=(Animation("swim", (("rest", 0.0), ("pinwheel", 1.0), ("rest", 0.0)), frames_per_step=6),),
        expected={"max_muscles": 5}, resolution=n, source=__file__, units="cm",
        # one muscle layout for both strokes: swirl, recover, curl, recover (issue 16)
        gait=Gait("swim_cycle", ("rest", "pinwheel", "rest", "curl"), frames_per_step=4, max_muscles=10))


if __name__ == "__main__":
    raise SystemExit(run_main(build))
