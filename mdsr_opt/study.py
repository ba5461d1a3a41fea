"""Solver comparison studies: speed against accuracy, where methods fail, and how much model a scene needs.

A *study* sweeps problems x mesh resolution x material model x method (an equilibrium backend or a design
method) x load x first guess, and records one tidy row per run (see :data:`COLUMNS`). Accuracy is measured
against a *reference*: the same problem solved with the full Neo-Hookean model by IPOPT on a finer mesh,
interpolated (piecewise linearly) onto each run's rest nodes. Design runs are measured against the known
contractions that made their target.

Study problems are factories ``(resolution, load) -> Setup`` in :data:`PROBLEMS` (a 4 x 1 strip stretched,
bent, compressed or contracted by a muscle), so the studies need nothing else. Scenes of the problem library
(:mod:`mdsr_opt.scenes`) are accepted as ``"<scene>/<case>"`` when it is installed.

Runs are independent, so a study runs serially or on Dask (:func:`run_study` with ``scheduler="local"`` or
an address). Results do not depend on where a run ran: every column except the timing columns
(:data:`TIMING_COLUMNS`) is equal between a serial and a Dask run of the same study.

Failure reasons (column ``failure``):

``none``
    The run succeeded: the solver converged, the residual is small, no element is inverted and the state is a
    strict minimum (the free-coordinate Hessian is positive definite).
``no convergence``
    The solver stopped without converging (iteration limit, load stepping stalled on solver failures).
``inverted elements``
    The first guess, the predictor or the converged state inverts an element (``det F <= 0``).
``self-overlap``
    The solver converged, every element is upright, but the deformed boundary crosses itself: the body
    passes through itself (there is no contact model), e.g. a crease on the compressed side of a bend.
``saddle``
    The solver converged to a stationary point that is not a minimum (e.g. an unbuckled compressed strip).
``time-out``
    The run took longer than its budget. The runner interrupts a run at its next Python instruction after
    the budget; IPOPT backends also get ``max_wall_time``. ``sqpmethod`` and ``uno`` solves run in C and
    can overrun the budget by one solve.
``error``
    The run raised an exception (its text is in ``status``).

Example
-------
>>> from mdsr_opt.study import run_study
>>> res = run_study("quick", problems=["strip-bend"], resolutions=[300], methods=["ipopt"], progress=False)
>>> [(r["material"], r["failure"]) for r in res.rows]
[('neo-hookean', 'none'), ('linear', 'inverted elements')]
>>> res.rows[0]["error"] < 0.01 < res.rows[1]["error"]         # against Neo-Hookean on 1105 nodes
True
"""

from __future__ import annotations

import csv
import ctypes
import io
import logging
import math
import os
import platform
import threading
import time
import zlib
from dataclasses import asdict, dataclass, field, replace
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from .io import atomic_path, write_json
from .material import LinearElastic, NeoHookean
from .mesh import Mesh
from .muscles import Muscle
from .progress import advance, expect, progress_for_cli
from .results import format_value, to_jsonable

_LOG = logging.getLogger(__name__)

__all__ = ["COLUMNS", "TIMING_COLUMNS", "FAILURES", "GUESSES", "MATERIALS", "PROBLEMS", "STUDIES",
           "StudyProblem", "Setup", "Study", "RunSpec", "StudyResult", "list_studies", "list_study_problems",
           "get_study", "build_setup", "run_study", "execute_run", "fit_slopes", "pareto_front",
           "interpolate", "state_error", "boundary_overlaps", "add_cli"]

#: Columns of a study table, in order.
COLUMNS = ("study", "problem", "kind", "load", "guess", "material", "method", "resolution", "nodes",
           "build_time", "solve_time", "wall_time", "iterations", "steps", "energy", "energy_error", "error",
           "min_J", "residual", "stable", "overlap", "success", "failure", "status")
#: Columns that measure time and so differ between runs of the same study.
TIMING_COLUMNS = ("build_time", "solve_time", "wall_time")
#: Failure reasons, in the order charts list them.
FAILURES = ("none", "no convergence", "inverted elements", "self-overlap", "saddle", "time-out", "error")
#: First guesses: the default predictor with load steps; no predictor with load steps; one solve from rest;
#: one solve from a randomly perturbed rest shape.
GUESSES = ("predictor", "no-predictor", "rest", "noisy")
#: Material models by name, simplest first (the fidelity helper tries them in this order).
MATERIALS = {"linear": LinearElastic, "neo-hookean": NeoHookean}
DESIGN_METHODS = ("flattened", "nested", "derivative-free")
#: Geometry of the study strip: length and width.
STRIP = (4.0, 1.0)


# ============================================================================================== problems
@dataclass
class Setup:
    """One problem instance: a body and how it is driven.

    Attributes
    ----------
    mesh : Mesh
    E, nu, thickness : float
        Material parameters (the material *model* is chosen per run).
    anchors : (k,) int array or None
        External driving: nodes held at rest.
    drags : (indices, positions) or None
        External driving: nodes moved to positions.
    muscles : tuple of Muscle
        Internal driving: the muscles.
    contractions : (m,) array or None
        Internal driving: their contractions (also the known answer of a design recovery).
    muscle_model, stiffness : as in :func:`~mdsr_opt.solve_internal`.
    """

    mesh: Mesh
    E: float = 1.0
    nu: float = 0.3
    thickness: float = 1.0
    anchors: np.ndarray | None = None
    drags: tuple | None = None
    muscles: tuple = ()
    contractions: np.ndarray | None = None
    muscle_model: str = "springs"
    stiffness: float = 10.0

    @property
    def mode(self) -> str:
        """``"internal"`` (muscles) or ``"external"`` (anchors and drags)."""
        return "internal" if self.contractions is not None else "external"

    def material(self, name: str):
        """The material model ``name`` (see :data:`MATERIALS`) with this setup's parameters."""
        return MATERIALS[_check_name(name, MATERIALS, "material")](self.E, self.nu, self.thickness)


