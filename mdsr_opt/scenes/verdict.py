"""What made a design fail, in the user's words: the ``FAILED`` lines of ``mdsr run`` (:func:`plain_failure`: the
cause first, once, and what helps) and the ``design`` cell of its table (:func:`design_verdict`: ``ok`` or
``FAILED``, the cause first, then the flags that did not make it fail: saturated or dropped muscles, a layout
that cannot be moulded). A case whose validation against the virtual prototype failed fails
(:func:`prototype_verdict`): a design the finer model cannot reproduce is no success. The solvers' own status,
with every clause, stays in ``summary.json``.

Example
-------
>>> from types import SimpleNamespace as C
>>> design_verdict(C(success=False, message="design not verified: Solve_Succeeded; rejected by verification: "
...                  "the boundary crosses itself at node 3", saturated=["M2"], dropped=[], fabrication=[]))
'FAILED (the body would touch itself; saturated M2)'
"""

from __future__ import annotations

import re

from ..core.results import one_line

__all__ = ["design_verdict", "failure_cause", "plain_failure", "prototype_failure", "prototype_verdict",
           "saturation_line"]

#: the longest cause a cell shows (the whole reason is in the run's log, its FAILED lines and summary.json)
MAX_CAUSE = 90

#: a solver's status that names a success: never shown as (part of) a failure's cause
_SUCCESS = re.compile(r"\b(Solve_Succeeded|Solved_To_Acceptable_Level|converged|Optimization terminated "
                      r"successfully\.?)\b[;,]?\s*")

#: the virtual prototype's validations of a case (keys of its report's ``photo["prototype"]``), each by what
#: drove the prototype: a failed one fails the case (:func:`prototype_verdict`)
PROTOTYPE_PARTS = (("design", "driven by the design"), ("driving", "driven as the case"))

#: the head of the message of a case failed by its virtual prototype
PROTOTYPE_FAILED = "virtual prototype failed: "

#: the causes a design's status may hold, most telling first: (pattern, what happened, what helps)
_CAUSES = (
    (r"boundary crosses itself and no new contact pair",  # contact on: the solver lost the fold
     "the contact solve could not follow the body as it folds onto itself",
     "ask for a smaller deformation, or a finer mesh"),
    (r"boundary crosses itself",
     "the body would touch itself",
     "its outline crosses itself; turn contact on (contact=True in Python, contact = true under [design] in a "
     "scene file)"),
    (r"every muscle is idle",
     "every muscle is idle: the design does not move the body",
     "muscles only pull: the target must shorten the body along them (or lower idle_contraction, if set high)"),
    (r"target is not a stable equilibrium",
     "the target is not stable under its drags",
     "drag less far or anchor more nodes"),
    (r"target is not an equilibrium",
     "the target is not an equilibrium of its drags",
     "drag less far or anchor more nodes"),
    (r"inverts an element|inverted an element",
     "the shape would turn elements inside out",
     "ask for a smaller deformation, or a finer mesh"),
    (r"end fixtures meet in the designed state: rope (\S+) at a = (\S+) leaves (\S+) of rope between its end "
     r"fixtures' centres.*?need \((\S+)\)",
     "the end fixtures of rope {0} would meet: at a = {1} {2} of rope is left between their centres, {3} needed",
     "smaller fixtures (anchor_radius, or fixture_radius under [fabrication]) or longer muscles"),
    (r"not a (stable equilibrium|minimum of the energy)",
     "the designed shape is not stable (the body would snap to another shape)",
     "ask for a smaller deformation, or give more muscles (routing max_muscles)"),
    (r"gap \S+ between the design's state and the forward re-solve",
     "the muscles, pulled from rest, reach another shape than the design's",
     "try warm_start = \"rest\" under [design]"),
    (r"load stepping stalled at fraction (\S+)",
     "the solver could not follow the load past a fraction {0} of it",
     "ask for a smaller deformation, or a finer mesh"),
    (r"Maximum_Iterations_Exceeded|ITERATIONS REACHED LIMIT|max_iter",
     "the optimiser ran out of iterations",
     "raise max_iter under [design]"),
    (r"not verified \(verify=False\)",
     "not verified (verify=False), so the solver's acceptable exit is not a success",
     "verify the design (verify = true)"),
)


def _short(text: str, limit: int = MAX_CAUSE) -> str:
    """``text`` cut cleanly to ``limit`` characters (:func:`~mdsr_opt.core.results.one_line`), with no ``|``
    (it would split a Markdown table's cell)."""
    return one_line(str(text).replace("|", "/"), limit)


def _solver_status(status: str) -> str:
    """A solver's status with its success words removed (``Solve_Succeeded; rejected: ...`` is a failure)."""
    return _SUCCESS.sub("", str(status or "")).strip(" ;,")


def causes(status: str) -> list[tuple[str, str]]:
    """The known causes in a design's ``status``, each once: ``(what happened, what helps)``."""
    out, status = [], str(status or "")
    for pattern, what, helps in _CAUSES:
        m = re.search(pattern, status)
        said = what.format(*m.groups()) if m else what if "{" not in what and what in status else None
        if said and all(w != said for w, _ in out):  # a line already in the user's words keeps its cause
            out.append((said, helps))
    return out


