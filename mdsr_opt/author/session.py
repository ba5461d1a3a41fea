"""The state of one authoring session: a body, its anchors and drags, the live equilibrium, muscles, design.

Everything numerical goes through the public API: :func:`~mdsr_opt.solve_external` for the equilibria,
:func:`~mdsr_opt.contraction_graph` and :func:`~mdsr_opt.synthesis.routing.route_for_design` (the routing
``mdsr run`` makes) for the muscles, :func:`~mdsr_opt.design_contractions` for the design. The session keeps
one mesh for its whole life, so :func:`~mdsr_opt.get_model` builds the energy model once and every drag is a
repeated solve.

Two kinds of solve:

* **live** (:meth:`Session.drag`): while the mouse moves, a *preview*: the last shown state moved by one
  chord-Newton predictor step toward the new drag positions, then a few corrector steps with the same
  factorised tangent (reused across updates, refreshed every :attr:`Session.REFRESH` updates), stopped
  at the scaled residual :attr:`Session.PREVIEW_TOL` -- no solver set-up, no stability check. When the
  preview inverts an element or does not reach that residual, ``solve_external`` takes over from the
  predicted state (no load stepping), and when that fails, the settled solve below. A preview or warm
  solve converged to a state whose boundary crosses itself is shown as the failed state it is (no
  further solve), and the next drag starts from it.
* **settled** (:meth:`Session.settle`): ``solve_external(mesh, material, anchors, drags)`` with its
  defaults and the case's obstacles, friction and self-contact, exactly what ``mdsr run`` solves for the saved
  scene's target (:mod:`~mdsr_opt.author.contact`; bit for bit; a warm start would reach the same equilibrium
  only to the tolerance). A released drag is settled; the server starts this solve (:meth:`Session.exact`)
  as soon as a drag waits for the next move. With contact the live drag makes no preview (it models none).
"""

from __future__ import annotations

import inspect
import math
import time
from dataclasses import dataclass, field
import warnings
from pathlib import Path

import numpy as np
import scipy.sparse.linalg as spla

from ..body.material import NeoHookean
from ..synthesis.acceptance import design_active
from ..synthesis.contractions import design_contractions
from ..synthesis.results import MuscleWarning
from ..mechanics.equilibrium import solve_external
from ..body.mesh import Mesh
from ..core.checks import node_indices
from ..mechanics.anchors import body_size
from ..mechanics.model import get_model
from ..synthesis.fabrication import Fabrication, check_channel_fits, check_fabrication
from ..synthesis.routing import RoutingWarning, contraction_graph, route_for_design, route_muscles
from ..scenes.scene import Scene, mesh_polygon, resolve_resolution
from ..scenes.library import get_problem
from ..plot.style import label_slots, muscle_color
from ..scenes.reader import read_file
from ..scenes.scenefile import load_scene, scene_from_data
from .contact import design_options_with_obstacles, live_options, target_solve
from .roundtrip import Origin
from .summary import design_summary

__all__ = ["Session", "SolveReport", "MAX_NODES", "design_defaults", "routing_defaults"]

#: Largest mesh the page will build (node count), to keep a typo from freezing the server.
MAX_NODES = 20000
#: Coordinates farther than this many body diameters (:func:`body_size`) from the body are refused.
FAR = 1e3


def design_defaults() -> dict:
    """The keyword defaults of :func:`~mdsr_opt.design_contractions` the page offers (read, not copied)."""
    sig = inspect.signature(design_contractions).parameters
    return {k: sig[k].default for k in ("method", "a_max", "muscle_model", "stiffness")}


def routing_defaults() -> dict:
    """The keyword defaults of :func:`~mdsr_opt.route_muscles` the page offers (read, not copied): the knobs
    ``mdsr run`` routes a scene with when the scene gives none."""
    sig = inspect.signature(route_muscles).parameters
    return {k: sig[k].default for k in ("K_a", "K_b", "max_muscles")}


