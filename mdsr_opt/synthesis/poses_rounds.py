"""Every pose of :func:`~mdsr_opt.synthesis.poses.design_poses` designed on one shared layout (a *round*), and
the muscles no pose uses taken out of that layout.

:func:`design_round` designs each pose on the layout with the muscles it engages (their paths shorten in its
target) and leaves the others released (their ropes paid out to the designed state's path lengths, no
tension). :func:`drop_idle` then treats a muscle that pulls in no pose as
:func:`~mdsr_opt.synthesis.acceptance.design_active` treats an idle muscle of one design: released in every
pose, or designed below ``idle_contraction`` (or slack) in every successful pose design that engages it, it
is a rope a workshop would mould and thread for nothing. It is dropped from the layout and the poses that
engaged it are designed again without it; when one of those designs fails (and is not
:func:`~mdsr_opt.synthesis.acceptance.as_good` as before) the muscle is kept, with a
:class:`~mdsr_opt.synthesis.results.MuscleWarning` and a note.
"""

from __future__ import annotations

import inspect
import math
import warnings
from dataclasses import dataclass

import numpy as np

from ..mechanics.anchors import body_size
from .acceptance import IDLE_RTOL, DroppedMuscle, as_good, difference_failure, idle_mask

__all__ = ["PoseRound", "design_round", "drop_idle"]


@dataclass
class PoseRound:
    """Every pose designed on one layout.

    Attributes
    ----------
    muscles : tuple of Muscle
        The layout.
    contractions, strokes, tensions : (P, m) ndarrays
        As :class:`~mdsr_opt.synthesis.poses_result.PosesResult`'s.
    differences : (P,) ndarray
    ok : (P,) bool ndarray
        Each pose's verdict (converged, verified, moving the body towards its target).
    status : list of str
    states : list of (n, 2) ndarrays
    designs : dict pose name -> DesignResult
        The poses that engage a muscle.
    engaged : (P, m) bool ndarray
    caught : dict pose name -> list of warnings.WarningMessage
        The warnings each pose's design issued, held back (only the round kept issues them).
    """

    muscles: tuple
    contractions: np.ndarray
    strokes: np.ndarray
    tensions: np.ndarray
    differences: np.ndarray
    ok: np.ndarray
    status: list
    states: list
    designs: dict
    engaged: np.ndarray
    caught: dict


def _chains(muscles) -> list:
    return [tuple(int(n) for n in m.nodes) for m in muscles]


def _per_muscle(design, muscles, mesh):
    """(stroke, tension) of a design, read from its per-muscle fields when it has them."""
    a = np.asarray(design.contractions, dtype=float)
    L0 = np.array([m.rest_length(mesh) for m in muscles])
    stroke = getattr(design, "stroke", None)
    stroke = a * L0 if stroke is None or np.size(stroke) != len(a) else np.asarray(stroke, dtype=float)
    tension = getattr(design, "tension", None)
    tension = np.full(len(a), np.nan) if tension is None or np.size(tension) != len(a) else \
        np.asarray(tension, dtype=float)
    return stroke, tension


def same_design(mesh, sep, engaged, dopt) -> bool:
    """Is the separate ``(muscles, DesignResult)`` the design ``design_contractions(mesh, ..., engaged,
    **dopt)`` would make (same muscles in the same order, same recorded options)?"""
    from ..mechanics.anchors import anchor_radius_or_default
    from .contactdesign import gradient_method
    from .contractions import design_contractions
    from .fallback import FALLBACK_METHOD

    muscles, d = sep
    if d is None or _chains(muscles) != _chains(engaged):
        return False
    default = inspect.signature(design_contractions).parameters  # the options' defaults, not copies of them
    for key in ("method", "a_max", "muscle_model", "stiffness", "verify", "fixture_wall"):
        want = dopt.get(key, default[key].default)
        if key == "method" and want is None:  # design_contractions' choice: with contact either route
            grad = gradient_method(dopt.get("held"))
            allowed = (grad, "derivative-free") if dopt.get("contact") or dopt.get("obstacles") else (grad,)
            if getattr(d, "fallback", "") and d.method == FALLBACK_METHOD:  # the default's own fallback
                allowed += (FALLBACK_METHOD,)
            if d.method not in allowed:
                return False
        elif key == "verify":
            if want and d.verification is None:
                return False
            if want and want != "design" and not str(d.verification.forward_start or "rest").startswith("rest"):
                return False  # verified from its own state only: not the re-solve from rest asked for
        elif getattr(d, key, None) != want:  # a design that records no fixture_wall: not the same
            return False
    radius = anchor_radius_or_default(mesh, dopt.get("anchor_radius"))
    return bool(np.isclose(float(d.anchor_radius), radius, rtol=1e-12, atol=0.0))


