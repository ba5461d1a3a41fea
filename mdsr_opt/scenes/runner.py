"""One case through the pipeline (target, routing, design, verification, photograph) and its files."""

from __future__ import annotations

import functools
import logging
import os
from dataclasses import dataclass, field
from pathlib import Path
import time
from typing import Any, Callable, Sequence
import warnings
import numpy as np

from ..core.errors import LayoutError
from ..core.quantities import band_text, length_unit
from ..core.results import compact_repr, to_jsonable
from ..mechanics.anchors import body_size
from ..plot.style import muscle_label, unit_label
from ..synthesis.fabrication import FabricationWarning
from ..synthesis.results import MuscleWarning
from ..body.muscles import Muscle
from .casefab import fixture_wall
from .cases import CaseSetup, prepare_case
from .grips import BANDS_NOTE, PROTOTYPE_NOTE, case_grips, design_route, grip_line, obstacle_design
from .names import number_in_scene
from .obstacles import case_contact
from .verdict import plain_failure, prototype_verdict, saturation_line
from .rundir import check_interrupt
from .scene import Case, Scene

__all__ = ['CaseReport', 'CaseRun', 'run_case', 'measure_case', 'write_case', 'case_parts', 'case_files']

_LOG = logging.getLogger(__name__)


# ---------------------------------------------------------------------------------------------- the pipeline
@dataclass
class CaseReport:
    """Key figures of one case run through the pipeline (JSON-ready scalars and short lists).

    Attributes
    ----------
    scene, case, kind : names and ``"external"``/``"internal"``.
    n_nodes, n_muscles : mesh size and number of muscles designed.
    muscles : per muscle designed, its ``name`` and node chain ``nodes`` (the layout, so two cases on one
        layout show it): the muscles the per-muscle lists below give values for, in their order.
    success : the target solve, the routing (at least one muscle) and the design all succeeded.
    message : why not, when ``success`` is False.
    target_success, target_status : the solve that made the target.
    contractions : designed (commanded) contractions; known_contractions : internal cases' true ones.
    achieved, stroke : per muscle, the contraction reached along its node chain in the driven state
        (``1 - L/L0``) and the rope length pulled in (``achieved * L0``, length units).
    contraction_error : internal cases: largest ``|designed - known|``.
    difference : the design's difference to the target (a length, weighted RMS after rigid alignment);
        relative_difference : over the body's size, its rest diameter (:func:`~mdsr_opt.mechanics.anchors.body_size`).
        The ok/FAILED verdict judges this RMS figure.
    max_error, relative_max_error : the largest node distance to the target after the same alignment (a length,
        and over the body's size): reported beside the RMS, which can pass a pose missed at an extremity.
    initial_difference : difference at the design's starting point.
    rest_difference : the rest shape's difference to the target (the "do nothing" design; a case whose
        design removes less than a tenth of it fails: :func:`~mdsr_opt.synthesis.acceptance.difference_failure`).
    design_success, design_status, verified, gap : the design, its verification and the forward check's
        largest node distance between the design's state and a fresh forward solve at its contractions.
    routing : ``n_units`` and per-muscle ``contraction`` / ``n_edges``; internal cases also ``recovered``,
        the fraction of the true muscles' edges that routing on the target covers.
    photo : contour metrics of the SYNTHETIC photograph of the driven body: ``target`` compares the target's
        outline and holes with it (:func:`~mdsr_opt.photos.loops.compare_loops`), ``self`` the driven state's
        (the measuring chain's floor); each with ``mean_px``, ``std_px``, ``max_px``, ``ratio`` over every
        loop, ``outer_mean_px`` and ``mean_norm`` of the outline alone, and ``n_unmatched`` holes. These photograph the design model itself (a mirror). ``prototype``
        (when a virtual prototype was given) holds the validation against a DIFFERENT, finer model
        (:func:`~mdsr_opt.scenes.prototype.validate_case`): ``driving`` (Table 2/3) and ``design`` (Table 4), holes
        included.
    times : seconds per stage; files : files written (relative to the scene's folder).
    dropped : muscles taken out of the layout after a design (idle ones: name, nodes, contraction, reason).
    idle_kept : names of idle muscles the design kept because the design without them failed.
    saturated : names (``M1``, ... or their own) of the muscles whose designed contraction is at ``a_max``.
    stroke_band : per muscle the stroke's (low, high) under the fabrication's uncertainties, when computed
        (:func:`~mdsr_opt.synthesis.bands.stroke_bands`); band_notes : what the band left out, and why.
    tension : per muscle the rope's tension at the design, in ``units["tension"]``.
    units : ``{"stroke": ..., "tension": ...}``: the unit of the strokes (the scene's ``units``) and of the
        tensions (``"N"`` for a material with a ``stress_unit``, a silicone preset; else units of
        ``E*t*length``: :func:`~mdsr_opt.core.quantities.tension_unit`).
    contact : with contact: total and per-obstacle contact force, in ``force_unit`` (the tensions'), pairs.
    grip : per disk among the case's obstacles, whether the design's grip holds it at the stated friction,
        the contact forces and the load it resists (:func:`~mdsr_opt.scenes.grips.case_grips`); None without.
    fabrication : the FabricationWarning of muscles the scene gives that cannot be moulded as laid out (a
        channel on the outline, ropes too close; :func:`~mdsr_opt.scenes.cases.given_muscle_conflicts`).
    notes : what the pipeline resolved on its own, each a sentence headed by its stage (``routing: fixtures
        shrunk from radius ...``, ``design: M3 dropped (idle ...)``): the routing's resolutions when the case's
        muscles were routed, the idle muscles dropped. ``summary.md`` lists them under its table.
    """

    scene: str
    case: str
    kind: str
    n_nodes: int
    n_muscles: int = 0
    muscles: list = field(default_factory=list)
    success: bool = False
    message: str = ""
    target_success: bool = False
    target_status: str = ""
    contractions: list = field(default_factory=list)
    achieved: list = field(default_factory=list)
    stroke: list = field(default_factory=list)
    known_contractions: list | None = None
    contraction_error: float | None = None
    difference: float | None = None
    relative_difference: float | None = None
    max_error: float | None = None
    relative_max_error: float | None = None
    initial_difference: float | None = None
    rest_difference: float | None = None
    design_success: bool | None = None
    design_status: str = ""
    verified: bool | None = None
    gap: float | None = None
    routing: dict | None = None
    photo: dict | None = None
    times: dict = field(default_factory=dict)
    files: list = field(default_factory=list)
    dropped: list = field(default_factory=list)
    idle_kept: list = field(default_factory=list)
    saturated: list = field(default_factory=list)
    stroke_band: list = field(default_factory=list)
    tension: list = field(default_factory=list)
    units: dict = field(default_factory=dict)
    band_notes: list = field(default_factory=list)
    fabrication: list = field(default_factory=list)
    contact: dict | None = None
    grip: list | None = None
    notes: list = field(default_factory=list)

    def __repr__(self) -> str:
        return compact_repr(self, ("scene", "case", "kind", "success"), why="" if self.success else self.message,
                            extra={k: getattr(self, k) for k in ("n_nodes", "n_muscles", "difference", "contractions")
                                   + (("message",) if self.success else ())})

    def to_dict(self) -> dict:
        """Every field, JSON-ready (NaN as None)."""
        return {f: to_jsonable(getattr(self, f)) for f in self.__dataclass_fields__}


