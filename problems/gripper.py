"""Gripper: the second of the paper's three MDSR bodies, a C-shaped ring whose jaws close.

The paper tests its muscle routing and contraction design on five deformations of three MDSR bodies made
by external driving (its Figure 6, Table 1); the third is a humanoid figure (``humanoid.py``), the first
our tapered finger (``tentacle.py``). This second body is a C-shaped ring (a gripper): an annulus of
centre-line radius 2 and width 1, open over 60 degrees on its right, with one of the five deformations,
``close``: the back (left) of the ring is anchored and the two jaws are dragged towards each other, as
the ring's centre line curls more tightly (angles from the back grow by ``CLOSE``, lengths along the
centre line kept). ``two_muscles.py`` uses the same body for the paper's two-muscle experiment.

The gripper closing on an object, a free disk, with its grip report, is ``gripper_hold.py``.

The shapes are drawn by the mdsr_opt authors from the paper's descriptions (it gives no geometry); they
are not the paper's meshes.

Material: ``NeoHookean(E=1.0, nu=0.4)`` in plane strain, in units where E = 1 (E scales forces and energies
only: drag- and stroke-driven shapes do not depend on it). Plane strain at nu = 0.4 is the law the library's
results were made and checked with, kept so they stay comparable; a cast silicone robot is a thin, nearly
incompressible sheet (``NeoHookean(1.0, 0.5, plane="stress")`` or ``silicone(...)``), which moves no node of
these cases by more than 0.3 % of the largest motion (default resolution).

Run ``python problems/gripper.py --out out/gripper`` or ``mdsr run gripper --out out/gripper``.
"""

from __future__ import annotations

import numpy as np

from mdsr_opt import NeoHookean
from mdsr_opt.scenes.scene import Case, Scene, mesh_polygon, resolve_resolution, seeds_for
from mdsr_opt.scenes.select import nodes_in_polygon
from mdsr_opt.scenes.runscene import run_main

R0, WIDTH = 2.0, 1.0          # centre-line radius and ring width
OPENING = np.radians(60.0)    # the gap between the jaws, centred on +x
CLOSE = 1.12                  # angles from the back are multiplied by this


def outline(n_arc: int = 40) -> np.ndarray:
    """The C's outline, counter-clockwise: outer arc from the lower jaw round the back to the upper jaw,
    then the inner arc back (jaw ends are straight)."""
    phi = np.linspace(OPENING / 2, 2 * np.pi - OPENING / 2, n_arc)
    ro, ri = R0 + WIDTH / 2, R0 - WIDTH / 2
    outer = np.column_stack([ro * np.cos(phi), ro * np.sin(phi)])
    inner = np.column_stack([ri * np.cos(phi), ri * np.sin(phi)])[::-1]
    return np.vstack([outer, inner])


def body(resolution="medium"):
    """The gripper's mesh and material (shared with ``two_muscles.py``)."""
    n = resolve_resolution(resolution)
    return mesh_polygon(outline(max(24, int(2 * np.sqrt(n)))), resolution=n), NeoHookean(E=1.0, nu=0.4)


def closed(points: np.ndarray, factor: float = CLOSE) -> np.ndarray:
    """Curl the ring: the angle from the back (-x) grows by ``factor``, radii shrink about the centre line
    so that lengths along it are kept; the back stays where it is."""
    P = np.asarray(points, dtype=float)
    r = np.linalg.norm(P, axis=1)
    psi = np.arctan2(P[:, 1], -P[:, 0])            # 0 at the back, +-(pi - OPENING/2) at the jaws
    Rn = R0 / factor
    rn = Rn + (r - R0)
    centre = np.array([-R0 + Rn, 0.0])             # keep the back's centre-line point fixed
    return centre + np.column_stack([-rn * np.cos(factor * psi), rn * np.sin(factor * psi)])


def build(resolution="medium") -> Scene:
    """The gripper scene: case ``close`` (external driving, muscles routed)."""
    mesh, material = body(resolution)
    P = mesh.points
    wedge = lambda a0, a1: nodes_in_polygon(mesh, 4 * np.array(  # noqa: E731
        [[0, 0], [np.cos(a0), np.sin(a0)], [np.cos(a1), np.sin(a1)]]))
    back = wedge(np.pi - 0.12, np.pi + 0.12)
    jaws = np.concatenate([wedge(OPENING / 2 - 0.01, OPENING / 2 + 0.25),
                           wedge(-OPENING / 2 - 0.25, -OPENING / 2 + 0.01)])
    cases = (Case("close", anchors=back, drag_nodes=jaws, drag_positions=closed(P[jaws]),
                  description=f"back anchored, jaws closed (centre line curled by a factor {CLOSE})"),)
    return Scene(
        name="gripper", title="Gripper (MDSR body 2 of 3): the C closes its jaws by external driving",
        description=__doc__.split("\n\n")[1].replace("\n", " "), mesh=mesh, material=material, cases=cases,
        regions={"back": back, "jaws": jaws},
        routing_options={"K_a": 10.0, "K_b": 4.0, "max_muscles": 3, "n_seeds": seeds_for(mesh)},
        design_options={"method": "flattened", "a_max": 0.6},
        expected={"max_muscles": 3}, resolution=resolve_resolution(resolution), source=__file__)


if __name__ == "__main__":
    raise SystemExit(run_main(build))
