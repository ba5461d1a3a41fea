"""Design results: :class:`DesignResult` (contractions, strokes, tensions, state) and :class:`Verification`."""

from __future__ import annotations

import math
import os
import time
from dataclasses import asdict, dataclass, field
import numpy as np

from ..core.results import compact_repr, load_fields, save_fields
from ..core.quantities import contact_in_unit, length_unit, point_band, tension_unit
from ..plot.style import muscle_name
from .problem import DesignProblem

__all__ = ['Verification', 'DesignResult', 'MuscleWarning', 'SATURATION_TOL']


METHODS = ("flattened", "nested", "derivative-free")

#: a designed contraction within this of ``a_max`` is saturated (:attr:`DesignResult.saturated`): the
#: muscle would pull further if it could, so the body reaches less than the layout could with more stroke
SATURATION_TOL = 1e-3


class MuscleWarning(UserWarning):
    """A designed muscle is saturated (its contraction at ``a_max``): the design's shape is the best within
    the bound, not the target's; raise ``a_max``, add muscles or accept the difference. Also: an idle muscle
    kept because the design without it failed (:func:`~mdsr_opt.synthesis.acceptance.design_active`)."""


# ---------------------------------------------------------------------------------------------- results
@dataclass
class Verification:
    """The independent check of a design.

    Attributes
    ----------
    passed : bool
        The forward re-solve succeeded, its gap to the design's state is within ``gap_tol`` and the design's
        state is an equilibrium (``residual`` within the verification's ``tol``) and a strict minimum.
    gap : float
        Largest node distance between the design's state and the forward re-solve at the same contractions
        (started from rest, or from the design's state with ``verify_design(start="design")``), after rigidly
        aligning the two (a length).
    gap_tol : float
        The tolerance on ``gap`` (a length: ``gap_rtol * mesh.size``).
    forward_success, forward_status : bool, str
        Outcome of the forward re-solve.
    forward_difference : float
        Difference index of the forward re-solve to the target.
    residual : float
        The scaled KKT residual of the design's state at its contractions
        (:func:`~mdsr_opt.mechanics.residual.kkt_residual`: the max-norm of the Lagrangian's gradient on the
        free coordinates relative to ``E t size``, and the constraints' violation), at most the
        verification's ``tol`` when it passed.
    positive_definite : bool
        The free-coordinate Hessian at the design's state is positive definite (every pivot of its
        symmetric factorisation is positive); when the forward re-solve lands within
        :data:`~mdsr_opt.synthesis.verify.SAME_STATE_RTOL` of the body's size of that state, the answer of
        the re-solve's own stability check there.
    min_eigenvalue : float
        Its smallest eigenvalue, relative to ``E t`` (negative: a saddle); see :func:`check_minimum`. When
        the state is positive definite it is only estimated with ``verify_design(..., lowest=True)`` (an
        eigen-solve, 30-100x the cost of the inertia) and is NaN otherwise; when it is not, the curvature
        along the direction of negative curvature found (an upper bound on the smallest eigenvalue).
    message : str
        Why the check failed (empty when it passed).
    time : float
        Seconds spent verifying.
    target_stable : bool or None
        The target is a stable equilibrium of its external driving (None: anchors and drags not given).
    contact : dict or None
        With contact, the forward re-solve's contact report (``pairs`` with their normal forces,
        ``node_forces``, ``obstacle_forces``, ``total_force``, ``gap``; see :func:`~mdsr_opt.solve_internal`);
        None without.
    forward_iterations : int or None
        The forward re-solve's solver iterations (all its solves; None: a result saved before they were kept).
    forward_start : str or None
        Where the forward re-solve started: ``"rest"`` (the rest shape), ``"rest, predictor"`` (from rest with
        the load-stepping predictor, after the solve from the rest shape failed) or ``"design"``.
    """

    passed: bool
    gap: float
    gap_tol: float
    forward_success: bool
    forward_status: str
    forward_difference: float
    residual: float
    positive_definite: bool
    min_eigenvalue: float
    message: str = ""
    time: float = 0.0
    target_stable: bool | None = None
    contact: dict | None = None
    forward_iterations: int | None = None
    forward_start: str | None = None

    def __repr__(self) -> str:
        return compact_repr(self, ("passed", "gap", "gap_tol", "residual", "positive_definite", "message"))

    def to_dict(self) -> dict:
        """The fields as a JSON-ready dict (NaN as None)."""
        return finite_or_none(asdict(self))


