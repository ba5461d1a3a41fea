"""The outcome of an equilibrium solve (:class:`EquilibriumResult`) and its failure exception."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
import numpy as np

from ..core.results import compact_repr, load_fields, save_fields, to_jsonable

__all__ = ['SolverFailure', 'EquilibriumResult', 'MinimizeOutcome', 'solver_status']


class SolverFailure(RuntimeError):
    """Raised by :meth:`EquilibriumResult.raise_on_failure` when a solve did not succeed."""


@dataclass
class EquilibriumResult:
    """The outcome of an equilibrium solve.

    Attributes
    ----------
    x : (n, 2) deformed node positions (the last accepted state if the solve failed: a load step before the
        last is solved only to :data:`~mdsr_opt.mechanics.loadsteps.INTERMEDIATE_TOL`, or for internal driving
        :data:`~mdsr_opt.mechanics.loadsteps.INTERNAL_INTERMEDIATE_TOL`, when ``tol`` is tighter).
    energy : total energy at ``x`` (elastic plus muscle springs).
    elastic_energy : strain energy of the body alone.
    success : solver converged, residual small and no element inverted.
    status : solver status text (or the reason for failure).
    iterations : solver iterations summed over load steps.
    residual : the scaled KKT residual (:func:`~mdsr_opt.mechanics.residual.kkt_residual`): the max-norm of
        the energy gradient over the free coordinates, relative to ``E t size``; with muscle constraints that
        of the Lagrangian (least-squares multipliers, ropes pulling only within ``tol L0`` of their targets)
        or the constraints' violation, whichever is larger. At most ``tol`` in a success.
    min_J : smallest element ``det F``.
    steps : load fractions accepted (``[1.0]`` when no stepping was needed).
    build_time, solve_time : seconds spent building the model/solver (0 when reused) and solving.
    commanded, achieved, stroke, tension, slack, rest_lengths : internal driving, one entry per muscle: the
        contraction asked; the contraction reached, ``1 - L/L0`` with ``L`` the node chain's length in ``x``;
        the stroke ``achieved * L0`` (length units, what a servo winds in); the tension (cable: the rope
        constraint's multiplier, never negative; springs: the springs' mean force
        ``K L0/L0_free (a - achieved)``, negative when they push); slack (cable: the path is shorter than the
        rope, so achieved > commanded at zero tension; springs: not pulling); ``L0``.
    anchor_radius : internal driving: the radius of the rigid anchor patches at the muscles' ends.
    contact : with contact modelled (``obstacles``, ``contact=True``): the gap kept, the active pairs (kind,
        nodes, obstacle, gap, normal force: the multipliers), the contact force on each node, the force on
        each obstacle and the candidates' count (:func:`~mdsr_opt.mechanics.contactsteps.contact_report`);
        None otherwise.
    """

    x: np.ndarray
    energy: float
    elastic_energy: float
    success: bool
    status: str
    iterations: int
    residual: float
    min_J: float
    steps: list = field(default_factory=list)
    build_time: float = 0.0
    solve_time: float = 0.0
    backend: str = "ipopt"
    mode: str = "external"
    rotation: np.ndarray | None = None  # internal driving: rotation applied to align with rest
    translation: np.ndarray | None = None
    muscle_model: str | None = None  # internal driving: "springs" or "cable"
    stable: bool | None = None  # the free (reduced) Hessian is positive definite; None when not checked
    stability: dict | None = None  # StabilityCheck.summary(): n_negative, n_zero, curvature, method, time
    # internal driving, per muscle (see solve_internal):
    commanded: np.ndarray | None = None  # contraction asked
    achieved: np.ndarray | None = None  # 1 - L/L0 along the node chain in the returned state
    stroke: np.ndarray | None = None  # achieved * L0 (length units): the rope length taken in
    tension: np.ndarray | None = None  # rope tension (cable: the multiplier; springs: the rod force)
    slack: np.ndarray | None = None  # cable: path shorter than the rope (achieved > commanded); springs: not pulling
    rest_lengths: np.ndarray | None = None  # L0 per muscle
    anchor_radius: float | None = None  # radius of the rigid anchor patches at the muscles' ends
    contact: dict | None = None  # with contact modelled: active pairs and forces (see the docstring)

    def __repr__(self) -> str:
        return compact_repr(self, ("mode", "backend", "success", "iterations", "residual", "min_J", "energy", "x",
                                   "status"))

    def to_dict(self) -> dict:
        """Every field as JSON-ready values (arrays as nested lists, NaN as None)."""
        return {f: to_jsonable(getattr(self, f)) for f in self.__dataclass_fields__}

    def save(self, path: str | os.PathLike) -> str:
        """Write the result as one ``.npz`` file (arrays exactly, the rest as JSON metadata), atomically:
        ``path`` ends in ``.npz`` (a folder name is refused, naming a file in it to use; a
        :class:`~mdsr_opt.synthesis.pipeline.PipelineResult`, which holds meshes too, is saved into a folder).

        Returns the path; :meth:`load` reads it back equal to this result. An existing file of that name is replaced,
        without a warning (``mdsr run`` refuses to without ``--overwrite``)."""
        return save_fields(self, path, "equilibrium")

    @classmethod
    def load(cls, path: str | os.PathLike) -> "EquilibriumResult":
        """Read a result written by :meth:`save`.

        Raises
        ------
        FileNotFoundError
            No such file.
        ValueError
            The file (named) is damaged, not a ``.npz`` or holds another kind of result.
        """
        return load_fields(cls, path, "equilibrium")

    def raise_on_failure(self) -> "EquilibriumResult":
        if not self.success:
            raise SolverFailure(f"{self.mode} driving with backend {self.backend!r} failed: {self.status} "
                                f"(iterations {self.iterations}, residual {self.residual:.3g}, "
                                f"min J {self.min_J:.3g})")
        return self

    def summary(self) -> dict:
        out = {"mode": self.mode, "backend": self.backend, "success": self.success, "status": self.status,
               "iterations": self.iterations, "energy": self.energy, "residual": self.residual,
               "min_J": self.min_J, "n_steps": len(self.steps), "build_time": self.build_time,
               "solve_time": self.solve_time, "stable": self.stable}
        if self.achieved is not None:
            out.update(muscle_model=self.muscle_model, anchor_radius=self.anchor_radius,
                       **{k: [float(v) if k != "slack" else bool(v) for v in getattr(self, k)]
                          for k in ("commanded", "achieved", "stroke", "tension", "slack")})
        return out


@dataclass
class MinimizeOutcome:
    """What one backend's minimisation returned.

    Attributes
    ----------
    x : (2n,) ndarray
        The flattened coordinates reached.
    success : bool
    status : str
    iterations : int
    solve_time, build_time : float
        Seconds solving and building the solver (0 when reused).
    lam_g : ndarray or None
        Constraint multipliers (constrained models only).
    certified : bool
        IPOPT's last factorisation showed ``x`` a strict local minimum
        (:func:`~mdsr_opt.mechanics.stability.ipopt_certifies_minimum`): load stepping skips its own check.
    """

    x: np.ndarray  # (2n,) flattened coordinates
    success: bool
    status: str
    iterations: int
    solve_time: float
    build_time: float
    lam_g: np.ndarray | None = None  # constraint multipliers (constrained models only)
    certified: bool = False  # a strict minimum by IPOPT's own inertia test (see the docstring)

    def __repr__(self) -> str:
        return compact_repr(self, ("success", "iterations", "solve_time", "x", "lam_g", "status"))

    def to_dict(self) -> dict:
        """Every field as JSON-ready values (arrays as lists)."""
        return {f: to_jsonable(getattr(self, f)) for f in self.__dataclass_fields__}

    def save(self, path) -> str:
        """Write the outcome as one ``.npz`` file (arrays exactly); :meth:`load` reads it back.
        An existing file of that name is replaced, without a warning (``mdsr run`` refuses to without
        ``--overwrite``)."""
        return save_fields(self, path, "minimize")

    @classmethod
    def load(cls, path) -> "MinimizeOutcome":
        """Read an outcome written by :meth:`save` (ValueError naming a damaged or foreign file)."""
        return load_fields(cls, path, "minimize")


def solver_status(stats: dict) -> tuple[str, int]:
    """``(return status, iterations)`` from a CasADi ``nlpsol``'s ``stats()``: IPOPT's ``return_status`` and
    ``iter_count``, or another plugin's ``unified_return_status`` and last ``iterations["iter"]``."""
    status = str(stats.get("return_status", stats.get("unified_return_status", "unknown")))
    its = stats.get("iterations")
    return status, int(stats.get("iter_count", its.get("iter", [0])[-1] if its else 0))
