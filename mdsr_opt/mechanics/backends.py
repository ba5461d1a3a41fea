"""Minimisers of a model's energy with some coordinates held fixed: one function per backend.

Every backend takes the same inputs (an :class:`~mdsr_opt.mechanics.model.EnergyModel`, parameters ``p``, a first
guess, a mask of fixed coordinates and their values) and returns a :class:`MinimizeOutcome`. Building a
CasADi solver happens once per model and backend; later solves reuse it. A model with muscle
constraints (exact cable ropes, rigid anchor patches) is solved by :mod:`~mdsr_opt.mechanics.ropesolve`.

Backends
--------
``ipopt``         IPOPT, exact Hessian (scattered element Hessians), MUMPS. The default. Energy, gradient
                  and Hessian are evaluated in vectorised numpy where the model allows it
                  (:attr:`~mdsr_opt.mechanics.model.EnergyModel.is_numeric`), else symbolically.
``ipopt-symbolic`` The same IPOPT problem with the energy's gradient and Hessian always from the symbolic
                  CasADi model (the reference formulation; slower to build and to evaluate).
``ipopt-lbfgs``   IPOPT with a limited-memory quasi-Newton Hessian.
``sqpmethod``     CasADi's SQP method with the exact Hessian and the ``qrqp`` QP solver.
``uno``           The Uno solver shipped with the casadi wheel (exact Hessian derived by CasADi), with its
                  interior-point preset (:data:`UNO_PRESET`, MUMPS). Uno's default preset, filtersqp, solves
                  its QP subproblems with BQPD on a dense reduced Hessian as large as the free coordinates
                  (two orders of magnitude slower from a few hundred nodes on), and the casadi wheel's build
                  sizes BQPD's integer workspace too small (a Fortran "not enough real (ws) or integer
                  (lws) workspace" message on stderr); ``{"uno.preset": "filtersqp"}`` in ``options``
                  still selects it.
``scipy``         ``scipy.optimize.minimize(method="trust-constr")`` on the free coordinates with
                  CasADi-generated gradient and sparse Hessian: the baseline a user might write.
``newton``        A projected Newton method in numpy/scipy (:mod:`mdsr_opt.mechanics.newton`): vectorised element
                  terms projected to positive semi-definite, one fill-reducing ordering reused by every
                  sparse factorisation, backtracking line search.
"""

from __future__ import annotations

import functools
import time
import warnings
from typing import Mapping

import casadi as ca
import numpy as np

from ..core.guards import captured_stdout, check_stop, interruptible, quiet_stdout
from . import ropesolve
from .residual import ipopt_tolerances
from .assembly import ipopt_functions
from .newton import projected_newton
from .result import MinimizeOutcome, solver_status
from .stopping import with_stop_callback
from .stability import STEP_RTOL, ipopt_certifies_minimum

__all__ = ["BACKENDS", "CONSTRAINED_BACKENDS", "UNO_PRESET", "available_backends", "minimize", "supports_constraints",
           "check_options"]


def _casadi_factory(plugin: str, opts: dict, symbolic: bool = False):
    def factory(model):
        o = dict(opts)
        o["show_eval_warnings"] = False  # NaN from log J in a trial step is expected; IPOPT cuts the step
        o = with_stop_callback(o)  # Ctrl-C stops the solver at its next iteration
        if plugin == "ipopt" and not symbolic and getattr(model, "is_numeric", False):
            # energy, gradient and Hessian in vectorised numpy through callbacks: no symbolic graph to build
            fns = ipopt_functions(model)
            x, p = ca.MX.sym("x", model.n_dof), ca.MX.sym("p", model.n_params)
            o["grad_f"], o["hess_lag"] = fns["grad_f"], fns["hess_lag"]
            o["no_nlp_grad"] = True  # only for multipliers of bounds and parameters, which are not used
            return ca.nlpsol(f"equilibrium_{plugin.replace('-', '_')}", plugin,
                             {"x": x, "p": p, "f": fns["f"](x, p)}, o)
        nlp = {"x": model.x, "p": model.p, "f": model.f_fn(model.x, model.p)}
        if plugin == "ipopt":
            o["hess_lag"] = model.hess_lag_fn
            o["grad_f"] = model.grad_fn
        elif plugin == "sqpmethod":
            o["hess_lag"] = model.hess_lag_full_fn
        # uno: CasADi derives its own gradient and Hessian from the expanded energy
        return ca.nlpsol(f"equilibrium_{plugin.replace('-', '_')}", plugin, nlp, o)
    return factory


