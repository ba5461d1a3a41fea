"""The whole design in one call: target, routing, contractions, verification (:func:`design_pipeline`)."""

from __future__ import annotations

import json
import logging
import os
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Sequence
import numpy as np

from ..body.io import read_mesh
from ..body.material import material_dict, material_from_dict
from ..core.guards import interruptible
from ..body.fingerprint import check_same_mesh
from ..body.mesh import Mesh
from ..body.muscles import Muscle, check_muscles
from ..core.checks import check_options, keyword_names, node_indices
from ..core.quantities import check_length_unit
from ..core.results import compact_repr
from ..mechanics.equilibrium import check_held
from ..mechanics.loadsteps import check_mesh_material, parse_drags
from ..mechanics.result import EquilibriumResult
from ..mechanics.anchors import body_size
from .acceptance import (IDLE_CONTRACTION, AcceptanceWarning, DroppedMuscle, design_active, difference_failure,
                         rest_difference)
from .results import DesignResult, finite_or_none
from .routing_result import DroppedUnit, MuscleStats, RoutingResult
from .routing import RoutingWarning, route_for_design
from .routing_why import no_muscle_message
from .fabrication import Fabrication, check_channel_fits, check_fabrication, rope_conflicts, warn_conflicts

_LOG = logging.getLogger(__name__)

__all__ = ['PipelineResult', 'design_pipeline']