@dataclass
class DesignResult:
    """Contractions found for a target, the driven state and how they were found.

    Attributes
    ----------
    method : str
        ``"flattened"``, ``"nested"`` or ``"derivative-free"``.
    contractions : (m,) ndarray
        One contraction per muscle, in ``[0, a_max]``.
    x : (n, 2) ndarray
        The driven equilibrium at ``contractions``, rigidly aligned to the rest shape (as
        :func:`~mdsr_opt.solve_internal` returns it).
    rotation, translation : (2, 2) and (2,) ndarrays
        The best rigid motion taking ``x`` onto the target: ``x @ rotation.T + translation``.
    difference : float
        Weighted RMS node distance to the target after that motion (a length): what the design minimises and
        what ``mdsr run``'s ok/FAILED verdict judges (:func:`~mdsr_opt.synthesis.acceptance.difference_failure`).
    max_error : float
        The largest node distance to the target after the same motion (a length, in the body's units): an
        RMS can pass a design that misses the pose at an extremity (an arm's tip), so reports give both.
    relative_max_error : float
        ``max_error`` over the body's size, its diameter at rest (:func:`~mdsr_opt.mechanics.anchors.body_size`).
    max_error_node : int
        The node at ``max_error`` (-1 when not recorded).
    success : bool
        The optimiser converged and the verification passed.
    status : str
        The optimiser's status, with the reason when the design was rejected.
    iterations : int
        Outer iterations (IPOPT iterations for ``"flattened"``).
    n_forward : int
        Forward (equilibrium) solves made, warm start included.
    inner_iterations : int
        Solver iterations summed over those forward solves.
    build_time, solve_time, time : float
        Seconds building models and solvers (0 when cached), optimising (warm start included), and their sum.
    initial_contractions : (m,) ndarray
        The starting point.
    initial_difference : float
        Difference of the warm-start state.
    a_max : float
        Upper bound on the contractions.
    a_upper : (m,) ndarray
        Each muscle's own upper bound: ``a_max``, or less where its end fixtures cap it (the most its rope
        can shorten with ``2 anchor_radius + fixture_wall`` of rope kept between them); empty when not
        recorded (then ``a_max`` for every muscle).
    muscle_model : str
        ``"cable"`` (the exact rope) or ``"springs"``.
    stiffness : float
        Spring stiffness relative to ``E t`` (springs only).
    anchor_radius : float
        Radius of the rigid patch at each muscle end (a length; see
        :func:`~mdsr_opt.mechanics.anchors.anchor_patches`).
    fixture_wall : float or None
        The wall (a length) the design kept between a rope's two end fixtures (``design_contractions``'
        ``fixture_wall``); None for a design that does not record it.
    held : tuple of int or None
        The nodes clamped at rest in the design's forward solves (``design_contractions(held=...)``; the
        pipeline's anchors with obstacles), whose frame ``x`` is in; None for the free body.
        :func:`~mdsr_opt.synthesis.verify.verify_design` clamps them again unless told otherwise.
    rest_lengths : (m,) ndarray
        Each muscle's rest length ``L0`` along its node chain.
    achieved : (m,) ndarray
        Achieved contraction ``1 - L / L0`` of every muscle along its node chain in ``x`` (the cable:
        equal to ``contractions`` unless the rope is slack; springs: less, the springs stretch).
    stroke : (m,) ndarray
        The rope length each muscle pulls in, ``achieved * L0`` (a length; what a servo winds).
    tension : (m,) ndarray
        The muscle's pull (force: ``E t`` times a length). The cable: the rope's tension, the multiplier
        of its length constraint (never negative). Springs: the mean force of its segment springs.
    slack : (m,) bool ndarray
        The muscle does not pull (tension about zero, or negative for springs).
    verification : Verification or None
        The independent check (None when ``verify=False``).
    history : list of (float, float)
        ``(seconds since start, difference)`` after each forward solve of the outer loop (nested,
        derivative-free) or at start and end (flattened, whose iterates are not equilibria).
    rest_mesh : dict or None
        The fingerprint of the mesh the design was made on (:func:`~mdsr_opt.body.fingerprint.mesh_fingerprint`),
        saved and loaded with the result: functions taking a mesh with the result refuse another body
        (None: not recorded, not checked).
    stroke_band : (m, 2) ndarray
        Per muscle the (low, high) range of the stroke under the fabrication's uncertainties (fixture size,
        Poisson's ratio, mesh refinement; :func:`~mdsr_opt.synthesis.bands.stroke_bands`); empty (shape
        ``(0, 2)``) when not computed.
    muscle_names : tuple of str
        The muscles' names (their own, else ``M1, M2, ...``): :attr:`names` reads them, tables, reprs and
        warnings use them.
    units : str or None
        The length unit of the body (a scene's ``units``: ``"mm"``...), None when not known: strokes are
        lengths in it.
    stress_unit : str or None
        The unit of the material's constants (``"Pa"`` for the silicone presets), None when dimensionless:
        with ``units`` it gives the tensions in newtons (:meth:`tensions_in_unit`).
    contact_route : str
        A design with contact and no method named (:mod:`~mdsr_opt.synthesis.contactdesign`): how it was made,
        ``"by method 'nested' without the obstacles, then checked with them: untouched ..."`` or ``"by method
        'derivative-free' with the obstacles, started from the contractions of the nested design without
        them, which touches ..."``; empty otherwise.
    fallback : str
        Why another method than the default designed it: ``""`` when the method asked for (or the default)
        did; else what failed and what designed it instead (the default flattened design that fails is
        made again by ``method="nested"``: :mod:`~mdsr_opt.synthesis.fallback`), or that the fallback was
        tried and failed too.
    """

    method: str
    contractions: np.ndarray
    x: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    difference: float
    success: bool
    status: str
    iterations: int
    n_forward: int
    inner_iterations: int
    build_time: float
    solve_time: float
    time: float
    initial_contractions: np.ndarray
    initial_difference: float
    a_max: float
    muscle_model: str = "cable"
    stiffness: float = 10.0
    verification: Verification | None = None
    history: list = field(default_factory=list)
    anchor_radius: float = float("nan")
    rest_lengths: np.ndarray = field(default_factory=lambda: np.zeros(0))
    achieved: np.ndarray = field(default_factory=lambda: np.zeros(0))
    stroke: np.ndarray = field(default_factory=lambda: np.zeros(0))
    tension: np.ndarray = field(default_factory=lambda: np.zeros(0))
    slack: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    rest_mesh: dict | None = None
    stroke_band: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    muscle_names: tuple = ()
    units: str | None = None
    stress_unit: str | None = None
    fixture_wall: float | None = None
    held: tuple | None = None
    a_upper: np.ndarray = field(default_factory=lambda: np.zeros(0))
    max_error: float = float("nan")
    relative_max_error: float = float("nan")
    max_error_node: int = -1
    fallback: str = ""
    contact_route: str = ""

    @property
    def contact(self) -> dict | None:
        """The contact report of the verified state (the verification's forward re-solve with contact: pairs
        and their normal forces, forces on nodes and obstacles); None without contact or verification. Its
        forces are in the unit of the tensions (:attr:`tension_unit`: N when the material's stress unit and
        :attr:`units` are known), named by its ``force_unit``."""
        c = None if self.verification is None else self.verification.contact
        return contact_in_unit(c, self.stress_unit, self.units)

    def __repr__(self) -> str:
        extra = {"difference": self.difference, "contractions": self.contractions}
        if self.saturated.any():
            extra["saturated"] = self.saturated_names
        extra.update(muscle_model=self.muscle_model, x=self.x, time=self.time)
        return compact_repr(self, ("method", "success"), why=self.reason, extra=extra)

    @property
    def reason(self) -> str:
        """Why the design is no success, in one phrase ("" when it is one): its :attr:`status`, and the
        verification's message when the verification failed and the status does not give it already (its
        ``repr`` shows it as ``why=...``)."""
        if self.success:
            return ""
        why = " ".join(str(self.status or "").split()) or "not a success"
        v = self.verification
        said = " ".join(str(getattr(v, "message", "") or "").split())
        if v is not None and not v.passed and said and said[:60] not in why:
            why += f"; verification: {said}"
        return why

    @property
    def bounds(self) -> np.ndarray:
        """(m,) each muscle's upper bound: :attr:`a_upper` where recorded, else ``a_max``."""
        m = len(self.contractions)
        up = np.asarray(self.a_upper, dtype=float).reshape(-1)
        return up.copy() if len(up) == m else np.full(m, float(self.a_max))

    @property
    def saturated(self) -> np.ndarray:
        """(m,) bool: the muscle's contraction is at its upper bound (within :data:`SATURATION_TOL`): ``a_max``,
        or the cap its end fixtures set (:attr:`a_upper`). Either way the design is the best within the bound."""
        a = np.asarray(self.contractions, dtype=float)
        return np.isfinite(a) & (a >= self.bounds - SATURATION_TOL)

    @property
    def capped(self) -> np.ndarray:
        """(m,) bool: the muscle is :attr:`saturated` at a cap of its end fixtures below ``a_max``."""
        return self.saturated & (self.bounds < float(self.a_max) - SATURATION_TOL)

    @property
    def names(self) -> tuple:
        """The muscles' names, as every figure, drawing and table calls them: ``muscle_names`` when it
        names every muscle, else ``M1, M2, ...`` (:func:`mdsr_opt.plot.style.muscle_name`)."""
        n = len(self.contractions)
        if len(self.muscle_names) == n:
            return tuple(str(v) for v in self.muscle_names)
        return tuple(muscle_name(i) for i in range(n))

    @property
    def saturated_names(self) -> list:
        """The names (:attr:`names`) of the saturated muscles."""
        names = self.names
        return [names[i] for i in np.flatnonzero(self.saturated)]

    @property
    def commanded(self) -> np.ndarray:
        """The designed (commanded) contractions, the same as ``contractions``."""
        return self.contractions

    def muscle_table(self) -> str:
        """One line per muscle: commanded and achieved contraction, stroke (with its band when computed),
        tension, slack, saturated; strokes in :attr:`units` (else body units), tensions in N when the
        material's stress unit and the length unit are known, else in units of ``E*t*length``
        (:func:`~mdsr_opt.core.quantities.tension_unit`)."""
        band = np.asarray(self.stroke_band, dtype=float).reshape(-1, 2)
        has_band = len(band) == len(self.contractions) and len(band) > 0
        names = self.names
        w = max([6] + [len(v) for v in names])
        lu = length_unit(self.units)
        tu, factor = tension_unit(self.stress_unit, self.units)
        sh, th = f"stroke ({lu})", f"tension ({tu})"
        ws, wt = max(10, len(sh)), max(10, len(th))
        lines = [f"{'muscle':>{w}} {'commanded':>10} {'achieved':>9} {sh:>{ws}} "
                 + (f"{'stroke band':>21} " if has_band else "") + f"{th:>{wt}} slack saturated"]
        sat = self.saturated
        for i in range(len(self.contractions)):
            def at(v, k=i):
                return float(v[k]) if len(v) > k else float("nan")
            sl = bool(self.slack[i]) if len(self.slack) > i else False
            # a saturated muscle's band of zero width is its bound (a_max or the fixtures' cap), not a certainty
            point = has_band and point_band(band[i, 0], band[i, 1], sat[i])
            b = "" if not has_band else f"{f'{band[i, 0]:.4g} (its bound)':>21} " if point else \
                f"{f'{band[i, 0]:.4g} .. {band[i, 1]:.4g}':>21} "
            lines.append(f"{names[i]:>{w}} {at(self.contractions):>10.4f} {at(self.achieved):>9.4f} "
                         f"{at(self.stroke):>{ws}.4g} {b}{factor * at(self.tension):>{wt}.4g} "
                         f"{'yes' if sl else 'no':>5} {'YES' if sat[i] else 'no':>9}")
        return "\n".join(lines)

    @property
    def tension_unit(self) -> str:
        """The unit :meth:`tensions_in_unit` gives: ``"N"`` when the material's stress unit and the length
        unit are known, else ``"units of E*t*<length>"``."""
        return tension_unit(self.stress_unit, self.units)[0]

    def tensions_in_unit(self) -> np.ndarray:
        """The tensions in :attr:`tension_unit` (``tension`` is in the material's and the body's units,
        ``E * t * length``)."""
        return tension_unit(self.stress_unit, self.units)[1] * np.asarray(self.tension, dtype=float)

    def table(self) -> str:
        """The stroke table: :meth:`muscle_table`."""
        return self.muscle_table()

    @property
    def x_aligned(self) -> np.ndarray:
        """The driven state moved onto the target: ``x @ rotation.T + translation``."""
        return self.x @ self.rotation.T + self.translation

    @property
    def angle(self) -> float:
        """Rotation angle (radians) of the motion onto the target."""
        return float(math.atan2(self.rotation[1, 0], self.rotation[0, 0]))

    def count_in(self, others, clock0: float, build_time: bool = False) -> None:
        """Count the work of the designs ``others``, made on the way to this one (a first attempt, a design
        by another method), in this one's counters: iterations, forward solves, inner iterations, and with
        ``build_time`` their build times; its clock then runs from ``clock0`` (a ``time.perf_counter()``
        reading)."""
        for o in others:
            self.iterations += o.iterations
            self.n_forward += o.n_forward
            self.inner_iterations += o.inner_iterations
            if build_time:
                self.build_time += o.build_time
        self.time = time.perf_counter() - clock0
        self.solve_time = self.time - self.build_time

    def summary(self) -> dict:
        """Scalars of the result (no arrays except the per-muscle lists), for tables and logs: strokes and
        tensions in the units ``units`` names (tensions in N when the material and length units are known)."""
        v = self.verification
        return {"method": self.method, "success": self.success, "status": self.status,
                "muscle_model": self.muscle_model, "muscles": list(self.names),
                "units": {"stroke": length_unit(self.units), "tension": self.tension_unit},
                "contractions": [float(c) for c in self.contractions],
                "achieved": [float(c) for c in self.achieved], "stroke": [float(c) for c in self.stroke],
                "tension": [float(c) for c in self.tensions_in_unit()], "slack": [bool(s) for s in self.slack],
                "saturated": [bool(s) for s in self.saturated],
                "stroke_band": [[float(lo), float(hi)] for lo, hi in np.asarray(self.stroke_band).reshape(-1, 2)],
                "anchor_radius": self.anchor_radius, "difference": self.difference,
                "max_error": self.max_error, "relative_max_error": self.relative_max_error,
                "initial_difference": self.initial_difference, "iterations": self.iterations,
                "n_forward": self.n_forward, "inner_iterations": self.inner_iterations,
                "build_time": self.build_time, "solve_time": self.solve_time, "time": self.time,
                "verified": None if v is None else v.passed, "gap": None if v is None else v.gap,
                "min_eigenvalue": None if v is None or not np.isfinite(v.min_eigenvalue) else v.min_eigenvalue,
                **self.contact_summary()}

    def contact_summary(self) -> dict:
        """With contact: the total contact force and each obstacle's, in :attr:`tension_unit`."""
        c = self.contact
        if c is None:
            return {}
        return {"contact": {"force_unit": c["force_unit"], "total_force": c.get("total_force"),
                            "obstacle_forces": c.get("obstacle_forces", []), "n_pairs": len(c.get("pairs", []))}}

    def to_dict(self) -> dict:
        """A JSON-ready dict (arrays as nested lists); :meth:`from_dict` inverts it."""
        d = {}
        for k, v in self.__dict__.items():
            if isinstance(v, np.ndarray):
                d[k] = v.tolist()
            elif isinstance(v, Verification):
                d[k] = asdict(v)
            elif k == "history":
                d[k] = [[float(a), float(b)] for a, b in v]
            else:
                d[k] = v
        return finite_or_none(d)

    @classmethod
    def from_dict(cls, d: dict) -> "DesignResult":
        nan_keys = ("difference", "initial_difference", "anchor_radius", "max_error", "relative_max_error")
        d = {k: (float("nan") if v is None and k in nan_keys else v) for k, v in d.items()}
        for k in ("contractions", "x", "rotation", "translation", "initial_contractions"):
            d[k] = np.asarray(d[k], dtype=float)
        for k in ("rest_lengths", "achieved", "stroke", "tension", "a_upper"):
            if k in d:
                d[k] = np.asarray([np.nan if v is None else v for v in d[k]], dtype=float)
        if "slack" in d:
            d["slack"] = np.asarray(d["slack"], dtype=bool)
        if "stroke_band" in d:
            d["stroke_band"] = np.asarray([[np.nan if v is None else v for v in row] for row in d["stroke_band"]],
                                          dtype=float).reshape(-1, 2)
        if d.get("verification") is not None:
            v = dict(d["verification"])
            if v.get("min_eigenvalue") is None:  # not estimated (NaN, written as null)
                v["min_eigenvalue"] = np.nan
            d["verification"] = Verification(**v)
        d["history"] = [tuple(h) for h in d.get("history", [])]
        d["muscle_names"] = tuple(d.get("muscle_names", ()))
        if d.get("held") is not None:
            d["held"] = tuple(int(i) for i in d["held"])
        return cls(**d)

    def save(self, path: str | os.PathLike) -> str:
        """Write the result as one ``.npz`` file (arrays exactly, the rest as JSON metadata), atomically:
        ``path`` ends in ``.npz`` (a folder name is refused, naming a file in it to use; a
        :class:`~mdsr_opt.synthesis.pipeline.PipelineResult`, which holds meshes too, is saved into a folder).

        Returns the path; :meth:`load` reads it back equal to this result (:meth:`to_dict` is the JSON
        view). An existing file of that name is replaced, without a warning (``mdsr run`` refuses to without
        ``--overwrite``)."""
        return save_fields(self, path, "design")

    @classmethod
    def load(cls, path: str | os.PathLike) -> "DesignResult":
        """Read a result written by :meth:`save`.

        Raises
        ------
        FileNotFoundError
            No such file.
        ValueError
            The file (named) is damaged, not a ``.npz`` or holds another kind of result.
        """
        return load_fields(cls, path, "design",
                           convert={"verification": lambda v: Verification(**v),
                                    "history": lambda h: [tuple(p) for p in h], "muscle_names": tuple,
                                    "held": lambda h: tuple(int(i) for i in h)})


def finite_or_none(o):
    """Replace NaN/inf floats by None (JSON has no NaN), recursively."""
    if isinstance(o, dict):
        return {k: finite_or_none(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [finite_or_none(v) for v in o]
    if isinstance(o, (float, np.floating)):
        return float(o) if math.isfinite(o) else None
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.bool_):
        return bool(o)
    return o


def report_muscles(prob: DesignProblem, res: DesignResult, xflat, kappa) -> None:
    """Fill the per-muscle fields of ``res``: achieved contraction, stroke, tension, slack."""
    x2 = np.asarray(xflat, dtype=float).reshape(-1, 2)
    if not np.all(np.isfinite(x2)):
        return
    res.achieved = prob.achieved(x2)
    res.stroke = res.achieved * prob.L0
    try:
        if kappa is not None and prob.muscle_model == "cable":  # the NLP's own multipliers
            res.tension = prob.block.tension(kappa)
        else:
            res.tension = prob.tensions(res.contractions, x2.reshape(-1))
    except (RuntimeError, ValueError):  # pragma: no cover - singular least squares
        res.tension = np.full(prob.m, np.nan)
    tiny = 1e-7 * prob.Et * prob.h
    res.slack = res.tension <= tiny
