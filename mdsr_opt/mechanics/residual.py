"""What a solve's ``tol`` means: the scaled KKT residual, the one test every accepted state passes.

An equilibrium of external or internal driving is accepted at tolerance ``tol`` when its scaled KKT residual
(:func:`kkt_residual`) is at most ``tol``:

``r(x) = max(stationarity, violation)``

- ``stationarity = |grad E(x) + J(x)' lam|_inf / (E t S)`` over the free coordinates (``E t S`` a force:
  Young's modulus times thickness times the body's size ``S = mesh.size``), with ``lam`` the least-squares
  multipliers of the constraints (:meth:`~mdsr_opt.mechanics.constrained.ConstrainedModel.multipliers`): every
  rigid anchor-patch row, and every rope whose path is within ``tol L0`` of its target and whose fitted
  tension is not negative (a rope shorter than that carries no tension: complementarity to ``tol``);
  without constraints the energy gradient alone;
- ``violation = max((L_c - T_c)_+ / L0_c, |c_rigid| / S)``: how far a rope is longer than its target
  (a strain) and how far an anchor patch is from rigid (a length over ``S``).

Every place that accepts a state tests this same number against the solve's ``tol``: the last load step
(:func:`~mdsr_opt.mechanics.loadsteps.load_continuation`), the saddle escape's re-solves, the result's own
check (:func:`~mdsr_opt.mechanics.loadsteps.equilibrium_result`: ``residual``) and the design's
verification. IPOPT is asked for the same measure (its unscaled dual infeasibility, constraint violation
and complementarity at most ``tol`` too, :func:`ipopt_tolerances`); since its multipliers are its own, a
state it returns above ``tol`` is polished by Newton steps on the KKT system (:func:`meet_tolerance`) and
rejected only if they do not bring it down. A state accepted at ``tol`` is therefore accepted again by
:func:`kkt_residual` at ``tol``.

A rope that pulls must be at its length to ``tol``, not only to the product of its shortness and tension
that an interior point method bounds: IPOPT's answers with a rope in the inequality form (its barrier
keeps a taut rope short by 1e-8 to 1e-7 L0 at tol 1e-8) and those with a rope ending at its length with
almost no tension (short by up to 1e-4 L0, the state as far off) are polished; a product measure would
accept both as they are.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .kkt import kkt_factor

__all__ = ["Residual", "kkt_residual", "meet_tolerance", "ipopt_tolerances", "stiffness_of"]


def ipopt_tolerances(tol: float) -> dict:
    """IPOPT options that make its termination test the scaled KKT residual at ``tol`` (on top of its own
    ``tol`` on its scaled problem): unscaled dual infeasibility, constraint violation and complementarity
    at most ``tol`` (never looser than IPOPT's defaults, 1, 1e-4 and 1e-4, which a loose ``tol`` keeps)."""
    return {"ipopt.tol": tol, "ipopt.dual_inf_tol": min(tol, 1.0), "ipopt.constr_viol_tol": min(tol, 1e-4),
            "ipopt.compl_inf_tol": min(tol, 1e-4)}


def stiffness_of(p_energy) -> float:
    """``E t`` from an energy parameter vector whose first two entries are ``mu t`` and ``lam t``
    (:meth:`~mdsr_opt.mechanics.model.EnergyModel.params`)."""
    mu, lam = float(p_energy[0]), float(p_energy[1])
    return mu * (3.0 * lam + 2.0 * mu) / (lam + mu)


@dataclass
class Residual:
    """The scaled KKT residual of a state (see the module docstring).

    Attributes
    ----------
    value : float
        ``max(stationarity, violation)``: what ``tol`` bounds.
    stationarity, violation : float
    lam : ndarray or None
        The constraints' multipliers (physical units; None without constraints).
    taut : ndarray or None
        Per rope, whether it carries tension in ``lam``.
    """

    value: float
    stationarity: float
    violation: float
    lam: np.ndarray | None = None
    taut: np.ndarray | None = None


def _force(model, p, force) -> float:
    if force is not None:
        return float(force)
    pe = model.split(p)[0] if hasattr(model, "split") else p
    return stiffness_of(pe) * model.mesh.size


def kkt_residual(model, x, p, fixed, tol: float, force: float | None = None,
                 gradient: np.ndarray | None = None) -> Residual:
    """The scaled KKT residual of the state ``x`` (2n,) of ``model`` with parameters ``p`` (a constrained
    model's: energy parameters and rope targets; its multipliers are refitted) and ``fixed`` coordinates.

    ``tol`` decides which ropes may pull (those within ``tol L0`` of their targets); ``force`` is the
    force scale, ``E t S`` (default: from ``p`` and the mesh); ``gradient`` the energy gradient at ``x``
    when the caller has it."""
    x = np.asarray(x, dtype=float).reshape(-1)
    free = ~np.asarray(fixed, dtype=bool)
    F = _force(model, p, force)
    if not hasattr(model, "multipliers"):  # no constraints: the energy gradient
        g = model.gradient(x, p) if gradient is None else gradient
        s = float(np.abs(g[free]).max()) / F if free.any() else 0.0
        return Residual(s, s, 0.0)
    pe, targets, _ = model.split(p)
    g = model.model.gradient(x, pe) if gradient is None else gradient
    lam, taut = model.multipliers(x, model.params(pe, targets if model.n_targets else None), fixed,
                                  rtol=float(tol), gradient=g)
    gl = g + model.jacobian(x).T @ lam if model.n_rows else g
    s = float(np.abs(gl[free]).max()) / F if free.any() else 0.0
    v = model.values(x)
    nt = model.n_targets
    over = float(np.max((v[:nt] - targets) / model.constraints.rest_lengths[:nt], initial=0.0))
    rigid = float(np.abs(v[nt:]).max(initial=0.0)) / model.mesh.size
    viol = max(over, rigid, 0.0)
    return Residual(max(s, viol), s, viol, lam, taut)


#: a state being polished (:func:`meet_tolerance`) takes Newton steps until its residual is this fraction of
#: the tolerance (or they stop lowering it): one step more than ``tol`` itself needs, so that the state is
#: not accepted right at the tolerance
POLISH_MARGIN = 1e-2


def _newton_step(model, x, p, fixed, lam, active, tol):
    """One Newton step on the KKT system from ``x``: ``(y, lam, active)`` or None when it is singular.

    The Hessian is the Lagrangian's with the multipliers ``lam``; every rigid row and the ropes in
    ``active`` are linearised and met. The ropes held are then corrected as an active set on the
    linearisation: a held rope whose new multiplier is negative is released, a released one the step
    would leave longer than its target (by more than ``tol L0 / 10``) is held, and the step made again
    (at most ``2 m + 1`` times for ``m`` ropes). Returns the new state, its multipliers and the ropes held."""
    free = ~fixed
    constrained = hasattr(model, "multipliers")
    if constrained:
        pe, targets, _ = model.split(p)
        emodel = model.model
        H = model.hessian(x, model.params(pe, targets if model.n_targets else None, lam))
        g = emodel.gradient(x, pe)
        J = model.jacobian(x).tocsr()
        c = model.values(x) - model.bounds(p)[1]  # ropes: L - target; rigid rows: their values
        rows = np.ones(model.n_rows, dtype=bool)
        rows[:model.n_targets] = active
        nt = model.n_targets
        L0 = model.constraints.rest_lengths[:nt]
    else:
        emodel = model
        H, g = model.hessian(x, p), model.gradient(x, p)
        J, c, rows, nt, L0 = sp.csr_matrix((0, len(x))), np.zeros(0), np.zeros(0, dtype=bool), 0, np.zeros(0)
    Hf = H.tocsr()[free][:, free]
    Jf = J[:, free]
    order = emodel.free_ordering(free) if getattr(emodel, "is_numeric", False) else None
    nf = int(free.sum())
    for _ in range(2 * nt + 1):
        fac = kkt_factor(Hf, Jf[rows], order)
        if fac is None:
            return None
        sol = fac.solve(np.concatenate([-g[free], -c[rows]]))
        if not np.all(np.isfinite(sol)):
            return None
        new = np.zeros(len(rows))
        new[rows] = sol[nf:]
        neg = rows[:nt] & (new[:nt] < 0.0)
        if neg.any():
            rows[:nt] &= ~neg
            continue
        over = ~rows[:nt] & ((c[:nt] + Jf[:nt] @ sol[:nf]) > 0.1 * tol * L0)
        if not over.any():
            break
        rows[:nt] |= over
    y = x.copy()
    y[free] += sol[:nf]
    return y, new, rows[:nt].copy()


def meet_tolerance(model, x, p, fixed, tol: float, force: float | None = None, upright=None, lam=None,
                   max_steps: int = 3) -> tuple[np.ndarray, Residual, bool]:
    """``x`` (2n,) or a state polished from it, its :func:`kkt_residual` and whether it was polished.

    A state above ``tol`` takes up to ``max_steps`` Newton steps on the KKT system (:func:`_newton_step`),
    until its residual is below :data:`POLISH_MARGIN` x ``tol``; each is kept while it lowers the residual
    and keeps every element upright (``upright(y)``, when given). The first step holds the ropes within
    ``sqrt(tol) L0`` of their targets (or longer) and those whose tension (``lam``, the solver's
    multipliers, else fitted with every rope) relative to ``E t S`` is at least their distance to the
    target relative to ``L0`` (the interior point's estimate of its active set); the steps correct that
    set on the linearisation (:func:`_newton_step`). A solver that stops just short of ``tol`` in this
    measure (its own multipliers or scaling differ) so still returns a state that meets it."""
    x = np.asarray(x, dtype=float).reshape(-1)
    fixed = np.asarray(fixed, dtype=bool)
    F = _force(model, p, force)
    res = kkt_residual(model, x, p, fixed, tol, F)
    if res.value <= tol or not np.isfinite(res.value):
        return x, res, False
    active = None
    if hasattr(model, "multipliers"):
        pe, targets, _ = model.split(p)
        if lam is None:
            lam = model.multipliers(x, model.params(pe, targets if model.n_targets else None), fixed,
                                    ropes_only_pull=False)[0]
        nt = model.n_targets
        short = (targets - model.values(x)[:nt]) / model.constraints.rest_lengths[:nt]
        active = (short <= np.sqrt(tol)) | (np.asarray(lam)[:nt] / F >= short)
    polished = False
    for _ in range(max_steps):  # once polishing, aim below the tolerance: a margin for re-checks
        step = _newton_step(model, x, p, fixed, lam, active, tol)
        if step is None:
            break
        y, lam_y, active_y = step
        if not np.all(np.isfinite(y)) or (upright is not None and not upright(y)):
            break
        r2 = kkt_residual(model, y, p, fixed, tol, F)
        if not r2.value < res.value:
            break
        x, res, polished, lam, active = y, r2, True, lam_y, active_y
        if res.value <= POLISH_MARGIN * tol:
            break
    return x, res, polished