def muscle_entries(muscles) -> list[dict]:
    """The muscles as the page draws them: name, node path and colour, the colour every figure, SVG and DXF
    gives the same name (:func:`mdsr_opt.plot.style.label_slots`)."""
    slots = label_slots([m.name for m in muscles])
    return [{"name": m.name, "nodes": [int(v) for v in m.nodes], "color": muscle_color(k)}
            for m, k in zip(muscles, slots)]


@dataclass
class SolveReport:
    """One equilibrium as the page shows it.

    Attributes
    ----------
    x : (n, 2) state (the last accepted one if the solve failed).
    success, status, iterations, residual, min_J : from the solve.
    crossing : the boundary crosses itself (shown, never hidden).
    inverted : indices of triangles with ``det F <= 0``.
    live : a warm-started drag solve (``False``: the plain ``solve_external`` call).
    warm_failed : the warm start was tried and a plain solve had to take over.
    solve_time : seconds spent in this request on the server.
    build_time : seconds ``solve_external`` spent building the model or solver (0 when reused).
    """

    x: np.ndarray
    success: bool
    status: str
    iterations: int
    residual: float
    min_J: float
    crossing: bool
    inverted: list
    live: bool
    warm_failed: bool = False
    solve_time: float = 0.0
    build_time: float = 0.0

    def to_dict(self) -> dict:
        return {"x": self.x.tolist(), "success": self.success, "status": self.status,
                "iterations": self.iterations, "residual": _num(self.residual), "min_J": _num(self.min_J),
                "crossing": self.crossing, "inverted": self.inverted, "live": self.live,
                "warm_failed": self.warm_failed, "solve_time": self.solve_time,
                "build_time": self.build_time}


def _num(v):
    v = float(v)
    return v if math.isfinite(v) else None


