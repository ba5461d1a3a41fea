"""One study run: solve, classify the outcome, measure accuracy against a reference; serial or Dask."""

from __future__ import annotations

import logging
import math
import os
import threading
import time
import zlib
from dataclasses import dataclass
import numpy as np
import scipy.sparse.linalg as spla

from ..body.mesh import Mesh
from ..core.guards import cancel_stop, request_stop
from ..core.errors import InputError
from ..core.progress import advance, expect
from ..core.results import format_value, to_jsonable
from ..mechanics.align import align
from ..mechanics.anchors import point_diameter
from ..mechanics.model import get_model, spring_parameters
from ..scenes.rundir import check_interrupt
from ..synthesis.verify import check_minimum
from .problems import Setup, build_setup
from .spec import RunSpec

__all__ = ['RunTimeout', 'boundary_overlaps', 'RunOutcome', 'execute_run', 'interpolate', 'state_error',
           'classify_failure', 'fill_accuracy', 'run_all']


# ============================================================================================== one run
class RunTimeout(BaseException):
    """Raised inside a run's thread when its time budget is spent (a BaseException, like KeyboardInterrupt,
    so that ``except Exception`` blocks in the solvers do not swallow it)."""


class _Deadline:
    """Stop the current thread's run ``seconds`` from now with :class:`RunTimeout`.

    A timer thread asks the thread's solves to stop at their next iteration and raise it
    (:func:`~mdsr_opt.core.guards.request_stop`; checked by every solver's iteration callback and between
    load steps). A run whose work ended past the deadline without meeting such a check raises it as the
    block ends, so it is a time-out either way. Leaving the block withdraws the request. No tracing and no
    asynchronous exceptions: runs are not slowed down, and Python code is never interrupted at an arbitrary
    instruction.
    """

    def __init__(self, seconds: float):
        self.seconds = float(seconds)

    def _fire(self):
        with self.lock:
            if not self.done:
                self.fired = True
                request_stop(self.tid, RunTimeout)

    def __enter__(self):
        self.tid = threading.get_ident()
        self.lock = threading.Lock()
        self.done = self.fired = False
        self.timer = threading.Timer(self.seconds, self._fire)
        self.timer.daemon = True
        self.timer.start()
        return self

    def __exit__(self, exc_type, exc, tb):
        with self.lock:
            self.done = True
            self.timer.cancel()
        cancel_stop(self.tid)
        if self.fired and exc_type is None:
            raise RunTimeout(f"the run ended after its {self.seconds:g} s budget")
        return False


def _noisy_guess(setup: Setup, spec: RunSpec) -> np.ndarray:
    """The rest shape with every node moved randomly by about 20 % of the shortest edge (seeded by the study
    seed, the problem and the resolution; never inverted)."""
    mesh = setup.mesh
    rng = np.random.default_rng([spec.seed, zlib.crc32(spec.problem.encode()), int(spec.resolution)])
    d = rng.normal(size=mesh.points.shape) * 0.2 * float(mesh.edge_lengths.min())
    for _ in range(30):
        x = mesh.points + d
        if mesh.jacobians(x).min() > 0:
            return x
        d = d / 2
    return mesh.points.copy()  # pragma: no cover


def _guess_kwargs(setup: Setup, spec: RunSpec) -> dict:
    if spec.guess == "predictor":
        return {}
    if spec.guess == "no-predictor":
        return {"initial_guess": "rest"}
    if spec.guess == "rest":
        return {"initial_guess": "rest", "min_step": 1.0}
    return {"initial_guess": _noisy_guess(setup, spec), "min_step": 1.0}


def _fixed_mask(setup: Setup) -> np.ndarray:
    nodes = np.concatenate([np.asarray(setup.anchors, dtype=np.int64), np.asarray(setup.drags[0], dtype=np.int64)])
    fixed = np.zeros(2 * setup.mesh.n_nodes, dtype=bool)
    fixed[2 * nodes] = True
    fixed[2 * nodes + 1] = True
    return fixed