@dataclass(frozen=True)
class StudyProblem:
    """A study problem: a factory of setups by mesh resolution and load.

    Attributes
    ----------
    name, description : str
    build : callable ``(resolution, load) -> Setup``
        ``resolution`` is the approximate number of mesh nodes wanted.
    default_load : float
    load_label : str
        What ``load`` means, for tables and charts.
    design : bool
        Internal driving with known contractions: design methods can recover them.
    """

    name: str
    description: str
    build: Callable[[int, float], Setup]
    default_load: float
    load_label: str
    design: bool = False


def _strip_mesh(resolution: int) -> Mesh:
    """A structured 4 x 1 strip with ``ny`` cells across, ``ny`` the power of two whose node count
    ``(4 ny + 1)(ny + 1)`` is nearest to ``resolution`` (27, 85, 297, 1105, 4257, ... nodes): the meshes nest,
    so every coarse node is a node of the finer meshes."""
    L, W = STRIP
    ny_est = (-5.0 + math.sqrt(25.0 + 16.0 * (max(resolution, 10) - 1.0))) / 8.0
    ny = 2 ** max(0, round(math.log2(max(ny_est, 1.0))))
    return Mesh.rectangle(L, W, round(L / W) * ny, ny)


def _ends(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    P = mesh.points
    return np.flatnonzero(P[:, 0] < 1e-9), np.flatnonzero(P[:, 0] > STRIP[0] - 1e-9)


def _arc(points: np.ndarray, angle: float) -> np.ndarray:
    """Strip points mapped onto a circular arc that bends the strip through ``angle`` radians (towards +y)."""
    L = STRIP[0]
    R = L / angle
    th = points[:, 0] / L * angle
    rr = R - points[:, 1]
    return np.column_stack([rr * np.sin(th), R - rr * np.cos(th)])


def _stretch(resolution: int, load: float) -> Setup:
    mesh = _strip_mesh(resolution)
    left, right = _ends(mesh)
    return Setup(mesh, anchors=left, drags=(right, mesh.points[right] + [load * STRIP[1], 0.0]))


def _bend(resolution: int, load: float) -> Setup:
    if not load > 0:
        raise ValueError(f"strip-bend needs a positive angle in degrees, got {load}")
    mesh = _strip_mesh(resolution)
    left, right = _ends(mesh)
    return Setup(mesh, anchors=left, drags=(right, _arc(mesh.points[right], math.radians(load))))


def _compress(resolution: int, load: float) -> Setup:
    mesh = _strip_mesh(resolution)
    left, right = _ends(mesh)
    return Setup(mesh, anchors=left, drags=(right, mesh.points[right] - [load * STRIP[0], 0.0]))


def _contract(resolution: int, load: float) -> Setup:
    if not 0 <= load < 1:
        raise ValueError(f"strip-contract needs a contraction in [0, 1), got {load}")
    mesh = _strip_mesh(resolution)
    P = mesh.points
    bottom = np.flatnonzero(P[:, 1] < 1e-9)
    bottom = bottom[np.argsort(P[bottom, 0])]
    return Setup(mesh, muscles=(Muscle(bottom, name="bottom"),), contractions=np.array([float(load)]))


#: The study's own problems (a 4 x 1 strip, E = 1, nu = 0.3).
PROBLEMS: dict[str, StudyProblem] = {p.name: p for p in (
    StudyProblem("strip-stretch", "left end anchored, right end pulled along the strip by `load` widths",
                 _stretch, 1.0, "stretch (widths)"),
    StudyProblem("strip-bend", "left end anchored, right end dragged onto a circular arc of `load` degrees",
                 _bend, 90.0, "bend (degrees)"),
    StudyProblem("strip-compress", "left end anchored, right end pushed towards it by `load` lengths "
                 "(buckles beyond about 0.2)", _compress, 0.3, "compression (lengths)"),
    StudyProblem("strip-contract", "free strip, a muscle along its lower edge contracts by `load`; design "
                 "methods recover the contraction", _contract, 0.3, "contraction", design=True),
)}


def _scene_problem(name: str) -> StudyProblem | None:
    """A problem-library case ``"<scene>/<case>"`` as a study problem (None when the library is absent).

    ``load`` scales the case: drag displacements (external) or contractions (internal); 1 is the case as
    written. ``resolution`` is passed to the scene's factory (approximate node count).
    """
    if "/" not in name:
        return None
    try:
        from . import scenes
    except ImportError:  # pragma: no cover - the library is optional
        return None
    scene_name, case_name = name.split("/", 1)
    if scene_name not in scenes.list_problems():
        return None

    def build(resolution: int, load: float) -> Setup:
        sc = scenes.get_problem(scene_name, resolution=int(resolution))
        case = sc.case(case_name)
        mat = sc.material
        opts = sc.design_options
        common = dict(E=mat.E, nu=mat.nu, thickness=mat.thickness,
                      muscle_model=opts.get("muscle_model", "springs"), stiffness=opts.get("stiffness", 10.0))
        if case.kind == "internal":
            return Setup(sc.mesh, muscles=tuple(sc.muscles), contractions=load * case.contractions, **common)
        rest = sc.mesh.points[case.drag_nodes]
        return Setup(sc.mesh, anchors=case.anchors,
                     drags=(case.drag_nodes, rest + load * (case.drag_positions - rest)), **common)

    try:
        sc = scenes.get_problem(scene_name, resolution="coarse")
        case = sc.case(case_name)
    except (KeyError, ValueError):
        return None
    return StudyProblem(name, f"problem library: scene {scene_name!r}, case {case_name!r}", build, 1.0,
                        "load (x case)", design=case.kind == "internal")


def list_study_problems() -> list[str]:
    """Names of the study problems: the built-in strips, then ``scene/case`` of the problem library."""
    names = list(PROBLEMS)
    try:
        from . import scenes
    except ImportError:  # pragma: no cover
        return names
    for s in scenes.list_problems():
        try:
            sc = scenes.get_problem(s, resolution="coarse")
        except Exception:  # pragma: no cover - a broken library script must not break the study list
            continue
        names += [f"{s}/{c}" for c in sc.case_names]
    return names


def get_problem(name: str) -> StudyProblem:
    """A study problem by name; an unknown name is an error that lists the valid ones."""
    if not isinstance(name, str):
        raise TypeError(f"problem name must be a string, got {type(name).__name__}")
    if name in PROBLEMS:
        return PROBLEMS[name]
    p = _scene_problem(name)
    if p is None:
        raise ValueError(f"unknown study problem {name!r}; valid: {', '.join(list_study_problems())}")
    return p


def build_setup(problem: str, resolution: int, load: float | None = None) -> Setup:
    """Build problem ``problem`` at ``resolution`` (approximate node count) and ``load`` (default: its own)."""
    p = get_problem(problem)
    return p.build(int(resolution), p.default_load if load is None else float(load))


def _check_name(name, valid, what: str) -> str:
    if not isinstance(name, str) or name not in valid:
        raise ValueError(f"unknown {what} {name!r}; valid: {', '.join(valid)}")
    return name


# ============================================================================================== studies
@dataclass(frozen=True)
class Study:
    """A sweep: every combination of its axes is one run.

    Attributes
    ----------
    name, description : str
    problems : tuple of str
        Study problem names (:func:`list_study_problems`).
    resolutions : tuple of int
        Approximate node counts.
    materials : tuple of str
        Material models (:data:`MATERIALS`).
    methods : tuple of str
        Equilibrium backends (:func:`~mdsr_opt.available_backends`) and design methods
        (``flattened``, ``nested``, ``derivative-free``; these run only on problems with ``design=True``).
    loads : dict of problem name to tuple of float
        Loads per problem; a problem not listed runs at its default load.
    guesses : tuple of str
        First guesses (:data:`GUESSES`) for equilibrium methods; design methods always run once.
    reference_resolution : int or None
        Mesh of the reference solutions (Neo-Hookean, IPOPT, tight tolerance); default: the finest resolution.
    timeout : float
        Seconds allowed per run.
    max_iter : int
        Iteration cap per solve (per load step).
    caps : dict of method to int
        Largest node count a method is run at (slow methods; runs above the cap are left out and listed in
        the study's metadata).
    seed : int
        Seed of the noisy first guesses.
    """

    name: str
    description: str
    problems: tuple
    resolutions: tuple
    materials: tuple = ("neo-hookean",)
    methods: tuple = ("ipopt",)
    loads: Mapping[str, tuple] = field(default_factory=dict)
    guesses: tuple = ("predictor",)
    reference_resolution: int | None = None
    timeout: float = 60.0
    max_iter: int = 500
    caps: Mapping[str, int] = field(default_factory=dict)
    seed: int = 0

    def __post_init__(self):
        from .backends import available_backends

        for k in ("problems", "resolutions", "materials", "methods", "guesses"):
            v = getattr(self, k)
            if isinstance(v, (str, bytes)) or not isinstance(v, Iterable):
                raise TypeError(f"study {self.name!r}: {k} must be a sequence, got {v!r}")
            v = tuple(v)
            if not v:
                raise ValueError(f"study {self.name!r}: {k} is empty")
            object.__setattr__(self, k, v)
        for p in self.problems:
            get_problem(p)
        for r in self.resolutions:
            if isinstance(r, bool) or not isinstance(r, (int, np.integer)) or r < 4:
                raise ValueError(f"study {self.name!r}: resolutions must be integers >= 4 (node counts), got {r!r}")
        object.__setattr__(self, "resolutions", tuple(sorted(int(r) for r in self.resolutions)))
        for m in self.materials:
            _check_name(m, MATERIALS, "material")
        valid = tuple(available_backends()) + DESIGN_METHODS
        for m in self.methods:
            _check_name(m, valid, "method (backend or design method)")
        for g in self.guesses:
            _check_name(g, GUESSES, "first guess")
        loads = {}
        for k, v in dict(self.loads).items():
            if k not in self.problems:
                raise ValueError(f"study {self.name!r}: loads given for {k!r}, which is not among its problems")
            loads[k] = tuple(float(x) for x in np.atleast_1d(v))
        object.__setattr__(self, "loads", loads)
        for p in self.problems:  # a bad load is an error now, not in the middle of a sweep
            for load in self.loads_of(p):
                try:
                    get_problem(p).build(self.resolutions[0], load)
                except ValueError as exc:
                    raise ValueError(f"study {self.name!r}: {exc}") from None
        if self.reference_resolution is None:
            object.__setattr__(self, "reference_resolution", self.resolutions[-1])
        if isinstance(self.timeout, bool) or not (isinstance(self.timeout, (int, float)) and self.timeout > 0):
            raise ValueError(f"study {self.name!r}: timeout must be a positive number of seconds, "
                             f"got {self.timeout!r}")
        if isinstance(self.max_iter, bool) or not isinstance(self.max_iter, (int, np.integer)) or self.max_iter < 1:
            raise ValueError(f"study {self.name!r}: max_iter must be a positive integer, got {self.max_iter!r}")
        object.__setattr__(self, "caps", dict(self.caps))

    def with_options(self, **changes) -> "Study":
        """A copy with some fields replaced (``None`` values are ignored); e.g. fewer resolutions."""
        changes = {k: (tuple(v) if isinstance(v, list) else v) for k, v in changes.items() if v is not None}
        if "problems" in changes and "loads" not in changes:  # keep the loads of the problems that remain
            changes["loads"] = {k: v for k, v in self.loads.items() if k in changes["problems"]}
        if "resolutions" in changes and "reference_resolution" not in changes and \
                self.reference_resolution == self.resolutions[-1]:
            changes["reference_resolution"] = None
        return replace(self, **changes)

    def loads_of(self, problem: str) -> tuple:
        return self.loads.get(problem, (get_problem(problem).default_load,))

    def plan(self) -> tuple[list["RunSpec"], list["RunSpec"], list[dict]]:
        """``(runs, references, capped)``: the runs in table order, the reference solves, and the
        combinations left out by :attr:`caps` (``capped`` rows give problem, method, resolution, nodes)."""
        runs, refs, capped = [], [], []
        nodes_of = {}
        for p in self.problems:
            prob = get_problem(p)
            for load in self.loads_of(p):
                refs.append(RunSpec(self.name, p, load, "predictor", "neo-hookean", "ipopt",
                                    self.reference_resolution, self.timeout * 4, 3000, "reference", self.seed))
                for r in self.resolutions:
                    for mat in self.materials:
                        for m in self.methods:
                            design = m in DESIGN_METHODS
                            if design and not prob.design:
                                continue
                            cap = self.caps.get(m)
                            if cap is not None:
                                key = (p, r)
                                if key not in nodes_of:
                                    nodes_of[key] = build_setup(p, r, load).mesh.n_nodes
                                if nodes_of[key] > cap:
                                    if mat == self.materials[0]:
                                        capped.append({"problem": p, "load": load, "method": m, "resolution": r,
                                                       "nodes": nodes_of[key], "cap": cap})
                                    continue
                            for g in (("predictor",) if design else self.guesses):
                                runs.append(RunSpec(self.name, p, load, g, mat, m, r, float(self.timeout),
                                                    self.max_iter, "run", self.seed))
        return runs, refs, capped

    def to_dict(self) -> dict:
        d = asdict(self)
        d["loads"] = {k: list(v) for k, v in self.loads.items()}
        return d


@dataclass(frozen=True)
class RunSpec:
    """One run of a study: plain data, so it travels to Dask workers; :func:`execute_run` runs it."""

    study: str
    problem: str
    load: float
    guess: str
    material: str
    method: str
    resolution: int
    timeout: float
    max_iter: int
    role: str = "run"  # or "reference"
    seed: int = 0

    @property
    def kind(self) -> str:
        return "design" if self.method in DESIGN_METHODS else "equilibrium"

    def label(self) -> str:
        g = "" if self.guess == "predictor" else f" guess={self.guess}"
        return (f"{self.problem} load={self.load:g} n~{self.resolution} {self.material} {self.method}{g}"
                + (" [reference]" if self.role == "reference" else ""))


_QUICK_PROBLEMS = ("strip-stretch", "strip-bend", "strip-contract")
_ALL_BACKENDS = ("ipopt", "ipopt-lbfgs", "sqpmethod", "uno", "scipy", "newton")

#: The registry of studies, by name.
STUDIES: dict[str, Study] = {s.name: s for s in (
    Study("quick", "every backend and design method on a stretch by the strip's width, a 90 degree bend and a "
          "30 % contraction, both material models, three meshes: about a minute on two cores",
          _QUICK_PROBLEMS, (30, 100, 300), ("neo-hookean", "linear"), _ALL_BACKENDS + DESIGN_METHODS,
          reference_resolution=1000, timeout=30.0, caps={"uno": 100, "ipopt-lbfgs": 100}),
    Study("speed", "speed against accuracy and scaling: stretch, 60 degree bend (at 90 degrees the 17k-node "
          "reference creases through itself) and contraction on meshes of about 100 to 4000 nodes against a "
          "17k-node reference, every backend and design method (slow ones capped)",
          _QUICK_PROBLEMS, (100, 300, 1000, 4000), ("neo-hookean", "linear"), _ALL_BACKENDS + DESIGN_METHODS,
          loads={"strip-bend": (60.0,)}, reference_resolution=16000, timeout=120.0,
          caps={"uno": 100, "ipopt-lbfgs": 300, "derivative-free": 1200, "nested": 1200, "flattened": 1200}),
    Study("stability", "where methods fail: drag size (stretch up to three widths, bends past 90 degrees), "
          "compression past buckling, contraction past 50 %, and poor first guesses",
          ("strip-stretch", "strip-bend", "strip-compress", "strip-contract"), (300,), ("neo-hookean",),
          ("ipopt", "ipopt-lbfgs", "sqpmethod", "scipy", "newton"),
          loads={"strip-stretch": (0.5, 1.0, 2.0, 3.0), "strip-bend": (45.0, 90.0, 135.0, 180.0, 270.0),
                 "strip-compress": (0.1, 0.2, 0.3, 0.4), "strip-contract": (0.3, 0.5, 0.7, 0.85)},
          guesses=("predictor", "no-predictor", "rest", "noisy"), reference_resolution=1000, timeout=20.0,
          max_iter=500),
)}

#: The fidelity study (run by :func:`mdsr_opt.fidelity.run_fidelity_study`): problems with loads.
FIDELITY_STUDY = "fidelity"


def list_studies() -> list[str]:
    """Names of the registered studies (sweeps and the fidelity study)."""
    return list(STUDIES) + [FIDELITY_STUDY]


def get_study(name: str | Study) -> Study:
    """A registered sweep study by name (a :class:`Study` passes through)."""
    if isinstance(name, Study):
        return name
    if name == FIDELITY_STUDY:
        raise ValueError("'fidelity' is not a sweep: run it with mdsr_opt.fidelity.run_fidelity_study "
                         "(or `mdsr study fidelity`)")
    return STUDIES[_check_name(name, list_studies(), "study")]


# ============================================================================================== one run
class RunTimeout(BaseException):
    """Raised inside a run's thread when its time budget is spent (a BaseException, like KeyboardInterrupt,
    so that ``except Exception`` blocks in the solvers do not swallow it)."""


class _Deadline:
    """Raise :class:`RunTimeout` in the current thread ``seconds`` from now (at its next Python instruction).

    A timer thread sets an asynchronous exception on the running thread; C code (an IPOPT solve) finishes its
    call first. Leaving the block cancels the timer and clears an exception that was set but not yet raised,
    so nothing leaks past the block. No tracing: runs are not slowed down.
    """

    def __init__(self, seconds: float):
        self.seconds = float(seconds)

    def _fire(self):
        with self.lock:
            if not self.done:
                self.fired = True
                ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(self.tid), ctypes.py_object(RunTimeout))

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
            if self.fired:
                ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(self.tid), None)
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
    import scipy.sparse.linalg as spla

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
        from .design import check_minimum

        pd, _lam, _r = check_minimum(setup.mesh, material, setup.muscles, setup.contractions, res.x,
                                     muscle_model=setup.muscle_model, stiffness=setup.stiffness, lowest=False)
        return bool(pd)
    from .model import get_model

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
    >>> boundary_overlaps(m, m.points), boundary_overlaps(m, _arc(m.points, 2 * np.pi * 1.1))
    (False, True)
    """
    return mesh.boundary_crosses(x)


def _classify(success: bool, status: str, min_J: float, stable: bool, overlap: bool, wall: float,
              timeout: float) -> str:
    s = status.lower()
    if wall > timeout or "walltime" in s or "cputime" in s or "time limit" in s:
        return "time-out"
    if success:
        return "self-overlap" if overlap else ("none" if stable else "saddle")
    if "invert" in s or min_J <= 0:
        return "inverted elements"
    if "saddle" in s:  # a design rejected by its verification
        return "saddle"
    return "no convergence"


def _solve_equilibrium(setup: Setup, material, spec: RunSpec, tol: float):
    from .equilibrium import solve_external, solve_internal

    kw = dict(backend=spec.method, tol=tol, max_iter=spec.max_iter, **_guess_kwargs(setup, spec))
    if spec.method in ("ipopt", "ipopt-lbfgs"):
        kw["options"] = {"ipopt.max_wall_time": float(spec.timeout)}
    if setup.mode == "external":
        return solve_external(setup.mesh, material, setup.anchors, setup.drags, **kw)
    return solve_internal(setup.mesh, material, setup.muscles, setup.contractions, model=setup.muscle_model,
                          stiffness=setup.stiffness, **kw)


def _internal_energy(setup: Setup, material, a, x) -> float:
    from .model import get_model, spring_parameters

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
                  overlap=False, success=False, failure="error", status="")
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
    from .rundir import check_interrupt

    check_interrupt()  # a Ctrl-C that a solver turned into a failed solve stops the study, never a failed row
    wall = time.perf_counter() - t_start
    fields["wall_time"] = wall
    if not raised:
        fields["failure"] = _classify(fields["success"], fields["status"], fields["min_J"], fields["stable"],
                                      fields["overlap"], wall, spec.timeout)
        fields["success"] = fields["failure"] == "none"
    row.update(fields)
    return RunOutcome(index, row, None if x is None else np.asarray(x, dtype=float), mesh.points,
                      mesh.triangles if spec.role == "reference" else None, setup.mode == "internal")


def _run_design(setup: Setup, material, spec: RunSpec, mesh_time: float) -> dict:
    """A design recovery: the target is the internal-driving equilibrium at the known contractions on the same
    mesh; the error is the largest contraction error."""
    from .design import design_contractions
    from .equilibrium import solve_internal

    target = solve_internal(setup.mesh, material, setup.muscles, setup.contractions, model=setup.muscle_model,
                            stiffness=setup.stiffness)
    if not target.success:
        raise RuntimeError(f"the design target did not solve: {target.status}")
    res = design_contractions(setup.mesh, material, setup.muscles, target.x, method=spec.method,
                              muscle_model=setup.muscle_model, stiffness=setup.stiffness)
    v = res.verification
    e_ref = float(target.energy)
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
                ref_x: np.ndarray, free_body: bool = False) -> float:
    """Largest node distance between state ``x`` (on rest ``points``) and the reference state interpolated at
    those rest points, over the reference body's size (its bounding-box diagonal). ``free_body``: compare
    after the best rigid motion of ``x`` onto the reference (internal driving has no fixed frame)."""
    from .align import align

    y = interpolate(ref_points, ref_triangles, ref_x, points)
    x = np.asarray(x, dtype=float)
    if free_body:
        x = align(x, y).apply(x)
    size = float(np.linalg.norm(np.ptp(np.asarray(ref_points), axis=0)))
    return float(np.linalg.norm(x - y, axis=1).max() / size)


def _fill_accuracy(outcomes: list[RunOutcome], refs: dict) -> None:
    for o in outcomes:
        r = o.row
        if r["kind"] != "equilibrium":
            continue
        ref = refs.get((r["problem"], r["load"]))
        if ref is None or o.x is None or not ref.row["success"]:
            continue
        r["error"] = state_error(o.points, o.x, ref.points, ref.triangles, ref.x, o.free_body)
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
        raise ValueError("Dask runs need the optional dask extra, which is not installed: "
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


def _run_all(specs: list[RunSpec], scheduler, workers, log) -> list[RunOutcome]:
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


@dataclass
class StudyResult:
    """A finished study: its table (one dict per run, :data:`COLUMNS`), references and metadata."""

    study: Study
    rows: list
    references: list
    meta: dict = field(default_factory=dict)

    def __repr__(self) -> str:
        ok = sum(bool(r.get("success")) for r in self.rows)
        methods = list(dict.fromkeys(r.get("method") for r in self.rows))
        wall = self.meta.get("wall_time")
        return (f"StudyResult(study={self.study.name!r}, runs={len(self.rows)}, success={ok}, "
                f"methods={format_value(methods)}, references={len(self.references)}"
                + (f", wall_time={wall:.3g} s)" if isinstance(wall, (int, float)) else ")"))

    def to_dict(self) -> dict:
        """The study's definition, rows, references and metadata as a JSON-ready dict (NaN as None)."""
        return to_jsonable({"study": self.study.to_dict(), "rows": self.rows, "references": self.references,
                            "meta": self.meta})

    def column(self, name: str) -> list:
        if name not in COLUMNS:
            raise ValueError(f"unknown column {name!r}; columns: {', '.join(COLUMNS)}")
        return [r[name] for r in self.rows]

    def comparable(self) -> list[tuple]:
        """The rows without their timing columns: equal for any two runs of the same study."""
        keep = [c for c in COLUMNS if c not in TIMING_COLUMNS]
        return [tuple(r[c] for c in keep) for r in self.rows]

    def csv_text(self, rows: list | None = None) -> str:
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=list(COLUMNS), lineterminator="\n")
        w.writeheader()
        for r in (self.rows if rows is None else rows):
            w.writerow({k: _fmt(r[k]) for k in COLUMNS})
        return buf.getvalue()

    def summary(self) -> list[dict]:
        """Per method: runs, successes, median time and error of the successes, and the fitted scaling slope."""
        slopes = fit_slopes(self.rows)
        out = []
        for m in dict.fromkeys(r["method"] for r in self.rows):
            rs = [r for r in self.rows if r["method"] == m]
            ok = [r for r in rs if r["success"]]
            t = [r["build_time"] + r["solve_time"] for r in ok]
            e = [r["error"] for r in ok if np.isfinite(r["error"])]
            fails = {f: sum(r["failure"] == f for r in rs) for f in FAILURES[1:]}
            out.append({"method": m, "runs": len(rs), "success": len(ok),
                        "median_time": float(np.median(t)) if t else math.nan,
                        "median_error": float(np.median(e)) if e else math.nan,
                        "slope": slopes.get(m, (math.nan,))[0],
                        "failures": ", ".join(f"{k} {v}" for k, v in fails.items() if v) or "-"})
        return out

    def markdown(self) -> str:
        lines = [f"# Study {self.study.name}", "", self.study.description, "",
                 "| method | runs | success | median time s | median error | time ~ nodes^slope | failures |",
                 "| --- | ---: | ---: | ---: | ---: | ---: | --- |"]
        def num(v, f):
            return "-" if not math.isfinite(v) else format(v, f)

        for s in self.summary():
            lines.append(f"| {s['method']} | {s['runs']} | {s['success']} | {num(s['median_time'], '.3g')} | "
                         f"{num(s['median_error'], '.2g')} | {num(s['slope'], '.2f')} | {s['failures']} |")
        return "\n".join(lines) + "\n"

    def write(self, out: str | os.PathLike, figures: bool = True) -> dict:
        """Write ``<name>.csv``, ``<name>_references.csv``, ``<name>.json`` (metadata), ``<name>.md`` and the
        charts ``<name>_pareto.png``, ``<name>_scaling.png``, ``<name>_success.png`` into ``out``; every file
        through a temporary file. Returns ``{kind: path}``."""
        out = os.fspath(out)
        os.makedirs(out, exist_ok=True)
        name = self.study.name
        paths = {}
        for key, fname, text in (("csv", f"{name}.csv", self.csv_text()),
                                 ("references", f"{name}_references.csv", self.csv_text(self.references)),
                                 ("md", f"{name}.md", self.markdown())):
            p = os.path.join(out, fname)
            with atomic_path(p) as tmp, open(tmp, "w") as fh:
                fh.write(text)
            paths[key] = p
        paths["json"] = write_json(os.path.join(out, f"{name}.json"), _jsonable(self.meta))
        if figures:
            from . import plot

            paths["pareto"] = plot.save_figure(plot.plot_study_pareto(self.rows, title=name),
                                               os.path.join(out, f"{name}_pareto.png"), close=True)
            paths["scaling"] = plot.save_figure(plot.plot_study_scaling(self.rows, fit_slopes(self.rows),
                                                                        title=name),
                                                os.path.join(out, f"{name}_scaling.png"), close=True)
            paths["success"] = plot.save_figure(plot.plot_study_success(self.rows, title=name),
                                                os.path.join(out, f"{name}_success.png"), close=True)
        return paths