@dataclass
class CaseRun:
    """A case's report with the arrays behind it (the setup, the design, the photograph).

    :func:`write_case` writes its files; :meth:`CaseSetup.save` and :meth:`DesignResult.save` save the
    states it holds.
    """

    report: CaseReport
    setup: CaseSetup | None = None
    design: Any = None
    photo: Any = None
    comparison: Any = None
    prototype_photos: dict = field(default_factory=dict)

    def __repr__(self) -> str:
        r = self.report
        return compact_repr(self, (), why="" if r.success else r.message,
                            extra={"scene": r.scene, "case": r.case, "success": r.success,
                                   "design": self.design is not None, "photo": self.photo is not None,
                                   "difference": r.difference})

    def to_dict(self) -> dict:
        """JSON-ready: the report, the setup's and the design's dicts, the photograph's metadata and the
        comparison's figures (None for what the run did not make)."""
        def d(obj):
            return None if obj is None else obj.to_dict()

        return to_jsonable({"report": self.report.to_dict(), "setup": d(self.setup), "design": d(self.design),
                            "photo": d(self.photo), "comparison": d(self.comparison),
                            "prototype_photos": {k: d(v) for k, v in self.prototype_photos.items()}})


def finite(v):
    from ..synthesis.results import finite_or_none

    return finite_or_none(v)


