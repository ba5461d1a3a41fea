"""What a study sweeps (:class:`Study`, :class:`RunSpec`) and the named studies."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from typing import Iterable, Mapping
import numpy as np

from ..body.mesh import MAX_RESOLUTION
from ..core.checks import positive_int
from .problems import MATERIALS, check_name, build_setup, get_study_problem
from ..mechanics.backends import available_backends

__all__ = ['Study', 'RunSpec', 'list_studies', 'get_study']


#: Columns of a study table, in order.
COLUMNS = ("study", "problem", "kind", "load", "guess", "material", "method", "resolution", "nodes",
           "build_time", "solve_time", "wall_time", "iterations", "steps", "energy", "energy_error", "error",
           "min_J", "residual", "stable", "overlap", "success", "failure", "status", "branch")


#: Columns that measure time and so differ between runs of the same study.
TIMING_COLUMNS = ("build_time", "solve_time", "wall_time")


#: Failure reasons, in the order charts list them: ``iteration limit`` (the solver stopped at its cap),
#: ``no convergence`` (any other failed solve), ``inverted elements``, ``self-contact`` (the boundary crosses
#: itself: contact is not modelled), ``saddle`` (a converged state that is not a minimum of the energy),
#: ``time-out`` (the run's budget), ``error`` (an exception).
FAILURES = ("none", "iteration limit", "no convergence", "inverted elements", "self-contact", "saddle", "time-out",
            "error")


#: First guesses: the default predictor with load steps; no predictor with load steps; one solve from rest;
#: one solve from a randomly perturbed rest shape.
GUESSES = ("predictor", "no-predictor", "rest", "noisy")


DESIGN_METHODS = ("flattened", "nested", "derivative-free")


#: the default reference mesh: this many times the finest resolution of a study
REFERENCE_FACTOR = 4


def default_reference(resolutions) -> int:
    """The default reference resolution of a study on ``resolutions``: :data:`REFERENCE_FACTOR` times the
    finest, at most :data:`~mdsr_opt.body.mesh.MAX_RESOLUTION`."""
    return int(min(MAX_RESOLUTION, REFERENCE_FACTOR * max(int(r) for r in resolutions)))


def _check_nodes(r, what: str) -> None:
    """Refuse a node count that is not an integer from 4 to :data:`~mdsr_opt.body.mesh.MAX_RESOLUTION`."""
    if isinstance(r, bool) or not isinstance(r, (int, np.integer)) or not 4 <= r <= MAX_RESOLUTION:
        raise ValueError(f"{what}: {r!r} is not a node count from 4 to {MAX_RESOLUTION} (a solve's memory grows "
                         f"with the nodes: about 3 GB at {MAX_RESOLUTION})")


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
        Mesh of the reference solutions (Neo-Hookean, IPOPT, tight tolerance); default
        :data:`REFERENCE_FACTOR` times the finest resolution (at most the largest mesh allowed). A run is
        measured only against a reference on a finer mesh than its own (else its ``error`` stays NaN: the
        same discrete solution measures nothing).
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
        for k in ("problems", "resolutions", "materials", "methods", "guesses"):
            v = getattr(self, k)
            if isinstance(v, (str, bytes)) or not isinstance(v, Iterable):
                raise TypeError(f"study {self.name!r}: {k} must be a sequence, got {v!r}")
            v = tuple(v)
            if not v:
                raise ValueError(f"study {self.name!r}: {k} is empty")
            object.__setattr__(self, k, v)
        for p in self.problems:
            get_study_problem(p)
        for r in self.resolutions:
            _check_nodes(r, f"study {self.name!r}: resolutions")
        object.__setattr__(self, "resolutions", tuple(sorted(int(r) for r in self.resolutions)))
        for m in self.materials:
            check_name(m, MATERIALS, "material")
        valid = tuple(available_backends()) + DESIGN_METHODS
        for m in self.methods:
            check_name(m, valid, "method (backend or design method)")
        for g in self.guesses:
            check_name(g, GUESSES, "first guess")
        loads = {}
        for k, v in dict(self.loads).items():
            if k not in self.problems:
                raise ValueError(f"study {self.name!r}: loads given for {k!r}, which is not among its problems")
            loads[k] = tuple(float(x) for x in np.atleast_1d(v))
        object.__setattr__(self, "loads", loads)
        for p in self.problems:  # a bad load is an error now, not in the middle of a sweep
            for load in self.loads_of(p):
                try:
                    get_study_problem(p).build(self.resolutions[0], load)
                except ValueError as exc:
                    raise ValueError(f"study {self.name!r}: {exc}") from None
        if self.reference_resolution is None:
            object.__setattr__(self, "reference_resolution", default_reference(self.resolutions))
        _check_nodes(self.reference_resolution, f"study {self.name!r}: reference_resolution")
        object.__setattr__(self, "reference_resolution", int(self.reference_resolution))
        if isinstance(self.timeout, bool) or not (isinstance(self.timeout, (int, float)) and self.timeout > 0):
            raise ValueError(f"study {self.name!r}: timeout must be a positive number of seconds, "
                             f"got {self.timeout!r}")
        positive_int(self.max_iter, f"study {self.name!r}: max_iter")
        object.__setattr__(self, "caps", dict(self.caps))

    def with_options(self, **changes) -> "Study":
        """A copy with some fields replaced (``None`` values are ignored); e.g. fewer resolutions."""
        changes = {k: (tuple(v) if isinstance(v, list) else v) for k, v in changes.items() if v is not None}
        if "problems" in changes and "loads" not in changes:  # keep the loads of the problems that remain
            changes["loads"] = {k: v for k, v in self.loads.items() if k in changes["problems"]}
        if "resolutions" in changes and "reference_resolution" not in changes and \
                self.reference_resolution == default_reference(self.resolutions):
            changes["reference_resolution"] = None
        return replace(self, **changes)

    def loads_of(self, problem: str) -> tuple:
        return self.loads.get(problem, (get_study_problem(problem).default_load,))

    def plan(self) -> tuple[list["RunSpec"], list["RunSpec"], list[dict]]:
        """``(runs, references, capped)``: the runs in table order, the reference solves, and the
        combinations left out by :attr:`caps` (``capped`` rows give problem, method, resolution, nodes)."""
        runs, refs, capped = [], [], []
        nodes_of = {}
        for p in self.problems:
            prob = get_study_problem(p)
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
                                                    self.max_iter, "run", self.seed,
                                                    reference_resolution=self.reference_resolution))
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
    #: the study's reference mesh: a design run's target is the reference solved there (a finer mesh)
    reference_resolution: int | None = None

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
          _QUICK_PROBLEMS, (100, 300, 1000, 4000), ("neo-hookean", "linear"),
          _ALL_BACKENDS + ("ipopt-symbolic",) + DESIGN_METHODS,
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


#: The fidelity study (run by :func:`mdsr_opt.studies.fidelity.run_fidelity_study`): problems with loads.
FIDELITY_STUDY = "fidelity"


#: The recommendation study (run by :func:`mdsr_opt.studies.recommend.run_recommendation`): per library scene.
RECOMMEND = "recommend"


def list_studies() -> list[str]:
    """Names of the registered studies (sweeps and the fidelity study)."""
    return list(STUDIES) + [FIDELITY_STUDY, RECOMMEND]


def get_study(name: str | Study) -> Study:
    """A registered sweep study by name (a :class:`Study` passes through)."""
    if isinstance(name, Study):
        return name
    if name == FIDELITY_STUDY:
        raise ValueError("'fidelity' is not a sweep: run it with mdsr_opt.studies.fidelity.run_fidelity_study "
                         "(or `mdsr study fidelity`)")
    if name == RECOMMEND:
        raise ValueError("'recommend' is not a sweep: run it with mdsr_opt.studies.recommend.run_recommendation "
                         "(or `mdsr study recommend`)")
    return STUDIES[check_name(name, list_studies(), "study")]
