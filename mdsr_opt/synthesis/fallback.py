"""When the default design fails: the flattened NLP's failure made good by the nested method.

The flattened NLP (:mod:`~mdsr_opt.synthesis.nlp`) poses equilibrium as constraints, and IPOPT may trade a
small violation of them for a large drop of the difference. On a body with a soft mode (trial12's mm dumbbell:
two discs of radius 20 joined by a neck 6 wide, one disc turned 40 degrees about the neck) a force residual
of a tenth of ``E t h`` turns the disc far, so its iterates left the equilibria at once, its restoration
phases kept coming back, and it stopped at its iteration limit at a state that was not an equilibrium; where
it stopped changed completely when the drags changed by 7e-15. The nested method (:mod:`~mdsr_opt.synthesis.
rivals`) only ever evaluates equilibria, and designed the same case in about a second.

So a design that did not name its method (``design_contractions(method=None)``: the pipeline, ``mdsr run``,
``design_poses`` unless told) and whose flattened design failed (not converged, or rejected by its
verification) is made again by ``method="nested"`` (:data:`FALLBACK_METHOD`): first from the flattened
attempt's contractions when they are usable (finite, within their bounds), then from the usual start. The
first success is the result; its ``method`` is ``"nested"``, its ``fallback`` and ``status`` say why. When
both fail the flattened result is returned, its ``status`` and ``fallback`` saying what was tried. A caller
who names ``method="flattened"``, or gives IPOPT ``options`` (which address the flattened method), gets no
fallback, and a failure's ``status`` suggests the nested method (:data:`NESTED_HINT`). A flattened design
that succeeds is returned as before.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np

_LOG = logging.getLogger(__name__)

__all__ = ["FALLBACK_METHOD", "NESTED_HINT", "design_with_fallback", "fallback_starts"]

#: the method that makes a failed default (flattened) design again
FALLBACK_METHOD = "nested"

#: appended to the status of a flattened design that failed when the caller named ``method="flattened"``
NESTED_HINT = ("; method='nested' (an outer search over the contractions, each trial an equilibrium) may succeed "
               "where the flattened NLP failed: the default (no method, no IPOPT options) tries it on its own")


def fallback_starts(failed, a0, a_upper) -> list[tuple[str, np.ndarray]]:
    """The starting contractions of the fallback designs, each with a phrase saying what it is: the failed
    design's ``contractions`` when they are usable (finite, in ``[0, a_upper]``, not the usual start), then
    the usual start ``a0``."""
    a0 = np.asarray(a0, dtype=float)
    a = np.asarray(getattr(failed, "contractions", ()), dtype=float).reshape(-1)
    up = np.asarray(a_upper, dtype=float).reshape(-1)
    starts = []
    if a.shape == a0.shape and np.isfinite(a).all() and (a >= 0.0).all() and (a <= up + 1e-12).all() \
            and not np.allclose(a, a0, rtol=0.0, atol=1e-12):
        starts.append(("the flattened attempt's contractions", a.copy()))
    starts.append(("the usual start", a0.copy()))
    return starts


def design_with_fallback(failed, redesign: Callable, a0, a_upper, clock0: float):
    """The result of a failed default (flattened) design ``failed``: the first of the nested designs
    ``redesign(start)`` (from :func:`fallback_starts`) that succeeds, else ``failed`` saying what was tried.

    Parameters
    ----------
    failed : DesignResult
        The flattened design, ``success`` False.
    redesign : callable
        ``redesign(a_start) -> DesignResult``: the same problem designed by :data:`FALLBACK_METHOD` from the
        contractions ``a_start``.
    a0, a_upper : (m,) arrays
        The usual starting contractions and each muscle's upper bound.
    clock0 : float
        ``time.perf_counter()`` at the start of the whole design (the result's ``time`` covers every attempt).
    """
    why = failed.reason  # its status, and the verification's message when that failed
    tried = []
    for where, start in fallback_starts(failed, a0, a_upper):
        _LOG.info("design: the default flattened design failed (%s); designing again by method=%r from %s",
                  why, FALLBACK_METHOD, where)
        res = redesign(start)
        if res.success:
            res.count_in([failed] + [r for _w, r in tried], clock0, build_time=True)
            res.fallback = (f"the default method='flattened' failed ({why}); method={FALLBACK_METHOD!r} designed "
                            f"it, started from {where}")
            res.status += f"; designed by method={FALLBACK_METHOD!r}: {res.fallback}"
            _LOG.info("design: method=%r succeeded where the flattened design failed", FALLBACK_METHOD)
            return res
        tried.append((where, res))
    failed.count_in([r for _w, r in tried], clock0, build_time=True)
    said = "; ".join(f"from {where}: {r.status}" for where, r in tried)
    failed.fallback = f"method={FALLBACK_METHOD!r} was tried too after the flattened design failed, and failed ({said})"
    failed.status += f"; method={FALLBACK_METHOD!r} tried too (the default's fallback), and failed: {said}"
    return failed
