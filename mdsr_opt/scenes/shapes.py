"""Target maps for problem scripts: rigid motions and arc bends of point sets."""

from __future__ import annotations

import math
import numpy as np
from numpy.typing import ArrayLike

from ..core.checks import as_float_array

__all__ = ['rigid_motion', 'arc_map', 'arc_rigid']


# ---------------------------------------------------------------------------------------------- target helpers
def rigid_motion(points: ArrayLike, angle: float = 0.0, center: ArrayLike = (0.0, 0.0),
                 shift: ArrayLike = (0.0, 0.0)) -> np.ndarray:
    """Rotate ``points`` by ``angle`` (radians, counter-clockwise) about ``center``, then shift them."""
    P = as_float_array(points, "points", shape=(None, 2))
    c = as_float_array(center, "center", shape=(2,))
    s = as_float_array(shift, "shift", shape=(2,))
    R = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    return (P - c) @ R.T + c + s


def arc_map(points: ArrayLike, origin: ArrayLike, direction: ArrayLike, length: float,
            angle: float) -> np.ndarray:
    """Where bending a straight limb onto a circular arc puts ``points``.

    The limb starts at ``origin`` and runs along ``direction``; its centre line (through ``origin``) of
    length ``length`` is bent through ``angle`` radians (positive: towards the left of ``direction``) onto
    an arc, keeping lengths along the centre line. A point at distance ``s`` along and ``t`` to the left of
    the centre line goes to the arc point at ``s``, offset ``t`` along the arc's normal. Points with
    ``s <= 0`` stay; points beyond ``length`` continue straight along the tangent.
    """
    P = as_float_array(points, "points", shape=(None, 2))
    o = as_float_array(origin, "origin", shape=(2,))
    d = as_float_array(direction, "direction", shape=(2,))
    d = d / np.linalg.norm(d)
    nrm = np.array([-d[1], d[0]])
    s = (P - o) @ d
    t = (P - o) @ nrm
    if abs(angle) < 1e-12:
        return P.copy()
    R = length / angle  # signed radius
    sc = np.clip(s, 0.0, length)
    th = sc / R
    # arc point of the centre line and its normal, in the limb frame (u along d, v along nrm)
    u = R * np.sin(th) + (s - sc) * np.cos(th)
    v = R * (1.0 - np.cos(th)) + (s - sc) * np.sin(th)
    uu = u - t * np.sin(th)
    vv = v + t * np.cos(th)
    out = o + np.outer(uu, d) + np.outer(vv, nrm)
    keep = s <= 0
    out[keep] = P[keep]
    return out


def arc_rigid(points: ArrayLike, root: ArrayLike, origin: ArrayLike, direction: ArrayLike, length: float,
              angle: float) -> np.ndarray:
    """Move ``points`` rigidly with the frame of a bent limb's centre line at ``root`` (see :func:`arc_map`).

    Feet, a head or a tail attached to a bending spine follow it without being squashed: the group turns
    by the centre line's tangent angle at ``root`` (projected on the centre line) and moves with that
    centre-line point.
    """
    P = as_float_array(points, "points", shape=(None, 2))
    o = as_float_array(origin, "origin", shape=(2,))
    d = as_float_array(direction, "direction", shape=(2,))
    d = d / np.linalg.norm(d)
    s = float(np.clip((as_float_array(root, "root", shape=(2,)) - o) @ d, 0.0, length))
    c0 = o + s * d
    c1 = arc_map(c0[None], o, d, length, angle)[0]
    return rigid_motion(P, angle * s / length, c0, c1 - c0)
