"""Weighted rigid alignment (Kabsch) and the difference index between two configurations.

``align(x, y, w)`` finds the rotation ``R`` and translation ``t`` minimising ``sum_i w_i |R x_i + t - y_i|^2``;
``difference(x, y, w)`` reports ``sqrt(D / sum w)`` after that alignment: a length in the mesh's units.

Example
-------
>>> import numpy as np
>>> x = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
>>> c, s = np.cos(0.3), np.sin(0.3)
>>> y = x @ np.array([[c, s], [-s, c]]) + [2.0, 1.0]
>>> round(difference(x, y), 12)
0.0
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..core.checks import as_float_array
from ..core.results import compact_repr, to_jsonable

__all__ = ["Alignment", "align", "difference", "node_weights"]


@dataclass(frozen=True)
class Alignment:
    R: np.ndarray  # (2, 2) rotation
    t: np.ndarray  # (2,) translation
    difference: float  # weighted RMS distance after alignment

    @property
    def angle(self) -> float:
        """Rotation angle in radians."""
        return float(np.arctan2(self.R[1, 0], self.R[0, 0]))

    def apply(self, x: ArrayLike) -> np.ndarray:
        return np.asarray(x, dtype=float) @ self.R.T + self.t

    def __repr__(self) -> str:
        return compact_repr(self, ("angle", "t", "difference"))

    def to_dict(self) -> dict:
        """The rotation (matrix and angle in radians), translation and difference as JSON-ready values."""
        return {"R": to_jsonable(self.R), "angle": self.angle, "t": to_jsonable(self.t),
                "difference": to_jsonable(self.difference)}


def _weights(w, n):
    if w is None:
        return np.ones(n)
    w = as_float_array(w, "weights", shape=(n,))
    if (w < 0).any() or w.sum() <= 0:
        raise ValueError("weights must be non-negative with a positive sum")
    return w


def align(x: ArrayLike, y: ArrayLike, weights: ArrayLike | None = None) -> Alignment:
    """Best rotation and translation taking ``x`` (n, 2) onto ``y`` (n, 2) in the weighted least-squares sense."""
    x = as_float_array(x, "x", shape=(None, 2))
    y = as_float_array(y, "y", shape=(len(x), 2))
    w = _weights(weights, len(x))
    W = w.sum()
    cx = (w[:, None] * x).sum(0) / W
    cy = (w[:, None] * y).sum(0) / W
    A = (w[:, None] * (x - cx)).T @ (y - cy)  # 2x2 cross-covariance
    # optimal rotation angle for 2D: maximise tr(R A)
    theta = np.arctan2(A[0, 1] - A[1, 0], A[0, 0] + A[1, 1])
    c, s = np.cos(theta), np.sin(theta)
    R = np.array([[c, -s], [s, c]])
    t = cy - R @ cx
    r = x @ R.T + t - y
    D = float((w * (r ** 2).sum(1)).sum())
    return Alignment(R, t, float(np.sqrt(max(D, 0.0) / W)))


def difference(x: ArrayLike, y: ArrayLike, weights: ArrayLike | None = None) -> float:
    """Weighted RMS node distance between ``x`` and ``y`` after the best rigid alignment."""
    return align(x, y, weights).difference


def node_weights(mesh, interior: float = 0.5) -> np.ndarray:
    """The paper's node weights: 1 on the boundary, ``interior`` in [0.3, 0.7] inside."""
    interior = float(interior)
    if not 0.3 <= interior <= 0.7:
        raise ValueError(f"interior weight must lie in [0.3, 0.7], got {interior}")
    w = np.full(mesh.n_nodes, interior)
    w[mesh.boundary_nodes] = 1.0
    return w
