"""Is an equilibrium a strict minimum? The inertia of a sparse symmetric factorisation, no eigen-solve.

An equilibrium ``x`` of an energy ``E`` with some coordinates held fixed (anchors, drags, gauge) and
possibly active equality constraints ``c(x) = 0`` (taut ropes, rigid anchor patches) is a strict local
minimum when the Hessian of the Lagrangian restricted to the free coordinates is positive definite on the
tangent space ``{d : A_f d = 0}`` of the active constraints (second-order sufficient condition).

:func:`check_stability` decides this from the *inertia* (the numbers of positive, negative and zero
eigenvalues) of a sparse symmetric factorisation ``P H P' = L D L'``: by Sylvester's law of inertia the
signs of the pivots ``D`` are the signs of the eigenvalues. SuperLU in symmetric mode with diagonal
pivoting gives exactly such a factorisation (``U = D L'``). With constraints, Finsler's lemma reduces the
question to the unconstrained one: ``Z' H Z`` is positive definite iff ``H + rho A' A`` is, for every
``rho`` above a finite threshold. ``H + rho A' A`` positive definite certifies stability for any ``rho``; a
``rho`` below the threshold can only add negative eigenvalues, so "not stable" is accepted only with a
tangent direction (``A d = 0``) of negative curvature, and ``rho`` grows by 100 otherwise.

When the state is not a minimum the factorisation also yields a direction of negative curvature:
``v = P' L^{-T} e_k`` for a negative pivot ``d_k`` has ``v' H v = d_k < 0``; a few steps of shifted inverse
iteration improve it towards the lowest mode (what a buckling body does).

An IPOPT solve can answer the question itself (:func:`ipopt_certifies_minimum`): its last step's matrix,
factorised without regularisation, had the inertia of a strict minimum, at a state within ``1e-8`` of the
body's size of the one returned. Load stepping then takes that as its check (``"ipopt-inertia"``). Of the
test suite's checked solves, 156 were so certified, and the factorisation agreed on every one.

Example
-------
>>> import numpy as np, scipy.sparse as sp
>>> H = sp.csc_matrix(np.diag([2.0, 1.0, -0.5]))
>>> chk = check_stability(H, np.ones(3, dtype=bool))
>>> chk.stable, chk.n_negative, round(chk.curvature, 6)
(False, 1, -0.5)
"""

from __future__ import annotations

import time
from dataclasses import dataclass
import warnings

import numpy as np
from scipy.linalg import lapack
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..core.results import compact_repr, to_jsonable
from .kkt import kkt_inertia

__all__ = ["StabilityCheck", "check_stability", "ipopt_certifies_minimum", "certified_minimum", "STEP_RTOL"]


@dataclass
class StabilityCheck:
    """The outcome of :func:`check_stability`.

    Attributes
    ----------
    stable : bool
        The (reduced) Hessian is positive definite: a strict local minimum.
    n_negative : int
        Negative eigenvalues of the reduced Hessian (from the inertia).
    n_zero : int
        Pivots zero relative to the largest one (``rtol``): singular or nearly singular directions.
    direction : (N,) ndarray or None
        When not stable: a unit direction over all coordinates (zero on fixed ones, tangent to the active
        constraints) along which the curvature is negative (or zero when only ``n_zero > 0``).
    curvature : float or None
        ``d' H d / d' d`` along ``direction`` (in the units of ``H``).
    method : str
        ``"ldl-inertia"`` (one factorisation), ``"kkt-inertia"`` (constrained: one factorisation of the KKT
        matrix, when it shows a stable state), ``"ldl-inertia+finsler"`` (constrained, otherwise), with the
        prefix ``"shifted-"`` when the factorisation broke down (exactly singular: two factorisations shifted
        by ``+-tau``) and the suffix ``"-uncertified"`` when a constrained state stayed indefinite for every
        ``rho`` tried without a tangent direction of negative curvature (reported as not stable); or
        ``"ipopt-inertia"``: the IPOPT solve that reached the state certified it (:func:`certified_minimum`).
    time : float
        Seconds spent.
    """

    stable: bool
    n_negative: int
    n_zero: int
    direction: np.ndarray | None
    curvature: float | None
    method: str
    time: float

    def __repr__(self) -> str:
        return compact_repr(self, ("stable", "n_negative", "n_zero", "curvature", "method", "direction"))

    def to_dict(self) -> dict:
        """Every field as JSON-ready values (the direction as a list, or None)."""
        return {f: to_jsonable(getattr(self, f)) for f in self.__dataclass_fields__}

    def summary(self) -> dict:
        """JSON-friendly figures (without the direction)."""
        return {"stable": bool(self.stable), "n_negative": int(self.n_negative), "n_zero": int(self.n_zero),
                "curvature": None if self.curvature is None else float(self.curvature),
                "method": self.method, "time": float(self.time)}