@dataclass
class Session:
    """A body with the user's anchors, drags, muscles and design.

    Build one with :meth:`from_problem`, :meth:`from_scene_file` or :meth:`from_outline`.
    """

    name: str
    mesh: Mesh
    material: object
    source: str = ""
    outline: list | None = None
    holes: list = field(default_factory=list)
    resolution: int = 0
    routing_options: dict = field(default_factory=dict)
    design_options: dict = field(default_factory=dict)
    anchors: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    drag_nodes: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    drag_positions: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    state: SolveReport | None = None
    target: np.ndarray | None = None  # the last settled, successful equilibrium
    routing: object = None
    routing_params: dict = field(default_factory=dict)
    muscles: tuple = ()
    design: object = None
    design_params: dict = field(default_factory=dict)
    log: list = field(default_factory=list)
    dropped: tuple = ()  # idle muscles the last design took out of the layout (DroppedMuscle)
    units: str = ""  # the scene's length unit, named on the figures' axes ("" for a drawn outline)
    #: the channel, wall and fixtures the last routing used: a dict of the fields given (None: the defaults;
    #: False: the routing search alone), saved as the scene's [fabrication] table
    fabrication: dict | bool | None = None
    deleted: tuple = ()  # names of the routed muscles the user deleted
    acceptance: dict = field(default_factory=dict)  # the scene's [acceptance] (mdsr run's; saved with the scene)
    origin: Origin | None = None  # the scene opened and its edited case: what a saved scene keeps (.roundtrip)
    placed: list = field(default_factory=list)  # the edited case's obstacles as the last target placed them
    design_notes: list = field(default_factory=list)  # what the obstacles changed in the last design (mdsr run's)
    designed_layout: tuple = ()  # the muscles the last design started from (before it dropped idle ones)

    # ------------------------------------------------------------------ building
    @classmethod
    def from_scene(cls, scene: Scene, case: str | None = None, data: dict | None = None) -> "Session":
        """A session on ``scene``'s body, starting from its first external case (or ``case``); ``data``: the
        scene file's content, whose tables a saved scene keeps where the page edits nothing."""
        s = cls(name=scene.name, mesh=scene.mesh, material=scene.material, source=scene.source,
                resolution=scene.resolution, routing_options=dict(scene.routing_options),
                design_options=dict(scene.design_options), units=scene.units,
                acceptance=dict(getattr(scene, "acceptance", None) or {}))
        ext = [c for c in scene.cases if c.kind == "external"]
        if case is not None:
            ext = [scene.case(case)]
        if ext and ext[0].kind == "external":
            s.anchors = ext[0].anchors.copy()
            s.drag_nodes = ext[0].drag_nodes.copy()
            s.drag_positions = ext[0].drag_positions.copy()
        s.origin = Origin(scene, ext[0].name if ext and ext[0].kind == "external" else None, data)
        return s

    @classmethod
    def from_problem(cls, name: str, resolution: str | int | None = None) -> "Session":
        """A library problem (see :func:`~mdsr_opt.list_problems`) at ``resolution``."""
        return cls.from_scene(get_problem(name, resolution=_resolution(resolution)))

    @classmethod
    def from_scene_file(cls, path, resolution: str | int | None = None, data: dict | None = None) -> "Session":
        """A scene file (TOML/JSON) as :func:`~mdsr_opt.load_scene` reads it (``data``: the file already read)."""
        if data is not None:
            return cls.from_scene(scene_from_data(path, data, resolution=_resolution(resolution)), data=data)
        return cls.from_scene(load_scene(path, resolution=_resolution(resolution)), data=read_file(Path(path)))

    @classmethod
    def from_outline(cls, outline, holes=(), resolution: str | int = 600, name: str = "authored",
                     material=None) -> "Session":
        """A polygon (with holes) meshed with about ``resolution`` nodes; Neo-Hookean E = 1, nu = 0.3."""
        n = resolve_resolution(_resolution(resolution))
        if n > MAX_NODES:
            raise ValueError(f"resolution {n} is above the page's limit of {MAX_NODES} nodes")
        out = np.asarray(outline, dtype=float)
        hs = [np.asarray(h, dtype=float) for h in holes]
        for what, p in [("outline", out)] + [(f"hole {i + 1}", h) for i, h in enumerate(hs)]:
            if p.ndim != 2 or p.shape[1] != 2 or not np.all(np.isfinite(p)):
                raise ValueError(f"{what}: expected finite [x, y] points")
        # a thin part that would need far more triangles than the page's node limit is refused before meshing
        mesh = mesh_polygon(out, hs, resolution=n, max_triangles=4 * MAX_NODES)
        return cls(name=name, mesh=mesh, material=material or NeoHookean(1.0, 0.3), source="outline",
                   outline=out.tolist(), holes=[h.tolist() for h in hs], resolution=n)

    # ------------------------------------------------------------------ checks
    @property
    def n_nodes(self) -> int:
        return self.mesh.n_nodes

    def check_nodes(self, nodes, what: str) -> np.ndarray:
        """Node ids as an int array; ValueError naming ``what`` for non-integers or ids out of range."""
        if not isinstance(nodes, (list, tuple, np.ndarray)):
            raise TypeError(f"{what}: expected a list of node ids, got {type(nodes).__name__}")
        return node_indices(nodes, what, n=self.n_nodes)  # the check of every entry point's node lists

    def check_points(self, pts, what: str) -> np.ndarray:
        """(k, 2) finite coordinates within ``FAR`` body sizes of the body."""
        try:
            a = np.asarray(pts, dtype=float)
        except (TypeError, ValueError):
            raise TypeError(f"{what}: expected [x, y] number pairs") from None
        if a.size == 0:
            return np.zeros((0, 2))
        if a.ndim != 2 or a.shape[1] != 2:
            raise ValueError(f"{what}: expected [x, y] pairs, got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{what}: coordinates must be finite numbers (got NaN or infinity)")
        c = self.mesh.points.mean(0)
        far, size = np.abs(a - c).max(), body_size(self.mesh)
        if far > FAR * size:
            raise ValueError(f"{what}: coordinate {far:.3g} away from the body is too large "
                             f"(limit {FAR:g} body sizes = {FAR * size:.3g})")
        return a

    def set_fixed(self, anchors, drag_nodes, drag_positions) -> None:
        """Replace anchors and drags (checked: ids in range, finite and bounded positions, no overlap)."""
        anc = self.check_nodes(anchors, "anchors")
        dn = self.check_nodes(drag_nodes, "drag nodes")
        dp = self.check_points(drag_positions, "drag positions")
        if len(dp) != len(dn):
            raise ValueError(f"drag positions: {len(dp)} for {len(dn)} drag nodes")
        both = np.intersect1d(anc, dn)
        if len(both):
            raise ValueError(f"node {int(both[0])} is both anchored and dragged")
        self.anchors, self.drag_nodes, self.drag_positions = anc, dn, dp

    # ------------------------------------------------------------------ solves
    def _ready(self) -> str | None:
        if len(self.anchors) + len(self.drag_nodes) < 2:
            return "mark at least two fixed nodes (anchors and drag nodes) to solve"
        return None

    def _report(self, res, live: bool, warm_failed: bool, t0: float) -> SolveReport:
        # solve_external accepts no inverted element and no self-crossing boundary
        crossing = not res.success and bool(self.mesh.boundary_crosses(res.x))
        inverted = [] if res.success else np.flatnonzero(self.mesh.jacobians(res.x) <= 0).tolist()
        return SolveReport(x=res.x.copy(), success=bool(res.success), status=str(res.status),
                           iterations=int(res.iterations), residual=float(res.residual),
                           min_J=float(res.min_J), crossing=crossing, inverted=inverted,
                           live=live, warm_failed=warm_failed, solve_time=time.perf_counter() - t0,
                           build_time=float(res.build_time))

    def _rest_report(self, why: str) -> SolveReport:
        return SolveReport(self.mesh.points.copy(), False, why, 0, 0.0, 1.0, False, [], live=False)

    def settle(self) -> SolveReport:
        """``solve_external`` with the session's anchors and drags and its defaults (the scene's target)."""
        t0 = time.perf_counter()
        why = self._ready()
        if why:
            self.state = self._rest_report(why)
            return self.state
        try:
            res = self.exact()
        except ValueError as exc:  # what the saved scene would refuse (a drag into an obstacle ...): shown
            self.state, self.target = self._rest_report(f"refused: {exc}"), None
            return self.state
        self.placed = list(self.__dict__["_exact"][2])
        self.state, self.target = self._report(res, False, False, t0), (res.x.copy() if res.success else None)
        return self.state

    def exact(self):
        """``solve_external`` of the current anchors and drags with its defaults (what :meth:`settle` shows), with
        the scene's self-contact and the case's obstacles and friction as ``mdsr run`` solves the saved scene's
        target (:func:`~mdsr_opt.author.contact.target_solve`).

        The last result is kept with its fixed set, so the same fixed set is solved once: the server solves
        it while a drag pauses (stopped when the drag moves on), and the release then takes that result."""
        key = b"|".join(np.ascontiguousarray(a).tobytes() + str(a.shape).encode()
                        for a in (self.anchors, self.drag_nodes, self.drag_positions))
        c = self.__dict__.get("_exact")
        if c is None or c[0] != key:
            res, placed, _ = target_solve(self)
            c = self.__dict__["_exact"] = (key, res, placed)
        return c[1]

    def drag(self) -> SolveReport:
        """A live solve: warm start from the shown state via a predictor step; settle on failure.

        The predictor reuses the tangent stiffness factored at an earlier state of the same drag (a chord
        step), refreshed every few updates and whenever the step fails; the shown state is an equilibrium,
        so its free gradient is zero and the step is ``-K_ff^-1 K_fc dx_fixed``.
        """
        t0 = time.perf_counter()
        if self._ready():
            return self.settle()
        prev = self.state
        if prev is None or not (prev.success or prev.crossing and not prev.inverted):
            return self._cold(t0)  # a crossing equilibrium shown: the next preview starts there too
        contact = live_options(self)  # the obstacles where the last settled solve placed them
        # with contact no preview (it models none) and no predictor (its step may enter an obstacle): a
        # continuation from the shown state, load-stepped as needed
        for fresh in (None,) if contact else (False, True):
            guess = prev.x if contact else self._predict(prev.x, fresh)
            if guess is None:
                continue
            rep = None if contact else self._preview(guess, t0)
            if rep is not None:
                self.state, self.target = rep, None  # a live state is not the settled target
                return rep
            try:
                res = solve_external(self.mesh, self.material, self.anchors, (self.drag_nodes, self.drag_positions),
                                     initial_guess=guess, **({} if contact else {"min_step": 1.0}), **contact)
            except ValueError:  # e.g. a drag into an obstacle: the settled solve names it
                break
            rep = self._report(res, live=True, warm_failed=False, t0=t0)
            # converged but crossing itself: shown as it is (a cold solve would not uncross it)
            if res.success or rep.crossing and not rep.inverted and res.residual <= 1e-6:
                self.state = rep
                self.target = None  # a live state is not the settled target until the drag is released
                return self.state
        return self._cold(t0)

    def _cold(self, t0: float) -> SolveReport:
        rep = self.settle()
        rep.warm_failed = True
        rep.solve_time = time.perf_counter() - t0
        return rep

    #: Live updates before the chord predictor's tangent is refactored at the current state.
    REFRESH = 6
    #: A live preview's largest scaled residual (free gradient over ``E * thickness * size``) and its
    #: corrector steps; the settled solve then meets ``solve_external``'s default tolerance.
    PREVIEW_TOL = 1e-4
    PREVIEW_STEPS = 6

    def _fixed_mask(self) -> np.ndarray:
        fixed = np.zeros((self.n_nodes, 2), dtype=bool)
        fixed[np.concatenate([self.anchors, self.drag_nodes])] = True
        return fixed.reshape(-1)

    def _preview(self, y: np.ndarray, t0: float) -> SolveReport | None:
        """Corrector steps from the predicted state ``y``, until the scaled residual is at most
        :attr:`PREVIEW_TOL`: with the chord predictor's factorised tangent while the residual halves each
        step, else with the tangent refactorised at the current state (a Newton step; that factorisation is
        then reused by the next updates). A live state, or None (an inverted element, no convergence within
        :attr:`PREVIEW_STEPS`); a converged state whose boundary crosses itself is a failed live state
        naming the crossing, as ``solve_external`` rejects it."""
        fixed = self._fixed_mask()
        free = ~fixed
        c = self.__dict__.get("_chord")
        if c is None or c[0] != fixed.tobytes():
            return None
        lu = c[1]
        model = get_model(self.mesh, self.material)
        p = model.params(self.material)
        scale = float(self.material.E) * float(self.material.thickness) * body_size(self.mesh)
        z = y.reshape(-1).copy()
        last = np.inf
        for k in range(self.PREVIEW_STEPS + 1):
            g = model.gradient(z, p)[free]
            r = float(np.abs(g).max()) / scale if g.size else 0.0
            if not np.isfinite(r):
                return None
            if r <= self.PREVIEW_TOL:
                x = z.reshape(-1, 2)
                # an equilibrium whose boundary crosses itself: shown as solve_external would reject it
                crossing = bool(self.mesh.boundary_crosses(x))
                status = (f"preview (residual {r:.1e}); rejected: the boundary crosses itself (self-contact is "
                          "not modelled)") if crossing else f"preview (residual {r:.1e})"
                return SolveReport(x=x.copy(), success=not crossing, status=status, iterations=k,
                                   residual=r, min_J=float(self.mesh.jacobians(x).min()), crossing=crossing,
                                   inverted=[], live=True, solve_time=time.perf_counter() - t0)
            if k == self.PREVIEW_STEPS:
                return None
            if r > 0.5 * last:  # the old tangent no longer contracts: a Newton step at this state
                t = self._tangent(z.reshape(-1, 2), fixed, True)
                if t is None:
                    return None
                lu = t[0]
            last = r
            dz = lu.solve(-g)
            if not np.all(np.isfinite(dz)):
                return None
            z[free] += dz
            if self.mesh.jacobians(z.reshape(-1, 2)).min() <= 0:
                return None
        return None

    def _tangent(self, x: np.ndarray, fixed: np.ndarray, fresh: bool):
        key = fixed.tobytes()
        c = self.__dict__.get("_chord")
        if fresh or c is None or c[0] != key or c[3] >= self.REFRESH:
            model = get_model(self.mesh, self.material)
            H = model.hessian(x.reshape(-1), model.params(self.material)).tocsc()
            free = ~fixed
            try:
                lu = spla.splu(H[free][:, free].tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                               options={"SymmetricMode": True})
            except RuntimeError:  # singular: e.g. a free island of nodes
                self.__dict__.pop("_chord", None)
                return None
            c = [key, lu, H[free][:, fixed].tocsr(), 0]
            self.__dict__["_chord"] = c
        c[3] += 1
        return c[1], c[2]

    def _predict(self, x: np.ndarray, fresh: bool = False) -> np.ndarray | None:
        """Chord step from the equilibrium ``x`` with the fixed nodes moved to their prescribed positions
        (None when the step inverts an element or the free block is singular)."""
        n = self.n_nodes
        nodes = np.concatenate([self.anchors, self.drag_nodes])
        vals = np.vstack([self.mesh.points[self.anchors], self.drag_positions])
        fixed = np.zeros((n, 2), dtype=bool)
        fixed[nodes] = True
        fixed = fixed.reshape(-1)
        t = self._tangent(x, fixed, fresh)
        if t is None:
            return None
        lu, Hfc = t
        move = np.zeros((n, 2))
        move[nodes] = vals - x[nodes]
        dz = lu.solve(-(Hfc @ move.reshape(-1)[fixed]))
        if not np.all(np.isfinite(dz)):
            return None
        y = x.reshape(-1) + move.reshape(-1)
        y[~fixed] += dz
        y = y.reshape(-1, 2)
        return y if self.mesh.jacobians(y).min() > 0 else None

    # ------------------------------------------------------------------ muscles and design
    def _need_target(self) -> np.ndarray:
        if self.target is None:
            raise ValueError("no settled target yet: mark anchors and drags and let the solve succeed "
                             "(release the drag) first")
        return self.target

    def graph_weights(self) -> list:
        """Contraction-graph weights of the target, one per ``mesh.edges`` row."""
        G = contraction_graph(self.mesh, self._need_target())
        return [float(G.edges[int(a), int(b)]["weight"]) for a, b in self.mesh.edges]

    def fabrication_shown(self) -> dict:
        """The channel, wall and fixture sizes the next routing uses, every field set (in the body's unit).

        The page's fields when it routed, else the scene's ``[fabrication]`` (its fixture radius the design's
        ``anchor_radius`` if the scene gives one), each field left open taking
        :meth:`~mdsr_opt.synthesis.fabrication.Fabrication.for_body`'s default for this body."""
        spec = self.fabrication if self.routing is not None else self.routing_options.get("fabrication")
        return self.fabrication_sizes(spec) or Fabrication().for_body(self.mesh).to_dict()

    def fabrication_sizes(self, spec) -> dict | bool:
        """The sizes a routing with the fabrication ``spec`` (a dict of Fabrication's fields, None or False)
        uses on this body, every field set; False when ``spec`` turns the fabrication off."""
        fab = self._fabrication(spec)
        return False if fab is False else (fab or Fabrication()).for_body(self.mesh).to_dict()

    def _fabrication(self, spec):
        """``spec`` (a dict of Fabrication's fields, None or False) checked against the design's anchor_radius
        (which a fixture radius given here replaces: the page's field is that radius)."""
        given = spec if isinstance(spec, dict) else {}
        r = None if given.get("fixture_radius") is not None else self.design_options.get("anchor_radius")
        return check_fabrication(spec, r)

    def check_fabrication_fields(self, spec) -> dict:
        """The page's fabrication fields as a dict of the ones given (ValueError/TypeError naming a bad one).

        ``spec``: a dict with any of ``channel_diameter``, ``wall``, ``fixture_radius``,
        ``min_fixture_radius``, each a length >= 0 in the body's unit, and ``min_inset_fraction`` (a fraction of
        the body's diameter in [0, 0.5)), each or None (the default for this body)."""
        if not isinstance(spec, dict):
            raise TypeError(f"fabrication must be an object of lengths, got {type(spec).__name__}")
        names = [f for f in Fabrication.__dataclass_fields__]
        unknown = sorted(set(map(str, spec)) - set(names))
        if unknown:
            raise ValueError(f"fabrication: unknown field(s) {', '.join(unknown)}; expected {', '.join(names)}")
        out = {}
        for k in names:
            v = spec.get(k)
            if v is None or v == "":
                continue
            what = "fraction" if k == "min_inset_fraction" else "length"
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise TypeError(f"fabrication: {k} must be a {what} (a number >= 0), got {v!r}")
            if not math.isfinite(float(v)) or float(v) < 0:
                raise ValueError(f"fabrication: {k} must be a finite {what} >= 0, got {v!r}")
            out[k] = float(v)
        fab = self._fabrication(out)
        fab.for_body(self.mesh)  # min above fixture, a fixture half the body: refused here
        check_channel_fits(self.mesh, fab)  # a channel and wall the body cannot hold: refused as entered
        return out

    def route(self, K_a: float, K_b: float, max_muscles: int | None, fabrication: dict | None = None) -> dict:
        """Route muscles on the target with these knobs (the scene's other routing options kept).

        ``fabrication``: the channel, wall and fixture sizes (:meth:`check_fabrication_fields`; fields left out
        take their defaults for this body); None keeps the scene's ``[fabrication]``."""
        target = self._need_target()
        opts = dict(self.routing_options)
        # routed as mdsr run routes: route_for_design with its fallbacks, the scene's n_seeds or the default; a
        # knob is given only where the page changed it from the scene's (or the default), since route_for_design
        # keeps a given K_a as given
        defaults = routing_defaults()
        for k, v in (("K_a", float(K_a)), ("K_b", float(K_b))):
            if k in self.routing_options or v != defaults[k]:
                opts[k] = v
        opts["max_muscles"] = max_muscles
        if max_muscles is None:
            opts.pop("max_muscles")
        spec = opts.pop("fabrication", None)
        if fabrication is not None:
            spec = self.check_fabrication_fields(fabrication)
        fab = self._fabrication(spec)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", RoutingWarning)
            rr = route_for_design(self.mesh, target, **dict(opts, fabrication=fab))
        self.routing, self.routing_params, self.muscles, self.design = rr, opts, tuple(rr.muscles), None
        self.fabrication = spec
        self.dropped = ()
        self.deleted = ()
        self.routed_target = target.copy()
        out = self.routing_message()
        out["warnings"] = [str(w.message) for w in caught if issubclass(w.category, RoutingWarning)]
        return out

    def routing_message(self) -> dict:
        """The routed muscles still in the layout, their figures, the routing's notes (ends moved, stubs dropped,
        fixtures shrunk), the fixture radius and fabrication used, and the muscles the user deleted."""
        rr = self.routing
        names = {m.name for m in self.muscles}
        return {"muscles": muscle_entries(self.muscles),
                "stats": [{"name": s.name, "n_edges": s.n_edges, "contraction": s.contraction,
                           "nonuniformity": s.nonuniformity} for s in rr.stats if s.name in names],
                "n_units": rr.n_units, "params": {k: v for k, v in self.routing_params.items()},
                "notes": list(rr.notes), "fixture_radius": rr.fixture_radius,
                "fabrication": None if rr.fabrication is None else rr.fabrication.to_dict(),
                "deleted": list(self.deleted), "warnings": []}

    def delete_muscle(self, name: str) -> dict:
        """Take the muscle ``name`` out of the layout; the design is dropped (design again)."""
        if not isinstance(name, str):
            raise TypeError(f"muscle name must be a string, got {name!r}")
        if self.routing is None and not self.muscles:
            raise ValueError("no muscles yet: route muscles first")
        left = tuple(m for m in self.muscles if m.name != name)
        if len(left) == len(self.muscles):
            raise ValueError(f"no muscle {name!r} in the layout (muscles: "
                             f"{', '.join(str(m.name) for m in self.muscles) or 'none'})")
        self.muscles, self.design, self.dropped = left, None, ()
        self.deleted = self.deleted + (name,)
        return self.routing_message() if self.routing is not None else {
            "muscles": muscle_entries(left), "stats": [],
            "notes": [], "fixture_radius": None, "deleted": list(self.deleted), "warnings": []}

    @property
    def fixture_radius(self) -> float | None:
        """The end-fixture radius the routed muscles were fitted to (the design's ``anchor_radius``), while every
        muscle of the layout is a routed one (after deletions too); else None."""
        rr = self.routing
        if rr is None or rr.fixture_radius is None or not self.muscles:
            return None
        routed = {tuple(m.nodes) for m in rr.muscles}
        return rr.fixture_radius if all(tuple(m.nodes) in routed for m in self.muscles) else None

    def run_design(self, **params) -> dict:
        """Design the contractions of the routed muscles for the target (``params``: method, a_max,
        muscle_model, stiffness; the rest of the scene's design options kept)."""
        target = self._need_target()
        if not self.muscles:
            raise ValueError("no muscles yet: route muscles first")
        if not np.array_equal(getattr(self, "routed_target", None), target):
            raise ValueError("the target changed since the muscles were routed: route again")
        opts = dict(self.design_options)
        opts.update({k: v for k, v in params.items() if v is not None})
        if self.fixture_radius is not None:  # routed muscles: designed with the end fixtures they were fitted to
            opts["anchor_radius"] = self.fixture_radius
        # the wall a rope's two end fixtures keep between them: the fabrication's, as mdsr run designs it
        opts["fixture_wall"] = self.fabrication_shown()["wall"]
        # a case with obstacles: designed as mdsr run designs it (checked with them, clamped), said how
        run, said = design_options_with_obstacles(self, opts)
        # an idle muscle is dropped from the layout and the design made again; the summary says so
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", MuscleWarning)  # the summary's "saturated" says it
            idle = {k: self.acceptance[k] for k in ("idle_contraction",) if k in self.acceptance}  # as mdsr run
            res, kept, self.dropped = design_active(self.mesh, self.material, self.muscles, target, **idle, **run)
        self.designed_layout, self.muscles = self.muscles, tuple(kept)  # a save lays the layout designed
        self.design, self.design_params, self.design_notes = res, opts, said
        return self.design_summary()

    def design_summary(self) -> dict:
        """The design as the page shows it (:func:`~mdsr_opt.author.summary.design_summary`)."""
        return design_summary(self)


def _resolution(resolution):
    """Accept the page's strings for numbers ("600") as well as names and ints."""
    if isinstance(resolution, str) and resolution.strip().isdigit():
        return int(resolution)
    return resolution