# ---------------------------------------------------------------------------------------------- the pipeline
@dataclass
class PipelineResult:
    """The whole design pipeline: target by external driving, routed muscles, contractions, verification.

    Attributes
    ----------
    mesh : Mesh
    material : NeoHookean, LinearElastic, Yeoh or MooneyRivlin
    anchors : (k,) int ndarray
    drag_nodes, drag_positions : (d,) int and (d, 2) float ndarrays
    target : (n, 2) ndarray
        The external-driving equilibrium the design aims at.
    external : EquilibriumResult
        The external-driving solve (its ``x`` is ``target``).
    muscles : tuple of Muscle
    routing : RoutingResult or None
        The routing: muscles, per-muscle figures (``.table()``), knobs, the fabrication, the fixture radius
        the design used and ``notes`` (what was resolved to make the ropes buildable; None when muscles
        were given). A
        loaded result's has the contraction graph rebuilt from the mesh and the target, and no
        ``reflection``.
    design : DesignResult
    times : dict
        Seconds per stage (``external``, ``routing``, ``design``, ``total``; ``bands`` when computed).
    dropped : tuple of DroppedMuscle
        Muscles taken out of the layout after a design, with the reason (an idle muscle:
        :func:`~mdsr_opt.synthesis.acceptance.design_active`); ``muscles`` are those kept.
    bands : StrokeBands or None
        The strokes' uncertainty bands (:func:`~mdsr_opt.synthesis.bands.stroke_bands`), when asked for
        (``design.stroke_band`` holds their ranges).
    fabrication : Fabrication or None
        The channel, wall and fixtures the muscles were routed (``routing.fabrication``) or given for:
        :func:`~mdsr_opt.synthesis.export.export_fabrication` draws them (None: routed without one).
    far_from_target : str
        Why ``mdsr run`` would fail this design for its distance to the target
        (:func:`~mdsr_opt.synthesis.acceptance.difference_failure`: more than
        :data:`~mdsr_opt.synthesis.acceptance.MAX_DIFFERENCE` of the body's diameter, or less than
        :data:`~mdsr_opt.synthesis.acceptance.MIN_PROGRESS` of the rest shape's difference removed); ``""``
        when it would not. A success that is far gives an
        :class:`~mdsr_opt.synthesis.acceptance.AcceptanceWarning`.
    """

    mesh: Mesh
    material: Any
    anchors: np.ndarray
    drag_nodes: np.ndarray
    drag_positions: np.ndarray
    target: np.ndarray
    external: EquilibriumResult
    muscles: tuple
    routing: RoutingResult | None
    design: DesignResult
    times: dict = field(default_factory=dict)
    dropped: tuple = ()
    bands: Any = None
    fabrication: Any = None
    far_from_target: str = ""

    @property
    def success(self) -> bool:
        """The design succeeded and was verified (a stable state; how close it comes to the target is
        :attr:`far_from_target`'s)."""
        return bool(self.design.success)

    @property
    def contractions(self) -> np.ndarray:
        return self.design.contractions

    @property
    def reason(self) -> str:
        """Why this is no design to build, in one phrase ("" when it is one): the design's
        (:attr:`DesignResult.reason <mdsr_opt.synthesis.results.DesignResult.reason>`), else
        :attr:`far_from_target` (its ``repr`` shows them as ``why=...``, ``far_from_target=...``)."""
        return self.design.reason or self.far_from_target

    def __repr__(self) -> str:
        d = self.design
        why = self.reason  # then the difference first: the figure that says how far, before what was left out
        return compact_repr(self, ("success",), why=why, why_name="why" if d.reason else "far_from_target",
                            extra={**({"difference": d.difference} if why else {}),
                                   "n_nodes": self.mesh.n_nodes, "n_muscles": len(self.muscles), "method": d.method,
                                   "difference": d.difference, "contractions": d.contractions,
                                   **({"saturated": d.saturated_names} if d.saturated.any() else {}),
                                   **({"dropped": [m.name for m in self.dropped]} if self.dropped else {}),
                                   "total_time": self.times.get("total", float("nan"))})

    def table(self) -> str:
        """The stroke table (:meth:`DesignResult.muscle_table`, with the stroke bands when computed), then
        one line per dropped muscle."""
        lines = [self.design.muscle_table()]
        lines += [f"dropped {m.name}: {m.reason}" for m in self.dropped]
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """A JSON-ready dict (arrays as lists, NaN as None): what ``design.json`` holds, with the mesh
        (``points``, ``triangles``) and the ``target`` state instead of the mesh files' names."""
        data = self._data()
        data["mesh"] = {"points": self.mesh.points.tolist(), "triangles": self.mesh.triangles.tolist()}
        data["target"] = np.asarray(self.target).tolist()
        return finite_or_none(data)

    def _data(self) -> dict:
        mat = self.material
        return {
            "format": "mdsr_opt.design/1",
            "material": material_dict(mat),
            "anchors": self.anchors.tolist(), "drag_nodes": self.drag_nodes.tolist(),
            "drag_positions": self.drag_positions.tolist(),
            "external": {k: v for k, v in self.external.to_dict().items() if k != "x"},  # x: the target
            "muscles": [{"nodes": list(mu.nodes), "name": mu.name} for mu in self.muscles],
            "routing": None if self.routing is None else self.routing.to_dict(), "design": self.design.to_dict(),
            "times": self.times, "dropped_muscles": [m.to_dict() for m in self.dropped],
            "bands": None if self.bands is None else self.bands.to_dict(),
            "fabrication": None if self.fabrication is None else self.fabrication.to_dict(),
            "far_from_target": self.far_from_target,
        }

    def save(self, out: str | os.PathLike) -> str:
        """Write ``design.json`` and the meshes ``target.vtu`` and ``driven.vtu`` (states as displacements)
        into the folder ``out`` (created if missing), each atomically.

        Parameters
        ----------
        out : str or path-like
            The folder; :meth:`load` reads it back.

        Returns
        -------
        str
            The path of ``design.json``.

        Notes
        -----
        Files of those three names already in ``out`` are replaced, without a warning (``mdsr run`` refuses a
        folder with files in it unless ``--overwrite``): give a new folder to keep an earlier result.
        """
        from ..body.io import write_json, write_mesh

        directory = os.fspath(out)
        if not str(directory).strip():
            raise ValueError("out is empty: give a folder name")
        if os.path.exists(directory) and not os.path.isdir(directory):
            raise ValueError(f"{directory} is an existing file, not a folder")
        os.makedirs(directory, exist_ok=True)
        write_mesh(os.path.join(directory, "target.vtu"), self.mesh, x=self.target, material=self.material)
        write_mesh(os.path.join(directory, "driven.vtu"), self.mesh, x=self.design.x_aligned,
                   material=self.material)
        data = dict(self._data(), meshes={"target": "target.vtu", "driven": "driven.vtu"})
        return write_json(os.path.join(directory, "design.json"), finite_or_none(data))

    @classmethod
    def load(cls, path: str | os.PathLike) -> "PipelineResult":
        """Read a result written by :meth:`save` from its folder ``path``.

        Raises
        ------
        FileNotFoundError
            ``path``, its ``design.json`` or a mesh file it names does not exist.
        ValueError
            ``path`` is a file; ``design.json`` is not valid JSON, not a design result, or damaged (a
            field missing or of the wrong kind, named); a mesh file cannot be read or does not match.
        """
        directory = os.fspath(path)
        if not os.path.exists(directory):
            raise FileNotFoundError(f"no such design result folder: {directory}")
        if not os.path.isdir(directory):
            raise ValueError(f"{directory} is a file; PipelineResult.load takes the folder written by save()")
        path = os.path.join(directory, "design.json")
        if not os.path.exists(path):
            raise FileNotFoundError(f"no design.json in {directory}")
        try:
            with open(path, encoding="utf-8") as fh:
                data = json.load(fh)
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ValueError(f"{path} is damaged: not valid JSON ({exc})") from None
        except RecursionError:
            raise ValueError(f"{path} is damaged: lists and objects nested too deeply to read") from None
        if not isinstance(data, dict) or data.get("format") != "mdsr_opt.design/1":
            fmt = data.get("format") if isinstance(data, dict) else None
            raise ValueError(f"{path} is not a mdsr_opt design result (format {fmt!r})")
        field_ = "meshes.target"
        try:
            mpath = os.path.join(directory, data["meshes"]["target"])
            if not os.path.exists(mpath):
                raise FileNotFoundError(f"{path}: the target mesh {mpath} is missing")
            md = read_mesh(mpath)
            field_ = "material"
            m = data["material"]
            material = material_from_dict(m)
            field_ = "muscles"
            muscles = tuple(Muscle(tuple(mu["nodes"]), name=mu.get("name")) for mu in data["muscles"])
            for mu in muscles:
                mu.check_on(md.mesh)
            field_ = "anchors/drags"
            kw = dict(anchors=np.asarray(data["anchors"], dtype=np.int64),
                      drag_nodes=np.asarray(data["drag_nodes"], dtype=np.int64),
                      drag_positions=np.asarray(data["drag_positions"], dtype=float).reshape(-1, 2))
            field_ = "design"
            design = DesignResult.from_dict(data["design"])
            if design.x.shape != md.x.shape:
                raise ValueError(f"the design's state has shape {design.x.shape}, the mesh {md.x.shape}")
            check_same_mesh(md.mesh, design.rest_mesh, "the design")  # the saved mesh is the design's body
            field_ = "external/routing/times"
            external = _equilibrium_from(data["external"], md.x)
            routing = None if data["routing"] is None else _routing_from(data["routing"], muscles, md.mesh, md.x)
            field_ = "dropped_muscles"
            dropped = tuple(DroppedMuscle(name=str(d["name"]), nodes=tuple(int(n) for n in d["nodes"]),
                                          contraction=float(d["contraction"]), reason=str(d["reason"]))
                            for d in data.get("dropped_muscles", ()))
            return cls(mesh=md.mesh, material=material, target=md.x, external=external,
                       muscles=muscles, routing=routing, design=design, times=data.get("times", {}),
                       dropped=dropped, **kw, fabrication=None if data.get("fabrication") is None
                       else Fabrication(**data["fabrication"]), far_from_target=str(data.get("far_from_target", "")))
        except FileNotFoundError:
            raise
        except KeyError as exc:
            raise ValueError(f"{path} is damaged: field {exc.args[0]!r} is missing (in {field_})") from None
        except (TypeError, ValueError, AttributeError, IndexError) as exc:
            raise ValueError(f"{path} is damaged ({field_}): {exc}") from None