#: :func:`ipopt_certifies_minimum` takes IPOPT's last factorisation for the final state's when the last step
#: moved no coordinate by more than this fraction of the body's size (the last of a converged solve's steps
#: are 1e-10 to 1e-9 of it: quadratic convergence)
STEP_RTOL = 1e-8

#: IPOPT options (without the ``ipopt.`` prefix) that leave its inertia test what
#: :func:`ipopt_certifies_minimum` relies on, with the values allowed (None: any); any other IPOPT option
#: (``hessian_constant``, ``obj_scaling_factor``, another linear solver or Hessian, ...) refuses it
_IPOPT_ALLOWED = {
    "hessian_approximation": ("exact",), "linear_solver": ("mumps",),
    "fixed_variable_treatment": ("make_parameter", "make_parameter_nodual"),
    **{k: None for k in (
        "tol", "max_iter", "acceptable_tol", "acceptable_iter", "dual_inf_tol", "constr_viol_tol",
        "compl_inf_tol", "acceptable_dual_inf_tol", "acceptable_constr_viol_tol", "acceptable_compl_inf_tol",
        "max_cpu_time", "max_wall_time", "print_level", "sb", "print_timing_statistics", "print_user_options",
        "print_frequency_iter", "output_file", "file_print_level", "mu_strategy", "mu_init", "mu_target",
        "bound_relax_factor", "bound_push", "bound_frac", "warm_start_init_point", "warm_start_bound_push",
        "warm_start_bound_frac", "warm_start_mult_bound_push", "constr_mult_init_max", "bound_mult_init_val",
        "mumps_pivot_order", "mumps_mem_percent", "mumps_scaling", "mumps_permuting_scaling")}}


def _ipopt_options(options: dict) -> dict | None:
    """IPOPT's own options among CasADi ``nlpsol`` ``options`` (``ipopt.NAME`` keys and a nested ``"ipopt"``
    dictionary), by name; None when they cannot be read as such."""
    out = {}
    for key, value in options.items():
        if key == "ipopt":
            if not isinstance(value, dict):
                return None
            out.update(value)
        elif isinstance(key, str) and key.startswith("ipopt."):
            out[key[len("ipopt."):]] = value
    return out


def ipopt_certifies_minimum(stats: dict, options: dict, step_tol: float) -> bool:
    """Did IPOPT's own last factorisation show that the state it returned is a strict local minimum?

    For a solve whose constraints were all equalities and whose only bounds pinned coordinates (made
    parameters: ``fixed_variable_treatment`` ``make_parameter[_nodual]``). Before every step IPOPT factorises
    ``K = [[W + dw I, J'], [J, -dc I]]`` (``W`` the Hessian of the Lagrangian over the free coordinates) and
    raises ``dw`` from 0 until ``K`` has ``n`` positive and ``m`` negative eigenvalues. With ``dw = 0`` that
    inertia means ``W`` is positive definite on the tangent space ``{J d = 0}``: for ``dc = 0`` (``J`` of full
    row rank) by Sylvester's law, and for ``dc > 0`` (``J`` rank-deficient) because ``W + J'J / dc`` is then
    positive definite, which certifies it (Finsler's lemma) -- the question :func:`check_stability` answers.

    So: a successful solve (``Solve_Succeeded``) under IPOPT options that keep that test (the exact Hessian,
    MUMPS's inertia: see ``_IPOPT_ALLOWED``; ``options`` as given to ``nlpsol``) whose last iteration took
    the full step (``alpha_pr`` 1) without ``dw`` (``stats["iterations"]["regularization_size"]``) and moved
    the state by at most ``step_tol`` (``d_norm``): that factorisation was made at the state before the last
    step, this close to the one returned. False otherwise (no step taken, a quasi-Newton or constant
    Hessian, an unknown option), when :func:`check_stability` has to answer.

    The factorisation is IPOPT's: a state within about ``step_tol`` times the Hessian's rate of change of a
    zero curvature (at the edge of buckling) is not told apart as :func:`check_stability` does.
    """
    if not stats.get("success") or stats.get("return_status") != "Solve_Succeeded":
        return False
    opts = _ipopt_options(options)
    if opts is None:
        return False
    for key, value in opts.items():
        if key not in _IPOPT_ALLOWED:
            return False
        allowed = _IPOPT_ALLOWED[key]
        if allowed is not None and value not in allowed:
            return False
    it = stats.get("iterations") or {}
    rg, dn, ap = it.get("regularization_size"), it.get("d_norm"), it.get("alpha_pr")
    if not rg or not dn or not ap or min(len(rg), len(dn), len(ap)) < 2:  # no step: no factorisation
        return False
    return float(rg[-1]) == 0.0 and float(ap[-1]) == 1.0 and bool(np.isfinite(dn[-1])) and \
        float(dn[-1]) <= step_tol


