"""Animations of a scene: forward solves between designed contractions, frame by frame."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Sequence
import numpy as np

from ..body.muscles import Muscle
from ..core.results import compact_repr, load_fields, save_fields
from ..plot.style import muscle_label
from ..synthesis.gait import warm_start_state
from .fixtures import scene_fixture_radius
from .obstacles import case_contact
from .reader import contact_options
from .rundir import check_interrupt
from .scene import Animation, Scene, UnknownName

__all__ = ['AnimationResult', 'animate']


@dataclass
class AnimationResult:
    """The frames of an :class:`Animation`: forward internal-driving solves of interpolated contractions.

    Attributes
    ----------
    name : str
    muscles : tuple of Muscle
        The muscles of every case in the animation (each once).
    contractions : (frames, m) ndarray
        The contractions of every frame.
    states : list of (n, 2) ndarrays
        The equilibrium of every frame (aligned to the rest shape).
    success : bool
        Every frame's forward solve succeeded.
    failed_frames : list of int
    message : str
        Why the animation could not be made, or (a success) the note that its end fixtures differ from
        the cases' designs; empty otherwise.
    """

    name: str
    muscles: tuple = ()
    contractions: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    states: list = field(default_factory=list)
    success: bool = False
    failed_frames: list = field(default_factory=list)
    message: str = ""

    def __repr__(self) -> str:
        return compact_repr(self, ("name", "success"), extra={
            "n_frames": len(self.states), "n_muscles": len(self.muscles), "failed_frames": self.failed_frames,
            "contractions": np.asarray(self.contractions), "message": self.message})

    def to_dict(self) -> dict:
        """JSON-ready: no states (they are in the GIF), the muscles and per-frame contractions."""
        return {"name": self.name, "success": self.success, "message": self.message,
                "n_frames": len(self.states), "failed_frames": list(self.failed_frames),
                "muscles": [{"nodes": list(m.nodes), "name": m.name} for m in self.muscles],
                "contractions": np.asarray(self.contractions).tolist()}

    def save(self, path) -> str:
        """Write the animation, its states included, as one ``.npz`` file (arrays exactly); returns the path.
        :meth:`load` reads it back. An existing file of that name is replaced, without a warning (``mdsr run`` refuses
        to without ``--overwrite``)."""
        states = np.asarray(self.states, dtype=float) if self.states else np.zeros((0, 0, 2))
        return save_fields(self, path, "animation", skip=("states",), extra_arrays={"states": states})

    @classmethod
    def load(cls, path) -> "AnimationResult":
        """Read an animation written by :meth:`save` (ValueError naming a damaged or foreign file)."""
        return load_fields(cls, path, "animation", convert={
            "muscles": lambda ms: tuple(Muscle(tuple(m["nodes"]), name=m["name"]) for m in ms),
            "states": lambda s: [np.array(x) for x in s]})


def animate(scene: Scene, animation: Animation | str, designs: Mapping[str, tuple]) -> AnimationResult:
    """Forward-solve every frame of an animation.

    Parameters
    ----------
    scene : Scene
    animation : Animation or its name in ``scene.animations``.
    designs : mapping of case name to ``(muscles, contractions)`` or ``(muscles, contractions, anchor_radius)``
        The designed muscles and contractions of every case the animation names (from :func:`run_case`:
        ``(run.setup.muscles, run.design.contractions, run.design.anchor_radius)``), and the radius of the
        end fixtures the design was made with.

    Each keyframe ``(case, f)`` sets that case's muscles to ``f`` times its contractions and every other
    muscle to 0 (``"rest"`` sets all to 0); frames in between interpolate linearly. Muscles shared by
    several cases (equal node paths) are one muscle. The frames are solved with the end fixtures the cases
    were designed with (the scene's ``anchor_radius``, else the radius every case's design gives); only
    when the cases' fixtures differ (layouts fitted apart) one size is taken at which every rope keeps its
    fixtures (:func:`~mdsr_opt.synthesis.routing_fixtures.common_fixture_radius`), and the result's
    ``message`` says so. Every frame takes the scene's obstacles and those of the cases named (the
    message names the cases whose own obstacles stand in every frame), and self-contact as the scene asks.
    """
    from ..mechanics.equilibrium import solve_internal

    if isinstance(animation, str):
        found = [a for a in scene.animations if a.name == animation]
        if not found:
            raise UnknownName(f"scene {scene.name!r} has no animation {animation!r} "
                              f"(animations: {', '.join(a.name for a in scene.animations) or 'none'})")
        animation = found[0]
    for cname in animation.cases:
        if cname not in designs:
            return AnimationResult(animation.name, message=f"case {cname!r} has no design in this run")
        mus, a = designs[cname][:2]
        if len(mus) != len(a):
            raise ValueError(f"designs[{cname!r}]: {len(a)} contraction(s) for {len(mus)} muscle(s)")
    union, slots = union_of_layouts({c: designs[c][0] for c in animation.cases})
    a_of = {}
    for cname, idx in slots.items():
        v = np.zeros(len(union))
        v[idx] = np.asarray(designs[cname][1], dtype=float)
        a_of[cname] = v
    keys = [np.zeros(len(union)) if c == "rest" else f * a_of[c] for c, f in animation.keyframes]
    frames = []
    for k0, k1 in zip(keys[:-1], keys[1:]):
        for j in range(animation.frames_per_step):
            frames.append(k0 + (k1 - k0) * j / animation.frames_per_step)
    frames.append(keys[-1])
    opts = scene.design_options
    model, stiffness = opts.get("muscle_model", "cable"), opts.get("stiffness", 10.0)
    states, fails = [], []
    # An animation goes out and back (rest -> pose -> rest ...): frames with the same contractions are solved
    # once (to 12 decimals; the way back computes them with other rounding) and the state reused. A frame in
    # which nothing contracts is the rest shape exactly. A frame is started from the previous frame's state
    # (moved to the solver's gauge: warm_start_state), else from the solver's default start.
    solved: dict[bytes, tuple] = {}
    prev = None
    # given muscles end on the scene's one fixture size ([design] anchor_radius or [fabrication] fixture_radius)
    radius, note = (scene_fixture_radius(scene) if scene.muscles is not None else opts.get("anchor_radius")), ""
    # the fixtures the cases' designs were made with (a routed layout's fit its ropes)
    given = {c: float(designs[c][2]) for c in animation.cases if len(designs[c]) > 2 and designs[c][2] is not None
             and np.isfinite(designs[c][2])}
    if given and len(given) == len(animation.cases) and (
            max(given.values()) - min(given.values()) <= 1e-9 * max(max(given.values()), 1e-300)):
        radius = next(iter(given.values()))  # also over the scene's: a case's own muscles bring their own
    elif radius is not None and given and any(abs(r - radius) > 1e-9 * radius for r in given.values()):
        note = (f"end fixtures of radius {radius:.4g}, the scene's (the cases' designs: "
                + ", ".join(f"{c} {r:.4g}" for c, r in given.items()) + ")")
    elif radius is None and scene.muscles is None and scene.routing_options.get("fabrication") is not False:
        # routed layouts fitted apart: one size all the driven ropes keep their fixtures with
        from ..synthesis.fabrication import check_fabrication
        from ..synthesis.routing_fixtures import common_fixture_radius

        fab = check_fabrication(scene.routing_options.get("fabrication")).for_body(scene.mesh)
        radius = common_fixture_radius(scene.mesh, union, fab)
        if given:
            note = (f"end fixtures of radius {radius:.4g} (the cases' designs: "
                    + ", ".join(f"{c} {r:.4g}" for c, r in given.items()) + "): one size every rope keeps its "
                    "fixtures with")
    kw = dict(muscle_model=model, stiffness=stiffness, anchor_radius=radius, **contact_options(opts))
    # the scene's obstacles and those of every case named, in every frame (a frame is one state of the body)
    obs = list(scene.obstacles) + [o for c in animation.cases for o in scene.case(c).obstacles]
    if obs:
        mus = {case_contact(scene, scene.case(c)).get("friction", 0.0) for c in animation.cases} or {0.0}
        kw.update(obstacles=obs, friction=max(mus) if animation.cases else float(scene.friction or 0.0))
        own = [c for c in animation.cases if scene.case(c).obstacles]
        if own:
            note = "; ".join(m for m in (note, "every frame solved with the obstacles of case(s) " + ", ".join(own)
                                         + (" and the scene's" if scene.obstacles else "")) if m)
    for i, a in enumerate(frames):
        key = np.round(a, 12).tobytes()
        if key not in solved:
            if not np.any(a > 0):
                solved[key] = (scene.mesh.points.copy(), True)
            else:
                guess = warm_start_state(scene.mesh, prev) if prev is not None else None
                res = None
                if guess is not None:
                    res = solve_internal(scene.mesh, scene.material, union, a, initial_guess=guess, **kw)
                    check_interrupt()
                if res is None or not res.success:
                    res = solve_internal(scene.mesh, scene.material, union, a, **kw)
                    check_interrupt()
                solved[key] = (res.x, bool(res.success))
        x, ok = solved[key]
        if not ok:
            fails.append(i)
        states.append(x.copy())
        prev = x if ok and np.any(a > 0) else None
    msg = "; ".join(m for m in (f"{len(fails)} forward solve(s) failed" if fails else "", note) if m)
    return AnimationResult(animation.name, tuple(union), np.array(frames), states, not fails, fails, msg)


def union_of_layouts(layouts: Mapping[str, Sequence[Muscle]]) -> tuple[tuple, dict]:
    """The muscles of several cases' layouts, each once, with names unique in the union.

    A muscle whose node path is in several cases' layouts is one muscle and keeps its name. When names
    collide (``M1`` of two separately routed cases), every muscle of one case only is prefixed by its case
    (``bend_left:M1``, ``bend_right:M1``, ``bend_right:M2``), so that no name reads as another case's;
    unnamed muscles are named by their place in their case's layout
    (:func:`~mdsr_opt.plot.style.muscle_label`) first.

    Returns
    -------
    union : tuple of Muscle
    slots : dict
        Per case, the places in ``union`` of its layout's muscles, in order.
    """
    union: list[Muscle] = []
    source: list[tuple[str, str]] = []  # (first case, the muscle's name there)
    cases_of: list[set] = []
    slots: dict[str, list[int]] = {}
    for cname, mus in layouts.items():
        idx = []
        for i, m in enumerate(mus):
            if m not in union:  # equal node paths are one muscle (Muscle compares its nodes only)
                union.append(m)
                source.append((cname, muscle_label(m, i)))
                cases_of.append(set())
            k = union.index(m)
            cases_of[k].add(cname)
            idx.append(k)
        slots[cname] = idx
    names = [own for _, own in source]
    if len(set(names)) < len(names):
        names = [own if len(cases_of[k]) > 1 else f"{c}:{own}" for k, (c, own) in enumerate(source)]
        for k, n in enumerate(names):  # a shared muscle's name another one still carries: its first case too
            if names.count(n) > 1:
                names[k] = f"{source[k][0]}:{n}" if ":" not in n else f"{n}#{k + 1}"
    return tuple(Muscle(m.nodes, name=n) for m, n in zip(union, names)), slots
