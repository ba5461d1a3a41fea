"""Internal driving of the quadratic-element body started from the linear-element equilibrium (nested
iteration over the element order).

The quadratic body's Newton matrix has about four times the unknowns of the linear body on the same vertex
mesh, and its continuation from rest (or from a coarser model's prediction) takes many damped Newton steps.
:func:`solve_quadratic_nested` first solves the same problem with linear (3-node) elements on the vertex mesh
-- the same material, the ropes along the same vertex chains with the same friction, the fixtures' vertex
nodes -- whose Newton steps cost a fraction of the quadratic ones, and starts the quadratic solve there at
the full load: the vertices at the linear equilibrium, each edge midpoint at the middle of its edge (an
element of straight edges is as upright as its linear one). The quadratic solve is
:func:`~mdsr_opt.mechanics.quadsolve.solve_quadratic_internal` with that state as its ``guess``: it converges to
``tol`` on the quadratic equations, and when it does not (or the linear solve fails) the quadratic load is
stepped from rest as without the linear start. The linear body is stepped from rest too, so that the start
follows the branch from rest, as the quadratic continuation would.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .capstan import CapstanRope
from .quadratic import QuadraticModel
from .quadsolve import QuadraticResult, solve_quadratic_internal

__all__ = ["solve_quadratic_nested", "linear_counterpart"]


def linear_counterpart(model: QuadraticModel, ropes: Sequence[CapstanRope], fixtures: Sequence[np.ndarray] = ()):
    """The linear-element problem of a quadratic one: ``(model, ropes, fixtures)`` on the vertex mesh of
    ``model`` (its first ``model.mesh.n_nodes`` nodes), each rope along its chain's vertices (a quadratic chain
    alternates vertices and edge midpoints, :func:`~mdsr_opt.mechanics.capstan.quadratic_chain`), each fixture
    its vertex nodes (an end node first)."""
    nv = model.mesh.n_nodes
    lin = QuadraticModel(model.mesh, model.material, 1, numeric=model.numeric)
    lropes = []
    for r in ropes:
        chain = np.asarray(r.chain)
        if len(chain) % 2 == 0 or (chain[0::2] >= nv).any() or (chain[1::2] < nv).any():
            raise ValueError("a rope of the quadratic model must alternate vertices and edge midpoints, "
                             "from a vertex to a vertex")
        lropes.append(CapstanRope(chain[0::2], r.mu))
    lgroups = [np.asarray(g, dtype=np.int64)[np.asarray(g) < nv] for g in fixtures]
    return lin, lropes, lgroups


def solve_quadratic_nested(model: QuadraticModel, ropes: Sequence[CapstanRope], contractions,
                           fixtures: Sequence[np.ndarray] = (), *, start: QuadraticResult | None = None,
                           guess=None, **options) -> QuadraticResult:
    """:func:`~mdsr_opt.mechanics.quadsolve.solve_quadratic_internal` of a quadratic ``model`` whose load
    stepping from rest is replaced by the linear counterpart's (:func:`linear_counterpart`).

    In the order of :func:`~mdsr_opt.mechanics.quadsolve.solve_quadratic_internal`: one Newton solve at the full
    load from ``guess`` when given (its result when it converges); then the linear counterpart stepped from
    rest and one quadratic Newton solve from its equilibrium; when that fails, the quadratic load stepped from
    rest. A linear ``model`` or a ``start`` (an earlier state of these ropes: stepped from it) is solved
    directly. ``options`` (``tol``, ``max_iter``, ``min_step``, ``align_to_rest``) apply to every solve. The
    result's ``iterations`` counts the quadratic Newton iterations of its last solve; its status says where
    it started."""
    a = np.asarray(contractions, dtype=float).ravel()
    if model.order != 2 or start is not None:
        return solve_quadratic_internal(model, ropes, a, fixtures, start=start, guess=guess, **options)
    if guess is not None:
        res = solve_quadratic_internal(model, ropes, a, fixtures, guess=guess, step=False, **options)
        if res.success:
            return res
    lin, lropes, lgroups = linear_counterpart(model, ropes, fixtures)
    coarse = solve_quadratic_internal(lin, lropes, a, lgroups, **dict(options, align_to_rest=False))
    if coarse.success:
        x = coarse.x
        E = model.mesh.edges
        predicted = np.vstack([x, 0.5 * (x[E[:, 0]] + x[E[:, 1]])])
        res = solve_quadratic_internal(model, ropes, a, fixtures, guess=predicted, step=False, **options)
        if res.success:
            res.status = res.status.replace("the predicted state", "the linear-element equilibrium")
            return res
    return solve_quadratic_internal(model, ropes, a, fixtures, **options)