def _ipopt_opts(tol, max_iter, limited_memory=False, linear_solver="mumps"):
    # the unscaled tolerances too: IPOPT's own "tol" bounds its scaled problem (gradient-based scaling), the
    # package accepts the scaled KKT residual at tol (mdsr_opt.mechanics.residual)
    o = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes", **ipopt_tolerances(tol),
         "ipopt.max_iter": max_iter, "ipopt.linear_solver": linear_solver, "error_on_fail": False,
         # multipliers of bounds and parameters are not used: skip their extra derivative evaluations
         "calc_lam_p": False, "calc_lam_x": False,
         # fixed coordinates become parameters without bound multipliers: about half the gradient calls,
         # the same iterates
         "ipopt.fixed_variable_treatment": "make_parameter_nodual"}
    if limited_memory:
        o["ipopt.hessian_approximation"] = "limited-memory"
    return o


def _solve_casadi(plugin, opts, model, p, x0, fixed, values, symbolic: bool = False):
    solver, build_time = model.solver(plugin + ("-symbolic" if symbolic else ""), opts,
                                      _casadi_factory(plugin, opts, symbolic))
    lbx, ubx, x0 = ropesolve.pinned_bounds(model.n_dof, x0, fixed, values)
    t0 = time.perf_counter()
    with quiet_stdout(plugin == "uno"):
        sol = solver(x0=x0, p=p, lbx=lbx, ubx=ubx)
    solve_time = time.perf_counter() - t0
    st = solver.stats()
    status, iters = solver_status(st)
    # no constraints, only pinned coordinates: IPOPT's inertia test is the stability check's question
    cert = plugin == "ipopt" and ipopt_certifies_minimum(st, opts, STEP_RTOL * model.mesh.size)
    return MinimizeOutcome(np.asarray(sol["x"]).ravel(), bool(st.get("success", False)), status, iters,
                           solve_time, build_time, certified=cert)


def _free_problem(model, p, fixed, values, x0):
    free = ~fixed
    base = np.array(x0, dtype=float)
    base[fixed] = values

    def full(z):
        y = base.copy()
        y[free] = z
        return y

    return free, base, full


def _solve_scipy(model, p, x0, fixed, values, tol, max_iter):
    from scipy.optimize import minimize as sp_minimize

    free, base, full = _free_problem(model, p, fixed, values, x0)

    def fun(z):
        check_stop()  # an interrupt swallowed in a CasADi evaluation stops trust-constr here
        f, g = model.grad_fn(full(z), p)
        f = float(f)
        if not np.isfinite(f):
            return np.inf, np.zeros(free.sum())
        return f, np.asarray(g).ravel()[free]

    def hess(z):
        return model.hessian(full(z), p)[free][:, free]

    t0 = time.perf_counter()
    res = sp_minimize(fun, base[free], jac=True, hess=hess, method="trust-constr",
                      options={"gtol": tol, "xtol": 1e-14, "maxiter": max_iter, "verbose": 0})
    solve_time = time.perf_counter() - t0
    return MinimizeOutcome(full(res.x), bool(res.status in (1, 2)) and bool(np.isfinite(res.fun)),
                           f"status {res.status}: {res.message}", int(res.nit), solve_time, 0.0)


def _solve_newton(model, p, x0, fixed, values, tol, max_iter):
    """Projected Newton in numpy/scipy (:mod:`mdsr_opt.mechanics.newton`): vectorised assembly, one ordering reused."""
    x, success, status, it, seconds = projected_newton(model, p, x0, fixed, values, tol=tol, max_iter=max_iter)
    return MinimizeOutcome(x, success, status, it, seconds, 0.0)


BACKENDS = {
    "ipopt": "IPOPT, exact Hessian, MUMPS (default)",
    "ipopt-lbfgs": "IPOPT, limited-memory Hessian",
    "ipopt-symbolic": "IPOPT, exact Hessian from the symbolic CasADi model (reference)",
    "sqpmethod": "CasADi sqpmethod (exact Hessian, qrqp)",
    "uno": "Uno through CasADi (exact Hessian, interior-point preset, MUMPS)",
    "scipy": "scipy.optimize.minimize trust-constr with CasADi derivatives",
    "newton": "projected Newton in numpy/scipy (baseline)",
}


def _plugin(backend: str) -> str:
    """The CasADi plugin of a backend (the IPOPT variants differ in options and derivatives)."""
    return "ipopt" if backend in ("ipopt-lbfgs", "ipopt-symbolic") else backend


def available_backends() -> list[str]:
    """Names of the backends usable with this CasADi build."""
    return list(_available())