def _edge_set(muscles) -> set:
    return {(min(a, b), max(a, b)) for m in muscles for a, b in m.segments.tolist()}


def run_case(scene: Scene, case: Case | str, *, method: str | None = None, photo: bool = True,
             photo_size: tuple[int, int] = (500, 500), log: Callable[[str], None] | None = None,
             prefix: str = "", prototype: Any = None, max_difference: float | None = None,
             bands: bool | None = None, taken: Sequence[Muscle] = ()) -> CaseRun:
    """Run one case through the pipeline (nothing is written).

    Target (external or internal driving) -> contraction graph and muscles (:func:`prepare_case`) ->
    contractions (:func:`~mdsr_opt.synthesis.contractions.design_contractions` with the scene's ``design_options``, its
    verification being the forward check) -> SYNTHETIC photograph of the driven body and contour metrics
    (:mod:`mdsr_opt.photos`).

    With ``prototype`` (a :class:`~mdsr_opt.scenes.prototype.VirtualPrototype` of the scene) and ``photo``, the
    case is also validated against the virtual prototype (:func:`~mdsr_opt.scenes.prototype.validate_case`): the
    paper's Table 2 or 3 (the case's own driving) and Table 4 (the design) in ``report.photo["prototype"]``.

    What counts as a success is the scene's ``acceptance`` (:func:`~mdsr_opt.scenes.scene.check_acceptance`):
    the design's difference within ``max_difference`` of the body's diameter (this keyword overrides the scene's), no
    idle muscle (an external case's muscles designed below ``idle_contraction`` are dropped and the design
    made again, :func:`~mdsr_opt.synthesis.acceptance.design_active`; an internal case keeps the scene's
    layout, whose known contractions are the answer); a saturated muscle is reported in ``saturated``.
    With ``bands`` (default: the scene's ``acceptance["bands"]``) every stroke gets its uncertainty band
    (:func:`~mdsr_opt.synthesis.bands.stroke_bands`). ``taken``: the muscles earlier cases of the same run
    were designed with or dropped as idle; routed muscles are named as the scene's (:func:`~mdsr_opt.scenes.names.number_in_scene`:
    one rope, one name and colour in every case's figures, the gait and the animations).

    A failure at any stage is reported, not raised: ``report.success`` is False and ``report.message``
    says where and why; a stage that refuses the case's own data (a routed layout whose end patches
    join, say) is such a failure. Bad arguments (``TypeError``/``ValueError`` from the checks at the door)
    still raise.
    """
    from ..synthesis.acceptance import (check_max_difference, design_active, difference_failure, idle_mask,
                                        rest_difference)
    from ..synthesis.routing_why import no_muscle_message

    say = log or (lambda s: None)
    if isinstance(case, str):
        case = scene.case(case)
    accept = dict(scene.acceptance)
    if max_difference is not None:
        accept["max_difference"] = check_max_difference(max_difference)
    if bands is not None:
        accept["bands"] = bool(bands)
    mesh = scene.mesh
    rep = CaseReport(scene=scene.name, case=case.name, kind=case.kind, n_nodes=mesh.n_nodes)
    run = CaseRun(report=rep)
    t0 = time.perf_counter()
    what = ("external driving" if case.kind == "external" else
            f"internal driving at {', '.join(f'{a:.0%}' for a in case.contractions)}")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FabricationWarning)  # reported in the case's ``fabrication`` and log
            setup = prepare_case(scene, case)
    except LayoutError as exc:  # the scene's muscles cannot make this case's target (their end patches)
        rep.message = f"target refused: {exc}"
        rep.times["total"] = time.perf_counter() - t0
        say(f"{prefix}FAILED: {rep.message}")
        return run
    check_interrupt()  # Ctrl-C swallowed inside a solve stops here, never reported as a failed case
    if taken and setup.routing is not None and case.kind == "external" and scene.muscles is None \
            and case.muscles is None:  # routed for this case: numbered on from the earlier cases'
        setup.muscles = number_in_scene(setup.muscles, taken)
    run.setup = setup
    tr = setup.target_result
    rep.target_success, rep.target_status = bool(tr.success), str(tr.status)
    rep.times.update(setup.times)
    say(f"{prefix}target by {what}: {tr.status} ({tr.iterations} iterations, {len(tr.steps)} load step(s), "
        f"{setup.times['target']:.2f} s)")
    if setup.routing is not None:
        rr = setup.routing
        rep.routing = {"n_units": rr.n_units,
                       "muscles": [{"n_edges": s.n_edges, "contraction": s.contraction,
                                    "nonuniformity": s.nonuniformity} for s in rr.stats],
                       # what made the ropes buildable (ends moved inward, ropes dropped, fixtures shrunk)
                       "fixture_radius": rr.fixture_radius, "notes": list(rr.notes)}
        if case.kind == "internal":
            # the muscle edges that contract in the target: an edge inside a muscle's rigid end patch keeps
            # its length, so no routing can see it (it is counted apart as hidden)
            true = _edge_set(scene.case_muscles(case))
            X0, Y = scene.mesh.points, np.asarray(setup.target)
            seen = {e for e in true
                    if np.linalg.norm(Y[e[1]] - Y[e[0]]) < (1 - 1e-3) * np.linalg.norm(X0[e[1]] - X0[e[0]])}
            rep.routing["recovered"] = len(seen & _edge_set(rr.muscles)) / max(len(seen), 1)
            rep.routing["hidden_edges"] = len(true - seen)
    if not tr.success:
        rep.message = f"target solve failed: {plain_failure(tr.status)}"
        rep.times["total"] = time.perf_counter() - t0
        say(f"{prefix}FAILED: {rep.message}")
        return run
    if not setup.muscles:
        rep.message = no_muscle_message(setup.warnings) if setup.routing_error is None else \
            f"routing failed: {setup.routing_error}"  # a body too thin for the ropes' inset, a mesh too coarse
        rep.times["total"] = time.perf_counter() - t0
        say(f"{prefix}FAILED: {rep.message}")
        return run
    if setup.routing_error is not None:  # the routing was only a diagnostic here (the case's muscles are given)
        rep.notes.append(f"routing (a diagnostic beside the given muscles) not made: {setup.routing_error}")
        say(f"{prefix}routing (a diagnostic beside the given muscles) not made: {setup.routing_error}")
    rep.n_muscles = len(setup.muscles)
    # every muscle by its label, an unnamed one by its place (M1, M2 ...), as every table, figure and file
    rep.muscles = [{"name": muscle_label(m, i), "nodes": list(map(int, m.nodes))} for i, m in enumerate(setup.muscles)]
    if setup.routing is not None and case.kind == "external" and scene.muscles is None and case.muscles is None:
        units = f" from {setup.routing.n_units} unit(s)" if setup.routing.n_units else ""
        say(f"{prefix}routing: {rep.n_muscles} muscle(s){units} ({setup.times['routing']:.2f} s)")
        for note in setup.routing.notes:  # what made the ropes buildable, each resolution once
            say(f"{prefix}routing: {note}")
        rep.notes = [f"routing: {note}" for note in setup.routing.notes]
    elif case.muscles is not None or (case.kind == "external" and scene.muscles is not None):
        names = ", ".join(muscle_label(m, i) for i, m in enumerate(setup.muscles))
        whose, why = ("case's own", "") if case.muscles is not None else ("scene's", " (a scene's [[muscles]] drive "
            "every case without muscles of its own; in a scene without them an external case's are routed)")
        say(f"{prefix}not routed: the {whose} {rep.n_muscles} muscle(s) ({names}) are designed for this target{why}")
    rep.fabrication = list(getattr(setup, "fabrication", []))
    for msg in rep.fabrication:
        say(f"{prefix}FabricationWarning: {msg}")
    # the muscles' end fixtures (cases.case_anchor_radius): routed ropes' fitted size, a case's own, the scene's;
    # the wall a rope's two fixtures keep between them: the fabrication's (casefab.fixture_wall)
    opts = {**scene.design_options, "anchor_radius": setup.anchor_radius, "fixture_wall": fixture_wall(scene)}
    if method is not None:
        opts["method"] = method
    opts, said = obstacle_design(scene, case, opts, setup.obstacles)  # a case with obstacles: designed with them, said how
    rep.notes += said
    for note in said:
        say(prefix + note)
    t1 = time.perf_counter()
    idle = accept["idle_contraction"] if case.kind == "external" else 0.0
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", MuscleWarning)  # reported in the case's ``saturated``
            res, kept, dropped = design_active(mesh, scene.material, setup.muscles, setup.target,
                                               idle_contraction=idle, **opts)
        check_interrupt()
    except (RuntimeError, LayoutError) as exc:
        # a solver inside the design failed hard (SolverFailure, CasADi errors), or the design refused the
        # case's layout (end patches joined through other muscles', say): this case fails, the others go on
        what = "failed" if isinstance(exc, RuntimeError) else "refused"
        rep.message = f"design {what}: {type(exc).__name__}: {exc}"
        rep.times["total"] = time.perf_counter() - t0
        say(f"{prefix}FAILED: {rep.message}")
        return run
    run.design = res
    res.units = scene.units
    for note in design_route(scene, case, res):  # how a case with obstacles was designed: checked, or searched
        rep.notes.append(note)
        say(prefix + note)
    if res.fallback:  # the default flattened design failed: which method designed it (or was tried), and why
        rep.notes.append(f"design: {res.fallback}")
        say(f"{prefix}design: {res.fallback}")
    if dropped:
        if setup.routing is not None and rep.routing is not None and tuple(m.nodes for m in setup.muscles) == tuple(
                m.nodes for m in setup.routing.muscles):  # the routing names the muscles the case keeps
            setup.routing = setup.routing.keeping(kept, dropped)
            rep.routing["muscles"] = [{"n_edges": s.n_edges, "contraction": s.contraction,
                                       "nonuniformity": s.nonuniformity} for s in setup.routing.stats]
        setup.muscles = kept
        rep.n_muscles = len(kept)  # the names line up with the values below; dropped ones are in ``dropped``
        rep.muscles = [{"name": muscle_label(m, i), "nodes": list(map(int, m.nodes))} for i, m in enumerate(kept)]
        rep.dropped = [d.to_dict() for d in dropped]
        rep.notes += [f"design: {d.name} dropped ({d.reason})" for d in dropped]
        say(f"{prefix}dropped " + "; ".join(f"{d.name} ({d.reason})" for d in dropped))
    rep.saturated = res.saturated_names
    still = idle_mask(res, idle) if idle > 0 and res.success else np.zeros(0, dtype=bool)
    if still.any():  # idle muscles the design kept (the design without them failed): said, as dropped ones are
        rep.idle_kept = [muscle_label(m, i) for i, m in enumerate(kept) if still[i]]
        rep.notes.append(f"design: idle {', '.join(rep.idle_kept)} kept (a contraction below idle_contraction "
                         f"{idle:g} or a slack rope): the design without them failed; a build may leave them out")
        say(f"{prefix}idle {', '.join(rep.idle_kept)} kept: the design without them failed")
    rep.times["design"] = time.perf_counter() - t1
    rep.contractions = [float(a) for a in res.contractions]
    rep.achieved = [float(a) for a in res.achieved]
    rep.stroke = [float(s) for s in res.stroke]
    rep.tension = [float(t) for t in res.tensions_in_unit()]
    rep.units = {"stroke": length_unit(res.units), "tension": res.tension_unit}
    rep.contact = res.contact_summary().get("contact")  # forces in the tensions' unit
    rep.difference = float(res.difference)
    rep.relative_difference = float(res.difference) / body_size(mesh)  # the same however the body is turned
    rep.max_error, rep.relative_max_error = float(res.max_error), float(res.relative_max_error)
    rep.initial_difference = float(res.initial_difference)
    rep.design_success, rep.design_status = bool(res.success), str(res.status)
    if res.verification is not None:
        rep.verified, rep.gap = bool(res.verification.passed), float(res.verification.gap)
    if setup.known_contractions is not None:
        rep.known_contractions = [float(a) for a in setup.known_contractions]
        rep.contraction_error = float(np.abs(res.contractions - setup.known_contractions).max())
    a = ", ".join(f"{v:.3f}" for v in res.contractions)
    ach = ", ".join(f"{v:.3f}" for v in res.achieved)
    st = ", ".join(f"{v:.4g}" for v in res.stroke)
    u = unit_label(scene.units)
    tn = ", ".join(f"{v:.4g}" for v in res.tensions_in_unit())
    verdict = "verified" if res.success else "FAILED: " + plain_failure(res.status)
    say(f"{prefix}design ({res.method}, {res.muscle_model}): commanded a = [{a}], achieved [{ach}], "
        f"strokes [{st}] {u}, tensions [{tn}] {res.tension_unit}, difference {res.difference:.3g} {u} "
        f"({100 * rep.relative_difference:.2f} % of size; largest node error {res.max_error:.3g} {u}, "
        f"{100 * res.relative_max_error:.2f} %), {verdict} ({rep.times['design']:.1f} s)")
    if rep.saturated:
        say(prefix + saturation_line(res))
    rep.grip = case_grips(scene, case, res.x, res.contact, "design", setup.obstacles, setup.free_disk) or None
    for g in rep.grip or ():
        rep.notes.append(grip_line(g))
        say(prefix + grip_line(g))
    touching = bool(case_contact(scene, case))  # obstacles: stages that model none say so
    if accept["bands"] and res.success:
        if touching:
            rep.band_notes = [BANDS_NOTE]
            say(f"{prefix}stroke bands: {BANDS_NOTE}")
        else:
            _bands(scene, run, opts, say, prefix)
    if prototype is not None and touching:
        prototype = None
        rep.notes.append(PROTOTYPE_NOTE)
        say(prefix + PROTOTYPE_NOTE)
    if photo:
        measure_case(scene, run, photo_size=photo_size, prototype=prototype, log=say, prefix=prefix)
        check_interrupt()
    rep.rest_difference = rest_difference(mesh, setup.target, opts)  # the design's own weights
    far = difference_failure(res.difference, body_size(mesh), accept["max_difference"], units=scene.units,
                             rest_difference=rep.rest_difference,
                             n_anchors=len(case.anchors) if case.kind == "external" else None)
    rep.success = bool(res.success) and not far
    if not res.success:
        rep.message = f"design {'rejected' if 'verification' in res.status else 'failed'}: {plain_failure(res.status)}"
        _LOG.debug("%sdesign status: %s", prefix, res.status)
    elif far:
        rep.message = f"design too far from the target: {far}"
        say(f"{prefix}FAILED: {rep.message}")
    elif prototype_verdict(rep):  # a design the virtual prototype cannot reproduce is no success
        say(f"{prefix}FAILED: {rep.message}")
    rep.times["total"] = time.perf_counter() - t0
    _LOG.debug("%sstage times: %s", prefix, ", ".join(f"{k} {v:.3f} s" for k, v in rep.times.items()))
    return run


