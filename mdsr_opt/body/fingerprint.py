"""The rest geometry a result was made on: a small fingerprint of a mesh, and the check that a mesh is that one.

A design's strokes, rest lengths and states are lengths and positions of the body it was made on. Given
another body with the same node count (a copy scaled by 2, moved, with a node shifted), the numbers would be
read against the wrong geometry without any error: a muscle of rest length 3.5 with the stroke designed for
one of 1.75. Every result that pairs with a mesh later (:class:`~mdsr_opt.synthesis.results.DesignResult`,
:class:`~mdsr_opt.synthesis.poses_result.PosesResult`, :class:`~mdsr_opt.synthesis.gait.GaitSchedule`) therefore records
:func:`mesh_fingerprint` of its mesh, saved and loaded with it, and every function that takes such a
``(mesh, result)`` pair calls :func:`check_same_mesh` first.

The fingerprint is a short JSON-ready dict, not a copy of the mesh: the node and triangle counts, a digest of
the triangles (as a set: their order in the list does not matter), the bounding box, and eight projections of the node positions onto fixed
pseudo-random weights (a sketch: a node moved by more than about ``1e-7`` of the body's size changes it,
while a mesh written to a file and read back, to the last digit or so, does not).

Example
-------
>>> from mdsr_opt import Mesh
>>> mesh = Mesh.rectangle(2.0, 1.0, 4, 2)
>>> fp = mesh_fingerprint(mesh)
>>> check_same_mesh(Mesh(mesh.points.copy(), mesh.triangles.copy()), fp)  # the same body: passes
>>> check_same_mesh(Mesh(mesh.points * 2, mesh.triangles), fp)
Traceback (most recent call last):
...
ValueError: the design was made on a mesh of size 2.23607 (bounding-box diagonal); this mesh has size 4.47214 (2 times as large): give the mesh the design was made on
"""

from __future__ import annotations

import hashlib
import math
from typing import Mapping

import numpy as np

__all__ = ["mesh_fingerprint", "check_same_mesh", "FINGERPRINT_RTOL"]

#: Relative tolerance of the comparison (of the body's size, or of its distance from the origin when larger).
FINGERPRINT_RTOL = 1e-7

#: Irrational steps of the Weyl sequences that weight the nodes in the sketch (deterministic on every platform).
_STEPS = (math.sqrt(2.0), math.sqrt(3.0), math.sqrt(5.0), math.sqrt(7.0))


def _weights(n: int) -> np.ndarray:
    """(4, n) weights in [-0.5, 0.5): the fractional parts of ``i * step``, centred."""
    i = np.arange(1, n + 1, dtype=float)
    return np.array([(i * s) % 1.0 - 0.5 for s in _STEPS])


def _sketch(points: np.ndarray) -> np.ndarray:
    return (_weights(len(points)) @ points).reshape(-1)


def _canonical(T: np.ndarray) -> np.ndarray:
    """The triangles as a set: each rotated to start at its smallest node (orientation kept), rows sorted."""
    k = np.argmin(T, axis=1)
    rows = np.arange(len(T))[:, None]
    R = T[rows, (k[:, None] + np.arange(3)) % 3]
    return np.ascontiguousarray(R[np.lexsort(R.T[::-1])], dtype="<i8")


def mesh_fingerprint(mesh) -> dict:
    """A JSON-ready fingerprint of ``mesh``'s rest geometry (see the module docstring); computed once per mesh."""
    cache = mesh.__dict__
    if "_fingerprint" not in cache:
        P = np.asarray(mesh.points, dtype=float)
        T = _canonical(np.asarray(mesh.triangles, dtype=np.int64))
        cache["_fingerprint"] = {
            "n_nodes": int(len(P)), "n_triangles": int(len(T)),
            "triangles": hashlib.sha256(T.tobytes()).hexdigest()[:16],
            "lo": [float(v) for v in P.min(axis=0)], "hi": [float(v) for v in P.max(axis=0)],
            "sketch": [float(v) for v in _sketch(P)]}
    return dict(cache["_fingerprint"])


def _fmt(v: float) -> str:
    return f"{v:.6g}"


def check_same_mesh(mesh, fingerprint: Mapping | None, what: str = "the design") -> None:
    """Raise ``ValueError`` unless ``mesh`` is the body ``fingerprint`` was taken of (see
    :func:`mesh_fingerprint`); the message says what differs: the node or triangle count, the triangles, the
    size, the place, or a node's position. ``what`` names the result in the message. A ``fingerprint`` of None
    (a result saved before fingerprints were recorded) is not checked."""
    if fingerprint is None:
        return
    try:
        n, t = int(fingerprint["n_nodes"]), int(fingerprint["n_triangles"])
        lo, hi = np.asarray(fingerprint["lo"], dtype=float), np.asarray(fingerprint["hi"], dtype=float)
        sketch = np.asarray(fingerprint["sketch"], dtype=float)
        tri = str(fingerprint["triangles"])
    except (KeyError, TypeError, ValueError):
        raise ValueError(f"{what} carries a damaged mesh fingerprint: {fingerprint!r}") from None
    give = "give the mesh the design was made on"
    if (n, t) != (mesh.n_nodes, mesh.n_triangles):
        raise ValueError(f"{what} was made on a mesh of {n} nodes and {t} triangles; this mesh has {mesh.n_nodes} "
                         f"nodes and {mesh.n_triangles} triangles: {give}")
    mine = mesh_fingerprint(mesh)
    if mine["triangles"] != tri:
        raise ValueError(f"{what} was made on a mesh with the same node and triangle counts but other triangles "
                         f"(another connectivity): {give}")
    mlo, mhi = np.asarray(mine["lo"]), np.asarray(mine["hi"])
    size, msize = float(np.hypot(*(hi - lo))), float(np.hypot(*(mhi - mlo)))
    scale = max(size, float(np.abs(np.concatenate([lo, hi])).max()), np.finfo(float).tiny)
    tol = FINGERPRINT_RTOL * scale
    if abs(msize - size) > tol:
        ratio = msize / size if size > 0 else math.inf
        raise ValueError(f"{what} was made on a mesh of size {_fmt(size)} (bounding-box diagonal); this mesh has "
                         f"size {_fmt(msize)} ({_fmt(ratio)} times as large): {give}")
    if np.abs(mlo - lo).max() > tol or np.abs(mhi - hi).max() > tol:
        d = mlo - lo
        raise ValueError(f"{what} was made on a mesh at another place: this one is moved by ({_fmt(d[0])}, "
                         f"{_fmt(d[1])}): {give}")
    # each sketch entry sums n weighted coordinates (|w| <= 0.5): rounding errors of size tol per coordinate
    # add up to about tol * ||w||, far below a moved node's change (its weight times the move)
    w = _weights(n)
    bound = 4.0 * tol * np.repeat(np.linalg.norm(w, axis=1), 2) + 1e-12 * scale * n
    off = np.abs(np.asarray(mine["sketch"]) - sketch) > bound
    if off.any():
        raise ValueError(f"{what} was made on a mesh of the same size, place and triangles but other node "
                         f"positions (a node moved?): {give}")