def _equilibrium_from(data: dict, x: np.ndarray) -> EquilibriumResult:
    """The external solve saved in ``design.json`` (its fields but ``x``, the target): an
    :class:`EquilibriumResult` again."""
    if not isinstance(data, dict):
        raise TypeError(f"external is a {type(data).__name__}, not an object")
    known = EquilibriumResult.__dataclass_fields__
    fields = {k: v for k, v in data.items() if k in known and k != "x"}
    for k in ("rotation", "translation", "commanded", "achieved", "stroke", "tension", "slack", "rest_lengths"):
        if fields.get(k) is not None:
            fields[k] = np.asarray(fields[k], dtype=bool if k == "slack" else float)
    fields.setdefault("elastic_energy", fields.get("energy"))
    return EquilibriumResult(x=np.asarray(x, dtype=float).copy(), **fields)


def _routing_from(data: dict, muscles: tuple, mesh: Mesh, target: np.ndarray) -> RoutingResult:
    """The routing saved in ``design.json`` (:meth:`RoutingResult.to_dict`): a :class:`RoutingResult` of
    ``muscles`` again, its contraction graph rebuilt from ``mesh`` and ``target``."""
    from .routing import contraction_graph

    if not isinstance(data, dict):
        raise TypeError(f"routing is a {type(data).__name__}, not an object")
    stats = [MuscleStats(**st) for st in data["stats"]]
    names = {m.name for m in muscles}
    if len(stats) != len(muscles):  # saved before the routing dropped the muscles the design took out
        stats = [st for st in stats if st.name in names]
    return RoutingResult(muscles=tuple(muscles), stats=tuple(stats),
                         graph=lambda: contraction_graph(mesh, target),
                         seeds=tuple(tuple(int(i) for i in sd) for sd in data.get("seeds", ())),
                         n_units=int(data.get("n_units", 0)), params=dict(data.get("params", {})),
                         fabrication=None if data.get("fabrication") is None else Fabrication(**data["fabrication"]),
                         fixture_radius=data.get("fixture_radius"), notes=tuple(map(str, data.get("notes", ()))),
                         dropped=tuple(DroppedUnit(nodes=tuple(d["nodes"]), rest_length=float(d["rest_length"]),
                                                   reason=str(d["reason"])) for d in data.get("dropped", ())))


