"""Contours with holes: every simulated loop matched to its photographed counterpart and measured."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Sequence
import numpy as np
from numpy.typing import ArrayLike

from ..body.checks import check_mesh
from ..body.polygons import polygon_area
from ..core.checks import as_float_array
from ..core.results import compact_repr
from .compare import (ContourComparison, as_contour, compare_contours, rotation_matrix, signed_distances,
                      unsigned_distances)

__all__ = ['simulated_loops', 'LoopComparison', 'compare_loops']


def simulated_loops(mesh, x: ArrayLike | None = None) -> list[np.ndarray]:
    """Every boundary loop of the mesh in state ``x``: the outer outline first (counter-clockwise), then
    the holes (clockwise), each (b, 2). Checks as :func:`simulated_outline`."""
    mesh = check_mesh(mesh)
    x = mesh.points if x is None else as_float_array(x, "x", shape=(mesh.n_nodes, 2))
    return [np.asarray(x)[loop] for loop in mesh.boundary_loops]


@dataclass(frozen=True, eq=False)
class LoopComparison:
    """How well a simulated body with holes fits a photographed one, loop by loop.

    Attributes
    ----------
    outer : ContourComparison
        The outer outline's comparison; its registration (rotation, scale, translation) maps the holes too.
    loops : list of dict
        One entry per simulated loop (outline first) and per photographed hole without a simulated
        counterpart: ``kind`` (``"outer"``, ``"hole"`` or ``"photo-only hole"``), ``index`` (simulated
        loop index, or the measured hole's for a photo-only hole), ``matched`` (index of the measured
        loop it was compared with, ``None`` when it has no counterpart), ``n``, ``mean_px``, ``std_px``,
        ``max_px``. A simulated hole with no counterpart is measured to the nearest photographed loop of
        any kind (a mouth painted shut: the distance to the lips' surroundings); a photographed hole with
        no counterpart, each of its points to the nearest simulated loop.
    mean_px, std_px, max_px : float
        Over every distance of every loop together (so a loop counts by its number of points).
    ratio : float
        ``mean_px`` over the square root of the area the measured outline encloses.
    n_unmatched : int
        Simulated holes without a photographed counterpart plus photographed holes without a simulated one.
    """

    outer: ContourComparison
    loops: list
    mean_px: float
    std_px: float
    max_px: float
    ratio: float
    n_unmatched: int

    def __repr__(self) -> str:
        return compact_repr(self, ("mean_px", "std_px", "max_px", "ratio", "n_unmatched"))

    def summary(self) -> dict:
        """The scalar metrics and the per-loop rows (JSON-ready)."""
        return {"mean_px": self.mean_px, "std_px": self.std_px, "max_px": self.max_px, "ratio": self.ratio,
                "n_unmatched": self.n_unmatched, "outer_mean_px": self.outer.mean_px,
                "loops": [dict(r) for r in self.loops]}


def compare_loops(simulated: Sequence[ArrayLike], measured: Sequence[ArrayLike], **compare) -> LoopComparison:
    """Compare a simulated body's outline and holes with a photograph's (e.g. :func:`simulated_loops` with
    :func:`contour_loops_from_image`).

    The outer outlines are registered and compared by :func:`compare_contours` (``compare`` holds its
    options). An outline that fits at several rotations (a disk, a square) may be registered at one that
    puts the holes far from the photographed ones: when a simulated hole lies far from every photographed
    one, the registration is turned about the photographed outline's centre to the rotation that places
    every loop best, if that at least halves the mean distance over every loop (``outer`` then holds the
    turned registration). The same map takes every simulated hole into the photograph's pixels, where each is matched
    to its photographed counterpart: an optimal one-to-one assignment on centroid distance, a pair
    accepted only when the centroids lie closer than the larger hole's equivalent radius
    (``sqrt(area / pi)``) plus a fifth of the smaller's. Each simulated hole node is then measured to its
    counterpart by ``cv2.pointPolygonTest``; holes without a counterpart are measured as described in
    :class:`LoopComparison`, so a hole that is open in the simulation and shut in the photograph (or the
    reverse) costs its full distance.

    Raises
    ------
    ValueError
        An empty ``simulated`` or ``measured``, or loops that are not (k >= 3, 2) arrays.
    """
    if len(simulated) == 0 or len(measured) == 0:
        raise ValueError("simulated and measured need at least the outer outline each")
    S = [as_contour(c, f"simulated[{i}]") for i, c in enumerate(simulated)]
    M = [as_contour(c, f"measured[{i}]") for i, c in enumerate(measured)]
    outer = compare_contours(S[0], M[0], **compare)
    if len(S) > 1 and len(M) > 1 and outer.registration == "similarity" and compare.get("scaling", "uniform") == "uniform":
        outer = _turned_by_holes(outer, S[1:], M)
    A = outer.transform
    Sp = [c @ A[:, :2].T + A[:, 2] for c in S[1:]]
    Mh = M[1:]

    def centre_radius(c):
        a = abs(polygon_area(c))
        return c.mean(axis=0), math.sqrt(a / math.pi)

    cs = [centre_radius(c) for c in Sp]
    cm = [centre_radius(c) for c in Mh]
    pairs: dict[int, int] = {}
    if Sp and Mh:  # holes on both sides (scipy.optimize imported only then)
        from scipy.optimize import linear_sum_assignment

        C = np.array([[np.linalg.norm(a[0] - b[0]) for b in cm] for a in cs])
        for i, j in zip(*linear_sum_assignment(C)):
            if C[i, j] < max(cs[i][1], cm[j][1]) + 0.2 * min(cs[i][1], cm[j][1]):
                pairs[int(i)] = int(j)
    rows = [{"kind": "outer", "index": 0, "matched": 0, "n": int(outer.n_nodes), "mean_px": outer.mean_px,
             "std_px": outer.std_px, "max_px": outer.max_px}]
    every = [outer.distances_px]
    for i, p in enumerate(Sp):
        if i in pairs:
            d = np.abs(signed_distances(p, Mh[pairs[i]].astype(np.float32).reshape(-1, 1, 2)))
        else:
            d = np.min([unsigned_distances(p, m) for m in M], axis=0)
        every.append(d)
        rows.append({"kind": "hole", "index": i + 1, "matched": pairs[i] + 1 if i in pairs else None,
                     "n": len(d), "mean_px": float(d.mean()), "std_px": float(d.std()), "max_px": float(d.max())})
    sim_px = [outer.simulated_px] + Sp
    matched_m = set(pairs.values())
    for j, m in enumerate(Mh):
        if j in matched_m:
            continue
        d = np.min([unsigned_distances(m, p) for p in sim_px], axis=0)
        every.append(d)
        rows.append({"kind": "photo-only hole", "index": j + 1, "matched": None, "n": len(d),
                     "mean_px": float(d.mean()), "std_px": float(d.std()), "max_px": float(d.max())})
    d = np.concatenate(every)
    n_un = (len(Sp) - len(pairs)) + (len(Mh) - len(matched_m))
    return LoopComparison(outer=outer, loops=rows, mean_px=float(d.mean()), std_px=float(d.std()),
                          max_px=float(d.max()), ratio=float(d.mean() / math.sqrt(abs(polygon_area(M[0])))),
                          n_unmatched=int(n_un))


def _turned_by_holes(outer: ContourComparison, holes, measured) -> ContourComparison:
    """``outer``, turned about the photographed outline's centre when that places the holes far better.

    An outline with a rotational symmetry (a disk, a square) registers equally well at several rotations,
    and the one :func:`compare_contours` keeps may put the holes far from the photographed ones. When a
    simulated hole lies more than ``3 * outer.mean_px + 1`` pixels (mean) from every photographed hole, the
    turn (a sweep of 5 degrees, then 0.25) that minimises the mean distance of every loop is taken if it at
    least halves it; otherwise, and always for a registration that places the holes, ``outer`` is kept."""
    M0, Mh = measured[0], measured[1:]
    c = M0.mean(axis=0)
    A = outer.transform

    def placed(phi):
        R = rotation_matrix(phi)
        return [(p - c) @ R.T + c for p in [outer.simulated_px] + [h @ A[:, :2].T + A[:, 2] for h in holes]]

    def cost(phi, parts=False):
        P = placed(phi)
        d = [unsigned_distances(P[0], M0)] + [np.min([unsigned_distances(h, m) for m in Mh], axis=0) for h in P[1:]]
        return d if parts else float(np.concatenate(d).mean())

    at0 = cost(0.0, parts=True)
    if max(float(d.mean()) for d in at0[1:]) <= 3.0 * outer.mean_px + 1.0:
        return outer
    coarse = np.radians(np.arange(-180.0, 180.0, 5.0))
    best = coarse[int(np.argmin([cost(t) for t in coarse]))]
    fine = best + np.radians(np.arange(-5.0, 5.01, 0.25))
    best = float(fine[int(np.argmin([cost(t) for t in fine]))])
    if cost(best) > 0.5 * float(np.concatenate(at0).mean()):
        return outer
    R = rotation_matrix(best)
    P = placed(best)[0]
    signed = signed_distances(P, M0.astype(np.float32).reshape(-1, 1, 2))
    dist = np.abs(signed)
    lin = R @ A[:, :2]
    turn = -1.0 if np.linalg.det(A[:, :2]) < 0 else 1.0  # a mirrored map (y down) turns the other way
    angle = (outer.angle_deg + turn * math.degrees(best) + 180.0) % 360.0 - 180.0
    return replace(outer, mean_px=float(dist.mean()), std_px=float(dist.std()), max_px=float(dist.max()),
                   mean_norm=float(dist.mean() / outer.size_px), std_norm=float(dist.std() / outer.size_px),
                   max_norm=float(dist.max() / outer.size_px),
                   ratio=float(dist.mean() / math.sqrt(abs(polygon_area(M0)))), bias_px=float(signed.mean()),
                   angle_deg=float(angle), distances_px=dist, signed_px=signed, simulated_px=P,
                   transform=np.hstack([lin, (R @ (A[:, 2] - c) + c)[:, None]]))