def certified_minimum() -> StabilityCheck:
    """The :class:`StabilityCheck` of a state :func:`ipopt_certifies_minimum` certified (method
    ``"ipopt-inertia"``; no curvature estimate, nothing factorised again)."""
    return StabilityCheck(True, 0, 0, None, None, "ipopt-inertia", 0.0)


class _Factor:
    """``P M P' = L D L'`` of a sparse symmetric matrix by SuperLU with symmetric diagonal pivoting."""

    def __init__(self, M: sp.csc_matrix, ordered: bool = False):
        self.lu = spla.splu(M, permc_spec="NATURAL" if ordered else "MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                            options={"SymmetricMode": True})
        self.symmetric = bool(np.array_equal(self.lu.perm_r, self.lu.perm_c))
        self.d = self.lu.U.diagonal()

    def direction(self, k: int) -> np.ndarray:
        """``v`` with ``v' M v = d_k``: solve ``L' w = e_k`` (unit lower ``L``), ``v = Pc w``."""
        lu = self.lu
        n = lu.shape[0]
        e = np.zeros(n)
        e[k] = 1.0
        LT = sp.csr_matrix(lu.L.T)
        w = spla.spsolve_triangular(LT, e, lower=False, unit_diagonal=True)
        return w[lu.perm_c]  # v = Pc w with Pc[i, perm_c[i]] = 1


def _check_inputs(H, free, A):
    if not sp.issparse(H):
        if isinstance(H, np.ndarray) and H.ndim == 2:
            H = sp.csc_matrix(H)
        else:
            raise TypeError(f"H must be a scipy sparse (N, N) matrix, got {type(H).__name__}")
    N = H.shape[0]
    if H.shape != (N, N):
        raise ValueError(f"H must be square, got shape {H.shape}")
    free = np.asarray(free)
    if free.dtype != bool or free.shape != (N,):
        raise ValueError(f"free must be a boolean mask of shape ({N},), got dtype {free.dtype} shape "
                         f"{free.shape}")
    if A is not None:
        if not sp.issparse(A):
            if isinstance(A, np.ndarray) and A.ndim == 2:
                A = sp.csr_matrix(A)
            else:
                raise TypeError(f"A must be a scipy sparse (m, N) matrix or None, got {type(A).__name__}")
        if A.shape[1] != N:
            raise ValueError(f"A must have {N} columns like H, got shape {A.shape}")
        if A.shape[0] == 0:
            A = None
    return H, free, A


def _independent_rows(Af: sp.csr_matrix) -> sp.csr_matrix:
    """A maximal linearly independent subset of the rows of ``Af`` (same null space): rank-revealing
    pivoted Cholesky (LAPACK ``dpstrf``) of the small ``m x m`` Gram matrix when its sparse LU finds it
    singular."""
    G = (Af @ Af.T).tocsc()
    try:  # G is symmetric positive semidefinite: diagonal pivots in a minimum-degree order (as a Cholesky)
        d = spla.splu(G, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}).U.diagonal()
        if np.all(np.isfinite(d)) and np.abs(d).min() > 1e-10 * np.abs(d).max():
            return Af
    except RuntimeError:
        pass

    Gd = G.toarray()
    _, piv, rank, _ = lapack.dpstrf(Gd, tol=1e-10 * float(np.abs(np.diag(Gd)).max()))
    return Af[np.sort(piv[:rank] - 1)]