def _again(previous: PoseRound | None, k: int, name: str, on_chains: list, dopt: dict):
    """For pose ``k`` designed again on a smaller layout: its design in ``previous`` and the options that start
    the new design from it (its contractions of the muscles kept and, unless ``warm_start`` says otherwise, its
    state), as :func:`~mdsr_opt.synthesis.acceptance.design_active` starts its design without the idle ones."""
    old = None if previous is None else previous.designs.get(name)
    if old is None:
        return None, {}
    was = {c: j for j, c in enumerate(_chains(previous.muscles))}
    more = {}
    if "initial_guess" not in dopt and all(c in was for c in on_chains):
        more["initial_guess"] = np.array([max(0.0, float(previous.contractions[k, was[c]])) for c in on_chains])
    ws = dopt.get("warm_start", True)
    if isinstance(ws, (bool, str)) and ws in (True, "target") and np.isfinite(np.asarray(old.x, dtype=float)).all():
        more["warm_start"] = np.asarray(old.x, dtype=float)
    return old, more


def design_round(mesh, material, items, muscles, dopt: dict, separate: dict, rest_differences, units,
                 previous: PoseRound | None = None) -> PoseRound:
    """Design every pose of ``items`` (:class:`~mdsr_opt.synthesis.poses.Pose` s) on the layout ``muscles``.

    A pose whose engaged muscles are those it engaged in ``previous`` (the same node chains) keeps that design;
    a pose that engages exactly its ``separate`` layout takes that design (:func:`same_design`); the others are
    designed with :func:`~mdsr_opt.synthesis.contractions.design_contractions` and ``dopt``, started from
    ``previous``'s design when there is one, which they replace when they fail but end
    :func:`~mdsr_opt.synthesis.acceptance.as_good`. Warnings are held back in ``caught``.
    """
    from .contractions import design_contractions

    P, m = len(items), len(muscles)
    L0 = np.array([mu.rest_length(mesh) for mu in muscles])
    A, S, T = np.zeros((P, m)), np.zeros((P, m)), np.full((P, m), np.nan)
    D, ok, status, states, designs, caught = np.zeros(P), np.zeros(P, bool), [], [], {}, {}
    engaged = np.zeros((P, m), bool)
    size = body_size(mesh)
    for k, p in enumerate(items):
        # a muscle whose path lengthens in this pose is released (its rope paid out, slack)
        engaged[k] = np.array([mu.length(p.target) for mu in muscles]) < L0 * (1.0 - 1e-9)
        on = np.flatnonzero(engaged[k])
        if not len(on):
            x = mesh.points.copy()
            D[k] = rest_differences[k]
            status.append("no muscle of the shared layout shortens in this pose: left at rest")
        else:
            pulling = [muscles[i] for i in on]
            chains = _chains(pulling)
            prev_on = None if previous is None else \
                _chains([previous.muscles[i] for i in np.flatnonzero(previous.engaged[k])])
            sep = separate.get(p.name)
            if prev_on == chains and p.name in previous.designs:  # the same NLP, already solved
                d, said = previous.designs[p.name], previous.caught.get(p.name, [])
            elif sep is not None and same_design(mesh, sep, pulling, dopt):
                d, said = sep[1], []  # the pose engages exactly its own layout: the same NLP, already solved
            else:
                old, more = _again(previous, k, p.name, chains, dopt)
                with warnings.catch_warnings(record=True) as said:
                    d = design_contractions(mesh, material, pulling, p.target, **dopt, **more)
                said = list(said)
                if not d.success and old is not None and as_good(d, old):
                    d.success = True
                    d.status += (f"; a success all the same: verified, at a difference {d.difference:.4g} no larger "
                                 f"than with the idle muscle(s) ({old.difference:.4g}, to {100 * IDLE_RTOL:g} %)")
            designs[p.name], caught[p.name] = d, said
            x = np.asarray(d.x, dtype=float)
            st, tn = _per_muscle(d, pulling, mesh)
            A[k, on], S[k, on], T[k, on] = d.contractions, st, tn
            D[k], ok[k] = d.difference, d.success
            status.append(str(d.status))
            why = difference_failure(D[k], size, math.inf, units, rest_difference=rest_differences[k])
            if ok[k] and why:  # converged and verified, but the layout barely moves the body towards this pose
                ok[k] = False
                status[-1] += f"; {why}"
        off = np.flatnonzero(~engaged[k])
        if len(off):  # released: the rope at exactly the path's length (paid out or slack taken up), no tension
            Lx = np.array([muscles[i].length(x) for i in off])
            S[k, off] = L0[off] - Lx
            A[k, off] = S[k, off] / L0[off]
            T[k, off] = 0.0
        states.append(x)
    return PoseRound(tuple(muscles), A, S, T, D, ok, status, states, designs, engaged, caught)