def _positive_definite(H) -> bool:
    """Is the sparse symmetric ``H`` positive definite? Signs of the pivots of a symmetric factorisation
    (Sylvester's law of inertia), or the smallest eigenvalue when SuperLU pivots off the diagonal."""
    H = H.tocsc()
    try:
        lu = spla.splu(H, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    except RuntimeError:  # exactly singular
        return False
    if np.array_equal(lu.perm_r, lu.perm_c):
        return bool((lu.U.diagonal() > 0).all())
    if H.shape[0] <= 2000:  # pragma: no cover - rare
        return bool(np.linalg.eigvalsh(H.toarray())[0] > 0)
    return bool(spla.eigsh(H, k=1, which="SA", return_eigenvectors=False)[0] > 0)  # pragma: no cover


def _is_minimum(setup: Setup, material, res) -> bool:
    """Is the equilibrium ``res`` a strict minimum of its energy (fixed nodes / gauge pinned)?"""
    if setup.mode == "internal":
        pd, _lam, _r = check_minimum(setup.mesh, material, setup.muscles, setup.contractions, res.x,
                                     muscle_model=setup.muscle_model, stiffness=setup.stiffness, lowest=False)
        return bool(pd)

    model = get_model(setup.mesh, material)
    free = ~_fixed_mask(setup)
    H = model.hessian(res.x.reshape(-1), model.params(material))[free][:, free]
    return _positive_definite(H / (material.E * material.thickness))


def boundary_overlaps(mesh: Mesh, x: np.ndarray) -> bool:
    """Does the boundary of ``mesh`` in configuration ``x`` cross itself (the body overlapping itself)?

    Every pair of boundary edges that share no node is tested for a proper crossing.

    Example
    -------
    >>> m = Mesh.rectangle(4.0, 1.0, 8, 2)
    >>> coil = m.points * [1.0, 0.1]  # a thin strip wound 1.1 turns round a circle: it overlaps itself
    >>> t, r = coil[:, 0] / 4.0 * 2 * np.pi * 1.1, 1.0 + coil[:, 1]
    >>> boundary_overlaps(m, m.points), boundary_overlaps(m, np.c_[r * np.cos(t), r * np.sin(t)])
    (False, True)
    """
    return mesh.boundary_crosses(x)


#: words of a status that rejects a converged state for its curvature (the solvers' and the design
#: verification's own wording; "left a saddle" in a status is a saddle the solver escaped, not a failure)
_SADDLE_WORDS = ("not a stable equilibrium", "not a minimum of the energy")

#: words of a status that stopped at the solver's iteration cap (IPOPT, CasADi's SQP, scipy, Newton)
_LIMIT_WORDS = ("maximum_iterations_exceeded", "max_iter", "maximum number of iterations", "iteration limit",
                "iterations exceeded", "iterations reached limit", "maximum number of function evaluations")


def classify_failure(success: bool, status: str, min_J: float, stable: bool, overlap: bool, wall: float,
                     timeout: float) -> str:
    """A run's failure reason (:data:`~mdsr_opt.studies.spec.FAILURES`) from its outcome and its solver's
    status: the time budget first, then self-contact (a state whose boundary crosses itself, or a solve
    rejected for it, whatever else its status says), then a converged state's curvature (``saddle``), then
    inverted elements, the iteration cap and any other failure (``no convergence``)."""
    s = status.lower()
    if wall > timeout or "walltime" in s or "cputime" in s or "time limit" in s:
        return "time-out"
    if (success and overlap) or "crosses itself" in s:
        return "self-contact"
    if success:
        return "none" if stable else "saddle"
    if any(w in s for w in _SADDLE_WORDS):
        return "saddle"
    if "invert" in s or min_J <= 0:
        return "inverted elements"
    if any(w in s for w in _LIMIT_WORDS):
        return "iteration limit"
    return "no convergence"


def _solve_equilibrium(setup: Setup, material, spec: RunSpec, tol: float):
    from ..mechanics.equilibrium import solve_external, solve_internal

    kw = dict(backend=spec.method, tol=tol, max_iter=spec.max_iter, **_guess_kwargs(setup, spec))
    if spec.method in ("ipopt", "ipopt-lbfgs", "ipopt-symbolic"):
        kw["options"] = {"ipopt.max_wall_time": float(spec.timeout)}
    if setup.mode == "external":
        return solve_external(setup.mesh, material, setup.anchors, setup.drags, **kw)
    return solve_internal(setup.mesh, material, setup.muscles, setup.contractions, muscle_model=setup.muscle_model,
                          stiffness=setup.stiffness, **kw)


def _internal_energy(setup: Setup, material, a, x) -> float:
    model = get_model(setup.mesh, material)
    k = setup.stiffness * material.E * material.thickness
    p = model.params(material, springs=spring_parameters(setup.mesh, setup.muscles, a, k))
    return float(model.energy(np.asarray(x, dtype=float).reshape(-1), p))


@dataclass
class RunOutcome:
    """What a run returns: its row (accuracy columns filled later for equilibrium runs) and its state."""

    index: int
    row: dict
    x: np.ndarray | None
    points: np.ndarray
    triangles: np.ndarray | None = None  # references only
    free_body: bool = False

    def __repr__(self) -> str:
        r = self.row
        return (f"RunOutcome(index={self.index}, problem={r.get('problem')!r}, method={r.get('method')!r}, "
                f"success={r.get('success')}, failure={r.get('failure')!r}, "
                f"x={format_value(self.x)}, points={format_value(self.points)})")

    def to_dict(self) -> dict:
        """The row and the state as a JSON-ready dict."""
        return to_jsonable({"index": self.index, "row": self.row, "x": self.x, "points": self.points,
                            "triangles": self.triangles, "free_body": self.free_body})


def execute_run(spec: RunSpec, index: int = 0) -> RunOutcome:
    """Run one :class:`RunSpec` (in this process or on a Dask worker) and return its :class:`RunOutcome`.

    Never raises for a failing run: exceptions become ``failure="error"`` rows.
    """
    t_start = time.perf_counter()
    row = {"study": spec.study, "problem": spec.problem, "kind": spec.kind, "load": float(spec.load),
           "guess": spec.guess, "material": spec.material, "method": spec.method,
           "resolution": int(spec.resolution)}
    t0 = time.perf_counter()
    setup = build_setup(spec.problem, spec.resolution, spec.load)
    material = setup.material(spec.material)
    mesh_time = time.perf_counter() - t0
    mesh = setup.mesh
    row["nodes"] = mesh.n_nodes
    x = None
    fields = dict(build_time=mesh_time, solve_time=0.0, iterations=0, steps=0, energy=math.nan,
                  energy_error=math.nan, error=math.nan, min_J=math.nan, residual=math.nan, stable=False,
                  overlap=False, success=False, failure="error", status="", branch="-")
    tol = 1e-10 if spec.role == "reference" else 1e-8
    raised = False
    deadline = _Deadline(spec.timeout)
    try:
        with deadline:
            if spec.kind == "equilibrium":
                res = _solve_equilibrium(setup, material, spec, tol)
                stable = bool(res.success and _is_minimum(setup, material, res))
                x = res.x
                fields.update(build_time=mesh_time + res.build_time, solve_time=res.solve_time,
                              iterations=int(res.iterations), steps=len(res.steps), energy=float(res.energy),
                              min_J=float(res.min_J), residual=float(res.residual), stable=stable,
                              overlap=boundary_overlaps(mesh, res.x), success=bool(res.success),
                              status=str(res.status))
            else:
                fields.update(_run_design(setup, material, spec, mesh_time))
                x = fields.pop("x")
    except BaseException as exc:  # a failing run is a result, not a crash of the study
        if isinstance(exc, (KeyboardInterrupt, SystemExit)):
            raise
        raised = True
        if deadline.fired:  # RunTimeout, or an error it caused inside a C extension's callback
            fields.update(status=f"stopped after the {spec.timeout:g} s budget", failure="time-out",
                          success=False)
        else:
            fields.update(status=f"{type(exc).__name__}: {exc}".replace("\n", " ")[:300], failure="error",
                          success=False)
    finally:
        cancel_stop(threading.get_ident())

    check_interrupt()  # a Ctrl-C that a solver turned into a failed solve stops the study, never a failed row
    wall = time.perf_counter() - t_start
    fields["wall_time"] = wall
    if not raised:
        fields["failure"] = classify_failure(fields["success"], fields["status"], fields["min_J"], fields["stable"],
                                      fields["overlap"], wall, spec.timeout)
        fields["success"] = fields["failure"] == "none"
    row.update(fields)
    return RunOutcome(index, row, None if x is None else np.asarray(x, dtype=float), mesh.points,
                      mesh.triangles if spec.role == "reference" else None, setup.mode == "internal")


#: design targets solved on reference meshes, per process: ``{(problem, resolution, load): (points, triangles, x)}``
_TARGETS: dict = {}


def _design_target(setup: Setup, material, spec: RunSpec) -> tuple[np.ndarray, float]:
    """A design run's target on its own mesh and the target's energy there: the internal-driving
    equilibrium at the known contractions solved on the study's reference mesh (Neo-Hookean; a finer mesh,
    so the recovered contraction measures the run mesh's discretisation too, not a copy of its own
    solution) and interpolated at the run's rest nodes. Without a finer reference mesh, the run's own (in its
    material), with its energy (NaN otherwise)."""
    from ..mechanics.equilibrium import solve_internal

    ref_res = spec.reference_resolution
    if ref_res is not None:
        key = (spec.problem, int(ref_res), float(spec.load))
        if key not in _TARGETS:
            ref = build_setup(spec.problem, ref_res, spec.load)
            if ref.mesh.n_nodes > setup.mesh.n_nodes:
                t = solve_internal(ref.mesh, ref.material("neo-hookean"), ref.muscles, ref.contractions,
                                   muscle_model=ref.muscle_model, stiffness=ref.stiffness)
                if not t.success:
                    raise RuntimeError(f"the design target did not solve on the reference mesh: {t.status}")
                _TARGETS[key] = (ref.mesh.points, ref.mesh.triangles, np.asarray(t.x, dtype=float))
            else:
                _TARGETS[key] = None
        if _TARGETS[key] is not None:
            pts, tri, x = _TARGETS[key]
            return interpolate(pts, tri, x, setup.mesh.points), math.nan
    t = solve_internal(setup.mesh, material, setup.muscles, setup.contractions, muscle_model=setup.muscle_model,
                       stiffness=setup.stiffness)
    if not t.success:
        raise RuntimeError(f"the design target did not solve: {t.status}")
    return np.asarray(t.x, dtype=float), float(t.energy)


def _run_design(setup: Setup, material, spec: RunSpec, mesh_time: float) -> dict:
    """A design recovery: the target is the internal-driving equilibrium at the known contractions, solved on
    the study's reference mesh (:func:`_design_target`); the error is the largest contraction error."""
    from ..synthesis.contractions import design_contractions
    from ..mechanics.equilibrium import solve_internal

    target_x, e_ref = _design_target(setup, material, spec)
    res = design_contractions(setup.mesh, material, setup.muscles, target_x, method=spec.method,
                              muscle_model=setup.muscle_model, stiffness=setup.stiffness)
    v = res.verification
    if not math.isfinite(e_ref):  # the energy of the known contractions on the run's own mesh
        own = solve_internal(setup.mesh, material, setup.muscles, setup.contractions,
                             muscle_model=setup.muscle_model, stiffness=setup.stiffness)
        e_ref = float(own.energy) if own.success else math.nan
    energy = _internal_energy(setup, material, res.contractions, res.x)
    return dict(build_time=mesh_time + res.build_time, solve_time=float(res.solve_time),  # not verification
                iterations=int(res.iterations), steps=int(res.n_forward), energy=energy,
                energy_error=abs(energy - e_ref) / abs(e_ref) if e_ref else abs(energy),
                error=float(np.abs(res.contractions - setup.contractions).max()),
                min_J=float(setup.mesh.jacobians(res.x).min()), residual=float(v.residual) if v else math.nan,
                stable=bool(v.positive_definite) if v else False,
                overlap=boundary_overlaps(setup.mesh, res.x), success=bool(res.success),
                status=str(res.status) + ("" if v is None or v.passed else f"; {v.message}"), x=res.x)


# ============================================================================================== accuracy
def interpolate(points: np.ndarray, triangles: np.ndarray, values: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Piecewise-linear interpolation of node ``values`` on the mesh ``(points, triangles)`` at ``query``.

    Each query point is located among the triangles whose centroids are nearest; a point just outside the
    mesh (a curved boundary meshed differently) takes the barycentric weights of the nearest triangle,
    clipped to be non-negative.

    Example
    -------
    >>> from mdsr_opt import Mesh
    >>> m = Mesh.rectangle(2.0, 1.0, 2, 1)
    >>> interpolate(m.points, m.triangles, m.points * 2.0, np.array([[0.5, 0.25]])).round(12).tolist()
    [[1.0, 0.5]]
    """
    from scipy.spatial import cKDTree

    points = np.asarray(points, dtype=float)
    triangles = np.asarray(triangles, dtype=np.int64)
    values = np.asarray(values, dtype=float)
    query = np.atleast_2d(np.asarray(query, dtype=float))
    k = int(min(16, len(triangles)))
    _, cand = cKDTree(points[triangles].mean(axis=1)).query(query, k=k)
    cand = np.asarray(cand).reshape(len(query), k)
    A = points[triangles[cand]]  # (q, k, 3, 2)
    v0, v1 = A[:, :, 1] - A[:, :, 0], A[:, :, 2] - A[:, :, 0]
    v2 = query[:, None, :] - A[:, :, 0]
    det = v0[..., 0] * v1[..., 1] - v0[..., 1] * v1[..., 0]
    l1 = (v2[..., 0] * v1[..., 1] - v2[..., 1] * v1[..., 0]) / det
    l2 = (v0[..., 0] * v2[..., 1] - v0[..., 1] * v2[..., 0]) / det
    lam = np.stack([1.0 - l1 - l2, l1, l2], axis=-1)
    best = np.argmax(lam.min(axis=-1), axis=1)
    q = np.arange(len(query))
    w = np.clip(lam[q, best], 0.0, None)
    w /= w.sum(axis=1, keepdims=True)
    tri = triangles[cand[q, best]]
    return np.einsum("qi,qi...->q...", w, values[tri])


def state_error(points: np.ndarray, x: np.ndarray, ref_points: np.ndarray, ref_triangles: np.ndarray,
                ref_x: np.ndarray, free_body: bool = False, mirror=None) -> float:
    """Largest node distance between state ``x`` (on rest ``points``) and the reference state interpolated at
    those rest points, over the reference body's size (its diameter at rest, the largest distance between two
    of its nodes: the same however the body is turned, as ``mdsr run``'s). ``free_body``: compare
    after the best rigid motion of ``x`` onto the reference (internal driving has no fixed frame).

    ``mirror``: a reflection ``(k, 2) -> (k, 2)`` that maps the problem (rest body and loads) onto itself;
    the run is then compared with the reference's mirror image ``mirror(ref(mirror(p)))`` instead (a strip
    buckled down against a reference buckled up: the same solution, reflected)."""
    query = np.asarray(points, dtype=float) if mirror is None else mirror(np.asarray(points, dtype=float))
    y = interpolate(ref_points, ref_triangles, ref_x, query)
    if mirror is not None:
        y = mirror(y)
    x = np.asarray(x, dtype=float)
    if free_body:
        x = align(x, y).apply(x)
    size = point_diameter(ref_points)
    return float(np.linalg.norm(x - y, axis=1).max() / size)


def fill_accuracy(outcomes: list[RunOutcome], refs: dict) -> None:
    """Fill the equilibrium rows' ``error`` and ``energy_error`` against their problem's reference (a finer
    mesh), and ``branch``: for a problem with a mirror symmetry (:attr:`StudyProblem.mirror`) a buckled run
    is compared with the reference and with its mirror image, and the nearer one counts ("same" or
    "mirror"; the two branches have the same energy, so ``energy_error`` tells a mirror branch from another
    mode). Rows without a reference on a finer mesh than their own keep ``error`` and ``energy_error`` NaN
    and ``branch`` "-"."""
    from .problems import get_study_problem

    for o in outcomes:
        r = o.row
        if r["kind"] != "equilibrium":
            continue
        ref = refs.get((r["problem"], r["load"]))
        if ref is None or o.x is None or not ref.row["success"]:
            continue
        if len(ref.points) <= len(o.points):  # not a finer mesh: the same discrete solution measures nothing
            continue
        r["error"] = state_error(o.points, o.x, ref.points, ref.triangles, ref.x, o.free_body)
        r["branch"] = "same"
        mirror = getattr(get_study_problem(r["problem"]), "mirror", None)
        if mirror is not None:
            e = state_error(o.points, o.x, ref.points, ref.triangles, ref.x, o.free_body, mirror)
            if e < r["error"]:
                r["error"], r["branch"] = e, "mirror"
        e = ref.row["energy"]
        if np.isfinite(r["energy"]):
            r["energy_error"] = abs(r["energy"] - e) / abs(e) if e else abs(r["energy"])


# ============================================================================================== runner
def _executor(scheduler, workers: int | None):
    """``(client, cluster)`` for ``scheduler``: ``"local"`` starts a LocalCluster, anything else is an address
    (or a ``distributed.Client``)."""
    try:
        from distributed import Client, LocalCluster
    except ImportError as exc:
        raise InputError("Dask runs need the optional dask extra, which is not installed: "
                         f"pip install \"mdsr_opt[dask]\" ({exc})") from None
    if not isinstance(scheduler, str):
        return scheduler, None
    if scheduler == "local":
        n = workers or max(1, os.cpu_count() or 1)
        # quiet workers: at shutdown a worker's last heartbeat may find the scheduler gone and log an error;
        # a worker that really dies still fails its futures (KilledWorker) in this process
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=logging.CRITICAL)
        return Client(cluster), cluster
    if scheduler.startswith("inprocess"):  # threads in this process: quick to start (tests, small sweeps)
        cluster = LocalCluster(n_workers=workers or 1, threads_per_worker=1, processes=False,
                               dashboard_address=None, silence_logs=logging.CRITICAL)
        return Client(cluster), cluster
    return Client(scheduler, timeout="20s"), None


def run_all(specs: list[RunSpec], scheduler, workers, log) -> list[RunOutcome]:
    n = len(specs)
    expect(log, n)  # the progress bar of `mdsr study` (no-op for a plain callable)
    out: list[RunOutcome | None] = [None] * n
    t0 = time.perf_counter()

    def report(k, o):
        if log:
            r = o.row
            msg = "ok" if r["success"] else r["failure"]
            log(f"[{k}/{n}] {specs[o.index].label()}: {msg}, {r['wall_time']:.2f} s "
                f"(elapsed {time.perf_counter() - t0:.0f} s)")
            advance(log)

    if scheduler is None:
        for i, s in enumerate(specs):
            out[i] = execute_run(s, i)
            report(i + 1, out[i])
        return out  # type: ignore[return-value]
    client, cluster = _executor(scheduler, workers)  # a clear ValueError when the dask extra is missing
    from distributed import as_completed

    try:
        futs = client.map(execute_run, specs, list(range(n)), pure=False)
        for k, fut in enumerate(as_completed(futs), 1):
            o = fut.result()
            out[o.index] = o
            report(k, o)
    finally:
        if client is not scheduler:  # ours (not a Client the caller passed): close it
            client.close()
        if cluster is not None:
            cluster.close()
    return out  # type: ignore[return-value]