def _inertia(fac: _Factor, rtol: float, scale: float) -> tuple[int, int]:
    """``(negative, zero)`` pivots; a pivot is zero when ``|d| <= rtol * scale`` (``scale`` the largest
    diagonal entry of the matrix tested, not of the penalised one)."""
    d = fac.d
    zero = np.abs(d) <= rtol * scale
    return int(((d < 0) & ~zero).sum()), int(zero.sum())


def _factor_inertia(M, rtol: float, scale: float, ordered: bool = False):
    """``(factor, (negative, zero), shifted)``. When the factorisation breaks down (exactly singular, or
    SuperLU pivoted off the diagonal) the inertia of ``M + tau I`` and ``M - tau I`` brackets the zero
    eigenvalues (``shifted=True``, the factor of the lower one returned when it has a negative pivot).
    ``ordered``: ``M`` is in a fill-reducing order already (no ordering of SuperLU's own)."""
    try:
        fac = _Factor(M, ordered)
        if fac.symmetric and np.all(np.isfinite(fac.d)):
            return fac, _inertia(fac, rtol, scale), False
    except RuntimeError:
        pass
    tau = max(rtol, 1e-12) * scale
    I = sp.identity(M.shape[0], format="csc")
    lo, hi = _Factor((M + tau * I).tocsc(), ordered), _Factor((M - tau * I).tocsc(), ordered)
    n_neg = int((lo.d < 0).sum())
    n_zero = max(int((hi.d < 0).sum()) - n_neg, 0)
    return (lo if n_neg else hi), (n_neg, n_zero), True


def _tangent(project, v):
    """``project(v)``, or None when ``v`` lies (numerically) in the constraints' row space."""
    w = project(v)
    nv = np.linalg.norm(v)
    return w if nv > 0 and np.linalg.norm(w) > 1e-8 * nv else None


def _rayleigh(M, v) -> float:
    vv = float(v @ v)
    return float(v @ (M @ v)) / vv if vv > 0 else 0.0


def _refine(M: sp.csc_matrix, v: np.ndarray, steps: int = 6,
            ordered: bool = False) -> tuple[np.ndarray, "_Factor | None"]:
    """Shifted inverse iteration from ``v`` towards the lowest mode of ``M``.

    The shift ``sigma`` is pushed below the lowest eigenvalue, which the inertia of ``M - sigma I`` certifies
    (no negative pivot); iteration then converges to the lowest mode. Iterates are kept only while their
    curvature decreases, so the result is never worse than ``v``. Also returns the factor of the positive
    definite ``M - sigma I`` (None if none was found): a preconditioner for the lowest mode."""
    best, mu = v, _rayleigh(M, v)
    if mu >= 0:
        return v, None
    I = sp.identity(M.shape[0], format="csc")

    def below(sigma):  # the factor of M - sigma I when sigma is below every eigenvalue, else None
        try:
            f = _Factor((M - sigma * I).tocsc(), ordered)
        except RuntimeError:  # sigma is an eigenvalue
            return None
        return f if f.symmetric and not (f.d < 0).any() else None

    sigma, fac, above = 2.0 * mu, None, mu  # mu >= lambda_min: 'above' bounds it from above
    for _ in range(16):
        fac = below(sigma)
        if fac is not None:
            break
        above, sigma = sigma, 4.0 * sigma
    if fac is None:
        return v, None
    for _ in range(2):  # bisect [sigma, above] to bring the shift closer to lambda_min (faster iteration)
        mid = 0.5 * (sigma + above)
        f = below(mid)
        if f is None:
            above = mid
        else:
            sigma, fac = mid, f
    y = v
    for _ in range(steps):
        y = fac.lu.solve(y)
        nrm = np.linalg.norm(y)
        if not np.isfinite(nrm) or nrm == 0:
            break
        y = y / nrm
        r = _rayleigh(M, y)
        if r < mu:
            best, mu = y, r
    return best, fac