def _bands(scene: Scene, run: CaseRun, opts: dict, say, prefix: str) -> None:
    """The strokes' uncertainty bands of a run's design, into its design and report."""
    from ..synthesis.bands import stroke_bands

    rep, res = run.report, run.design
    t = time.perf_counter()
    try:
        b = stroke_bands(scene.mesh, scene.material, run.setup.muscles, run.setup.target, res,
                         **{k: v for k, v in opts.items() if k != "initial_guess"})
    except (RuntimeError, LayoutError) as exc:  # reported, never hiding the design
        rep.band_notes = [f"no band: {type(exc).__name__}: {exc}"]
        say(f"{prefix}stroke bands: not computed ({exc})")
    else:
        res.stroke_band = b.band.copy()
        rep.stroke_band = [[float(lo), float(hi)] for lo, hi in b.band]
        rep.band_notes = list(b.notes)
        say(f"{prefix}stroke bands: " + ", ".join(f"{s:.4g} {band_text(lo, hi, at)}" for s, (lo, hi), at
                                                  in zip(b.nominal, b.band, res.saturated))
            + "".join(f"; {n}" for n in b.notes))
    rep.times["bands"] = time.perf_counter() - t


def measure_case(scene: Scene, run: CaseRun, *, photo_size: tuple[int, int] = (500, 500), prototype: Any = None,
                 log: Callable[[str], None] | None = None, prefix: str = "") -> None:
    """:func:`run_case`'s photograph stage, on a run whose design is done: a SYNTHETIC photograph of the
    driven body, its contour metrics against the target and the driven body, and with ``prototype`` the
    virtual prototype's validation. Fills ``run.report.photo`` and ``run.report.times["photo"]``,
    ``run.photo``, ``run.comparison`` and ``run.prototype_photos``.
    """
    from ..photos.camera import render_photo
    from ..photos.contours import contour_loops_from_image
    from ..photos.loops import compare_loops, simulated_loops

    say = log or (lambda s: None)
    rep, setup, res, mesh = run.report, run.setup, run.design, scene.mesh
    if res is None:
        raise ValueError(f"case {rep.case!r} has no design to photograph")
    t2 = time.perf_counter()
    try:
        ph = render_photo(mesh, res.x_aligned, image_size=photo_size, seed=0)
        loops = contour_loops_from_image(ph.image)
        # every boundary loop is measured: the outline and each hole against its photographed counterpart
        cmp_t = compare_loops(simulated_loops(mesh, setup.target), loops)
        cmp_s = compare_loops(simulated_loops(mesh, res.x_aligned), loops)
    except ValueError as exc:  # e.g. a body too thin to segment at this resolution
        rep.photo = {"error": str(exc)}
        say(f"{prefix}photograph: could not measure ({exc})")
    else:
        def figures(c):
            return {"mean_px": c.mean_px, "std_px": c.std_px, "max_px": c.max_px, "ratio": c.ratio,
                    "mean_norm": c.outer.mean_norm, "outer_mean_px": c.outer.mean_px,
                    "n_unmatched": c.n_unmatched}

        rep.photo = {"synthetic": True, "image_size": list(photo_size),
                     "target": figures(cmp_t), "self": figures(cmp_s)}
        run.photo, run.comparison = ph, cmp_t.outer
        # "d over every loop" (outline and holes, the table's figure) and "outline d" (the outline alone, the
        # overlay's figure) are two numbers: each said by its name
        say(f"{prefix}SYNTHETIC photograph: target d over every loop = {cmp_t.mean_px:.2f} px "
            f"(sd {cmp_t.std_px:.2f}, ratio {100 * cmp_t.ratio:.2f} %), outline d = {cmp_t.outer.mean_px:.2f} px; "
            f"measuring floor {cmp_s.mean_px:.2f} px over every loop")
    if prototype is not None:
        measure_prototype(run, prototype, log=say, prefix=prefix)
    rep.times["photo"] = time.perf_counter() - t2


