"""A scene case with obstacles through the pipeline: its design's contact keywords, what the stages that
model no contact say, and the grip report of every disk it touches.

The design of a case with obstacles (:func:`obstacle_design`) is checked with them: unless the scene names
``method = "derivative-free"`` (whose search takes them in every forward solve), it is made as
:func:`~mdsr_opt.design_contractions` makes a design with contact and no method
(:mod:`~mdsr_opt.synthesis.contactdesign`): by a gradient method without the obstacles, kept when the
forward solve with them touches nothing, else by the derivative-free search with them; the case's note
(:func:`design_route`) says which. An external case's body is clamped where its target was anchored
(``held``), as :func:`~mdsr_opt.synthesis.pipeline.design_pipeline` does; the design's solves are
frictionless (friction enters the target's solve and the grip report).

A :class:`~mdsr_opt.Disk` stays FIXED where the scene puts it; a
:class:`~mdsr_opt.scenes.obstacles.FreeDisk` is moved by the case's target until the contacts' net force on
it vanishes (:func:`~mdsr_opt.mechanics.grip.free_disk`), and the design takes it there. The grip report
(:func:`case_grips`) asks whether the grip holds the disk once any support is taken away: friction at the
stated coefficient, within ``mu`` times each contact's normal force, must balance the contacts' net push on
it (:func:`~mdsr_opt.mechanics.grip.grip_report`; a fixed disk pushed harder from one side than the other
is not held); ``holding_force`` is then the largest load of any direction the grip resists (of 16
directions tried: a grip of two opposite contacts resists none along their line).
"""

from __future__ import annotations

import numpy as np

from ..mechanics.obstacles import Disk
from .obstacles import FreeDisk, case_contact

__all__ = ["PROTOTYPE_NOTE", "BANDS_NOTE", "obstacle_design", "design_route", "case_grips", "grip_line"]

#: said (report notes, log) for a case with obstacles in place of the virtual prototype's validation
PROTOTYPE_NOTE = ("prototype: not run for this case: the virtual prototype models no contact, so it would pass "
                  "through the case's obstacles")
#: said for a case with obstacles in place of its strokes' uncertainty bands
BANDS_NOTE = "no band: the bands' designs take no obstacles (a case with obstacles gets none)"


def obstacle_design(scene, case, opts: dict, obstacles=None) -> tuple[dict, list[str]]:
    """The design keywords ``opts`` of ``case`` with its obstacles (module docstring; ``obstacles``: as its
    target placed them, :attr:`~mdsr_opt.scenes.cases.CaseSetup.obstacles`, default the case's), and the
    notes that say what they change: ``(opts, notes)``; ``opts`` unchanged for a case without obstacles. How
    the design was made is said once it is made (:func:`design_route`): a ``method`` other than
    ``"derivative-free"`` is taken out (a design with obstacles and no method, module docstring) and a note
    says so."""
    kw = case_contact(scene, case)
    if not kw:
        return opts, []
    out = dict(opts, obstacles=list(obstacles) if obstacles is not None else kw["obstacles"])
    notes = []
    asked = out.pop("method", None)
    if asked == "derivative-free":
        out["method"] = asked
    elif asked is not None:
        notes.append(f"design: method {asked!r} asked, which takes no obstacles: designed without them and "
                     "checked with them, by the derivative-free search with them when they are touched")
    if case.kind == "external" and out.get("held") is None:
        out["held"] = case.anchors  # mounted where the target was clamped: the obstacles stand in that frame
        notes.append("design: the body clamped at the target's anchors (the obstacles stand in their frame), and "
                     "its difference measured there, with no rigid alignment to the target (a case without "
                     "obstacles is aligned first: its difference can be smaller than a mounted robot's)")
    if kw["friction"] > 0 and not any(isinstance(o, FreeDisk) for o in out["obstacles"]):
        notes.append(f"design: frictionless contact (the design's solves take no friction; the target's "
                     f"friction {kw['friction']:g} enters its solve and the grip report)")
    return out, notes