def _fmt(v):
    if isinstance(v, (bool, np.bool_)):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    return v


def _jsonable(o):
    if isinstance(o, dict):
        return {str(k): _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    if isinstance(o, float) and not math.isfinite(o):
        return None
    return o


def _environment() -> dict:
    import casadi
    import scipy

    from . import __version__

    return {"mdsr_opt": __version__, "python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__, "casadi": casadi.__version__, "platform": platform.platform(),
            "machine": platform.machine(), "cpus": os.cpu_count()}


def run_study(study: str | Study, *, out: str | os.PathLike | None = None, resolutions: Sequence[int] | None = None,
              methods: Sequence[str] | None = None, problems: Sequence[str] | None = None,
              materials: Sequence[str] | None = None, reference_resolution: int | None = None,
              timeout: float | None = None, scheduler: Any = None, workers: int | None = None,
              progress: bool = True, figures: bool = True, log: Callable[[str], Any] | None = None) -> StudyResult:
    """Run a study and (with ``out``) write its table, metadata and charts.

    Parameters
    ----------
    study : str or Study
        A name from :func:`list_studies` or a :class:`Study`.
    out : path, optional
        Folder for the outputs (:meth:`StudyResult.write`).
    resolutions, methods, problems, materials, reference_resolution, timeout : optional
        Override the study's axes (e.g. the quick study at its smallest size: ``resolutions=[30]``).
    scheduler : None, "local", "inprocess", an address or a ``distributed.Client``
        ``None`` runs serially here; ``"local"`` starts a Dask LocalCluster (one single-threaded worker
        process per core, or ``workers``); ``"inprocess"`` a thread-based one in this process; an address
        such as ``"tcp://10.0.0.5:8786"`` uses a running cluster (its workers need mdsr_opt installed).
    progress : bool
        Print one line per finished run (to stderr, or through ``log``).

    Returns
    -------
    StudyResult
        ``rows`` are in plan order whatever the order runs finished in.

    Raises
    ------
    ValueError
        An unknown study, problem, backend, material or guess (the message lists the valid ones).
    """
    st = get_study(study).with_options(resolutions=resolutions, methods=methods, problems=problems,
                                       materials=materials, reference_resolution=reference_resolution,
                                       timeout=timeout)
    if log is None:
        log = _LOG.info if progress else None
    elif not progress:
        log = None
    runs, refs, capped = st.plan()
    t0 = time.perf_counter()
    if log:
        name = scheduler if isinstance(scheduler, str) else "client"
        where = "serially" if scheduler is None else f"on Dask ({name})"
        log(f"study {st.name}: {len(runs)} runs and {len(refs)} reference solves, {where}")
    outcomes = _run_all(refs + runs, scheduler, workers, log)
    ref_out, run_out = outcomes[:len(refs)], outcomes[len(refs):]
    refmap = {(o.row["problem"], o.row["load"]): o for o in ref_out}
    for o in ref_out:
        if not o.row["success"] and log:
            log(f"warning: reference {o.row['problem']} load {o.row['load']:g} failed ({o.row['failure']}: "
                f"{o.row['status']}); its runs have no accuracy (error and energy_error are nan)")
    _fill_accuracy(run_out, refmap)
    for o in ref_out:
        if o.row["success"]:
            o.row["error"], o.row["energy_error"] = 0.0, 0.0
    rows = [o.row for o in run_out]
    for r in rows:
        for k in COLUMNS:
            r.setdefault(k, math.nan)
        for k in ("load", "build_time", "solve_time", "wall_time", "energy", "energy_error", "error", "min_J",
                  "residual"):
            r[k] = float(r[k])
    meta = {"study": st.to_dict(), "runs": len(runs), "references": len(refs), "capped": capped,
            "scheduler": None if scheduler is None else str(scheduler if isinstance(scheduler, str) else "client"),
            "wall_time": time.perf_counter() - t0, "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "environment": _environment(), "columns": list(COLUMNS), "timing_columns": list(TIMING_COLUMNS),
            "identical_means": "all columns except the timing columns are equal"}
    res = StudyResult(st, rows, [o.row for o in ref_out], meta)
    if out is not None:
        paths = res.write(out, figures=figures)
        if log:
            log(f"wrote {', '.join(sorted(os.path.basename(p) for p in paths.values()))} to {out}")
    return res


def fit_slopes(rows: Sequence[dict], time_of: Callable[[dict], float] | None = None) -> dict:
    """Least-squares fit ``log10(time) = a + b log10(nodes)`` per method over its successful runs.

    Returns ``{method: (slope b, intercept a, number of runs)}`` for methods whose successful runs span node
    counts at least a factor 2 apart (closer ones give no meaningful slope). ``time_of`` defaults to build
    plus solve time.
    """
    time_of = time_of or (lambda r: r["build_time"] + r["solve_time"])
    out = {}
    for m in dict.fromkeys(r["method"] for r in rows):
        pts = [(r["nodes"], time_of(r)) for r in rows if r["method"] == m and r["success"] and time_of(r) > 0]
        nodes = {p[0] for p in pts}
        if not nodes or max(nodes) < 2 * min(nodes):
            continue
        x, y = np.log10(np.array(pts, dtype=float)).T
        b, a = np.polyfit(x, y, 1)
        out[m] = (float(b), float(a), len(pts))
    return out


def pareto_front(times: Sequence[float], errors: Sequence[float]) -> np.ndarray:
    """Indices of the points not dominated in (time, error), sorted by time: each is more accurate than every
    faster point."""
    t = np.asarray(times, dtype=float)
    e = np.asarray(errors, dtype=float)
    ok = np.flatnonzero(np.isfinite(t) & np.isfinite(e))
    order = ok[np.lexsort((e[ok], t[ok]))]
    front, best = [], math.inf
    for i in order:
        if e[i] < best:
            front.append(i)
            best = e[i]
    return np.array(front, dtype=np.int64)


# ============================================================================================== CLI
def _csv_list(text: str | None, cast=str, flag: str = "the list"):
    if text is None:
        return None
    items = [t.strip() for t in text.split(",") if t.strip()]
    if not items:
        raise ValueError(f"{flag}: expected a comma-separated list, got {text!r}")
    out = []
    for t in items:
        try:
            out.append(cast(t))
        except ValueError:
            kind = {int: "integers", float: "numbers"}.get(cast, "values")
            raise ValueError(f"{flag}: expected comma-separated {kind}, got {t!r}") from None
    return out


def _cli(args) -> int:
    if args.list or args.name is None:
        from .fidelity import FIDELITY_CASES

        for name, st in STUDIES.items():
            runs, _refs, _capped = st.plan()
            print(f"{name:<10} {len(runs):>4} runs  {st.description}")
        print(f"{FIDELITY_STUDY:<10} {len(FIDELITY_CASES):>4} scenes  the coarsest mesh and simplest material "
              "model within a tolerance, per scene")
        print("\nproblems: " + ", ".join(list_study_problems()))
        return 0
    if args.out is None:
        raise ValueError("give --out DIR for the study's table and charts")
    from .rundir import check_out_path

    check_out_path(args.out)  # every argument before any work
    if args.workers is not None and args.workers < 1:
        raise ValueError(f"--workers must be at least 1, got {args.workers}")
    if args.timeout is not None and not (math.isfinite(args.timeout) and args.timeout > 0):
        raise ValueError(f"--timeout must be a positive number of seconds, got {args.timeout}")
    if args.reference_resolution is not None and args.reference_resolution < 20:
        raise ValueError(f"--reference-resolution must be at least 20 nodes, got {args.reference_resolution}")
    scheduler = args.scheduler or ("local" if args.dask else None)
    if args.name == FIDELITY_STUDY:
        from .fidelity import fidelity_markdown, run_fidelity_study

        kw = {"resolutions": _csv_list(args.resolutions, int, "--resolutions"),
              "reference_resolution": args.reference_resolution}
        with progress_for_cli(args, 0, "mdsr study fidelity", stream="stderr", unit="run") as log:
            choices, _ = run_fidelity_study(args.out, tolerances=_csv_list(args.tol, float, "--tol"),
                                            scheduler=scheduler, workers=args.workers, progress=not args.quiet,
                                            log=log, **{k: v for k, v in kw.items() if v is not None})
        print(fidelity_markdown(choices), flush=True)
        return 0
    with progress_for_cli(args, 0, f"mdsr study {args.name}", stream="stderr", unit="run") as log:
        res = run_study(args.name, out=args.out, resolutions=_csv_list(args.resolutions, int, "--resolutions"),
                        methods=_csv_list(args.methods, str, "--methods"),
                        problems=_csv_list(args.problems, str, "--problems"),
                        materials=_csv_list(args.materials, str, "--materials"),
                        reference_resolution=args.reference_resolution, timeout=args.timeout,
                        scheduler=scheduler, workers=args.workers, progress=not args.quiet, log=log)
    print(res.markdown())
    return 0


def add_cli(sub) -> None:
    """Register ``mdsr study``."""
    p = sub.add_parser("study", help="run a solver comparison study (mdsr study --list)",
                       description="Run a solver comparison study: a tidy CSV, metadata and charts in --out.")
    p.add_argument("name", nargs="?", help="study name (see --list)")
    p.add_argument("--list", action="store_true", help="list the studies and problems")
    p.add_argument("--out", help="output folder")
    p.add_argument("--resolutions", help="comma-separated node counts, replacing the study's")
    p.add_argument("--methods", help="comma-separated backends / design methods, replacing the study's")
    p.add_argument("--problems", help="comma-separated problems, replacing the study's")
    p.add_argument("--materials", help="comma-separated material models, replacing the study's")
    p.add_argument("--reference-resolution", type=int, help="node count of the reference solutions")
    p.add_argument("--timeout", type=float, help="seconds allowed per run")
    p.add_argument("--tol", help="fidelity study: comma-separated tolerances (default 0.01,0.001)")
    p.add_argument("--dask", action="store_true", help="run on a local Dask cluster (one worker per core)")
    p.add_argument("--scheduler", help="address of a running Dask scheduler (implies Dask)")
    p.add_argument("--workers", type=int, help="workers of the local Dask cluster")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=_cli)