def measure_prototype(run: CaseRun, prototype: Any, *, log: Callable[[str], None] | None = None,
                      prefix: str = "", driving: bool = True, design: bool = True) -> float:
    """The virtual prototype's part of :func:`measure_case`, on a run whose design is done: its validation of
    the case's driving and design, or of one of them (``driving``, ``design``), added to
    ``run.report.photo["prototype"]`` (``run.prototype_photos``: the photographs of this call). Returns the
    seconds it took."""
    from .prototype import validate_case

    rep = run.report
    if run.design is None:
        raise ValueError(f"case {rep.case!r} has no design to photograph")
    t = time.perf_counter()
    metrics, shots = validate_case(prototype, run.setup, run.design if design else None, log, prefix, driving)
    rep.photo = dict(rep.photo or {}, prototype={**((rep.photo or {}).get("prototype") or {}), **metrics})
    run.prototype_photos = shots
    return time.perf_counter() - t


def write_case(scene: Scene, run: CaseRun, out: str | os.PathLike, mesh_format: str = "vtu") -> list[str]:
    """Write a case's figures, meshes and photograph into the folder ``out`` (created); returns the file
    names.

    Files: ``target.png`` (target with anchors and drags), ``graph.png`` (contraction graph),
    ``muscles.png`` (muscles over rest and target), ``design.png`` (driven state over the target),
    ``photo.png``/``photo.json`` (the SYNTHETIC photograph) and ``overlay.png`` (contour metrics), and the
    meshes ``target.<fmt>`` and ``driven.<fmt>`` (states as displacements). Every file is written
    atomically; what a failed stage did not produce is not written. The work is that of
    :func:`case_parts`, one part after the other.
    """
    folder = Path(out)
    return case_files([part() for part in case_parts(scene, run, folder, mesh_format)], folder)