def design_route(scene, case, design) -> list[str]:
    """The note saying how the ``design`` of ``case`` met its obstacles (none for a case without them):
    its :attr:`~mdsr_opt.synthesis.results.DesignResult.contact_route` (a gradient design checked with them
    and untouched, or the derivative-free search with them and why), or the method named."""
    if not case_contact(scene, case):
        return []
    return [f"design: {design.contact_route}" if design.contact_route else
            f"design: by method {design.method!r} as named, its search taking the obstacles"]


def case_grips(scene, case, x, contact: dict | None, state: str, obstacles=None, free: dict | None = None) -> list[dict]:
    """The grip report of every disk among ``case``'s obstacles (:func:`~mdsr_opt.scenes.obstacles.case_contact`;
    ``obstacles``: as its target placed them, in that order) in the state ``x`` with its ``contact`` report (a
    solve's with those obstacles), named ``state`` (``"design"``, ``"target"``); ``free``: the target's
    :attr:`~mdsr_opt.scenes.cases.CaseSetup.free_disk`.

    Each entry: ``obstacle`` (its index among the case's obstacles, the scene's first), ``disk`` (centre,
    radius), ``fixed`` (False for a :class:`~mdsr_opt.scenes.obstacles.FreeDisk`, with ``start``, ``moved``
    and ``free_search`` of ``free``; True: fixed where the scene puts it, the module docstring), ``state``,
    ``friction``, ``touching`` (contacts on it),
    ``normal_forces`` and ``contact_points``, ``net_force`` (the contacts' net push on the disk),
    ``held`` (friction balances that push; False when nothing touches it), ``holding_force`` (the largest
    load of any direction held besides; None when not held), ``resisted`` (per direction of ``directions``)
    and ``force_unit``."""
    kw = case_contact(scene, case)
    if not kw or contact is None:
        return []
    from ..mechanics.grip import grip_report  # scipy.optimize: only where a case has obstacles

    out = []
    for i, o in enumerate(kw["obstacles"] if obstacles is None else obstacles):
        if not isinstance(o, Disk):
            continue
        g = grip_report(x, contact, o, kw["friction"], obstacle=i)
        touching = len(g["normal_forces"])
        held = bool(g["held"]) and touching > 0
        hf = g["holding_force"] if held and np.isfinite(g["holding_force"]) else None
        extra = {}
        if isinstance(o, FreeDisk) and free is not None:
            extra = {"start": free["start"], "moved": float(np.hypot(*(o.center - free["start"]))),
                     "free_search": {k: free[k] for k in ("converged", "iterations", "net_force")}}
        out.append({"obstacle": i, "disk": {"center": o.center.tolist(), "radius": o.radius},
                    "fixed": not isinstance(o, FreeDisk), **extra,
                    "state": state, "friction": kw["friction"], "touching": touching,
                    "normal_forces": g["normal_forces"], "contact_points": g["contact_points"],
                    "net_force": g["squeeze"], "held": held, "holding_force": hf, "resisted": g["resisted"],
                    "directions": g["directions"], "force_unit": contact.get("force_unit", "")})
    return out


def grip_line(g: dict) -> str:
    """One sentence of a grip report (:func:`case_grips`), for the log and the notes."""
    unit = f" {g['force_unit']}" if g.get("force_unit") else ""
    how = "fixed" if g["fixed"] else f"free: moved {g.get('moved', 0.0):.3g} to where the contacts' net force vanishes"
    head = f"grip: disk obstacles[{g['obstacle']}] ({how}) in the {g['state']}'s state"
    if not g["touching"]:
        return f"{head}: NOT HELD: the body does not touch it"
    N = ", ".join(f"{v:.3g}" for v in g["normal_forces"])
    net = float(np.hypot(*g["net_force"]))
    if g["held"]:
        verdict = f"HELD at friction {g['friction']:g}: it stays without a load" + (
            f" and resists any load up to {g['holding_force']:.3g}{unit}" if g["holding_force"] > 0 else
            ", but a load in the weakest direction (of 16), however small, slips it")
    else:
        verdict = (f"NOT HELD at friction {g['friction']:g}: friction cannot balance the contacts' net push of "
                   f"{net:.3g}{unit}")
    return f"{head}: {verdict} ({g['touching']} contact(s), normal forces {N}{unit})"