def _target(mesh, material, anchors, drags, opts: dict, solve_external) -> EquilibriumResult:
    """The target: ``solve_external`` with ``opts``. Without a ``backend`` in ``opts`` the project's Newton
    backend solves it first (no constraints here: it meets the same tolerance contract and stability
    check as IPOPT, with one ordering reused), and IPOPT (``solve_external``'s default) when Newton fails."""
    if "backend" in opts:
        return solve_external(mesh, material, anchors, drags, **opts)
    ext = solve_external(mesh, material, anchors, drags, backend="newton", **opts)
    return ext if ext.success else solve_external(mesh, material, anchors, drags, **opts)


def _check_option_dicts(band_options, routing_options, external_options, design_options) -> tuple[dict, ...]:
    """The pipeline's option dicts checked at the door, each key against the keywords of the function it is
    passed to (an unknown key named with the nearest one: ``did you mean 'max_muscles'?``), before the
    target is solved; returns the first three as dicts."""
    from ..mechanics.equilibrium import solve_external
    from .contractions import design_contractions
    from .routing import route_muscles

    bands = check_options(band_options, BAND_OPTIONS, "band_options")
    routing = check_options(routing_options, keyword_names(route_muscles), "routing_options")
    external = check_options(external_options, keyword_names(solve_external), "external_options")
    check_options(design_options, set(keyword_names(design_contractions)) | {"drop_slack"},
                  "design_pipeline's design options (its other keywords)")
    return bands, routing, external


#: How the pipeline verifies its designs unless ``verify`` is given (:func:`design_contractions`): from the
#: design's state, which certifies it a stable equilibrium of the designed contractions (the forward
#: solver's KKT residual within its tolerance and the reduced Hessian positive definite); ``"rest"`` also
#: asks where a second, full solve from the rest shape lands
PIPELINE_VERIFY = "design"


#: The keys of ``band_options``: :func:`~mdsr_opt.synthesis.bands.stroke_bands`' own and the designs' ``max_iter``.
BAND_OPTIONS = ("radius_tol", "nu_tol", "refine", "max_refined_nodes", "max_iter")


