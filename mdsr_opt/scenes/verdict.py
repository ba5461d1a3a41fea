"""The ``design`` cell of ``mdsr run``'s table: ``ok`` or ``FAILED``, the cause of a failure first, then the
flags that did not make it fail (saturated or dropped muscles, a layout that cannot be moulded).

Example
-------
>>> from types import SimpleNamespace as C
>>> design_verdict(C(success=False, message="design not verified: Solve_Succeeded; rejected by verification: "
...                  "the boundary crosses itself at node 3", saturated=["M2"], dropped=[], fabrication=[]))
'FAILED (rejected by verification: the boundary crosses itself at node 3; saturated M2)'
"""

from __future__ import annotations

import re

__all__ = ["design_verdict", "failure_cause"]

#: the longest cause a cell shows (the whole reason is in the run's log, its FAILED lines and summary.json)
MAX_CAUSE = 90


def _short(text: str, limit: int = MAX_CAUSE) -> str:
    text = " ".join(str(text).split()).replace("|", "/")
    return text if len(text) <= limit else text[:limit - 3].rstrip() + "..."


def _from_status(status: str) -> str:
    """The reason a design's ``status`` gives for its failure: the clause that rejected it, else the solver's
    own status (IPOPT's return status)."""
    for pattern, label in ((r"every muscle is idle", "every muscle idle: the design does not move the body"),
                           (r"rejected by verification: ([^;]*)", "rejected by verification: {}"),
                           (r"rejected: ([^;]*)", "rejected: {}"),
                           (r"not verified: ([^;]*)", "not verified: {}"),
                           (r"not verified \(verify=False\)", "not verified (verify=False)")):
        m = re.search(pattern, status)
        if m:
            return label.format(*m.groups())
    return re.split(r";| \(", status, maxsplit=1)[0].strip() or "design failed"


def failure_cause(message: str) -> str:
    """What made a case fail, in a few words, from its report's ``message``."""
    msg = str(message or "")
    if msg.startswith("design too far from the target:"):
        far = msg.split(":", 1)[1]
        m = re.search(r"is ([\d.]+ %) of the size .*more than max_difference (\S+ %)", far)
        if m:
            return f"too far from the target: {m.group(1)} of size, more than max_difference {m.group(2)}"
        m = re.search(r"removes (-?\d+ %) of the rest shape.*less than min_progress (\S+ %)", far)
        if m:
            return f"too far from the target: removes {m.group(1)} of the rest shape's difference, less than {m.group(2)}"
        return _short("too far from the target: " + far.strip())
    for head in ("design not verified: ", "design failed: "):
        if msg.startswith(head) and not msg.startswith(("design failed: RuntimeError", "design failed: SolverFailure")):
            return _short(_from_status(msg[len(head):]))
    if msg.startswith("target solve failed: "):
        return _short(f"target solve failed ({msg.split(': ', 1)[1]})")
    return _short(re.split(r" \(", msg, maxsplit=1)[0] or "failed")


def design_verdict(case) -> str:
    """The ``design`` cell for a case report (:class:`~mdsr_opt.scenes.runner.CaseReport`): ``ok`` or
    ``FAILED``, then in brackets the failure's cause first and the secondary flags after it."""
    notes = [] if case.success else [failure_cause(case.message)]
    if case.saturated:
        notes.append(f"saturated {', '.join(map(str, case.saturated))}")
    if case.dropped:
        notes.append(f"dropped {', '.join(d['name'] for d in case.dropped)}")
    if getattr(case, "fabrication", None):
        notes.append("not mouldable as laid out")
    return ("ok" if case.success else "FAILED") + (f" ({'; '.join(notes)})" if notes else "")
