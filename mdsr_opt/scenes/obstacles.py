"""Rigid obstacles in scenes: the scene file's ``[[obstacles]]`` (and a case's ``obstacles``), the checks a
:class:`~mdsr_opt.scenes.scene.Scene` makes of them at the door, and the contact keywords of a case's solves.

A scene's obstacles stand in every case; a case's own stand in that case only (added to the scene's). Each
is a :class:`~mdsr_opt.Disk`, :class:`~mdsr_opt.HalfPlane` or convex :class:`~mdsr_opt.Obstacle`, in the
coordinates of the body at rest; ``friction`` is Coulomb's coefficient between the body and every obstacle
(the solvers take one), in the targets' solves; the design's solves are frictionless
(:func:`~mdsr_opt.synthesis.contractions.design_contractions` takes no friction), which a case's report says.

Example
-------
>>> from mdsr_opt.scenes.reader import Reader
>>> obs, mu = read_obstacles(Reader("scene.toml"), [{"disk": {"center": [0, 0], "radius": 1.0}, "friction": 0.3},
...                                                 {"halfplane": {"point": [0, -2], "normal": [0, 1]}}], "obstacles")
>>> obs, mu
([Disk(center=[0.0, 0.0], radius=1), HalfPlane(point=[0.0, -2.0], normal=[0.0, 1.0])], 0.3)
"""

from __future__ import annotations

import numbers

from ..core.checks import friction_coefficient
from ..mechanics.obstacles import Disk, HalfPlane, Obstacle, check_obstacles
from .reader import Reader, SceneFileError, tname

__all__ = ["FreeDisk", "read_obstacles", "check_friction", "check_case_obstacles", "case_contact", "solve_friction",
           "obstacle_tables"]


class FreeDisk(Disk):
    """A disk the body grips, free to move: a case's target solve places it where the contacts' net force on
    it vanishes, starting from ``center`` (:func:`~mdsr_opt.mechanics.grip.free_disk`, secant steps of the
    centre, each a solve), and the case's later solves take it there. The solves of a case with a free disk
    are frictionless (the disk follows the grip until nothing pushes it; friction is the grip report's
    coefficient, :mod:`~mdsr_opt.scenes.grips`). At most one per case."""

    def __repr__(self) -> str:
        return f"FreeDisk(center={self.center.tolist()}, radius={self.radius:g})"

    def to_dict(self) -> dict:
        return {"type": "FreeDisk", "center": self.center.tolist(), "radius": self.radius}

_OBSTACLE_KEYS = ("disk", "halfplane", "polygon", "friction")
_SHAPES = ("disk", "halfplane", "polygon")


def read_obstacles(r: Reader, spec, where: str) -> tuple[list, float | None]:
    """The obstacles of a scene file's ``[[obstacles]]`` list (or a case's ``obstacles``) and their friction
    (None: not given). Each entry holds exactly one of ``disk = {center, radius}``,
    ``halfplane = {point, normal}`` and ``polygon = [[x, y], ...]`` (convex), and optionally ``friction``;
    the frictions given must agree (the solvers take one coefficient). Errors name the file and the field."""
    if not isinstance(spec, list):
        r.fail(where, f"expected a list of obstacles ([[obstacles]] tables), got {tname(spec)}", TypeError)
    out, mu, mu_at = [], None, None
    for i, entry in enumerate(spec):
        w = f"{where}[{i}]"
        e = r.keys(entry, _OBSTACLE_KEYS, w)
        shapes = [k for k in _SHAPES if k in e]
        if len(shapes) != 1:
            r.fail(w, "give exactly one of disk = {center, radius}, halfplane = {point, normal} and polygon = "
                   "[[x, y], ...]")
        kind = shapes[0]
        try:
            if kind == "disk":
                d = r.keys(e["disk"], ("center", "radius", "free"), f"{w}.disk", required=("center", "radius"))
                free = d.get("free", False)
                if not isinstance(free, bool):
                    r.fail(f"{w}.disk.free", f"expected true or false, got {free!r}", TypeError)
                out.append((FreeDisk if free else Disk)(r.point(d["center"], f"{w}.disk.center"),
                                                        r.number(d["radius"], f"{w}.disk.radius", positive=True)))
            elif kind == "halfplane":
                h = r.keys(e["halfplane"], ("point", "normal"), f"{w}.halfplane", required=("point", "normal"))
                out.append(HalfPlane(r.point(h["point"], f"{w}.halfplane.point"),
                                     r.point(h["normal"], f"{w}.halfplane.normal")))
            else:
                out.append(Obstacle(r.points(e["polygon"], f"{w}.polygon", at_least=3)))
        except SceneFileError:
            raise
        except ValueError as exc:  # the obstacle's own check (a zero normal, a non-convex polygon ...)
            r.fail(f"{w}.{kind}", str(exc))
        if "friction" in e:
            f = r.number(e["friction"], f"{w}.friction")
            if f < 0:
                r.fail(f"{w}.friction", f"must be >= 0 (Coulomb's coefficient), got {f:g}")
            if mu is not None and f != mu:
                r.fail(f"{w}.friction", f"is {f:g}, but {mu_at} is {mu:g}: the solvers take one friction "
                       "coefficient between the body and every obstacle; give the same (or one) value")
            mu, mu_at = f, f"{w}.friction"
    return out, mu