@interruptible()
def design_pipeline(mesh: Mesh, material, anchors, drags, *, muscles: Sequence[Muscle] | None = None,
                    routing_options: dict | None = None, method: str | None = None,
                    external_options: dict | None = None, fabrication=None,
                    idle_contraction: float = IDLE_CONTRACTION, bands: bool = False,
                    band_options: dict | None = None, units: str | None = None, contact: bool = False,
                    obstacles=None,
                    **design_options) -> PipelineResult:
    """The whole pipeline in one call: external driving -> muscle routing -> contractions -> verification.

    Parameters
    ----------
    mesh, material : the body.
    anchors, drags : as in :func:`~mdsr_opt.solve_external`; their equilibrium is the target shape.
    muscles : optional
        Use these muscles instead of routing them.
    routing_options : dict, optional
        Keyword arguments for :func:`~mdsr_opt.synthesis.routing.route_muscles` (``K_a``, ``K_b``, ``max_muscles``...).
    method : str, optional
        The design method (see :func:`design_contractions`; default ``"flattened"``, ``"nested"`` with
        ``held`` nodes). With contact and no method, each design is made by that gradient method without the
        contacts and kept when, checked with them, it touches nothing; else by ``"derivative-free"`` with
        them, started from its contractions (``.design.method`` says which, ``.design.status`` why). Without
        contact, a default flattened design that fails is made again by ``"nested"``
        (:mod:`~mdsr_opt.synthesis.fallback`: ``.design.method`` and ``.design.fallback`` say so).
    contact, obstacles : optional
        Contact (as in :func:`~mdsr_opt.solve_external`) in the target's solve and in the design and its
        verification (:func:`design_contractions`); refused at the door with a method that cannot take it.
        With obstacles the design's body is clamped at the target's ``anchors`` (``held=anchors`` in
        :func:`design_contractions`, unless ``held`` is given among the design options): the obstacles stand
        in the target's frame, which its anchors fix, so a body that presses on or grips one is designed as the
        robot that does it, mounted where the target was clamped; a free body held at gauge coordinates chosen
        from its geometry would meet the obstacles (if at all) somewhere else. Without obstacles the design
        is the paper's free body (self-contact alone does not depend on where the body is). A design with
        obstacles needs at least two anchors, or ``held``: refused at the door otherwise.
    external_options : dict, optional
        Keyword arguments for :func:`~mdsr_opt.solve_external` (``backend``, ``tol``...). Without a
        ``backend`` the target is solved by ``"newton"``, and by IPOPT when Newton fails.
    fabrication : Fabrication or dict of its fields, optional
        Channel, wall and end fixtures (:class:`~mdsr_opt.synthesis.fabrication.Fabrication`, default: its
        defaults for this body). Routed ropes keep their clearance inside the body and are fitted to their
        fixtures (``routing.notes`` lists what was resolved), and the design's ``anchor_radius`` is the
        fixture radius they fit with (``routing.fixture_radius``). An ``anchor_radius`` given here is the
        fixture radius.
    idle_contraction : float, default :data:`~mdsr_opt.synthesis.acceptance.IDLE_CONTRACTION`
        A muscle designed to a contraction below it is idle: dropped from the layout and the design made
        again (:func:`~mdsr_opt.synthesis.acceptance.design_active`; ``.dropped`` lists it). 0 keeps every
        muscle. When every muscle is idle the design is no success.
    bands : bool, default False
        Also compute every stroke's uncertainty band (:func:`~mdsr_opt.synthesis.bands.stroke_bands`: a
        few more designs, one on a refined mesh), in ``.bands`` and ``.design.stroke_band``.
    band_options : dict, optional
        Keywords of ``stroke_bands`` (``radius_tol``, ``nu_tol``, ``refine``, ``max_refined_nodes``,
        ``max_iter``).
    units : str, optional
        The length unit of the mesh's coordinates (``"mm"``...: :data:`~mdsr_opt.synthesis.export.UNITS`),
        recorded in ``.design.units``: tables give strokes in it, tensions in N for a material with a
        ``stress_unit`` (a silicone preset), and the fabrication files default to it. None: body units.
    **design_options
        Passed to :func:`design_contractions` (``a_max``, ``muscle_model`` (default ``"cable"``, the exact
        rope), ``anchor_radius``, ``stiffness``, ``verify``...). The design is verified from its own state
        (``verify="design"``, :data:`PIPELINE_VERIFY`): the forward solver started there must find it a
        stable equilibrium of the designed contractions; ``verify="rest"`` also re-solves from the rest
        shape and asks that the solve lands there. ``.design`` reports per muscle the commanded and achieved
        contraction, the stroke (rope length pulled in) and the tension; a muscle at ``a_max`` is flagged
        (``.design.saturated``, a :class:`~mdsr_opt.synthesis.results.MuscleWarning`).

    Returns
    -------
    PipelineResult
        ``.design`` holds contractions, driven state, alignment, difference and verification; ``.save(out)``
        writes JSON plus meshes and :meth:`PipelineResult.load` reads them back.

    Raises
    ------
    SolverFailure
        The external-driving solve (the target) failed.
    ValueError
        Bad input, at the door (no drags, say). And, after the target has been solved (with contact that can
        take a while), when routing (``muscles`` not given) lays no muscle on it: a target that only
        stretches the body, contracted edges outside the buildable band of a mesh too coarse for the ropes'
        inset, units all shorter than ``min_length``. The message is the one ``mdsr run`` fails that case
        with, ``routing found no muscle on the target (<the routing's reasons, with values that would
        work>)`` (:func:`~mdsr_opt.synthesis.routing_why.no_muscle_message`), then ``; pass muscles=... or
        relax routing_options``. A body or mesh that holds no rope at all raises the routing's
        :class:`~mdsr_opt.core.errors.LayoutError` (a ValueError; ``mdsr run``: "routing failed: ...").

    Example
    -------
    >>> from mdsr_opt import Mesh, NeoHookean
    >>> mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    >>> left = [i for i, (x, y) in enumerate(mesh.points) if x == 0.0]
    >>> top_right = {i: (x - 0.3, y - 0.4) for i, (x, y) in enumerate(mesh.points) if x == 4.0}
    >>> out = design_pipeline(mesh, NeoHookean(1.0, 0.3), left, top_right)
    >>> out.success, out.design.difference < 0.05
    (True, True)
    """
    from ..mechanics.equilibrium import solve_external

    from .acceptance import A_MAX, check_idle_contraction

    t0 = time.perf_counter()
    check_mesh_material(mesh, material)
    units = check_length_unit(units)
    idle_contraction = check_idle_contraction(idle_contraction, a_max=design_options.get("a_max", A_MAX))
    if not isinstance(bands, (bool, np.bool_)):
        raise TypeError(f"bands must be True or False, got {type(bands).__name__}")
    band_options, routing_options, external_options = _check_option_dicts(
        band_options, routing_options, external_options, design_options)  # misspelt keys: before any work
    ropts = dict(routing_options or {})  # the fabrication checked at the door, before any solve
    ropts["fabrication"] = check_fabrication(ropts.get("fabrication", fabrication), design_options.get("anchor_radius"))
    check_channel_fits(mesh, ropts["fabrication"], routed=muscles is None)  # a channel the body cannot hold
    if muscles is not None:  # of this mesh, one label each: before the target's solve
        muscles = tuple(check_muscles(mesh, muscles))
    from .contactdesign import check_design_contact, gradient_method
    from ..mechanics.obstacles import check_obstacles

    didx, dpos = parse_drags(drags, mesh)  # the mesh: rigid drags' final positions need it
    if len(didx) == 0:
        raise ValueError("drags is empty: design_pipeline's target is the body dragged by its drags "
                         "({node: (x, y)}), so with none it is the rest shape and there is nothing to design")
    eopts = dict(external_options or {})
    if ("contact" in eopts or "obstacles" in eopts) and (contact is not False or obstacles is not None):
        raise ValueError("give contact and obstacles once: as design_pipeline's keywords, not in external_options")
    named = method is not None  # a default flattened design that fails is made again by the nested method
    if method is None and not (contact is True or check_obstacles(obstacles)):
        # as design_contractions chooses (held nodes: the nested method); with contact it chooses per design: a
        # gradient design checked with the contacts, else derivative-free (mdsr_opt.synthesis.contactdesign)
        method = gradient_method(design_options.get("held"))
    ckw = check_design_contact(mesh, material, contact, obstacles, design_options.get("contact_gap"), method)
    anc = node_indices(np.zeros(0, dtype=np.int64) if anchors is None else anchors, "anchors", n=mesh.n_nodes)
    if ckw.get("obstacles") and design_options.get("held") is None:
        if len(anc) < 2:
            raise ValueError(f"a design with obstacles clamps the body where the target was anchored (the obstacles "
                             f"stand in that frame), but the target has {len(anc)} anchor(s): give at least two "
                             "anchors, or the clamped nodes as held=[...]")
        design_options["held"] = anc  # the body mounted where its target was clamped
    if check_held(mesh, design_options.get("held"), muscles) is not None and method == "flattened":
        raise ValueError("held nodes are designed by method='nested' or 'derivative-free' (the flattened NLP pins "
                         "the body's three gauge coordinates only), got method='flattened'")
    if ckw:  # contact: the target by IPOPT (the Newton backend takes no contact)
        eopts.update(contact=ckw["contact"], obstacles=ckw["obstacles"])
        design_options.update(contact=ckw["contact"], obstacles=ckw["obstacles"])
        ext = solve_external(mesh, material, anchors, drags, **eopts)
    else:
        ext = _target(mesh, material, anchors, drags, eopts, solve_external)
    ext.raise_on_failure()
    t1 = time.perf_counter()
    _LOG.info("design_pipeline: target solved%s in %.1f s", " with contact" if ckw else "", t1 - t0)
    routing = None
    if muscles is None:
        with warnings.catch_warnings(record=True) as caught:  # the routing's reason, for the error below
            warnings.simplefilter("always", RoutingWarning)
            rr = route_for_design(mesh, ext.x, **ropts)
        for w in caught:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        mus = tuple(rr.muscles)
        if not mus:  # the sentence mdsr run fails the case with, and what to change in Python
            why = no_muscle_message(str(w.message) for w in caught if issubclass(w.category, RoutingWarning))
            raise ValueError(f"{why}; pass muscles=... or relax routing_options")
        routing = rr
        design_options["anchor_radius"] = rr.fixture_radius  # the fixtures the ropes fit with
    else:
        mus = tuple(check_muscles(mesh, muscles))
        # muscles the user gives are designed as given (a rope on the surface may be meant), but one that
        # cannot be moulded is said, with its inset and what the channel needs
        fab = ropts["fabrication"] or Fabrication()
        warn_conflicts(rope_conflicts(mesh, mus, fab, fixture_radius=design_options.get("anchor_radius")),
                       "design_pipeline: the muscles given")
    # the wall a rope's two end fixtures keep between them in the designed state: the fabrication's
    design_options.setdefault("fixture_wall", (ropts["fabrication"] or Fabrication()).for_body(mesh).wall)
    t2 = time.perf_counter()
    design_options.setdefault("verify", PIPELINE_VERIFY)
    _LOG.info("design_pipeline: designing %d muscle(s) by %s%s", len(mus), method or
              f"method {gradient_method(design_options.get('held'))} without contact, "
              "checked with it (derivative-free with it when it touches)",
              " with contact (each trial a contact solve; progress below)" if ckw and method else "")
    res, mus, dropped = design_active(mesh, material, mus, ext.x, idle_contraction=idle_contraction,
                                      method=method if named else None, **design_options)
    res.units = units
    if routing is not None and dropped:
        routing = routing.keeping(mus, dropped)
    t3 = time.perf_counter()
    times = {"external": t1 - t0, "routing": t2 - t1, "design": t3 - t2}
    out = PipelineResult(mesh=mesh, material=material, anchors=anc, drag_nodes=didx, drag_positions=dpos,
                         target=ext.x.copy(), external=ext, muscles=mus, routing=routing, design=res,
                         times=times, dropped=dropped,
                         fabrication=routing.fabrication if routing is not None else ropts["fabrication"] or None)
    out.far_from_target = difference_failure(res.difference, body_size(mesh), units=units, n_anchors=len(anc),
                                             rest_difference=rest_difference(mesh, ext.x, design_options))
    if res.success and out.far_from_target:
        warnings.warn(f"design_pipeline: the design is a verified stable state, but {out.far_from_target}: "
                      "mdsr run would fail it (add muscles, lower seed_threshold, or accept it)",
                      AcceptanceWarning, stacklevel=3)
    if bands and res.success:
        from .bands import stroke_bands

        out.bands = stroke_bands(out, **{**design_options, **(band_options or {})})
        res.stroke_band = out.bands.band.copy()
        times["bands"] = time.perf_counter() - t3
    times["total"] = time.perf_counter() - t0
    return out