@functools.lru_cache(maxsize=None)
def _available() -> tuple[str, ...]:
    # asked once per process: CasADi looks for each plugin's library, and every solve checks its backend
    out = []
    for name in BACKENDS:
        if name in ("scipy", "newton") or ca.has_nlpsol(_plugin(name)):
            out.append(name)
    return tuple(out)


def check_backend(backend: str) -> str:
    if not isinstance(backend, str):
        raise TypeError(f"backend must be a string, got {type(backend).__name__}")
    if backend not in available_backends():
        raise ValueError(f"unknown backend {backend!r}; available: {', '.join(available_backends())}")
    return backend


_OPTION_VERDICTS: dict = {}  # (plugin, name, repr(value)) -> None (valid) or the error message


def _casadi_verdict(plugin: str, name: str, value) -> str | None:
    x = ca.SX.sym("x")
    opts = {"ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": False} if plugin == "ipopt" else {}
    opts[name] = value
    printed: list[str] = []
    try:
        with captured_stdout(printed):
            ca.nlpsol("option_probe", plugin, {"x": x, "f": (x - 1) ** 2}, opts)
    except RuntimeError as exc:
        text = str(exc)
        if "No such IPOPT option" in text or "Unknown option" in text:
            hint = " (IPOPT's own options are written 'ipopt.NAME')" if plugin == "ipopt" and \
                not name.startswith("ipopt.") else ""
            return f"unknown {plugin} option {name!r}{hint}"
        said = [ln.strip() for ln in printed[0].splitlines() if ln.strip().startswith("Setting:")] if printed else []
        why = said[0].replace(" Check the option documentation.", "") if said else next(
            (ln.strip() for ln in reversed(text.splitlines()) if ln.strip() and "Error calling" not in ln), text)
        why = why.split(".cpp:", 1)[1].split(": ", 1)[-1] if ".cpp:" in why else why
        return f"invalid value {value!r} for {plugin} option {name!r}: {why}"
    return None


def _scipy_verdict(method: str, name: str, value) -> str | None:
    from scipy.optimize import OptimizeWarning
    from scipy.optimize import minimize as sp_minimize

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", OptimizeWarning)
            sp_minimize(lambda z: float(z @ z), np.ones(2), method=method, bounds=[(-1.0, 2.0)] * 2,
                        options={name: value})
    except OptimizeWarning as exc:
        if "Unknown solver options" in str(exc):
            return f"unknown scipy {method} option {name!r}"
        return None  # a warning about the tiny probe problem, not about the option
    except Exception as exc:  # the value broke the method (wrong type, out of range)
        return f"invalid value {value!r} for scipy {method} option {name!r}: {type(exc).__name__}: {exc}"
    return None


def check_options(backend: str, options: Mapping | None) -> dict:
    """Check solver options against what the backend knows, before any solve.

    Parameters
    ----------
    backend : str
        A name of :data:`BACKENDS` (``options`` as :func:`minimize` takes them: CasADi ``nlpsol`` options,
        IPOPT's own with the ``ipopt.`` prefix), or ``"scipy:METHOD"`` for the options of
        ``scipy.optimize.minimize(method=METHOD)`` (as the nested and derivative-free designs take them).
    options : mapping of str to value, or None

    Returns
    -------
    dict
        A copy of ``options``.

    Raises
    ------
    TypeError
        ``options`` is not a mapping or a name is not a string.
    ValueError
        An unknown option or an invalid value, named (with IPOPT's own reason, e.g. the valid settings),
        instead of a CasADi ``RuntimeError`` when the solver is built; or options for a backend that takes
        none (``scipy``, ``newton``).

    Each option is tried once on a one-variable problem (building the solver, not solving) and the verdict
    cached per process, so repeated calls cost a dictionary lookup.

    Example
    -------
    >>> check_options("ipopt", {"ipopt.tol": 1e-6})
    {'ipopt.tol': 1e-06}
    >>> check_options("ipopt", {"ipopt.tolerance": 1e-6})
    Traceback (most recent call last):
    ...
    ValueError: unknown ipopt option 'ipopt.tolerance'
    """
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise TypeError(f"options must be a dict of option names to values, got {type(options).__name__}")
    for k in options:
        if not isinstance(k, str):
            raise TypeError(f"option names must be strings, got {k!r}")
    if not isinstance(backend, str):
        raise TypeError(f"backend must be a string, got {type(backend).__name__}")
    if backend.startswith("scipy:"):
        plugin, verdict = backend, _scipy_verdict
        method = backend.split(":", 1)[1]
    else:
        check_backend(backend)
        if backend in ("scipy", "newton"):
            if options:
                raise ValueError(f"backend {backend!r} takes no options, got {', '.join(map(repr, options))}")
            return {}
        plugin, verdict = _plugin(backend), _casadi_verdict
        method = plugin
    for name, value in options.items():
        key = (plugin, name, repr(value))
        if key not in _OPTION_VERDICTS:
            _OPTION_VERDICTS[key] = verdict(method, name, value)
        if _OPTION_VERDICTS[key] is not None:
            raise ValueError(_OPTION_VERDICTS[key])
    return dict(options)