def _unused(rnd: PoseRound, names, thr: float, drop_slack: bool) -> tuple[np.ndarray, list]:
    """(P, m) bool: muscle ``j`` pulls not in pose ``k`` (released there, or left idle by its successful design),
    and per muscle the words for each pose."""
    P, m = rnd.engaged.shape
    out = ~rnd.engaged
    for k, name in enumerate(names):
        d, on = rnd.designs.get(name), np.flatnonzero(rnd.engaged[k])
        if d is not None and d.success and len(on):
            out[k, on] = idle_mask(d, thr, drop_slack)
    words = []
    for j in range(m):
        said = []
        for k, name in enumerate(names):
            a = rnd.contractions[k, j]
            said.append(f"{name}: released (its path lengthens)" if not rnd.engaged[k, j] else
                        f"{name}: contraction {a:.3g} below idle_contraction {thr:g}" if a < thr else
                        f"{name}: slack (contraction {a:.3g}, no tension)")
        words.append("; ".join(said))
    return out, words


def drop_idle(mesh, material, items, rnd: PoseRound, dopt: dict, separate: dict, rest_differences, units, *,
              thr: float, drop_slack: bool, notes: list) -> tuple[PoseRound, tuple, list]:
    """The muscles of ``rnd``'s layout that pull in no pose (released, or designed below ``thr`` or, with
    ``drop_slack``, slack wherever engaged) dropped, and the poses that engaged them designed
    again without them (:func:`design_round`), until every muscle pulls in some pose.

    A design without them that fails (and is not :func:`~mdsr_opt.synthesis.acceptance.as_good` as the one
    with them), or a pose that was a success and is no more, keeps them: a
    :class:`~mdsr_opt.synthesis.results.MuscleWarning` and a note name them. Every muscle idle (the layout moves
    no pose) drops none. Each drop is said in ``notes``.

    Returns
    -------
    round : PoseRound
        The round kept.
    dropped : tuple of DroppedMuscle
        Its ``contraction``: the largest over the poses.
    kept : list of str
        The idle muscles kept.
    """
    from .results import MuscleWarning

    names = [p.name for p in items]
    dropped: list[DroppedMuscle] = []
    while thr > 0 or drop_slack:
        unused, words = _unused(rnd, names, thr, drop_slack)
        idle = unused.all(axis=0)
        if not idle.any() or idle.all():
            return rnd, tuple(dropped), []
        keep = np.flatnonzero(~idle)
        gone = [j for j in range(len(rnd.muscles)) if idle[j]]
        label = ", ".join(rnd.muscles[j].name for j in gone)
        again = design_round(mesh, material, items, tuple(rnd.muscles[j] for j in keep), dopt, separate,
                             rest_differences, units, previous=rnd)
        hit = [k for k in range(len(names)) if rnd.engaged[k, gone].any()]
        worse = [k for k in hit if (names[k] in again.designs and not again.designs[names[k]].success)
                 or (rnd.ok[k] and not again.ok[k])]
        if worse:
            why = "; ".join(f"{names[k]}: {again.status[k]}" for k in worse)
            text = (f"idle muscle(s) {label} kept in the shared layout (no pose uses them: "
                    + " | ".join(f"{rnd.muscles[j].name}: {words[j]}" for j in gone)
                    + f"): the design without them failed ({why}); they may be left out of the build")
            notes.append(text)
            warnings.warn(f"design_poses: {text}", MuscleWarning, stacklevel=4)
            return rnd, tuple(dropped), [rnd.muscles[j].name for j in gone]
        for j in gone:
            mu = rnd.muscles[j]
            dropped.append(DroppedMuscle(name=mu.name, nodes=tuple(int(n) for n in mu.nodes),
                                         contraction=float(np.nanmax(rnd.contractions[:, j])),
                                         reason=f"idle in every pose ({words[j]})"))
            again_by = [names[k] for k in hit if rnd.engaged[k, j]]
            notes.append(f"idle muscle {mu.name} dropped from the shared layout: no pose uses it ({words[j]})"
                         + (f"; pose(s) {', '.join(again_by)} designed again without it" if again_by else ""))
        rnd = again
    return rnd, tuple(dropped), []