def case_files(parts: Sequence[Sequence[str]], out: str | os.PathLike) -> list[str]:
    """The file names :func:`write_case` returns, from the paths its :func:`case_parts` wrote (in order)."""
    parent = Path(out).parent
    return [os.path.relpath(f, parent) for part in parts for f in part]


def case_parts(scene: Scene, run: CaseRun, out: str | os.PathLike, mesh_format: str = "vtu", vector=None) -> list:
    """:func:`write_case`'s work as three independent parts: functions without arguments, each writing some
    of the case's files into ``out`` and returning their paths (in :func:`write_case`'s order). The first
    draws the shapes (``target``, ``graph``, ``muscles``, ``design`` and the meshes), the second writes the
    virtual prototype's photographs (:func:`measure_prototype`'s), the third the synthetic photograph
    ``photo`` and its ``overlay`` (:func:`measure_case`'s own).

    ``run_scene`` gives each part to a job (:class:`~mdsr_opt.core.jobs.Jobs`), the photographs' after the
    stage that made them in the same job, so that worker processes draw a case's files while the parent
    solves the next case. ``vector``: every figure also as PDF/SVG beside its PNG
    (:func:`mdsr_opt.plot.common.save_figure`).
    """
    fmt = "." + mesh_format.lstrip(".")
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    if run.setup is None:
        return []
    return [functools.partial(_write_shapes, scene, run, folder, fmt, vector),
            functools.partial(_write_prototype_photos, run, folder),
            functools.partial(_write_photos, scene, run, folder, vector)]