def check_friction(friction, label: str) -> float | None:
    """``friction``: None (not given) or a number >= 0 (Coulomb's coefficient); TypeError/ValueError naming
    ``label`` otherwise."""
    if friction is None:
        return None
    if isinstance(friction, bool) or not isinstance(friction, numbers.Real):
        raise TypeError(f"{label}: friction must be a number >= 0, got {type(friction).__name__}")
    return friction_coefficient(friction, f"{label}: friction")


def check_case_obstacles(scene, case) -> None:
    """Refuse, naming the scene and the case, what the case's solves would refuse mid-run: an obstacle that
    holds a node of the body at rest (:func:`~mdsr_opt.mechanics.obstacles.check_obstacles`), a drag whose
    straight path from rest enters an obstacle (:func:`~mdsr_opt.mechanics.obstacles.check_prescribed`, the
    solver's own check), and an external case with obstacles anchored at fewer than two nodes (its design is
    clamped where the target was anchored, :func:`~mdsr_opt.synthesis.pipeline.design_pipeline`)."""
    from ..mechanics.anchors import body_size
    from ..mechanics.contactsteps import DEFAULT_GAP
    from ..mechanics.obstacles import check_prescribed

    kw = case_contact(scene, case)
    obs = kw.get("obstacles", [])
    label = f"scene {scene.name!r}, case {case.name!r}"
    if not obs:
        if case.friction is not None:  # a coefficient between the body and nothing: a mistake, said
            raise ValueError(f"{label}: friction {case.friction:g} is given but the case has no obstacles (neither "
                             "the scene's nor its own)")
        return
    free = [i for i, o in enumerate(obs) if isinstance(o, FreeDisk)]
    if len(free) > 1:
        raise ValueError(f"{label}: {len(free)} free disks (obstacles {free}): a case places one free disk where its "
                         "grip holds it; give the others as fixed disks")
    for whose, given in (("the scene's", scene.obstacles), ("the case's", case.obstacles)):
        try:  # each list on its own, so that the message's index is where the scene or the case gives it
            check_obstacles(list(given), scene.mesh)
        except ValueError as exc:
            raise ValueError(f"{label}: {whose} {exc}") from None
    if case.kind != "external":
        return
    if len(case.anchors) < 2:
        raise ValueError(f"{label}: a case with obstacles is designed clamped where its target was anchored (the "
                         f"obstacles stand in that frame), but it has {len(case.anchors)} anchor(s): give at least "
                         "two anchors")
    if len(case.drag_nodes):
        P = scene.mesh.points[case.drag_nodes]
        gap = scene.design_options.get("contact_gap") or DEFAULT_GAP * body_size(scene.mesh)
        try:
            check_prescribed(obs, case.drag_nodes, lambda s: P + s * (case.drag_positions - P), gap)
        except ValueError as exc:
            raise ValueError(f"{label}: {exc}") from None


def case_contact(scene, case) -> dict:
    """The obstacle keywords of ``case``'s solves: ``{}`` without obstacles, else ``{"obstacles": the
    scene's then the case's, "friction": the case's, else the scene's, else 0}`` (the friction of the grip
    report; the solves of a case with a :class:`FreeDisk` take none, :func:`solve_friction`)."""
    obs = list(scene.obstacles) + list(case.obstacles)
    if not obs:
        return {}
    mu = case.friction if case.friction is not None else scene.friction
    return {"obstacles": obs, "friction": 0.0 if mu is None else float(mu)}


def obstacle_tables(obstacles, friction=None) -> list[dict]:
    """The ``[[obstacles]]`` tables of a scene file that read back as ``obstacles`` (with ``friction`` on the
    first, when given)."""
    out = []
    for o in obstacles:
        if isinstance(o, Disk):
            out.append({"disk": {"center": o.center.tolist(), "radius": o.radius,
                                 **({"free": True} if isinstance(o, FreeDisk) else {})}})
        elif isinstance(o, HalfPlane):
            out.append({"halfplane": {"point": o.point.tolist(), "normal": o.normal.tolist()}})
        else:
            out.append({"polygon": o.polygon.tolist()})
    if out and friction is not None:
        out[0]["friction"] = float(friction)
    return out


def solve_friction(kw: dict) -> dict:
    """The keywords ``kw`` (:func:`case_contact`) as a case's solves take them: without friction when one
    obstacle is a :class:`FreeDisk` (the disk follows the grip until nothing pushes it)."""
    if any(isinstance(o, FreeDisk) for o in kw.get("obstacles", ())):
        return dict(kw, friction=0.0)
    return dict(kw)