def plain_failure(status: str) -> str:
    """A design's failure, from its ``status``, in the user's words: the first cause, once, then what helps;
    a status holding no known cause gives the solver's own words without its success statuses.

    Example
    -------
    >>> plain_failure("Solve_Succeeded; rejected by verification: forward re-solve failed (Solve_Succeeded; "
    ...               "rejected: the boundary crosses itself (contact is off))")
    'the body would touch itself: its outline crosses itself; turn contact on (contact=True in Python, contact = true under [design] in a scene file)'
    """
    found = causes(status)
    if found:
        return f"{found[0][0]}: {found[0][1]}"
    return _short(_solver_status(re.split(r" \(", str(status or ""), maxsplit=1)[0]) or "design failed", 200)


def failure_cause(message: str) -> str:
    """What made a case fail, in a few words (no advice), from its report's ``message``."""
    msg = str(message or "")
    if msg.startswith(PROTOTYPE_FAILED):  # which validation, then the prototype's own status, cut to fit
        return _short("virtual prototype failed " + re.sub(r"^driven [^(]*", "", msg[len(PROTOTYPE_FAILED):]))
    if msg.startswith("design too far from the target:"):
        far = msg.split(":", 1)[1]
        m = re.search(r"is ([\d.]+ %) of the size .*more than max_difference (\S+ %)", far)
        if m:
            return f"too far from the target: {m.group(1)} of size, more than max_difference {m.group(2)}"
        m = re.search(r"removes (-?[\d.]+ %) of the rest shape.*less than min_progress (\S+ %)", far)
        if m:
            return f"too far from the target: removes {m.group(1)} of the rest shape's difference, less than {m.group(2)}"
        return _short("too far from the target: " + far.strip())
    if msg.startswith("target solve failed: "):
        found = causes(msg)
        why = found[0][0] if found else _solver_status(msg.split(": ", 1)[1])
        return _short(f"target solve failed: {why or 'no equilibrium'}")
    if msg.startswith("routing failed: "):  # the body or mesh holds no rope: its cause, before the numbers
        return _short("routing failed: " + msg[len("routing failed: "):].split(":", 1)[0])
    if msg.startswith(("design failed: RuntimeError", "design failed: SolverFailure")):
        return _short(re.split(r" \(", msg, maxsplit=1)[0])
    found = causes(msg)
    if found:
        return _short(found[0][0])
    for head in ("design rejected: ", "design not verified: ", "design failed: "):
        if msg.startswith(head):
            msg = msg[len(head):]
    return _short(_solver_status(re.split(r";| \(", msg, maxsplit=1)[0]) or "failed")


def prototype_failure(photo) -> str:
    """What failed in a case's validation against the virtual prototype, from its report's ``photo`` (its
    ``"prototype"`` entries, :func:`~mdsr_opt.scenes.prototype.validate_case`): each failed part with its
    table and the prototype's status; ``""`` when every part that ran succeeded, or none ran."""
    proto = (photo or {}).get("prototype") or {}
    out = []
    for key, what in PROTOTYPE_PARTS:
        entry = proto.get(key)
        if isinstance(entry, dict) and not entry.get("success", False):
            out.append(f"{what} (Table {entry.get('table', '?')}): {entry.get('status') or 'failed'}")
    return "; ".join(out)


def prototype_verdict(case) -> bool:
    """Fail a case (a :class:`~mdsr_opt.scenes.runner.CaseReport`) whose validation against the virtual
    prototype failed (:func:`prototype_failure`): ``success`` False and ``message`` ``"virtual prototype
    failed: ..."``. Returns True when it turned a success into this failure (the caller says so); a case that
    failed already keeps its first cause (its design cell names the prototype's failure too)."""
    why = prototype_failure(case.photo)
    if not why or not case.success:
        return False
    case.success, case.message = False, PROTOTYPE_FAILED + why
    return True


def design_verdict(case) -> str:
    """The ``design`` cell for a case report (:class:`~mdsr_opt.scenes.runner.CaseReport`): ``ok`` or
    ``FAILED``, then in brackets the failure's cause first and the secondary flags after it."""
    notes = [] if case.success else [failure_cause(case.message)]
    if not case.success and not str(case.message).startswith(PROTOTYPE_FAILED) and prototype_failure(
            getattr(case, "photo", None)):
        notes.append("virtual prototype failed too")
    if case.saturated:
        notes.append(f"saturated {', '.join(map(str, case.saturated))}")
    if case.dropped:
        notes.append(f"dropped {', '.join(d['name'] for d in case.dropped)}")
    if getattr(case, "idle_kept", None):
        notes.append(f"idle {', '.join(map(str, case.idle_kept))} kept")
    if getattr(case, "fabrication", None):
        notes.append("not mouldable as laid out")
    for g in getattr(case, "grip", None) or ():  # a disk the case touches: held or not (scenes.grips)
        notes.append(f"disk {g['obstacle']} {'held' if g['held'] else 'NOT HELD'} at friction {g['friction']:g}")
    return ("ok" if case.success else "FAILED") + (f" ({'; '.join(notes)})" if notes else "")


def saturation_line(design) -> str:
    """The log line naming a design's saturated muscles (:attr:`~mdsr_opt.synthesis.results.DesignResult.
    saturated`), those stopped by their end fixtures' cap below ``a_max`` marked ``(fixture cap)``."""
    capped = design.capped
    names = [f"{n}{' (fixture cap)' if c else ''}" for n, s, c in zip(design.names, design.saturated, capped) if s]
    return f"saturated at a_max = {design.a_max:g}{' or their fixture cap' if capped.any() else ''}: {', '.join(names)}"