def minimize(model, p, x0, fixed, values, backend="ipopt", tol=1e-8, max_iter=500,
             options: dict | None = None) -> MinimizeOutcome:
    """Minimise ``model``'s energy over the coordinates not in ``fixed`` (boolean mask over 2n).

    A SIGINT during the solve raises :class:`KeyboardInterrupt` (see :func:`interruptible`); it is never
    reported as a failed solve."""
    check_backend(backend)
    options = check_options(backend, options)  # unknown or invalid options: a ValueError naming them
    with interruptible():  # CasADi swallows SIGINT: re-raise it as KeyboardInterrupt after the call
        return _minimize(model, p, x0, fixed, values, backend, tol, max_iter, options)


def _minimize(model, p, x0, fixed, values, backend, tol, max_iter, options) -> MinimizeOutcome:
    constrained = hasattr(model, "constraints")
    if constrained and not supports_constraints(backend):
        raise ValueError(f"backend {backend!r} cannot take constraints (exact cable ropes, rigid anchor "
                         f"patches); use one of {', '.join(CONSTRAINED_BACKENDS)}")
    if backend == "scipy":
        return _solve_scipy(model, p, x0, fixed, values, tol, max_iter)
    if backend == "newton":
        return _solve_newton(model, p, x0, fixed, values, tol, max_iter)
    o = _casadi_options(backend, tol, max_iter, constrained)
    o.update(options or {})
    solve = ropesolve.solve_constrained if constrained else _solve_casadi
    return solve(_plugin(backend), o, model, p, x0, fixed, values, symbolic=backend == "ipopt-symbolic")


#: MUMPS's fill-reducing ordering in IPOPT's constrained equilibrium solves (ropes, anchor patches): approximate
#: minimum fill (2), quicker than MUMPS's automatic choice on fine meshes with the same iterates to round-off
CONSTRAINED_MUMPS_ORDERING = 2


def _casadi_options(backend: str, tol, max_iter, constrained: bool) -> dict:
    """The ``nlpsol`` options of a CasADi backend (the caller's options go on top)."""
    if _plugin(backend) == "ipopt":
        o = _ipopt_opts(tol, max_iter if backend != "ipopt-lbfgs" else max(max_iter, 3000),
                        limited_memory=backend == "ipopt-lbfgs")
        if constrained:
            # IPOPT relaxes inequality bounds by 1e-8 (relative) by default: a taut rope in the inequality
            # form (another rope slack) then ended up to 1e-8 L0 longer than its target. Unrelaxed, it is
            # never longer, and short by the barrier's 1e-10 to 3e-9 L0; same iterations on the strips measured.
            o["ipopt.bound_relax_factor"] = 0.0
            o["ipopt.mumps_pivot_order"] = CONSTRAINED_MUMPS_ORDERING
        return o
    if backend == "sqpmethod":
        return {"qpsol": "qrqp", "qpsol_options": {"print_iter": False, "print_header": False,
                                                   "error_on_fail": False},
                "print_header": False, "print_iteration": False, "print_status": False, "print_time": False,
                "max_iter": max_iter, "tol_du": tol, "tol_pr": tol, "error_on_fail": False}
    # uno: its interior-point preset (module docstring), capped as the other backends are
    return {"print_time": False, "error_on_fail": False, "uno.logger": "SILENT", "uno.preset": UNO_PRESET,
            "uno.max_iterations": int(max_iter)}


#: Uno's preset (``uno.preset``) for the ``uno`` backend: the primal-dual interior-point method with MUMPS.
#: Measured on trial 12's 351-node ring turned 60 degrees and a 297-node strip bent by a rope at 30 %: 7 and 8
#: iterations, the same energies as IPOPT's (16.898416, 0.0516574), two orders of magnitude quicker than the
#: default filtersqp, which also printed BQPD's workspace message
UNO_PRESET = "ipopt"


#: backends that accept constraints (exact cable, rigid anchor patches; constrained models are symbolic)
CONSTRAINED_BACKENDS = ("ipopt", "ipopt-lbfgs", "ipopt-symbolic", "sqpmethod", "uno")


def supports_constraints(backend: str) -> bool:
    """Can ``backend`` solve with muscle constraints (exact cable ropes, rigid anchor patches)?"""
    return backend in CONSTRAINED_BACKENDS