def check_stability(H, free, A=None, *, rtol: float = 1e-10, direction: bool = True,
                    lowest: bool = False, order=None) -> StabilityCheck:
    """Is ``H`` positive definite on the free coordinates (and the tangent space of active constraints)?

    Parameters
    ----------
    H : (N, N) scipy sparse symmetric matrix
        Hessian of the energy (of the Lagrangian when constraints are active) in all coordinates.
    free : (N,) bool ndarray
        Mask of the free coordinates; the others are held fixed (anchors, drags, gauge).
    A : (m, N) scipy sparse matrix, optional
        Jacobian of the *active* equality constraints (taut ropes, rigid patches). The test is then on
        ``{d_free : A_free d_free = 0}``. Linearly dependent rows are allowed (a maximal independent
        subset is used).
    rtol : float
        A pivot with ``|d| <= rtol * max|diag H_ff|`` counts as zero (``n_zero``); zero pivots make a
        state not stable.
    direction : bool
        Compute a direction of negative curvature when not stable (default). ``False`` skips it.
    lowest : bool
        Also compute the lowest eigenvalue of the reduced Hessian (reported in ``curvature``; when not
        stable, ``direction`` is then its eigenvector): LOBPCG preconditioned by a positive definite factor
        already made (of the matrix, or of the matrix shifted below its lowest eigenvalue), so a few
        iterations; below 100 free coordinates a dense solve of the small matrix. Off by default: the
        solvers only need the inertia.
    order : int array, optional
        A fill-reducing ordering of the free coordinates (a permutation of ``0 .. n_free - 1``, e.g.
        :meth:`~mdsr_opt.mechanics.model.EnergyModel.free_ordering`), used by the factorisations instead of
        SuperLU's own minimum degree ordering when there are no constraints; with constraints (and
        ``lowest=False``) the inertia of the KKT matrix factored in that order answers first when it says
        stable (:func:`~mdsr_opt.mechanics.kkt.kkt_inertia`). Same answer, less time.

    Returns
    -------
    StabilityCheck

    Notes
    -----
    Cost: one sparse factorisation of the free block (with constraints, of ``H + rho A'A``), plus, only
    when not stable, a few triangular solves and a few factorisations for the direction (with constraints,
    repeated with a 100x larger ``rho`` until a tangent direction of negative curvature certifies the
    answer). No eigen-solve.
    """
    t0 = time.perf_counter()
    H, free, A = _check_inputs(H, free, A)
    if not (isinstance(rtol, (int, float)) and np.isfinite(rtol) and 0 <= rtol < 1):
        raise ValueError(f"rtol must be a number in [0, 1), got {rtol!r}")
    N = H.shape[0]
    idx = np.flatnonzero(free)
    n = len(idx)
    if n == 0:
        return StabilityCheck(True, 0, 0, None, None, "ldl-inertia", time.perf_counter() - t0)
    if order is not None:
        order = np.asarray(order)
        if order.shape != (n,) or not np.array_equal(np.sort(order), np.arange(n)):
            raise ValueError(f"order must be a permutation of the {n} free coordinates")
    ordered = order is not None and A is None
    if ordered:  # everything below works on the free coordinates in this order; vdir[idx] maps them back
        idx = idx[order]
    H = sp.csc_matrix(H)
    Hff = H[idx][:, idx].tocsc()
    Hff = (0.5 * (Hff + Hff.T)).tocsc()
    method = "ldl-inertia"

    project = (lambda v: v)
    h = float(abs(Hff.diagonal()).max()) or 1.0
    Af, rho = None, 0.0
    if A is not None:
        Af = sp.csr_matrix(A)[:, idx]
        keep = np.asarray(abs(Af).sum(axis=1)).ravel() > 0  # rows touching only fixed coordinates
        Af = Af[keep] if keep.any() else None
    if Af is not None:
        method = "ldl-inertia+finsler"
        Af = _independent_rows(Af)
        if order is not None and not lowest:
            # one factorisation of the KKT matrix in the mesh's order: its inertia answers "stable" at
            # about half the cost of H + rho A'A with SuperLU's own ordering (3k nodes, 326 rows)
            inertia = kkt_inertia(Hff, Af, order, rtol)
            if inertia == (0, 0):
                return StabilityCheck(True, 0, 0, None, None, "kkt-inertia", time.perf_counter() - t0)
        AAt = (Af @ Af.T).tocsc()
        aat = spla.splu(AAt)

        def project(v, Af=Af, aat=aat):  # orthogonal projection onto null(A_f)
            return v - Af.T @ aat.solve(Af @ v)

        rho = 1e4 * h / float(AAt.diagonal().max())
        AtA = (Af.T @ Af).tocsc()

    # Finsler: M = H + rho A'A positive definite certifies Z'HZ positive definite for any rho. A rho below
    # the (unknown) threshold can only add negative eigenvalues, so "not stable" is certified by a tangent
    # direction of negative curvature, and otherwise rho grows.
    best, pre = None, None
    for attempt in range(1 if Af is None else 3):
        M = Hff if Af is None else (Hff + rho * AtA).tocsc()
        fac, (n_neg, n_zero), shifted = _factor_inertia(M, rtol, h, ordered)
        if shifted:
            method = "shifted-" + method.replace("shifted-", "")
        stable = n_neg == 0 and n_zero == 0
        best, pre = None, (fac if stable else None)  # a positive definite factor: a preconditioner
        if stable or not (direction or lowest or Af is not None):
            break
        d = fac.d
        order = np.argsort(d)[:5] if n_neg else np.argsort(np.abs(d))[:1]
        mu = np.inf
        for k in order:
            v = _tangent(project, fac.direction(int(k)))
            r = _rayleigh(Hff, v) if v is not None else np.inf
            if r < mu:
                best, mu = v, r
        if best is not None and n_neg:
            refined, pre = _refine(M, best, ordered=ordered)
            refined = _tangent(project, refined)
            if refined is not None and _rayleigh(Hff, refined) < mu:
                best = refined
        if Af is None or (best is not None and _rayleigh(Hff, best) < (rtol * h if not n_neg else 0.0)):
            break  # certified
        rho *= 100.0
    else:
        method += "-uncertified"  # not stable for every rho tried, but no tangent direction of negative curvature
    vdir, curv = None, None
    if lowest:
        lam, vec = _lowest(Hff, project, Af, pre, best)
        if lam is not None:
            curv = lam
            if not stable and vec is not None and (best is None or lam < _rayleigh(Hff, best)):
                best = vec
    if not stable and best is not None and np.all(np.isfinite(best)) and np.linalg.norm(best) > 0:
        best = best / np.linalg.norm(best)
        vdir = np.zeros(N)
        vdir[idx] = best
        curv = _rayleigh(Hff, best)
    if not direction:
        vdir = None
    return StabilityCheck(bool(stable), int(n_neg), int(n_zero), vdir, curv, method, time.perf_counter() - t0)


