"""Humanoid face: an outline with eye and mouth holes, and four expressions as targets.

The paper's introduction and conclusion name humanoid faces as the complex deformations its framework is
for (after the face "cloning" work it cites) but show no face. This scene is one: an egg-shaped face
6 units wide and 8 tall with two eye holes and a mouth hole. The face is held by its rim: the whole outer
outline is anchored, as a mask glued to a frame (or a skin on a skull). Four expressions are made by dragging
points round the holes (external driving): ``smile`` (the mouth corners pulled up and out), ``frown``
(corners down), ``wink`` (the left upper eyelid pulled down onto the lower one) and ``pucker`` (the
corners pulled in). Routing then finds the face's muscles (a ring round the mouth, cheek muscles, a
lid muscle) and the animation ``expressions`` plays smile, wink and pucker in turn.

The shapes are drawn by the mdsr_opt authors from the paper's descriptions (it gives no geometry); they
are not the paper's meshes. A face needs at least ``MIN_NODES`` = 300 nodes: on coarser meshes the
mouth corners are two or three nodes and routing finds no muscle for the smile and the frown, so the
``coarse`` resolution is raised to 300 here.

Run ``python problems/face.py --out out/face`` or ``mdsr run face --out out/face``.
"""

from __future__ import annotations

import numpy as np

from mdsr_opt import NeoHookean
from mdsr_opt.scenes import (Animation, Case, Scene, mesh_polygon, nodes_near,
                             resolve_resolution, run_main, seeds_for)

EYE_C, EYE_AX = (1.2, 0.9), (0.65, 0.28)       # right eye centre (the left is mirrored) and semi-axes
MOUTH_C, MOUTH_AX = (0.0, -1.9), (1.1, 0.2)
MIN_NODES = 300                                 # fewer do not resolve the mouth corners: "coarse" gets this


def ellipse(c, ax, n: int) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([c[0] + ax[0] * np.cos(t), c[1] + ax[1] * np.sin(t)])


def outline(n: int = 48) -> np.ndarray:
    """The face's outer outline, counter-clockwise: an egg, narrower at the chin."""
    t = np.linspace(0, 2 * np.pi, n, endpoint=False) - np.pi / 2
    return np.column_stack([3.0 * np.cos(t) * (0.85 + 0.15 * np.sin(t)), 4.0 * np.sin(t)])


def holes(n: int = 16) -> list[np.ndarray]:
    """The left eye, the right eye and the mouth."""
    return [ellipse((-EYE_C[0], EYE_C[1]), EYE_AX, n), ellipse(EYE_C, EYE_AX, n),
            ellipse(MOUTH_C, MOUTH_AX, max(n, 20))]


def build(resolution="medium") -> Scene:
    """The face scene: cases ``smile``, ``frown``, ``wink``, ``pucker``; animation ``expressions``."""
    n = max(MIN_NODES, resolve_resolution(resolution))
    k = max(10, int(np.sqrt(n) * 0.8))
    mesh = mesh_polygon(outline(3 * k), holes(k), resolution=n)
    P = mesh.points
    b = mesh.boundary_nodes
    outer = np.asarray(mesh.boundary_loops[0])
    skull = np.sort(outer)
    mouth_rim = np.intersect1d(b, nodes_near(mesh, MOUTH_C, MOUTH_AX[0] + 0.05))
    lx, ly = -EYE_C[0], EYE_C[1]
    left_eye = np.intersect1d(b, nodes_near(mesh, (lx, ly), EYE_AX[0] + 0.05))
    corners = [nodes_near(mesh, (s * MOUTH_AX[0] + MOUTH_C[0], MOUTH_C[1]), 0.22) for s in (-1, 1)]
    corners = [np.intersect1d(c, mouth_rim) for c in corners]
    lid = left_eye[P[left_eye, 1] > ly + 1e-9]
    lid = lid[np.abs(P[lid, 0] - lx) < 0.8 * EYE_AX[0]]
    regions = {"rim": skull, "mouth_corners": np.concatenate(corners), "left_upper_lid": lid,
               "mouth": mouth_rim, "left_eye": left_eye}

    def corner_case(name, dx, dy, text):
        nodes = np.concatenate(corners)
        pos = np.vstack([P[corners[0]] + (-dx, dy), P[corners[1]] + (dx, dy)])
        return Case(name, anchors=skull, drag_nodes=nodes, drag_positions=pos, description=text)

    # the wink: the lid's nodes go down onto the lower lid's curve, leaving a slit of 15 % of the eye
    u = (P[lid, 0] - lx) / EYE_AX[0]
    closed = np.column_stack([P[lid, 0], ly - EYE_AX[1] * np.sqrt(np.clip(1 - u ** 2, 0, 1)) * 0.7])
    cases = (
        corner_case("smile", 0.25, 0.35, "mouth corners pulled up and out"),
        corner_case("frown", 0.0, -0.3, "mouth corners pulled down"),
        Case("wink", anchors=skull, drag_nodes=lid, drag_positions=closed,
             description="left upper eyelid pulled down onto the lower one"),
        corner_case("pucker", -0.3, 0.0, "mouth corners pulled in"),
    )
    anim = Animation("expressions", (("rest", 0.0), ("smile", 1.0), ("rest", 0.0), ("wink", 1.0), ("rest", 0.0),
                                     ("pucker", 1.0), ("rest", 0.0)), frames_per_step=4)
    return Scene(
        name="face", title="Humanoid face: smile, frown, wink and pucker by external driving",
        description=__doc__.split("\n\n")[1].replace("\n", " "), mesh=mesh, material=NeoHookean(E=1.0, nu=0.4),
        cases=cases, regions=regions,
        routing_options={"K_a": 10.0, "K_b": 4.0, "max_muscles": 4, "n_seeds": seeds_for(mesh)},
        design_options={"method": "flattened", "a_max": 0.6}, animations=(anim,),
        expected={"max_muscles": 4}, resolution=n, source=__file__)


if __name__ == "__main__":
    raise SystemExit(run_main(build))
