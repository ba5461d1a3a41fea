"""A virtual prototype: photographs from an independent, higher-fidelity model instead of the design model.

The paper validates its simulations and designs against photographs of cast silicone prototypes
(Tables 2-4). Photographing the design model's own driven state instead (a mirror) measures only how well
the design converged. :class:`VirtualPrototype` stands in for the cast body with a model that differs from
the design model in what a real robot differs:

- quadratic (6-node) triangles (:mod:`~mdsr_opt.mechanics.quadratic`) instead of linear ones, on a finer
  mesh: the scene rebuilt from its outline at ``refine`` times the design mesh's nodes (default 2x; with
  the edge midpoints about 8x the design model's nodes), or,
  for a scene with no outline to re-mesh (a mesh file, ``max_area``, no source), every triangle split into
  four (:func:`~mdsr_opt.mechanics.quadratic.split_mesh`);
- nearly incompressible silicone, a sheet in plane stress: :func:`prototype_material`, Poisson's ratio
  :data:`SILICONE_NU` (drawn within ``nu_range``), whatever material the design scene uses;
- a rope with capstan friction in its channel (:mod:`~mdsr_opt.mechanics.capstan`), coefficient ``friction``
  (default :data:`DEFAULT_ROPE_FRICTION`), pulled at its muscle's first node: its tension falls as
  ``exp(-mu theta)`` along the route;
- end fixtures of their physical size, radius ``fixture_radius`` (default: the scene's anchor radius; the
  mesh refined round the rope ends where it is too coarse for its end's ring of elements to lie within it,
  :func:`~mdsr_opt.mechanics.fixtures.fixture_mesh`): every node within it, edge midpoints included, moves
  rigidly with the end node (:mod:`~mdsr_opt.mechanics.fixtures`);
- the muscle's node chain re-laid on the fine mesh through the fine nodes nearest the design muscle's nodes
  (as a builder would place the tube); Young's modulus drawn within ``e_range`` (it scales every force, so
  it changes no shape driven by drags or rope strokes);
- the synthetic camera (:func:`~mdsr_opt.photos.camera.render_photo`) with its own seed, a 2 degree tilt and a
  rotation on the plate, photographing the quadratic state (its nodes drawn as the split mesh).

What each table then measures. Table 2 (external driving: the design model's drag-driven state against the
prototype dragged alike): discretisation (element order, mesh) and material law only, no muscles; the
fixtures and friction do not enter. Table 3 (internal driving: the muscle experiments at known contractions)
and Table 4 (the design target against the prototype driven by the designed muscles and contractions):
all of the above plus rope friction, the fixtures' size and the re-laid rope path. None contains gravity,
out-of-plane (3-D) deformation or bending of the sheet, contact (self-contact, the table, obstacles), the
channel's own compliance or the rope's stretch, viscoelasticity, or a real camera's lens and lighting; the
photographs are SYNTHETIC: no body was cast or photographed.

Example
-------
>>> from mdsr_opt.scenes.library import get_problem
>>> scene = get_problem("one_muscle", resolution="coarse")
>>> proto = VirtualPrototype.for_scene(scene, refine=2.0, seed=1)
>>> proto.mesh.n_nodes > 1.5 * scene.mesh.n_nodes
True
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..core.checks import check_int, positive_float
from ..body.muscles import Muscle
from ..body.material import NeoHookean
from ..mechanics.anchors import check_anchor_radius
from .fixtures import scene_fixture_radius
from ..mechanics.capstan import CapstanRope, quadratic_chain
from ..mechanics.fixtures import fixture_groups, fixture_mesh, free_lengths
from ..mechanics.quadratic import QuadraticModel, extend_prescribed, split_mesh, transfer_state
from ..mechanics.quadsolve import START_FULL_STEP, solve_quadratic_external, solve_quadratic_internal
from .select import edge_path

__all__ = ["VirtualPrototype", "PrototypeShot", "DEFAULT_REFINE", "DEFAULT_E_RANGE", "DEFAULT_NU_RANGE",
           "DEFAULT_ROPE_FRICTION", "SILICONE_NU", "prototype_material", "measure", "validate_case",
           "validation_tables"]

#: Node count of the prototype's vertex mesh over the design mesh's; its quadratic elements add a node on
#: every edge, so the prototype has about 4 x 2 = 8 times the design model's nodes.
DEFAULT_REFINE = 2.0
#: Relative range of the prototype's Young's modulus: E * U(1 - r, 1 + r).
DEFAULT_E_RANGE = 0.10
#: Range of the shift of the prototype's Poisson's ratio: SILICONE_NU + U(-r, r), at most 0.499.
DEFAULT_NU_RANGE = 0.05
#: Poisson's ratio of cast silicone rubber: nearly incompressible.
SILICONE_NU = 0.49
#: Coefficient of friction between the rope and its channel (capstan law). An assumed value for a braided
#: line in a cast silicone channel, not a measurement; ``friction=`` states another.
DEFAULT_ROPE_FRICTION = 0.3
#: Element order of the prototype (quadratic triangles).
DEFAULT_ORDER = 2


def prototype_material(E: float, nu: float, thickness: float = 1.0):
    """The prototype's silicone sheet: a compressible Neo-Hookean sheet in plane stress (the out-of-plane
    stretch that frees the sheet's faces, :class:`~mdsr_opt.body.material.NeoHookean` with
    ``plane="stress"``), Young's modulus ``E``, Poisson's ratio ``nu`` (nearly incompressible), thickness
    ``thickness``."""
    return NeoHookean(E=E, nu=nu, thickness=thickness, plane="stress")


@dataclass(eq=False)
class PrototypeShot:
    """The prototype in one state and its photograph.

    Attributes
    ----------
    x : (n_fine, 2) ndarray
        The prototype's equilibrium (every node of its quadratic mesh: vertices, then edge midpoints).
    success : bool
        The prototype's solve succeeded.
    status : str
        Its status, or why it failed.
    iterations : int
    photo : SyntheticPhoto or None
        The photograph (None when the solve failed).
    """

    x: np.ndarray
    success: bool
    status: str
    iterations: int = 0
    photo: Any = None


#: shots a prototype keeps (its cases' drivings and designs: a run asks for each once or twice)
SHOTS_KEPT = 16


def _fine_body(scene, n_fine: int):
    """The prototype's vertex mesh and the fixed nodes of each external case on it: the scene rebuilt from
    its source at ``n_fine`` nodes, or, when that does not refine it (a mesh file, ``max_area``, no source),
    every triangle split into four. Returns ``(fine scene or the scene, mesh, {case: (anchors, drag nodes,
    drag positions)}, how)``."""
    from .library import get_problem, remeshable_source

    fine = get_problem(scene.source, resolution=n_fine) if scene.source and remeshable_source(scene.source) else None
    if fine is not None and fine.mesh.n_nodes >= 1.2 * scene.mesh.n_nodes:
        if fine.case_names != scene.case_names:
            raise ValueError(f"the prototype of {scene.name!r} has cases {fine.case_names}, the design scene "
                             f"{scene.case_names}")
        fixed = {c.name: (c.anchors, c.drag_nodes, c.drag_positions) for c in fine.cases if c.kind == "external"}
        return fine, fine.mesh, fixed, "re-meshed"
    mesh = split_mesh(scene.mesh)
    fixed = {c.name: extend_prescribed(scene.mesh, c.anchors, c.drag_nodes, c.drag_positions)
             for c in scene.cases if c.kind == "external"}
    return scene, mesh, fixed, "split"


@dataclass(eq=False, frozen=True)
class VirtualPrototype:
    """A scene's body rebuilt finer on quadratic triangles, of silicone, with frictional ropes on fixtures
    and its own camera.

    Build it with :meth:`for_scene`. Attributes: ``scene`` (the fine scene, or the design scene when its mesh
    was split), ``mesh`` (the fine vertex mesh), ``fixed`` (per external case its anchors, drag nodes and
    positions on ``mesh``), ``design_mesh`` (the design model's mesh), ``material`` (the silicone model,
    :func:`prototype_material`), ``E_factor`` and ``nu_shift`` (the draws), ``nu`` (the silicone's Poisson
    ratio), ``refine``, ``refined_by`` (``"re-meshed"`` or ``"split"``), ``e_range``, ``nu_range``,
    ``friction``, ``fixture_radius``, ``order``, ``seed``, ``camera`` (keyword arguments of
    :func:`~mdsr_opt.photos.camera.render_photo`), ``nu_drawn`` (False when ``material`` was given).
    """

    scene: Any
    mesh: Any
    fixed: dict
    design_mesh: Any
    material: Any
    E_factor: float
    nu_shift: float
    nu: float
    refine: float
    refined_by: str
    e_range: float
    nu_range: float
    friction: float
    fixture_radius: float
    order: int
    seed: int
    camera: dict = field(default_factory=dict)
    nu_drawn: bool = True

    def __getstate__(self):  # pickled without the shots and the model it keeps (see _keep, model)
        return {k: v for k, v in self.__dict__.items() if not k.startswith("_")}

    @property
    def model(self):
        """The prototype's elastic model (:class:`~mdsr_opt.mechanics.quadratic.QuadraticModel`), built once."""
        if "_model" not in self.__dict__:
            self.__dict__["_model"] = QuadraticModel(self.mesh, self.material, self.order)
        return self.__dict__["_model"]

    @classmethod
    def for_scene(cls, scene, *, refine: float = DEFAULT_REFINE, e_range: float = DEFAULT_E_RANGE,
                  nu_range: float = DEFAULT_NU_RANGE, seed: int = 0, photo_size: tuple[int, int] = (500, 500),
                  friction: float = DEFAULT_ROPE_FRICTION, fixture_radius: float | None = None,
                  order: int = DEFAULT_ORDER, material=None) -> "VirtualPrototype":
        """The virtual prototype of ``scene`` (a :class:`~mdsr_opt.scenes.scene.Scene` built from the library, a
        problem script or a scene file: it is rebuilt from its source at ``refine`` times its nodes, or split
        when it cannot be re-meshed).

        Parameters
        ----------
        scene : Scene
        refine, e_range, nu_range : float
            Node count over the design mesh's; the relative spread of ``E`` and the spread of the silicone's
            ``nu`` drawn.
        seed : int
            Seed of the material draw and of the camera.
        photo_size : (int, int)
            (width, height) of the prototype's photographs in pixels.
        friction : float
            Coefficient of friction of the ropes in their channels (capstan law), in [0, 2].
        fixture_radius : float, optional
            Radius of the end fixtures in length units (default: the scene's, ``anchor_radius`` or ``[fabrication]
            fixture_radius``, else :func:`~mdsr_opt.mechanics.anchors.default_anchor_radius` of the design mesh).
        order : 1 or 2
            Element order (2: quadratic triangles; 1 for comparisons only).
        material : optional
            The prototype's material, replacing the silicone of :func:`prototype_material` (then no ``nu``
            is drawn; ``E`` is still scaled).

        Raises
        ------
        TypeError
            ``scene`` is not a Scene; ``seed`` not an int.
        ValueError
            ``refine`` not in [1, 10], ``e_range`` not in [0, 0.5), ``nu_range`` not in [0, 0.2], ``friction``
            not in [0, 2], a bad ``fixture_radius`` or ``order``, or a fine scene whose cases differ from
            the design scene's.
        """
        from .scene import Scene

        if not isinstance(scene, Scene):
            raise TypeError(f"scene must be a Scene, got {type(scene).__name__}")
        refine = positive_float(refine, "refine")
        if not 1.0 <= refine <= 10.0:
            raise ValueError(f"refine must lie in [1, 10] (node count over the design mesh's), got {refine}")
        e_range = positive_float(e_range, "e_range", allow_zero=True)
        nu_range = positive_float(nu_range, "nu_range", allow_zero=True)
        if e_range >= 0.5:
            raise ValueError(f"e_range must lie in [0, 0.5), got {e_range}")
        if nu_range > 0.2:
            raise ValueError(f"nu_range must lie in [0, 0.2], got {nu_range}")
        friction = positive_float(friction, "friction", allow_zero=True)
        if friction > 2.0:
            raise ValueError(f"friction (the rope's capstan coefficient) must lie in [0, 2], got {friction}")
        if isinstance(order, bool) or order not in (1, 2):
            raise ValueError(f"order must be 1 or 2, got {order!r}")
        seed = check_int(seed, "seed", 0)
        if fixture_radius is None:  # [design] anchor_radius or [fabrication] fixture_radius: one size
            fixture_radius = scene_fixture_radius(scene)
        radius = check_anchor_radius(scene.mesh, fixture_radius)
        fine, mesh, fixed, how = _fine_body(scene, int(round(refine * scene.mesh.n_nodes)))
        rng = np.random.default_rng([int(seed), 14])
        f_E = 1.0 + e_range * (2.0 * rng.random() - 1.0)
        d_nu = nu_range * (2.0 * rng.random() - 1.0)
        m = scene.material
        given = material
        if material is None:
            nu = float(min(SILICONE_NU + d_nu, 0.499))
            material = prototype_material(m.E * f_E, nu, m.thickness)
        else:
            nu = float(getattr(material, "nu", float("nan")))
            d_nu = 0.0
            if hasattr(material, "E") and dataclasses.is_dataclass(material):
                material = dataclasses.replace(material, E=material.E * f_E)
        camera = {"image_size": tuple(photo_size), "seed": 1000 + int(seed), "tilt_deg": 2.0,
                  "rotation_deg": float(rng.uniform(-8.0, 8.0))}
        return cls(scene=fine, mesh=mesh, fixed=fixed, design_mesh=scene.mesh, material=material,
                   E_factor=float(f_E), nu_shift=float(nu - SILICONE_NU) if d_nu else 0.0, nu=nu, refine=refine,
                   refined_by=how, e_range=e_range, nu_range=nu_range, friction=friction,
                   fixture_radius=float(radius), order=int(order), seed=int(seed), camera=camera,
                   nu_drawn=given is None)

    def describe(self) -> dict:
        """The prototype's parameters (JSON-ready). ``nodes`` counts every node of the quadratic mesh
        (vertices and edge midpoints), ``vertex_nodes`` those of its linear mesh."""
        n_all = self.mesh.n_nodes + (len(self.mesh.edges) if self.order == 2 else 0)
        return {"nodes": int(n_all), "vertex_nodes": int(self.mesh.n_nodes), "design_nodes": int(self.design_mesh.n_nodes),
                "refine": self.refine, "refined_by": self.refined_by,
                "elements": "quadratic (6-node)" if self.order == 2 else "linear (3-node)",
                "material": self.material.kind if hasattr(self.material, "kind") else type(self.material).__name__,
                "silicone_nu": self.nu, "E": float(self.material.E), "nu": float(self.material.nu),
                "plane": getattr(self.material, "plane", "strain"),
                "E_factor": self.E_factor, "nu_shift": self.nu_shift, "e_range": self.e_range,
                "nu_range": self.nu_range, "seed": self.seed, "muscle_model": "capstan rope",
                "rope_friction": self.friction, "fixture_radius": self.fixture_radius,
                "camera": {k: list(v) if isinstance(v, tuple) else v for k, v in self.camera.items()},
                "synthetic": True}

    # ------------------------------------------------------------------------------------------------ muscles
    def transfer_muscle(self, muscle: Muscle) -> Muscle:
        """The design mesh's muscle laid on the prototype's mesh: through the fine nodes nearest its nodes
        (on the boundary when the muscle runs along it), joined by shortest edge paths."""
        if not isinstance(muscle, Muscle):
            muscle = Muscle(muscle)
        X = self.design_mesh.points
        nodes = np.asarray(muscle.nodes)
        on_b = bool(np.isin(nodes, self.design_mesh.boundary_nodes).all())
        far = 2.0 * float(np.mean(self.design_mesh.edge_lengths))
        tries = [X[nodes], X[nodes[::2]] if len(nodes) > 4 else X[nodes], X[nodes[[0, len(nodes) // 2, -1]]]
                 if len(nodes) > 2 else X[nodes], X[nodes[[0, -1]]]]
        last = None
        for wp in tries:
            for boundary in ((True, False) if on_b else (False,)):
                try:
                    return edge_path(self.mesh, wp, name=muscle.name, boundary=boundary, tol=far)
                except ValueError as exc:  # a path that folds back on itself: fewer waypoints
                    last = exc
        raise ValueError(f"muscle {muscle.name or ''} could not be laid on the prototype's mesh: {last}")

    def drive(self, scene, case, guess=None) -> PrototypeShot:
        """The prototype driven as the design scene's ``case`` (a Case, or the name of one of ``scene``'s)
        says, photographed: the anchors and drags of the prototype's case of that name (:meth:`external`),
        or the case's muscles (the scene's) at its contractions (:meth:`internal`, ``guess`` passed on)."""
        c = scene.case(case) if isinstance(case, str) else case
        if c.kind == "external":
            return self.external(c.name, guess=guess)
        return self.internal(scene.case_muscles(c), c.contractions, guess=guess)

    def _solved(self, key):
        """The shot kept for ``key`` (the arguments that made it), or None; a shot asked for is kept longest."""
        shots = self.__dict__.get("_shots", {})
        shot = shots.pop(key, None)
        if shot is not None:
            shots[key] = shot
        return shot

    def _keep(self, shot_key, shot: PrototypeShot) -> PrototypeShot:
        """Keep ``shot`` (read-only: callers share it) for ``shot_key``; at most :data:`SHOTS_KEPT`, the one
        asked for least recently goes first."""
        shots = self.__dict__.setdefault("_shots", {})
        shot.x.setflags(write=False)
        if shot.photo is not None:
            shot.photo.image.setflags(write=False)
        shots[shot_key] = shot
        while len(shots) > SHOTS_KEPT:
            shots.pop(next(iter(shots)))
        return shot

    # ---------------------------------------------------------------------------------------------- states
    def photograph(self, x, model=None) -> Any:
        """The synthetic camera's photograph of the prototype in state ``x`` (fine mesh; of ``model``'s nodes
        when given)."""
        from ..photos.camera import render_photo

        return render_photo((model or self.model).display_mesh, x, **self.camera)

    def _shot(self, res, photo: bool, model=None) -> PrototypeShot:
        shot = PrototypeShot(x=np.asarray(res.x).copy(), success=bool(res.success), status=str(res.status),
                             iterations=int(res.iterations))
        if shot.success and photo:
            shot.photo = self.photograph(shot.x, model)
        return shot

    def external(self, case: str, photo: bool = True, guess=None) -> PrototypeShot:
        """The prototype driven externally as the case ``case`` says (its anchors and drags on the fine mesh,
        carried to the edge midpoints), from ``guess`` (as :meth:`internal`'s). Solved once per case."""

        if case not in self.fixed:
            raise ValueError(f"case {case!r} is internal driving or unknown; use internal() (external cases: "
                             f"{', '.join(self.fixed) or 'none'})")
        key = ("external", case, bool(photo))
        shot = self._solved(key)
        if shot is None:
            anchors, dn, dp = self.fixed[case]
            if self.order == 2:
                anchors, dn, dp = extend_prescribed(self.mesh, anchors, dn, dp)
            res = solve_quadratic_external(self.model, anchors, dn, dp, guess=None if guess is None else
                                           transfer_state(self.design_mesh, guess, self.model.points))
            shot = self._keep(key, self._shot(res, photo))
        return shot

    def _model_on(self, mesh):
        """The elastic model on ``mesh``: :attr:`model` on the prototype's mesh, else one built for that mesh
        (refined round fixtures, :func:`~mdsr_opt.mechanics.fixtures.fixture_mesh`), the last few kept."""
        if mesh is self.mesh:
            return self.model
        models = self.__dict__.setdefault("_fixture_models", {})
        key = mesh.points.tobytes() + mesh.triangles.tobytes()
        if key not in models:
            while len(models) >= 4:
                models.pop(next(iter(models)))
            models[key] = QuadraticModel(mesh, self.material, self.order)
        return models[key]

    def internal(self, muscles: Sequence[Muscle], contractions, photo: bool = True, guess=None,
                 fixture_radius: float | None = None) -> PrototypeShot:
        """The prototype driven by the design mesh's ``muscles`` (laid on the fine mesh, each a rope with
        capstan friction pulled at its first node, ending on fixtures of radius ``fixture_radius``) at
        ``contractions`` (rounded to 1e-9). Solved once per muscles and contractions: a second call returns the
        same shot. ``guess``, a state of the design mesh near the answer (the design model's equilibrium at
        these contractions), is carried to the prototype's nodes
        (:func:`~mdsr_opt.mechanics.quadratic.transfer_state`) and the solve starts there at the full load,
        stepping the load as without it when that fails
        (:func:`~mdsr_opt.mechanics.quadsolve.solve_quadratic_internal`): the same state to the solver's
        tolerance, found sooner. A shot of the same ropes and fixtures solved before at contractions within
        :data:`~mdsr_opt.mechanics.quadsolve.START_FULL_STEP` starts it instead (``start=``), likewise. ``fixture_radius``: the ends' fixtures for these muscles (default
        ``fixture_radius``; a routed design's ropes carry the fixture size they were fitted to, which may
        be smaller). The mesh is refined round rope ends too coarse for their fixtures
        (:func:`~mdsr_opt.mechanics.fixtures.fixture_mesh`); a rope whose stroke is at least its length between
        its fixtures gives a failed shot ``"not built: ..."`` with the figures, not a solve, and a failed solve's
        status says how much the most shortened rope shortens its length between fixtures."""

        a = np.asarray(contractions, dtype=float).ravel()
        if len(a) != len(muscles):
            raise ValueError(f"{len(a)} contraction(s) for {len(muscles)} muscle(s)")
        if not np.isfinite(a).all() or (a < 0).any() or (a >= 1).any():
            raise ValueError(f"contractions must lie in [0, 1), got {a.tolist()}")
        muscles = [m if isinstance(m, Muscle) else Muscle(m) for m in muscles]  # checked before the look-up
        if guess is not None:
            guess = np.asarray(guess, dtype=float)
            if guess.shape != self.design_mesh.points.shape or not np.isfinite(guess).all():
                raise ValueError(f"guess must be finite positions of the design mesh's {self.design_mesh.n_nodes} "
                                 f"nodes, got shape {guess.shape}")
        # solved at the contractions rounded to 1e-9 (a rope length change of 1e-9 L0): a design that
        # recovers a case's known contractions to that precision is the same shot, whichever is asked first
        a = np.round(a, 9)
        radius = self.fixture_radius if fixture_radius is None else float(fixture_radius)
        key = ("internal", tuple(m.nodes for m in muscles), a.tobytes(), bool(photo), radius)
        shot = self._solved(key)
        if shot is None:
            # fixtures of their physical size: the mesh refined round the rope ends where it is coarser
            mesh, fine = fixture_mesh(self.mesh, [self.transfer_muscle(m) for m in muscles], radius)
            model = self._model_on(mesh)
            mid = mesh.n_nodes + np.arange(len(mesh.edges)) if self.order == 2 else None
            groups = fixture_groups(mesh, fine, radius, mid)
            ropes = [CapstanRope(quadratic_chain(mesh, m.nodes, mid) if mid is not None else m.nodes,
                                 self.friction) for m in fine]
            free = free_lengths(model.points, [r.chain for r in ropes], groups)
            stroke = a * np.array([r.length(model.points) for r in ropes])
            over = np.flatnonzero(stroke >= free)
            if over.size:  # the fixtures would meet: no equilibrium to look for
                i = int(over[0])
                return self._keep(key, PrototypeShot(
                    x=model.points.copy(), success=False, status=(
                        f"not built: rope {fine[i].name or i}'s stroke {stroke[i]:.4g} is at least its length between "
                        f"its fixtures (radius {radius:.4g}), {free[i]:.4g}: they would meet; a smaller contraction "
                        "or smaller fixtures")))
            layout = key[:2] + key[4:]  # the same ropes and fixtures (so the same refined mesh), any contractions
            near, below = self._nearest_state(layout, a)
            predicted = None
            if near is None and guess is not None:
                predicted = transfer_state(self.design_mesh, guess, model.points)
            res = solve_quadratic_internal(model, ropes, a, groups, guess=predicted,
                                           start=near if near is not None else below)
            if res.success:
                states = self.__dict__.setdefault("_states", {})
                states[(layout, a.tobytes())] = res
                while len(states) > SHOTS_KEPT:
                    states.pop(next(iter(states)))
            shot = self._shot(res, photo, model)
            if not shot.success:
                i = int(np.argmax(stroke / free))
                shot.status += (f"; rope {fine[i].name or i} shortens its length between its fixtures (radius "
                                f"{radius:.4g}) by {100 * stroke[i] / free[i]:.0f} %")
            shot = self._keep(key, shot)
        return shot

    def _nearest_state(self, layout, a: np.ndarray):
        """The prototype's own solved equilibria of the same ropes and fixtures (``layout``) to start a solve
        at contractions ``a`` from: ``(near, below)``. ``near``: the one whose contractions are nearest ``a``,
        when they lie within :data:`~mdsr_opt.mechanics.quadsolve.START_FULL_STEP` of it (the design of an
        internal case recovers its known contractions: its Table 4 shot starts from the Table 3 one); else
        None. ``below``: the one nearest ``a`` among those on the way from rest to ``a`` (each contraction
        between 0 and its value in ``a``), from which the load is stepped instead of from rest when there is
        no ``near`` state and a prediction fails (the muscle experiments' 20, 30, 40, 50 %); else None."""
        best, gap = None, START_FULL_STEP
        below, gap_below = None, np.inf
        for (lay, _a), res in self.__dict__.get("_states", {}).items():
            if lay != layout:
                continue
            d = float(np.abs(res.commanded - a).max())
            if d <= gap:
                best, gap = res, d
            if d < gap_below and (res.commanded <= a).all():
                below, gap_below = res, d
        return best, below


def measure(design_mesh, x_design, photo) -> dict:
    """Compare the design model's state with a photograph of the prototype, holes included.

    Returns a dict of ``mean_px``, ``std_px``, ``max_px``, ``ratio`` over every loop, ``outer_mean_px`` (the
    outer outline alone, the paper's measure) and ``n_unmatched`` holes."""
    from ..photos.loops import compare_loops, simulated_loops
    from ..photos.contours import contour_loops_from_image

    r = compare_loops(simulated_loops(design_mesh, x_design), contour_loops_from_image(photo.image))
    return {"mean_px": r.mean_px, "std_px": r.std_px, "max_px": r.max_px, "ratio": r.ratio,
            "outer_mean_px": r.outer.mean_px, "outer_std_px": r.outer.std_px, "outer_ratio": r.outer.ratio,
            "n_unmatched": r.n_unmatched}


def validate_case(prototype: VirtualPrototype, setup, design=None, log=None, prefix: str = "",
                  driving: bool = True) -> tuple[dict, dict]:
    """The paper's validation of one case against the virtual prototype.

    ``driving`` (Table 2 for an external case, Table 3 for an internal one): the design model's simulation
    of the case's own driving (``setup.target``) against a photograph of the prototype driven the same way
    (:meth:`VirtualPrototype.drive`: the anchors and drags of the prototype's case of that name; or the
    scene's muscles at ``setup.case``'s contractions). ``design`` (Table 4):
    the target against a photograph of the prototype driven by the designed contractions of the designed
    muscles (``design``, a :class:`~mdsr_opt.synthesis.results.DesignResult`; skipped when None; ``driving``
    False skips the driving: a job of its own beside the design's).

    Returns
    -------
    (metrics, photos)
        ``metrics``: ``{"driving": {...}, "design": {...}, "prototype": describe()}``, each entry with
        ``table``, ``success``, ``status`` and, when the prototype's solve succeeded, :func:`measure`'s
        figures; ``photos``: ``{"driving": SyntheticPhoto, "design": SyntheticPhoto}`` of those that exist.
        A failed prototype solve or an unmeasurable photograph is reported in ``status``, never raised.
    """
    say = log or (lambda s: None)
    case = setup.case
    scene = setup.scene
    out: dict = {"prototype": prototype.describe()}
    photos: dict = {}

    def run(key, table, make, radius=None):
        fixtures = {} if radius is None else {"fixture_radius": float(radius)}
        try:
            shot = make()
        except ValueError as exc:  # a muscle that cannot be laid on the fine mesh
            out[key] = {"table": table, "success": False, "status": f"not built: {exc}", **fixtures}
            return
        entry = {"table": table, "success": shot.success, "status": shot.status, **fixtures}
        if shot.success:
            try:
                entry.update(measure(scene.mesh, setup.target, shot.photo))
            except ValueError as exc:
                entry.update(success=False, status=f"photograph could not be measured: {exc}")
            else:
                photos[key] = shot.photo
        out[key] = entry
        what = "external driving" if table == 2 else "internal driving" if table == 3 else "design"
        what += f", fixtures of radius {radius:.3g}" if radius is not None else ""
        if entry["success"]:
            say(f"{prefix}virtual prototype ({what}, Table {table}): d over every loop = {entry['mean_px']:.2f} px "
                f"(ratio {100 * entry['ratio']:.2f} %), outline d = {entry['outer_mean_px']:.2f} px")
        else:
            say(f"{prefix}virtual prototype ({what}, Table {table}): FAILED: {entry['status']}")

    def near(x):  # a design-model equilibrium starts the prototype's solve (the same state, found sooner)
        x = None if x is None else np.asarray(x, dtype=float)
        return x if x is not None and x.shape == prototype.design_mesh.points.shape and np.isfinite(x).all() else None

    if driving:
        run("driving", 2 if case.kind == "external" else 3, lambda: prototype.drive(scene, case, guess=near(
            setup.target)), None if case.kind == "external" else prototype.fixture_radius)
    if design is not None:
        r_design = getattr(design, "anchor_radius", None)  # the fixtures the ropes were fitted to and exported with
        radius = float(r_design) if r_design is not None and np.isfinite(r_design) and r_design > 0 else \
            prototype.fixture_radius  # a point end (0) is no fixture a prototype can mould: its own size
        run("design", 4, lambda: prototype.internal(setup.muscles, design.contractions,
                                                    guess=near(getattr(design, "x", None)),
                                                    fixture_radius=radius), radius)
        out["prototype"]["fixture_radius"] = radius  # this case's ropes' fixtures, not the scene's default
    return out, photos


def _row(scene: str, case, entry: dict, extra: str) -> str:
    if not entry or not entry.get("success"):
        why = (entry or {}).get("status", "not run")
        return f"| {scene} | {case} | {extra} | - | - | - | - | FAILED: {why} |"
    return (f"| {scene} | {case} | {extra} | {entry['mean_px']:.2f} | {entry['std_px']:.2f} | "
            f"{100 * entry['ratio']:.2f} | {entry['outer_mean_px']:.2f} | {entry['n_unmatched']} |")


def validation_tables(reports: Sequence) -> str:
    """Tables 2, 3 and 4 against the virtual prototype as Markdown, from scene reports (``SceneReport``
    objects or their ``to_dict()``), one row per case that has the figures.

    Table 2: external cases, the design model's external driving against the prototype driven the same way.
    Table 3: internal cases (the muscle experiments), likewise with the scene's muscles. Table 4: external
    cases, the target against the prototype driven by the designed muscles and contractions (an internal
    case's design recovers its known contractions, so its Table 4 row would repeat Table 3)."""
    def cases(r):
        d = r if isinstance(r, dict) else r.to_dict()
        return d["scene"], d["cases"]

    head = ("| scene | case | {} | d over every loop (px) | sd (px) | ratio (%) | outline d (px) | unmatched holes |\n"
            "| --- | --- | --- | ---: | ---: | ---: | ---: | ---: |")
    t2, t3, t4 = [], [], []
    proto = None
    for r in reports:
        name, cs = cases(r)
        for c in cs:
            p = ((c.get("photo") or {}).get("prototype")) or {}
            if not p:
                continue
            proto = proto or p.get("prototype")
            if c["kind"] == "external":
                t2.append(_row(name, c["case"], p.get("driving"), "anchors + drags"))
            else:
                a = ", ".join(f"{v:.0%}" for v in (c.get("known_contractions") or []))
                t3.append(_row(name, c["case"], p.get("driving"), a or "-"))
            if "design" in p and c["kind"] == "external":  # an internal case's design repeats Table 3
                a = ", ".join(f"{v:.3f}" for v in (c.get("contractions") or []))
                t4.append(_row(name, c["case"], p.get("design"), a or "-"))
    desc = ""
    if proto:
        elements = proto.get("elements", "linear (3-node)")
        rope = (f"ropes with capstan friction mu = {proto['rope_friction']:g} pulled at the muscle's first node, "
                "end fixtures of the size each design's ropes were fitted to and exported with (a ring of "
                "elements where that radius holds no node)") if "rope_friction" in proto else "the exact sliding cable"
        nu = (f"silicone with nu = {proto['silicone_nu']:.3f} (drawn in {SILICONE_NU:g} +- {proto['nu_range']:g}, "
              "at most 0.499)" if "silicone_nu" in proto else f"nu + U(+- {proto['nu_range']:g})")
        if proto.get("plane") == "stress":
            nu += " as a plane-stress sheet"
        desc = (f"Virtual prototype (SYNTHETIC photographs): {elements} triangles on a {proto['refine']:g}x finer "
                f"mesh of each body, {nu}, {rope}, E x U(1 +- {proto['e_range']:g}) drawn from seed "
                f"{proto['seed']}, camera tilt {proto['camera']['tilt_deg']:g} deg at "
                f"{proto['camera']['image_size'][0]}x{proto['camera']['image_size'][1]} px. d: mean distance of "
                "the design model's boundary nodes (outline and holes) to the prototype photograph's contours; "
                "ratio: d over sqrt(area) of the photographed outline. Table 2 contains the element order, the "
                "mesh and the material law; Tables 3 and 4 also the rope friction, the fixtures and the re-laid "
                "rope path. None contains gravity, 3-D (out-of-plane) deformation or contact.\n\n")
    parts = ["# Validation against the virtual prototype (the paper's Tables 2-4)\n", desc]
    for title, rows, col in (("Table 2: external driving, simulation vs prototype", t2, "driving"),
                             ("Table 3: internal driving, simulation vs prototype", t3, "contractions"),
                             ("Table 4: design target vs prototype driven by the design", t4,
                              "designed contractions")):
        parts.append(f"## {title}\n\n" + head.format(col) + "\n" + ("\n".join(rows) if rows else
                                                                      "| (no case) | | | | | | | |") + "\n")
    return "\n".join(parts)