def _lowest(Hff, project, A_free=None, pre: "_Factor | None" = None, x0=None, k: int = 4,
            maxiter: int = 80) -> tuple[float | None, np.ndarray | None]:
    """Lowest eigenpair of the (reduced) matrix: LOBPCG preconditioned by a positive definite factor ``pre``
    (the matrix's own, or of the matrix shifted below its lowest eigenvalue), so a few iterations; on the
    null space of the active constraints when there are any. Below 100 coordinates LOBPCG is unreliable
    and a dense solve of the small matrix is instant: used there. ``(None, None)`` without a factor."""
    n = Hff.shape[0]
    if n < 100:
        if A_free is None:
            w, V = np.linalg.eigh(Hff.toarray())
            return float(w[0]), V[:, 0]
        Q = np.linalg.qr(A_free.T.toarray(), mode="complete")[0][:, A_free.shape[0]:]
        w, V = np.linalg.eigh(Q.T @ (Hff @ Q))
        return float(w[0]), Q @ V[:, 0]
    if pre is None:
        return None, None
    cols = [] if x0 is None else [np.asarray(x0, dtype=float)]
    cols += [project(c) for c in np.random.default_rng(0).standard_normal((k - len(cols), n))]
    X = np.column_stack(cols)
    M = spla.LinearOperator((n, n), matvec=lambda v: project(pre.lu.solve(np.ravel(v))), dtype=float)
    Y = None if A_free is None else A_free.T.toarray()

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        w, V = spla.lobpcg(Hff, X, M=M, Y=Y, largest=False, tol=1e-9, maxiter=maxiter)
    i = int(np.argmin(w))
    return float(w[i]), V[:, i]