def _write_shapes(scene: Scene, run: CaseRun, folder: Path, fmt: str, vector=None) -> list[str]:
    """``target.png``, ``target.<fmt>``, ``graph.png``, ``muscles.png`` (when the target was reached),
    ``design.png`` and ``driven.<fmt>`` (when there is a design)."""
    from ..plot.common import save_figure
    from ..plot.design import plot_contraction_graph, plot_design, plot_routing
    from ..plot.scenes import plot_target
    from ..plot.style import energy_label, figure_paths
    from ..body.io import write_mesh
    from ..synthesis.routing import contraction_graph
    from .casefab import write_case_fabrication

    setup, mesh, mat = run.setup, scene.mesh, scene.material
    case, x = setup.case, setup.target
    files: list[str] = []
    units = scene.units

    def save(fig, name):  # the PNG, and with vector its PDF/SVG beside it: every path listed
        save_figure(fig, folder / name, close=True, vector=vector)
        files.extend(figure_paths(folder / name, vector))

    if setup.target_result.success:
        energy = mat.psi(mesh.deformation_gradients(x))
        title = (f"{scene.name} / {case.name}: target by "
                 f"{'external driving' if case.kind == 'external' else 'internal driving'}")
        fig = plot_target(mesh, x, anchors=case.anchors, drag_nodes=case.drag_nodes,
                          drag_positions=case.drag_positions if len(case.drag_nodes) else None,
                          muscles=setup.muscles if case.kind == "internal" else (), values=energy,
                          title=title, units=units, obstacles=setup.obstacles or (),
                          colorbar_label=energy_label(getattr(mat, "stress_unit", None), units))
        save(fig, "target.png")
        write_mesh(folder / f"target{fmt}", mesh, x=x, material=mat)
        files.append(str(folder / f"target{fmt}"))
        graph = setup.routing.graph if setup.routing is not None else contraction_graph(mesh, x)
        seeds = setup.routing.seeds if setup.routing is not None else None
        # graph, muscles and design draw the target's frame again: its coordinates are on target.png, and
        # their ticks would be most of their drawing time
        save(plot_contraction_graph(mesh, x, graph, seeds=seeds, ticks=False, units=units), "graph.png")
        if setup.muscles:
            save(plot_routing(mesh, x, setup.muscles, ticks=False, units=units), "muscles.png")
    if run.design is not None:
        res = run.design
        save(plot_design(mesh, res, x, setup.muscles, ticks=False, units=units, obstacles=setup.obstacles or ()),
             "design.png")
        write_mesh(folder / f"driven{fmt}", mesh, x=res.x_aligned, material=mat)
        files.append(str(folder / f"driven{fmt}"))
        files += write_case_fabrication(scene, run, folder)  # the scene's [fabrication]: SVG, DXF, CSV
    return files


def _write_prototype_photos(run: CaseRun, folder: Path) -> list[str]:
    """The virtual prototype's photographs (Tables 2-4), each a PNG with its JSON."""
    files: list[str] = []
    for key, ph in run.prototype_photos.items():
        files.append(str(ph.save(folder / f"prototype_{key}.png")))
        files.append(str(folder / f"prototype_{key}.json"))
    return files


def _write_photos(scene: Scene, run: CaseRun, folder: Path, vector=None) -> list[str]:
    """``photo.png`` (with ``photo.json``) and ``overlay.png``."""
    from ..plot.common import save_figure
    from ..plot.style import figure_paths
    from ..plot.photos import plot_overlay

    files: list[str] = []
    if run.photo is not None:
        files.append(str(run.photo.save(folder / "photo.png")))
        files.append(str(folder / "photo.json"))
        fig = plot_overlay(run.photo.image, scene.mesh, run.setup.target, run.comparison, synthetic=True,
                           title="target outline on the driven body's photo", ticks=False)
        save_figure(fig, folder / "overlay.png", close=True, vector=vector)
        files.extend(figure_paths(folder / "overlay.png", vector))
    return files
